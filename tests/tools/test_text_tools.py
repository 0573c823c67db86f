"""The text tools against a running system (the vehicle process of the simulated Raptor,
bridged on a loopback port, in real time) and against a recording: output, exit codes,
Ctrl-C, a closed pipe, an unreachable system. Most run in this process through
``afa.cli.main`` (a tool is a short-lived Zenoh session); Ctrl-C and a closed pipe are
tried on real child processes."""

from __future__ import annotations

import asyncio
import json
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from tests.bridge.conftest import ROOT, Peer, environment
from tests.bridge.parts import endpoint, free_port
from tests.tools.conftest import Ran, Tool

pytest.importorskip("zenoh", reason="the tools need the extra afa[zenoh]")

RAPTOR = ROOT / "configs" / "raptor.xml"


@pytest.fixture(scope="module")
def running() -> Iterator[str]:
    """The simulated Raptor with a bridge on a free loopback port; its endpoint."""
    where = endpoint(free_port())
    raptor = Peer(["-m", "afa", "run", str(RAPTOR), "--sim", "--duration", "600", "--process",
                   "vehicle", "--listen", where], ready="never")
    try:
        deadline = time.monotonic() + 90
        while not asyncio.run(_serves(where, {"Raptor/ModelService", "Raptor/Laser11",
                                              "Raptor/Stereo", "Raptor/RaptorMotion"})):
            assert raptor.process.poll() is None, raptor.errors[-10:]
            assert time.monotonic() < deadline, "the simulated Raptor did not come up"
            time.sleep(0.2)
        yield where
    finally:
        raptor.stop()


async def _serves(where: str, names: set[str]) -> bool:
    """Whether the process at ``where`` serves all of ``names`` yet."""
    from afa.tools.attach import Attachment

    async with Attachment([where], timeout=1.0) as link:
        infos = await link.infos()
    served = {row["name"] for info in infos for row in info.get("names", [])}
    return names <= served


def afa(*args: str, check: bool = True, timeout: float = 60,
        **kwargs: object) -> subprocess.CompletedProcess[str]:
    """``python -m afa ARGS`` in a child process."""
    result = subprocess.run([sys.executable, "-m", "afa", *args], cwd=ROOT, env=environment(),
                            capture_output=True, text=True, timeout=timeout, **kwargs)
    if check:
        assert result.returncode == 0, result.stderr
    return result


def test_names_lists_the_registry_with_interfaces_owners_and_processes(
        running: str, tool: Tool) -> None:
    text = tool("names", "--connect", running).stdout
    assert text.splitlines()[0].split() == ["NAME", "INTERFACE", "OWNER", "PROCESS"]
    rows = {line.split()[0]: line.split()[1:] for line in text.splitlines()[1:]}
    assert rows["Raptor/ModelService"] == ["Platform", "modelServer", "vehicle"]
    assert rows["Raptor/RaptorMotion"] == ["VehicleControl", "RaptorService", "vehicle"]
    assert rows["Raptor/EventChannel"][1] == "system"
    table = json.loads(tool("names", "--json", "--connect", running).stdout)
    assert {"name": "Raptor/Gps", "interface": "idl.interfaces.Gps",
            "owner": "GpsSokkiaService", "process": "vehicle", "remote": False} in table


def test_echo_prints_events_as_text_and_as_lossless_json(running: str, tool: Tool) -> None:
    lines = tool("echo", "Gps", "--count", "2", "--connect", running).stdout.splitlines()
    assert len(lines) == 2 and all("Raptor/Gps from vehicle/GpsSokkiaService: GpsIDL" in line
                                   for line in lines)
    from idl import GpsIDL

    records = [json.loads(line) for line in tool("echo", "Gps", "--json", "--count", "2",
                                                 "--connect", running).stdout.splitlines()]
    assert [r["body_type"] for r in records] == ["idl.sensors.GpsIDL@1"] * 2
    fix = GpsIDL.from_json(json.dumps(records[0]["body"]))  # lossless: reads back
    assert 50 < fix.latitude < 51 and records[1]["time"] > records[0]["time"]


