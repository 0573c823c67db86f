"""``afa poll``, ``afa sensor3d get`` and ``afa top`` against a recording (``--log``):
answers as the replay gives them at ``--at`` T, the scan at T in the Raptor frame through
the recorded geometry, the Launcher's table the recorder wrote. Expected values come from
the recorded system's own construction (tests/tools/recorded.py: scan k at t = 0.1 k s,
its second point 2 + 0.1 k m ahead; the laser's mount 0.5 m ahead of and 1 m above the
rear axle) and from the file read with the ``mcap`` package, not with afa's reader."""

from __future__ import annotations

import base64
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from tests.tools.conftest import Tool

pytest.importorskip("afa.log.recorder", reason="the log mode needs afa.log")

ROOT = Path(__file__).resolve().parents[2]


def log_times(path: Path, topic: str) -> list[float]:
    """Seconds of every message on ``topic``, read with the mcap package."""
    with path.open("rb") as stream:
        return [message.log_time / 1e9 for _, channel, message in
                make_reader(stream).iter_messages() if channel.topic == topic]


def scan(t: float) -> int:
    """The number of the laser's scan stamped ``t``."""
    return round(t / 0.1)


def latest(times: list[float], at: float) -> float:
    return max(t for t in times if t <= at)


def stamp(t: float) -> dict[str, int]:
    """A TimeIDL's JSON of ``t``."""
    return {"sec": int(t), "usec": round((t - int(t)) * 1e6)}


def far_point(body: dict) -> float:
    """x of the second point of a scan's lossless JSON (float32, base64)."""
    array = body["points"]
    assert array["shape"] == [2, 3]
    return float(np.frombuffer(base64.b64decode(array["data"]), dtype=array["dtype"])[3])


def test_poll_answers_from_a_recording_as_the_replay_does(recording: Path, tool: Tool) -> None:
    scans = log_times(recording, "/Raptor/Laser11")
    assert len(scans) == 34 and log_times(recording, "/afa/poll/Raptor/ModelService/"
                                                     "getTransformation") == [0.0]

    def polled(*args: str) -> dict:
        return json.loads(tool("poll", *args, "--json", "--log", str(recording)).stdout)

    at = polled("Laser11", "get3dSeqFullScan", "--at", "1.25")  # the latest at or before
    assert at["time"] == stamp(latest(scans, 1.25))
    assert far_point(at) == pytest.approx(2 + 0.1 * scan(latest(scans, 1.25)))
    end = polled("Laser11", "get3dSeqFullScan")  # default: the end of the recording
    assert end["time"] == stamp(scans[-1]) and far_point(end) == pytest.approx(5.4)
    after = polled("Laser11", "get3dSeqWaitFullScan", "--at", "1.25")  # getWait: the next
    assert after["time"] == stamp(min(t for t in scans if t > 1.25))
    # a recorded call with the same arguments answers with its recorded result
    pose = polled("ModelService", "getTransformation", "Raptor:RearAxleCenter",
                  "FrontNoddingSICKLeft:Base")
    assert pose["poseValidFlag"] is True and pose["HTransform"]["shape"] == [4, 4]
    text = tool("poll", "ModelService", "getTransformation", "Raptor:RearAxleCenter",
                "FrontNoddingSICKLeft:Base", "--log", str(recording)).stdout
    assert text.startswith("PoseTransformIDL ") and "poseValidFlag=True" in text


