"""The commands: afa run --record, afa log info|echo|recover, afa replay [--check], and
LogNotify enabled from a configuration's Launcher."""

import json
from pathlib import Path

import pytest

from afa import registry
from afa.cli import main
from afa.log import LogReader
from afa.log import format as fmt
from afa.log.notify import LogNotify

ROOT = Path(__file__).resolve().parents[2]
RAPTOR = ROOT / "configs" / "raptor.xml"


def test_run_record_then_info_echo_replay_and_check(tmp_path, capsys):
    path = tmp_path / "run.mcap"
    summary = tmp_path / "summary.json"
    assert main(["run", str(RAPTOR), "--sim", "--fast", "--teleop", "--duration", "4",
                 "--record", str(path), "--record-events", "Gps,Imu,Pose,RaptorMotion",
                 "--summary", str(summary)]) == 0
    recording = json.loads(summary.read_text())["recording"]
    assert recording["events"] > 50 and recording["events_dropped"] == 0
    capsys.readouterr()

    assert main(["log", "info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "/Raptor/Gps" in out and "idl.sensors.GpsIDL@1" in out and "Hz" in out
    assert "/afa/poll/Raptor/RaptorMotion/setJoystickVelocity" in out
    assert "dropped: 0 event(s), 0 poll(s)" in out and "world open-field" in out
    assert "Laser11" not in out  # --record-events chose

    assert main(["log", "info", str(path), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["duration_s"] > 3 and info["metadata"]["seed"] == "0"

    assert main(["log", "echo", str(path), "Pose", "--json"]) == 0
    lines = capsys.readouterr().out.splitlines()
    first = json.loads(lines[0])
    assert first["origin"] == "modelServer" and "HTransform" in first["body"]
    assert main(["log", "echo", str(path), "/afa/poll/Raptor/RaptorMotion/startVehicle"]) == 0
    assert "startVehicle" in capsys.readouterr().out

    assert main(["replay", str(path), "--speed", "max"]) == 0
    out = capsys.readouterr()
    assert "replayed" in out.out and "re-running modelServer" in out.err

    assert main(["replay", str(path), "--check"]) == 0
    assert "identical" in capsys.readouterr().out


def test_bad_files_and_arguments_get_a_clear_message(tmp_path, capsys):
    bogus = tmp_path / "bogus.mcap"
    bogus.write_text("not a log")
    assert main(["log", "info", str(bogus)]) == 2
    assert "bogus.mcap: not an MCAP file" in capsys.readouterr().err
    assert main(["replay", str(bogus)]) == 2
    assert "bogus.mcap: not an MCAP file" in capsys.readouterr().err
    assert main(["replay", str(bogus), "--speed", "fast"]) == 2
    assert "--speed takes a positive number or max" in capsys.readouterr().err


def test_recover_rewrites_a_cut_file_and_check_reports_divergence_with_exit_3(
        recorded, tmp_path, capsys):
    data = recorded.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    whole = tmp_path / "whole.mcap"
    assert main(["log", "recover", str(cut), str(whole)]) == 0
    assert "recovered from" in capsys.readouterr().out
    with LogReader(whole) as reader:
        assert reader.indexed and not reader.problems
    config = RAPTOR.parent / f"_test_cli_{tmp_path.name}.xml"
    config.write_text(RAPTOR.read_text().replace('"UseRawPose" value="true"',
                                                 '"UseRawPose" value="false"'))
    try:
        assert main(["replay", str(whole), str(config), "--check"]) == 3
    finally:
        config.unlink()
    out = capsys.readouterr().out
    assert "first divergence at t=" in out and "/Raptor/Pose from modelServer" in out


LOG_NOTIFY = """
  <section name="LogNotifyConfig">
    <parameter name="Afa::LogNotifyParameters">
      <parameter name="FileName" value="{path}"/>
      <parameter name="Events" value="Gps,Pose"/>
    </parameter>
  </section>
  <section name="Launcher">
    <parameter name="Afa::LauncherParameters">
      <parameter name="Components">
        <parameter>
          <parameter name="Name" value="LogNotify"/>
          <parameter name="Type" value="LogNotify"/>
          <parameter name="Section" value="LogNotifyConfig"/>
        </parameter>"""


def test_log_notify_is_a_component_the_launcher_starts(tmp_path, capsys):
    registry.register("LogNotify", LogNotify)  # an installed afa finds it by entry point
    text = RAPTOR.read_text()
    opening = text[text.index('  <section name="Launcher">'):
                   text.index('<parameter name="Components">') + len(
                       '<parameter name="Components">')]
    path = tmp_path / "notify.mcap"
    config = RAPTOR.parent / f"_test_notify_{tmp_path.name}.xml"
    config.write_text(text.replace(opening, LOG_NOTIFY.format(path=path)))
    try:
        assert main(["run", str(config), "--sim", "--fast", "--teleop", "--duration", "3"]) == 0
    finally:
        config.unlink()
    assert "LogNotify" in capsys.readouterr().out
    with LogReader(path) as reader:
        assert reader.indexed
        assert {c.event for c in reader.topics(fmt.EVENT)} == {"Gps", "Pose"}
        assert reader.metadata["afa"]["recorded_by"] == "LogNotify"
        assert sum(reader.counts[c.id] for c in reader.topics(fmt.EVENT)) > 20


def _replay_with_keys(recorded, keys, *options, monkeypatch, capsys):
    """``afa replay`` through the CLI with ``keys`` typed on its terminal beforehand (a
    pty: the real key path, no wall-clock waiting: the replay is paused until keys
    move it, and ``q`` ends it). Returns (exit code, status lines, stdout)."""
    import os
    import pty
    import re
    import tty

    master, slave = pty.openpty()
    try:
        tty.setcbreak(slave)  # typed ahead: a canonical terminal would hold them back
        os.write(master, keys.encode())
        with open(slave, closefd=False) as terminal:
            monkeypatch.setattr("sys.stdin", terminal)
            code = main(["replay", str(recorded), *options])
    finally:
        os.close(master)
        os.close(slave)
    out = capsys.readouterr()
    status = re.findall(r"\[(\w+) (\S+) t=\s*([\d.]+) s\]", out.err)
    return code, [(state, speed, float(t)) for state, speed, t in status], out.out


def test_replay_keys_step_seek_and_speed(recorded, monkeypatch, capsys):
    code, status, out = _replay_with_keys(recorded, ".s]+-m1q", "--paused",
                                          monkeypatch=monkeypatch, capsys=capsys)
    assert code == 0
    assert [s[:2] for s in status] == [("paused", "x1"), ("paused", "x1"), ("paused", "x1"),
                                       ("paused", "x2"), ("paused", "x1"),
                                       ("paused", "max"), ("paused", "x1"), ("paused", "x1")]
    step, second, seek = (t for _, _, t in status[:3])
    assert step < 0.1  # one message: the first ones are at the start
    assert 0.9 <= second <= 1.0  # the last message within one more second
    assert seek == pytest.approx(second + 10, abs=0.01)  # ']' seeks 10 s on
    assert "replayed" in out


def test_replay_start_end_and_paused_by_keys(recorded, monkeypatch, capsys):
    code, status, out = _replay_with_keys(recorded, "s s", "--paused", "--start", "4",
                                          "--end", "6", monkeypatch=monkeypatch,
                                          capsys=capsys)
    assert code == 0
    assert status[0][0] == "paused" and 4.9 <= status[0][2] <= 5.0  # from --start 4
    assert status[1][0] == "playing"  # ' ' resumed; no 'q': the end stops it
    assert all(t <= 6.0 for _, _, t in status)  # never past --end
    assert "replayed 2.0 s" in out


def test_replay_loop_starts_again_at_start(recorded, monkeypatch, capsys):
    code, status, _ = _replay_with_keys(recorded, "sssq", "--paused", "--loop",
                                        "--start", "1", "--end", "3",
                                        monkeypatch=monkeypatch, capsys=capsys)
    assert code == 0
    times = [t for _, _, t in status]
    assert 1.9 <= times[0] <= 2.0  # one second from --start 1
    assert 1.0 <= times[1] < times[0]  # the next reached --end 3 and went back to 1
    assert times[1] < times[2] <= 2.0  # and it goes on from there


def test_echo_decodes_the_protobuf_viewer_channels(recorded, capsys):
    """``afa log echo`` of a protobuf point cloud or grid: its fields by name, the data in
    base64, the same points as the recorded stereo event's (decision 0038)."""
    import base64

    import numpy as np

    assert main(["log", "echo", str(recorded), "/viz/Stereo", "--json"]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert lines and all(line["topic"] == "/viz/Stereo" for line in lines)
    cloud = lines[0]["body"]
    assert cloud["point_stride"] == 12 and cloud["frame_id"]
    assert [(f["name"], f["offset"], f["type"]) for f in cloud["fields"]] == [
        ("x", 0, 7), ("y", 4, 7), ("z", 8, 7)]
    assert cloud["pose"]["orientation"]["w"] == 1.0
    points = np.frombuffer(base64.b64decode(cloud["data"]), "<f4").reshape(-1, 3)
    with LogReader(recorded) as reader:
        [stereo] = [c for c in reader.topics(fmt.EVENT) if c.topic == "/Raptor/Stereo"]
        event = reader.decode_event(next(reader.messages(channels=[stereo.id])))
    assert (cloud["timestamp"]["seconds"], cloud["timestamp"]["nanos"]) == (
        event.body.time.sec, event.body.time.usec * 1000)
    assert np.array_equal(points, np.asarray(event.body.points, "<f4"))
    assert main(["log", "echo", str(recorded), "/viz/Terrain"]) == 0
    assert "column_count" in capsys.readouterr().out
