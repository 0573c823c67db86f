"""``python -m afa``: help, run (honest about what exists), exit codes."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

from afa.cli import main

ROOT = Path(__file__).resolve().parents[2]
RAPTOR = ROOT / "configs" / "raptor.xml"


def test_help_lists_the_commands():
    result = subprocess.run([sys.executable, "-m", "afa", "--help"], capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 0
    for command in ("run", "config", "decode"):
        assert command in result.stdout


def test_run_reports_what_is_not_implemented_and_stops_cleanly(tmp_path):
    # --sim: the test must not open this machine's serial ports or the seed's laser
    # addresses, which the real-device mode would
    summary = tmp_path / "summary.json"
    result = subprocess.run(
        [sys.executable, "-m", "afa", "run", str(RAPTOR), "--sim", "--fast", "--duration", "10",
         "--summary", str(summary)],
        capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    data = json.loads(summary.read_text())
    assert data["sim_time_s"] >= 10.0  # the maps publish after MapUpdateTime (7 s)
    assert data["stack_up"] is True
    # after MapUpdateTime every started component, maps included, was healthy at some point
    assert all(info["ever_healthy"] for info in data["components"].values()), data["components"]
    for key in ("wall_time_s", "realtime_factor", "events", "events_dropped",
                "component_errors", "components", "not_started"):
        assert key in data
    # every configured component either runs or is reported as not implemented yet
    reported = " ".join(data["not_started"])
    for name in ("TerrainService", "arcArbiter", "modelServer", "GpsSokkiaService"):
        assert name in reported or name in data["components"]
    assert "not implemented yet" in result.stderr or not data["not_started"]


def test_real_device_mode_with_no_devices_says_the_stack_never_came_up(tmp_path):
    """Without --sim the drivers open what the XML names; absent devices make their
    components unhealthy (retrying with backoff), ModelServer waits for inputs that never
    come, the run stops cleanly and its exit status says the stack never came up."""
    text = RAPTOR.read_text()
    for device in ("/dev/ttyUSB0", "/dev/ttyS0"):
        text = text.replace(f'value="{device}"', f'value="{tmp_path}/no-such-port"')
    for host in ("131.135.74.200", "131.135.74.201"):
        text = text.replace(f'value="{host}"', 'value="127.0.0.1"')
    text = text.replace('name="Port" value="24750"', 'name="Port" value="9"')  # discard: closed
    text = text.replace('value="050917raptor01.XML"',
                        f'value="{RAPTOR.parent / "050917raptor01.XML"}"')
    config = tmp_path / "raptor-absent.xml"
    config.write_text(text)
    summary = tmp_path / "summary.json"
    result = subprocess.run(
        [sys.executable, "-m", "afa", "run", str(config), "--duration", "1", "--summary",
         str(summary)], capture_output=True, text=True, timeout=120, cwd=tmp_path,
        # every device this file names is absent or refused: real-device mode, safely
        env={**{k: v for k, v in os.environ.items() if k != "AFA_FORBID_REAL_DEVICES"},
             "PYTHONPATH": str(ROOT)})  # this checkout's afa, wherever afa is installed
    assert result.returncode == 1, result.stderr
    assert "the stack never came up" in result.stderr
    assert "No devices found; did you mean --sim?" in result.stderr
    assert re.search(r"0 component\(s\) with errors, 1[0-9] of 16 unhealthy", result.stdout)
    assert "Traceback" not in result.stderr
    data = json.loads(summary.read_text())
    components = data["components"]
    assert data["stack_up"] is False
    for name in ("3dmgService", "GpsSokkiaService", "RaptorService", "RaptorOdometryService",
                 "NodLaserService", "modelServer"):
        assert components[name]["state"] == "running"
        assert not components[name]["healthy"], components[name]
        assert not components[name]["ever_healthy"], components[name]  # never, not flapping
    assert "no-such-port" in components["3dmgService"]["detail"]
    assert components["modelServer"]["detail"] == "waiting for Gps, Imu"


def test_run_with_a_bad_config_exits_2_without_traceback(tmp_path, capsys):
    bad = tmp_path / "bad.xml"
    bad.write_text("<config><section name='Robot'>")
    assert main(["run", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"{bad}:") and "Traceback" not in err


def test_simulation_options_without_sim_are_refused(capsys):
    assert main(["run", str(RAPTOR), "--fast"]) == 2
    assert "--fast need(s) --sim" in capsys.readouterr().err
    assert main(["run", str(RAPTOR), "--teleop", "--realtime-factor", "2"]) == 2
    assert "--teleop, --realtime-factor need(s) --sim" in capsys.readouterr().err
    assert main(["run", str(RAPTOR), "--sim", "--fast", "--realtime-factor", "2"]) == 2
    assert "exclude each other" in capsys.readouterr().err


def test_an_unknown_world_name_is_explained(capsys):
    assert main(["run", str(RAPTOR), "--sim", "--fast", "--world", "rock-feild"]) == 2
    err = capsys.readouterr().err
    assert "did you mean 'rock-field'" in err and "shipped worlds:" in err


def test_version_and_the_scripts_own_name_in_its_usage(capsys):
    import pytest

    from afa import __version__

    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0
    assert capsys.readouterr().out.strip() == f"afa {__version__}"
    with pytest.raises(SystemExit):
        main(["--help"])
    assert capsys.readouterr().out.startswith("usage: afa ")  # the `afa` script
    with pytest.raises(SystemExit):
        main(["--help"], prog="python -m afa")
    assert capsys.readouterr().out.startswith("usage: python -m afa ")


def test_log_level_is_accepted_before_and_after_the_command():
    from afa.cli import _parser

    parser = _parser()
    assert parser.parse_args(["config", "check", "x.xml"]).log_level == "warning"
    assert parser.parse_args(["--log-level", "info", "config", "check", "x.xml"]) \
        .log_level == "info"
    assert parser.parse_args(["config", "check", "x.xml", "--log-level", "debug"]) \
        .log_level == "debug"
    assert parser.parse_args(["run", "x.xml", "--sim", "--log-level", "error"]) \
        .log_level == "error"
    assert parser.parse_args(["log", "info", "r.mcap", "--log-level", "info"]) \
        .log_level == "info"


def test_fast_runs_log_virtual_time_and_start_up_notes_appear_once(tmp_path):
    """Log lines of a --fast run carry the virtual seconds since the run began (not a
    wall-clock date, nor the virtual clock's 2005 epoch); a start-up note (a component
    not implemented yet) is printed once, not as a log line and again as 'afa: ...'."""
    entry = ('<parameter><parameter name="Name" value="futureThing"/>'
             '<parameter name="Type" value="FutureThing"/></parameter>')
    text = RAPTOR.read_text().replace(
        '<parameter name="Components">', '<parameter name="Components">' + entry, 1)
    config = tmp_path / "raptor.xml"
    config.write_text(text.replace('value="050917raptor01.XML"',
                                   f'value="{RAPTOR.parent / "050917raptor01.XML"}"'))
    script = (
        "import sys\n"
        "from afa import registry\n"
        "from afa.cli import main\n"
        "from components.arcs import ArcSetParameters\n"
        "registry.register('FutureThing', registry.not_implemented(\n"
        "    'FutureThing', ArcSetParameters, 'a capability not written yet'))\n"
        "sys.exit(main(sys.argv[1:]))\n")
    result = subprocess.run(
        [sys.executable, "-c", script, "run", str(config), "--sim", "--fast", "--duration",
         "1", "--log-level", "info"], capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    assert result.stderr.count("futureThing (FutureThing) is configured but not "
                               "implemented yet") == 1, result.stderr
    logged = [line for line in result.stderr.splitlines() if " INFO " in line]
    assert logged, result.stderr
    stamps = [re.match(r"t=\s*(\d+\.\d{3}) INFO ", line) for line in logged]
    assert all(stamps), logged
    assert all(0.0 <= float(m.group(1)) <= 5.0 for m in stamps if m)
    assert "2005" not in result.stderr and "1126" not in result.stderr


GPS_CAPTURE = ROOT / "tests" / "data" / "gps" / "swri_binary.bin"


def test_decode_into_a_closed_pipe_ends_quietly(tmp_path):
    """`afa decode gps FILE | head`: no BrokenPipeError traceback when the reader stops."""
    big = tmp_path / "big.bin"
    big.write_bytes(GPS_CAPTURE.read_bytes() * 400)  # far more output than a pipe holds
    process = subprocess.Popen([sys.executable, "-m", "afa", "decode", "gps", str(big)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT)
    assert process.stdout is not None and process.stderr is not None
    with process:
        first = process.stdout.readline()
        process.stdout.close()  # what head does after its lines
        err = process.stderr.read().decode()
        assert process.wait(timeout=60) == 0, err
    assert json.loads(first)["type"] and err == ""


def test_decode_streams_what_it_reads(tmp_path):
    """`afa decode` reads its input as a stream: messages come out while the input is
    still open, and memory stays bounded on an endless one (`/dev/zero`, a serial port,
    a pipe), which used to be read whole first (2.6 GB of memory in 8 s on /dev/zero)."""
    import select

    process = subprocess.Popen([sys.executable, "-m", "afa", "decode", "gps", "-"],
                               stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, cwd=ROOT)
    assert process.stdin is not None and process.stdout is not None
    with process:
        process.stdin.write(GPS_CAPTURE.read_bytes())
        process.stdin.flush()  # and the input stays open
        ready, _, _ = select.select([process.stdout], [], [], 60.0)  # (a hang guard only)
        first = process.stdout.readline() if ready else b""
        process.stdin.close()
        rest = process.stdout.read()
        assert process.wait(timeout=60) == 0
    assert json.loads(first)["type"] == "Prompt"
    assert json.loads(rest.splitlines()[-1])["statistics"]["bytes"] == \
        len(GPS_CAPTURE.read_bytes())


def test_decode_with_the_wrong_device_says_nothing_was_decoded(capsys):
    assert main(["decode", "imu", str(GPS_CAPTURE)]) == 1
    out, err = capsys.readouterr()
    assert json.loads(out.splitlines()[-1])["statistics"]["messages"] == 0
    assert f"nothing decoded from {GPS_CAPTURE} as imu" in err
    assert "is it a gps capture?" in err


def test_decode_prints_a_non_finite_number_as_json_null(tmp_path, capsys):
    import dataclasses
    import math

    from components.gps_sokkia.codec import BestPos, GpsDecoder, encode_bestpos_binary

    ascii_capture = ROOT / "tests" / "data" / "gps" / "swri_ascii_nmea.log"
    fix = next(m for m in GpsDecoder().feed(ascii_capture.read_bytes())
               if isinstance(m, BestPos))
    fix = dataclasses.replace(fix, header=dataclasses.replace(fix.header, port="COM1"),
                              latitude_deg=math.nan, height_msl_m=math.inf)
    capture = tmp_path / "nan.bin"
    capture.write_bytes(encode_bestpos_binary(fix))
    assert main(["decode", "gps", str(capture)]) == 0

    def refuse(constant):
        raise AssertionError(f"not JSON: {constant}")

    records = [json.loads(line, parse_constant=refuse)
               for line in capsys.readouterr().out.splitlines()]
    assert records[0]["type"] == "BestPos"
    assert records[0]["latitude_deg"] is None and records[0]["height_msl_m"] is None
    assert records[0]["longitude_deg"] == fix.longitude_deg


def test_expose_prints_where_each_emulated_device_is_served():
    """`--expose` prints its pseudo-terminals and TCP ports whatever the log level (a
    newcomer needs them to attach a serial tool or a laser client)."""
    result = subprocess.run(
        [sys.executable, "-m", "afa", "run", str(RAPTOR), "--sim", "--expose", "--duration",
         "2", "--log-level", "error"], capture_output=True, text=True, timeout=120, cwd=ROOT)
    served = dict(re.findall(r"^afa: (\S+) emulated on (\S+)$", result.stderr, re.M))
    assert sorted(served) == sorted(
        ["NodLaserService", "NodLaserService12", "3dmgService", "GpsSokkiaService",
         "RaptorOdometryService", "RaptorService"]), result.stderr
    assert served["3dmgService"].startswith("/dev/pts/")
    assert re.fullmatch(r"127\.0\.0\.1:\d+", served["NodLaserService"])
    assert served["RaptorService"] == served["RaptorOdometryService"]  # one MPC555 link


def test_real_device_mode_with_silent_devices_says_none_answered(tmp_path, monkeypatch,
                                                                 capsys):
    """Ports that open but never speak (a serial port with nothing on it, an address
    that accepts and sends nothing): the stack never came up and no device answered."""
    import socket

    monkeypatch.delenv("AFA_FORBID_REAL_DEVICES", raising=False)
    ptys = [os.openpty() for _ in range(3)]  # serial ports nobody answers on
    listener = socket.create_server(("127.0.0.1", 0))  # accepts, never sends
    port = listener.getsockname()[1]
    try:
        text = RAPTOR.read_text()
        for device, (_, terminal) in zip(("/dev/ttyUSB0", "/dev/ttyUSB1", "/dev/ttyS0"), ptys,
                                         strict=True):
            text = text.replace(f'value="{device}"', f'value="{os.ttyname(terminal)}"')
        for host in ("131.135.74.200", "131.135.74.201"):
            text = text.replace(f'value="{host}"', 'value="127.0.0.1"')
        text = text.replace('name="Port" value="24750"', f'name="Port" value="{port}"')
        text = text.replace('value="050917raptor01.XML"',
                            f'value="{RAPTOR.parent / "050917raptor01.XML"}"')
        config = tmp_path / "raptor-silent.xml"
        config.write_text(text)
        assert main(["run", str(config), "--duration", "1"]) == 1
    finally:
        listener.close()
        for fds in ptys:
            for fd in fds:
                os.close(fd)
    err = capsys.readouterr().err
    assert "the stack never came up" in err
    assert "No device answered; did you mean --sim?" in err


def test_run_help_lists_the_shipped_worlds(capsys):
    import pytest

    with pytest.raises(SystemExit):
        main(["run", "--help"])
    out = " ".join(capsys.readouterr().out.split())  # argparse wraps the help text
    for world in ("rock-field", "open-field", "slalom"):
        assert world in out.replace("- ", "-")


def test_the_reference_course_is_planned_after_the_system_stopped(tmp_path, monkeypatch,
                                                                  capsys):
    """Planning the shortest course (the run summary's path ratio) takes seconds of CPU
    on one thread: done while the components still ran, it starved the drivers of a
    real-time `--sim` run, which then ended with every link "lost" and the command
    watchdog's warnings. It is planned once the system has stopped."""
    from components.simulation import RaptorSimulation

    planned = RaptorSimulation.course_reference
    states = []

    def course_reference(self):
        states.append({c.state.value for c in self.system.components.values()})
        return planned(self)

    monkeypatch.setattr(RaptorSimulation, "course_reference", course_reference)
    summary = tmp_path / "summary.json"
    assert main(["run", str(RAPTOR), "--sim", "--fast", "--world", "short-hop",
                 "--duration", "1", "--summary", str(summary)]) == 0  # cut short: no verdict
    assert states == [{"stopped"}]
    data = json.loads(summary.read_text())
    assert data["oracle_distance_m"] > 20.0 and data["path_ratio"] is None
    assert "mission: NOT complete" in capsys.readouterr().out


def test_a_run_in_which_nothing_drives_and_nothing_ends_is_refused(capsys):
    """`--teleop` on a world without a <drive> script: nothing would drive and the run
    would never end (it used to go on, silently, at full CPU under --fast)."""
    assert main(["run", str(RAPTOR), "--sim", "--fast", "--world", "short-hop",
                 "--teleop"]) == 2
    err = capsys.readouterr().err
    assert "world 'short-hop' has no <drive> script for --teleop" in err
    assert "--duration" in err


def test_a_system_task_that_fails_mid_run_ends_it_with_one_line(monkeypatch, capsys):
    """A task of the system failing mid-run (a peer of a split run going away, the
    control station's mission) stops the run with exit 1 and one line naming it; it
    used to leave the run's task scope as an exception group, printed as a 60-line
    traceback with the line buried in it."""
    from afa.errors import ComponentError
    from components.simulation import RaptorSimulation

    async def broken_geofence(self, global_map):
        raise ComponentError("the operator's mission area is broken")

    monkeypatch.setattr(RaptorSimulation, "_geofence", broken_geofence)
    assert main(["run", str(RAPTOR), "--sim", "--fast", "--world", "short-hop",
                 "--duration", "30"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and "ExceptionGroup" not in err
    stopped = [line for line in err.splitlines() if line.startswith("afa run: stopped:")]
    assert len(stopped) == 1 and "the operator's mission area is broken" in stopped[0]