def test_poll_on_a_recording_names_what_it_lacks(recording: Path, tool: Tool,
                                                 tmp_path: Path) -> None:
    scans = log_times(recording, "/Raptor/Laser11")
    log = str(recording)
    other = tool("poll", "ModelService", "getTransformation", "Raptor:RearAxleCenter",
                 "Nobody:Nothing", "--log", log, check=False)
    assert other.returncode == 1
    assert other.stderr == ("afa poll: EDevIO: Raptor/ModelService.getTransformation("
                            "'Raptor:RearAxleCenter', 'Nobody:Nothing'): not in the "
                            "recording (yet)\n")
    nobody = tool("poll", "Nobody", "getPose", "--log", log, check=False)
    assert nobody.returncode == 1 and "has no recorded server 'Nobody'; it has " \
        "Raptor/Laser11, Raptor/ModelService" in nobody.stderr
    method = tool("poll", "ModelService", "getNothing", "--log", log, check=False)
    assert method.returncode == 2 and "Platform has no method 'getNothing'" in method.stderr
    arguments = tool("poll", "ModelService", "getTransformation", "one", "--log", log,
                     check=False)
    assert arguments.returncode == 2 and "missing argument B" in arguments.stderr
    before = tool("poll", "Laser11", "get3dSeqFullScan", "--at", "0.05", "--log", log,
                  check=False)
    assert before.returncode == 1 and "no Laser11 (recorded) received yet" in before.stderr
    late = tool("poll", "Laser11", "get3dSeqWaitFullScan", "--log", log, check=False)
    assert late.returncode == 1 and late.stderr == (  # nothing after the end
        "afa poll: EDevIO: Raptor/Laser11.get3dSeqWaitFullScan: nothing recorded after "
        f"t={scans[-1]:.6f} answers it\n")
    outside = tool("poll", "Laser11", "get3dSeqFullScan", "--at", "9", "--log", log,
                   check=False)
    assert outside.returncode == 1 and "--at 9 s is outside" in outside.stderr
    assert f"lasts {scans[-1]:.3f} s" in outside.stderr
    live = tool("poll", "Laser11", "get3dSeqFullScan", "--at", "1", check=False)
    assert live.returncode == 2 and "give --log FILE.mcap" in live.stderr
    following = tool("sensor3d", "get", "Laser11", "--next", "--connect", "tcp/127.0.0.1:9",
                     check=False)
    assert following.returncode == 2 and "--next steps through a recording" in following.stderr
    missing = tool("poll", "Laser11", "get3dSeqFullScan", "--log", str(tmp_path / "no.mcap"),
                   check=False)
    assert missing.returncode == 1 and "no.mcap: cannot open: No such file" in missing.stderr
    (tmp_path / "text.mcap").write_text("not a recording\n")
    invalid = tool("poll", "Laser11", "get3dSeqFullScan", "--log", str(tmp_path / "text.mcap"),
                   check=False)
    assert invalid.returncode == 1 and "text.mcap: not an MCAP file" in invalid.stderr


def points_of(k: int) -> list[str]:
    """Scan k in the Raptor frame: the mount's offset (0.5, 0, 1) added."""
    return ["1.500 0.000 1.000", f"{2.5 + 0.1 * k:.3f} 0.000 1.000"]


def test_sensor3d_get_prints_the_scan_at_a_time_in_the_raptor_frame(
        recording: Path, tool: Tool) -> None:
    scans = log_times(recording, "/Raptor/Laser11")
    lines = tool("sensor3d", "get", "Laser11", "--at", "2.04", "--log",
                 str(recording)).stdout.splitlines()
    t = latest(scans, 2.04)
    assert lines == [f"# Laser11 t={t:.6f} sensor 11 frame FrontNoddingSICKLeft:Base -> "
                     "Raptor:RearAxleCenter: 2 points, 2 shown", *points_of(scan(t))]
    # --next: the scans after --at, one per --count
    following = tool("sensor3d", "get", "Laser11", "--at", "2.04", "--next", "--count", "2",
                     "--log", str(recording)).stdout.splitlines()
    assert [line.split()[2] for line in following if line.startswith("#")] == [
        "t=2.100000", "t=2.200000"]
    assert following[1:3] == points_of(21) and following[4:6] == points_of(22)
    # the same text as the stream of that scan (and as live: the same printer)
    stream = tool("sensor3d", "stream", "Laser11", "--log", str(recording)).stdout.splitlines()
    start = stream.index(lines[0])
    assert stream[start:start + 3] == lines
    # before the first scan: the next one
    first = tool("sensor3d", "get", "Laser11", "--at", "0.05", "--log",
                 str(recording)).stdout.splitlines()
    assert first[0].startswith("# Laser11 t=0.100000 ") and first[1:] == points_of(1)


def test_sensor3d_get_uses_the_recorded_geometry_without_a_recorded_poll(
        geometry_recording: Path, tool: Tool) -> None:
    assert not any(t for t in log_times(geometry_recording, "/afa/poll/Raptor/ModelService/"
                                                            "getTransformation"))
    assert log_times(geometry_recording, "/viz/tf")  # the recorder's static transforms
    lines = tool("sensor3d", "get", "Laser11", "--at", "1.0", "--log",
                 str(geometry_recording)).stdout.splitlines()
    # this recording starts at the first scan, t=0.1: --at counts from there
    assert lines[0].startswith("# Laser11 t=1.100000 ") and lines[1:] == points_of(11)
    missing = tool("sensor3d", "get", "Laser11", "--frame", "Raptor:Nowhere", "--log",
                   str(geometry_recording), check=False)
    assert missing.returncode == 1 and "no recorded geometry of that frame" in missing.stderr
    wrong = tool("sensor3d", "get", "ModelService", "--log", str(geometry_recording),
                 check=False)
    assert wrong.returncode == 2 and "ModelService does not serve Range3dSensor" in wrong.stderr