def test_echo_says_when_no_process_declares_the_event(running: str) -> None:
    process = subprocess.Popen([sys.executable, "-m", "afa", "echo", "NoSuchEvent",
                                "--connect", running], cwd=ROOT, env=environment(),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        assert process.stderr is not None
        line = process.stderr.readline()
        while "warning" not in line and time.monotonic() < deadline:
            line = process.stderr.readline()
        assert "no running process declares the event 'NoSuchEvent'" in line
        process.send_signal(signal.SIGINT)  # Ctrl-C ends it cleanly
        assert process.wait(20) == 0
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        for stream in (process.stdout, process.stderr):
            assert stream is not None
            stream.close()


def test_hz_reports_rate_jitter_and_gaps(running: str, tool: Tool) -> None:
    text = tool("hz", "Imu", "--count", "1", "--every", "2", "--connect", running).stdout
    assert text.startswith("Imu: ") and " Hz  period min " in text and "gaps" in text
    rate = float(text.split()[1])
    assert rate > 1.0  # the simulated 3DM-GX1 sends several samples a second


def test_poll_calls_with_arguments_parsed_by_the_interface(running: str, tool: Tool) -> None:
    frames = tool("poll", "ModelService", "getBodyFrameList", "FrontNoddingSICKLeft", "--json",
                  "--connect", running).stdout
    values = json.loads(frames)["values"]
    assert values
    pose = json.loads(tool("poll", "ModelService", "getTransformation",
                           f"B=FrontNoddingSICKLeft:{values[0]}",
                          "A=Raptor:RearAxleCenter", "--json", "--connect", running).stdout)
    assert pose["poseValidFlag"] is True and pose["HTransform"]["shape"] == [4, 4]
    # a bad argument: the signature, exit 2
    bad = tool("poll", "ModelService", "getTransformation", "only-one", "--connect", running,
              check=False)
    assert bad.returncode == 2 and "missing argument B" in bad.stderr
    assert "getTransformation(A: str, B: str)" in bad.stderr
    # the server's own error, by name
    wrong = tool("poll", "ModelService", "getTransformation", "Raptor:RearAxleCenter",
                "Nobody:Nothing", "--connect", running, check=False)
    assert wrong.returncode == 1 and wrong.stderr.startswith("afa poll: EOutOfBounds: ")


def test_a_remote_setvelocity_is_refused_and_stopvehicle_is_not(running: str, tool: Tool) -> None:
    refused = tool("poll", "RaptorMotion", "setVelocity", '{"translation": 1.0}',
                   "--connect", running, check=False)
    assert refused.returncode == 1
    assert "CommandRefused" in refused.stderr and "setVelocity from tool refused" in refused.stderr
    assert tool("poll", "RaptorMotion", "stopVehicle", "--connect", running).stdout.strip() \
        == "None (false)"


def test_sensor3d_prints_range_points_in_the_raptor_frame(running: str, tool: Tool) -> None:
    text = tool("sensor3d", "stream", "Laser11", "--count", "10", "--max-points", "5",
                "--connect", running).stdout.splitlines()
    headers = [line for line in text if line.startswith("#")]
    assert len(headers) == 10 and all("Laser11 t=" in h and "-> Raptor:RearAxleCenter" in h
                                      for h in headers)
    rows = [line for line in text if not line.startswith("#")]
    points = np.array([[float(v) for v in line.split()] for line in rows])
    assert points.ndim == 2 and points.shape[1] == 3  # (a scan line may see nothing)
    # in the vehicle frame the forward lasers see the ground ahead: x > 0
    assert np.all(points[:, 0] > 0)
    same = tool("sensor3d", "stream", "Laser11", "--count", "1", "--frame", "sensor",
               "--connect", running).stdout.splitlines()
    assert "frame FrontNoddingSICK" in same[0] and same[0].endswith("shown")
    got = tool("sensor3d", "get", "Stereo", "--every", "1000", "--max-points", "3",
              "--connect", running).stdout.splitlines()
    assert got[0].startswith("# Stereo t=") and len(got) == 4


def test_top_shows_the_launcher_table(running: str, tool: Tool) -> None:
    text = tool("top", "--once", "--connect", running).stdout
    head, traffic, columns, *rows = text.strip().splitlines()
    assert head.startswith("Raptor/vehicle  pid ") and "memory" in head and "loop share" in head
    # the tools that ran before are no peers: they hold no token and serve nothing
    assert traffic.strip().startswith("bridge: peers none;")
    assert "running" in text and "FindPath" not in text  # the autonomy process is not here
    assert columns.split() == ["COMPONENT", "TYPE", "STATE", "HEALTH", "RESTARTS", "IN", "OUT",
                               "LOOP", "LONGEST"]
    table = {row.split()[0]: row.split() for row in rows}
    assert table["modelServer"][1:3] == ["ModelServer", "running"]
    assert int(table["modelServer"][-5]) > 0 and int(table["modelServer"][-4]) > 0  # in, out
    assert table["modelServer"][-3].endswith("%")
    assert float(table["modelServer"][-2]) > 0 and table["modelServer"][-1] == "ms"


@pytest.mark.parametrize("answer", [b"[1]", b'{"version":1,"robot":"Raptor","process":"rogue"}',
                                    b'{"version":9}', b"not json"])
def test_a_peer_answering_junk_for_its_info_is_ignored_with_a_warning(
        running: str, tool: Tool, answer: bytes) -> None:
    # any Zenoh peer can answer afa/Raptor/info/*: the tools read the real process and
    # name the one they ignored, once, instead of failing on a missing key
    import zenoh

    from afa.bridge import keys
    from afa.bridge.link import session_config
    from afa.bridge.parameters import BridgeParameters

    where = endpoint(free_port())
    key = keys.info("Raptor", "rogue")
    asked: list[str] = []

    def reply(query: zenoh.Query) -> None:
        asked.append(str(query.key_expr))
        query.reply(key, answer)

    def run(*args: str) -> Ran:
        """The tool, again until it has asked the rogue (a fresh session may query
        before the rogue's queryable has reached it)."""
        for _ in range(10):
            before = len(asked)
            result = tool(*args, "--connect", running, "--connect", where)
            if len(asked) > before:
                return result
        raise AssertionError(f"afa {args[0]} never asked the rogue peer")

    with zenoh.open(session_config(BridgeParameters(), listen=[where])) as session:
        rogue = session.declare_queryable(key, reply)
        try:
            names, top = run("names"), run("top", "--once")
        finally:
            rogue.undeclare()
    assert "Raptor/ModelService" in names.stdout and "Raptor/vehicle  pid " in top.stdout
    for result in (names, top):
        assert "Traceback" not in result.stderr
        assert result.stderr.count(f"ignored an info document from {key}") == 1


def test_a_closed_pipe_ends_a_tool_quietly(running: str) -> None:
    shell = (f"{sys.executable} -m afa echo Imu --connect {running} | head -1; "
             "echo status ${PIPESTATUS[0]}")
    result = subprocess.run(["bash", "-c", shell], cwd=ROOT, env=environment(),
                            capture_output=True, text=True, timeout=60)
    lines = result.stdout.splitlines()
    assert "Raptor/Imu" in lines[0] and lines[-1] == "status 0"
    assert "Traceback" not in result.stderr and "BrokenPipe" not in result.stderr


def test_tools_say_when_no_system_is_reachable(tool: Tool) -> None:
    nobody = endpoint(free_port())
    for args in (["names"], ["poll", "Gps", "getPosition"]):
        result = tool(*args, "--connect", nobody, check=False)
        assert result.returncode == 1, args
        assert f"no afa system is reachable at {nobody}" in result.stderr, args


def test_echo_hz_and_names_read_a_recording(recording: Path, tool: Tool) -> None:
    lines = tool("echo", "Laser11", "--log", str(recording)).stdout.splitlines()
    assert len(lines) == 34 and "Raptor/Laser11 from laser: Range3dSeqEventIDL" in lines[0]
    record = json.loads(tool("echo", "Laser11", "--json", "--count", "1", "--log",
                             str(recording)).stdout)
    assert record["body_type"] == "idl.range.Range3dSeqEventIDL@1"
    rate = tool("hz", "Laser11", "--log", str(recording)).stdout
    assert rate.startswith("Laser11: 10.000 Hz  period min 0.1000 max 0.1000") and "gaps 0" in rate
    names = tool("names", "--log", str(recording)).stdout
    assert "ModelService" in names and "Platform" in names and "model" in names


def test_sensor3d_stream_reads_a_recording_through_its_recorded_transformation(
        recording: Path, tool: Tool) -> None:
    lines = tool("sensor3d", "stream", "Laser11", "--count", "1", "--log",
                 str(recording)).stdout.splitlines()
    assert lines[0].startswith("# Laser11 t=") and "-> Raptor:RearAxleCenter: 2 points" in lines[0]
    assert lines[1:] == ["1.500 0.000 1.000", "2.600 0.000 1.000"]  # through the recorded pose
    missing = tool("sensor3d", "stream", "Laser11", "--frame", "Raptor:Nowhere", "--log",
                   str(recording), check=False)
    assert missing.returncode == 1 and "no recorded getTransformation" in missing.stderr


def test_without_afa_log_the_log_mode_says_so(
        tmp_path: Path, tool: Tool, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "afa.log.reader", None)  # as if not installed
    result = tool("echo", "Gps", "--log", str(tmp_path / "none.mcap"), check=False)
    assert result.returncode == 1 and "needs afa's record/replay package" in result.stderr