def table_rows(text: str) -> dict[str, list[str]]:
    lines = text.strip().splitlines()
    header = lines.index(next(line for line in lines if line.startswith("COMPONENT")))
    return {line.split()[0]: line.split()[1:] for line in lines[header + 1:]}


def test_top_shows_the_recorded_launcher_table(recording: Path, tool: Tool) -> None:
    tables = log_times(recording, "/afa/statistics")
    assert tables == pytest.approx([1.1, 2.1, 3.1])  # once per flush period (1 s)
    scans = log_times(recording, "/Raptor/Laser11")
    text = tool("top", "--log", str(recording), "--once").stdout
    title, head, columns, *_ = text.splitlines()
    assert title == "# small.mcap at 3.100 s"  # default: the last table
    assert head.startswith("Raptor/main  pid ") and "VirtualClock t=3.1 s" in head
    assert "memory" in head and "components' loop share" in head
    assert columns.split() == ["COMPONENT", "TYPE", "STATE", "HEALTH", "RESTARTS", "IN", "OUT",
                               "LOOP", "LONGEST"]
    rows = table_rows(text)
    assert set(rows) == {"model", "laser", "display"}
    # the scan of the table's own instant is published after the table is taken
    published = sum(t < 3.1 - 1e-9 for t in scans)
    assert rows["laser"][:6] == ["Laser", "running", "ok", "0", "0", str(published)]
    assert rows["model"][:6] == ["Model", "running", "ok", "0", "0", "0"]
    assert all(row[-3].endswith("%") and row[-1] == "ms" for row in rows.values())
    # --at: the table at or before it; refreshes step through recorded time
    earlier = tool("top", "--log", str(recording), "--at", "2.5", "--once").stdout
    assert earlier.startswith("# small.mcap at 2.100 s")
    assert table_rows(earlier)["laser"][5] == str(sum(t < 2.1 - 1e-9 for t in scans))
    stepping = tool("top", "--log", str(recording), "--at", "1.1", "--interval", "1").stdout
    assert [line for line in stepping.splitlines() if line.startswith("# ")] == [
        "# small.mcap at 1.100 s", "# small.mcap at 2.100 s", "# small.mcap at 3.100 s"]
    listed = tool("log", "info", str(recording)).stdout.splitlines()
    assert listed[listed.index("the Launcher's table (afa top --log):") + 1].split() == [
        "/afa/statistics", "3", "0.882", "Hz"]  # 3 tables over the 3.4 s recording
    none = tool("top", "--log", str(recording), "--at", "0.5", check=False)
    assert none.returncode == 1 and "no component statistics at or before 0.5 s; the first " \
        "is at 1.100 s" in none.stderr


def test_the_log_options_are_in_the_help(tool: Tool) -> None:
    for command, words in ((["poll"], ["--log FILE.mcap", "--at T", "getWait"]),
                           (["sensor3d", "get"], ["--log FILE.mcap", "--at T", "--next"]),
                           (["top"], ["--log FILE.mcap", "--at T", "--interval"])):
        text = " ".join(tool(*command, "--help").stdout.split())
        assert all(word in text for word in words), (command, text)


def test_a_closed_pipe_ends_a_log_tool_quietly(recording: Path) -> None:
    shell = (f"{sys.executable} -m afa sensor3d get Laser11 --at 0 --next --count 30 --log "
             f"{recording} | head -1; echo status ${{PIPESTATUS[0]}}")
    result = subprocess.run(["bash", "-c", shell], cwd=ROOT, capture_output=True, text=True,
                            timeout=60, env={**os.environ, "PYTHONPATH": str(ROOT)})
    lines = result.stdout.splitlines()
    assert lines[0].startswith("# Laser11 t=") and lines[-1] == "status 0", result.stderr
    assert "Traceback" not in result.stderr and "BrokenPipe" not in result.stderr
