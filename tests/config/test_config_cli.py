"""``python -m afa config ...``: check, show, defaults, and one-line errors for bad files."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest
from test_annex_a import DEVIATIONS, NA, TABLES

from afa.cli import main
from afa.config.loader import load_configuration
from afa.errors import ConfigError

ROOT = Path(__file__).resolve().parents[2]
RAPTOR = ROOT / "configs" / "raptor.xml"


def run_cli(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_check_accepts_the_raptor_file(capsys):
    code, out, err = run_cli(capsys, "config", "check", str(RAPTOR))
    assert code == 0, err
    assert "valid" in out and "'Raptor'" in out


def test_show_json_holds_every_annex_a_parameter_with_the_seed_value(capsys):
    code, out, _ = run_cli(capsys, "config", "show", str(RAPTOR), "--json")
    assert code == 0
    shown = json.loads(out)
    for table, _model, _type, section, instance, rows in TABLES:
        values = shown[section][instance or "default"]
        for name, _seed_text, expected in rows:
            assert name in values, f"{table} {name} missing from config show"
            if (section, name) in DEVIATIONS:  # documented departures from the seed
                deviation = DEVIATIONS[section, name]
                expected_value = deviation if isinstance(values[name], str) else float(deviation)
                assert values[name] == expected_value, f"{table} {name}"
            elif expected is not NA:
                assert values[name] == expected, f"{table} {name}: {values[name]!r}"
    assert shown["Robot"]["default"]["Name"] == "Raptor"


def test_show_text_lists_sections(capsys):
    code, out, _ = run_cli(capsys, "config", "show", str(RAPTOR))
    assert code == 0
    assert "[NodLaserConfig/Laser12]" in out and "Motorrates = 15.0" in out


def test_defaults_writes_a_file_that_validates(tmp_path, capsys):
    target = tmp_path / "defaults.xml"
    code, _, _ = run_cli(capsys, "config", "defaults", "-o", str(target))
    assert code == 0
    config = load_configuration(target)
    assert config.parameters("NodLaser").Motorrates == 15.0
    assert config.parameters("ArcArbiter").StaleVoteTimeUSec == 500000
    assert config.parameters("CandidateArcs").Count == 27  # the shared section's name


def test_defaults_launch_every_component_type_and_the_file_runs(tmp_path, capsys):
    """A newcomer's `config defaults -o FILE` then `afa run FILE --sim` starts the stack
    (it used to write no Launcher entries, so running it started nothing)."""
    import os

    from afa import System, registry

    target = tmp_path / "defaults.xml"
    code, _, err = run_cli(capsys, "config", "defaults", "-o", str(target))
    assert code == 0 and "--sim" in err
    config = load_configuration(target)
    types = [entry.Type for entry in config.launcher.Components]
    implemented = [t for t in registry.component_types()
                   if registry.is_implemented(registry.load_component(t))]
    assert sorted(types) == sorted(implemented)
    assert types.index("NodLaser") < types.index("ModelServer") < types.index("ArcArbiter")
    enabled = {entry.Type for entry in config.launcher.Components if entry.Enabled}
    assert "LogNotify" not in enabled  # it would write a recording
    assert set(System.from_xml(target, real_devices=False).components) == enabled
    summary = tmp_path / "summary.json"
    result = subprocess.run(  # from a directory with no geometry file beside the config
        [sys.executable, "-m", "afa", "run", str(target), "--sim", "--fast", "--duration", "10",
         "--summary", str(summary)], capture_output=True, text=True, timeout=120,
        cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert result.returncode == 0, result.stderr
    data = json.loads(summary.read_text())
    assert data["stack_up"] and data["distance_m"] > 1.0  # the autonomous stack drove


def test_defaults_into_a_missing_directory_is_a_clean_error(tmp_path, capsys):
    code, _, err = run_cli(capsys, "config", "defaults", "-o", str(tmp_path / "no" / "d.xml"))
    assert code == 2 and "cannot write" in err and "Traceback" not in err


def mutate(tmp_path, old, new, count=1):
    text = RAPTOR.read_text()
    assert text.count(old) >= count, old
    path = tmp_path / "bad.xml"
    path.write_text(text.replace(old, new, count))
    return path, text.split(old)[0].count("\n") + 1


BAD_CASES = {
    "syntax error": ('<parameter name="Motorrates" value="15"/>',
                     '<parameter name="Motorrates" value="15">', "XML syntax error"),
    "unknown parameter": ('name="Motorrates"', 'name="Motorate"',
                          "unknown parameter (did you mean 'Motorrates'?)"),
    "wrong type": ('<parameter name="Port" value="24750"/>',
                   '<parameter name="Port" value="twenty"/>', "Port"),
    "1 for a bool": ('<parameter name="Notify" value="true"/>',
                     '<parameter name="Notify" value="1"/>', "exactly 'true' or 'false'"),
    "missing instance": ('<parameter name="Instance" value="Laser12"/>',
                         '<parameter name="Instance" value="Laser13"/>',
                         "instance 'Laser13' is missing from section 'NodLaserConfig'"),
    "unknown type": ('type="Raptor::NodLaserParameters"', 'type="Raptor::NodLazerParameters"',
                     "did you mean 'Raptor::NodLaserParameters'"),
}


@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_bad_files_give_exit_2_and_file_line_messages(case, tmp_path, capsys):
    old, new, expected = BAD_CASES[case]
    path, line = mutate(tmp_path, old, new)
    code, out, err = run_cli(capsys, "config", "check", str(path))
    assert code == 2
    assert out == ""
    assert "Traceback" not in err
    messages = err.strip().splitlines()
    assert len(messages) == 1, messages
    assert messages[0].startswith(f"{path}:")
    assert expected in messages[0]
    if case != "missing instance":  # (that one is reported at its Launcher entry)
        assert messages[0].startswith(f"{path}:{line}:"), (messages[0], line)


def test_errors_name_section_instance_and_parameter(tmp_path):
    path, line = mutate(tmp_path, '<parameter name="HighAngle" value="-10"/>',
                        '<parameter name="HighAngle" value="up"/>', count=2)
    with pytest.raises(ConfigError) as info:
        load_configuration(path)
    assert info.value.problems[0].startswith(f"{path}:{line}: NodLaserConfig/Laser11/HighAngle:")


ENTITY_BOMB = """<?xml version="1.0"?>
<!DOCTYPE config [
 <!ENTITY a "aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa">
 <!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">
 <!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;">
 <!ENTITY d "&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;">
]>
<config><section name="Robot"><parameter name="Miro::RobotParameters">
<parameter name="Name" value="&d;&d;&d;&d;&d;&d;&d;&d;&d;&d;"/></parameter></section></config>
"""

EXTERNAL_ENTITY = """<?xml version="1.0"?>
<!DOCTYPE config [ <!ENTITY secret SYSTEM "file:///etc/passwd"> ]>
<config><section name="Robot"><parameter name="Miro::RobotParameters">
<parameter name="Name" value="&secret;"/></parameter></section></config>
"""


@pytest.mark.parametrize("document", [ENTITY_BOMB, EXTERNAL_ENTITY], ids=["bomb", "external"])
def test_entities_and_dtds_are_refused(document, tmp_path, capsys):
    path = tmp_path / "evil.xml"
    path.write_text(document)
    code, out, err = run_cli(capsys, "config", "check", str(path))
    assert code == 2
    assert err.startswith(f"{path}:") and len(err.strip().splitlines()) == 1
    assert "root:" not in err  # /etc/passwd was not read into the message


def test_oversized_files_are_refused(tmp_path, capsys):
    path = tmp_path / "huge.xml"
    path.write_bytes(b"<config>" + b" " * (5 * 1024 * 1024) + b"</config>")
    code, _, err = run_cli(capsys, "config", "check", str(path))
    assert code == 2 and "limit" in err


def test_a_missing_file_is_a_clean_error(tmp_path, capsys):
    code, _, err = run_cli(capsys, "config", "check", str(tmp_path / "none.xml"))
    assert code == 2 and "cannot read" in err and "Traceback" not in err


def test_the_real_command_line_exit_codes(tmp_path):
    ok = subprocess.run([sys.executable, "-m", "afa", "config", "check", str(RAPTOR)],
                        capture_output=True, text=True, timeout=60)
    assert ok.returncode == 0, ok.stderr
    path, _ = mutate(tmp_path, 'name="Motorrates"', 'name="Motorate"')
    bad = subprocess.run([sys.executable, "-m", "afa", "config", "check", str(path)],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr


def test_an_unknown_component_type_lists_the_known_ones(tmp_path):
    from afa import System

    path, _ = mutate(tmp_path, '<parameter name="Type" value="Stereo"/>',
                     '<parameter name="Type" value="Sterio"/>')
    with pytest.raises(ConfigError) as info:
        System.from_xml(path)
    message = str(info.value)
    assert "unknown component type 'Sterio'" in message
    assert "Stereo" in message and "GpsSokkia" in message  # the known types are listed


def test_unimplemented_components_are_reported_and_strict_refuses_them(tmp_path):
    """A component type declared before it is written (registry.not_implemented) lets
    a configuration validate; run reports it, --strict refuses it."""
    from afa import System, registry
    from components.arcs import ArcSetParameters

    registry.register("FutureThing", registry.not_implemented(
        "FutureThing", ArcSetParameters, "a capability not written yet"))
    entry = ('<parameter><parameter name="Name" value="futureThing"/>'
             '<parameter name="Type" value="FutureThing"/></parameter>')
    text = RAPTOR.read_text().replace(
        '<parameter name="Components">', '<parameter name="Components">' + entry, 1)
    config = tmp_path / "raptor.xml"
    config.write_text(text.replace('value="050917raptor01.XML"',
                                   f'value="{RAPTOR.parent / "050917raptor01.XML"}"'))
    try:
        system = System.from_xml(config)
        reported = " ".join(system.notes)
        assert "futureThing (FutureThing) is configured but not implemented yet" in reported
        assert "futureThing" not in system.components
        with pytest.raises(ConfigError, match="not implemented yet"):
            System.from_xml(config, strict=True)
    finally:
        registry._registered.pop("FutureThing", None)


@pytest.mark.parametrize("wrong, hint", [("GPSSokkia", "did you mean 'GpsSokkia'?"),
                                         ("Foo", "installed types:")])
def test_check_refuses_an_unknown_component_type_at_its_line(tmp_path, capsys, wrong, hint):
    """Issue 16, defect 2: `config check`, not only `run`, refuses a Launcher Type that
    no installed component has, with file:line: and a suggestion."""
    path, _ = mutate(tmp_path, '<parameter name="Type" value="GpsSokkia"/>',
                     f'<parameter name="Type" value="{wrong}"/>')
    line = next(i for i, text in enumerate(path.read_text().splitlines(), 1)
                if f'value="{wrong}"' in text)
    code, out, err = run_cli(capsys, "config", "check", str(path))
    assert code == 2 and "valid" not in out
    assert err.startswith(f"{path}:{line}: Launcher/Components[")
    assert f"unknown component type '{wrong}'" in err and hint in err


def test_check_warns_when_two_devices_share_a_port_at_different_rates(tmp_path, capsys):
    code, _, err = run_cli(capsys, "config", "check", str(RAPTOR))
    assert code == 0 and "serial port" not in err  # the shipped file: one port each
    path, _ = mutate(tmp_path, '<parameter name="Device" value="/dev/ttyUSB1"/>',
                     '<parameter name="Device" value="/dev/ttyUSB0"/>')
    code, out, err = run_cli(capsys, "config", "check", str(path))
    assert code == 0 and "1 warning(s)" in out
    assert re.search(rf"^{re.escape(str(path))}:\d+: warning: serial port /dev/ttyUSB0 ", err,
                     re.M), err
    assert "3dmgService at 38400" in err and "GpsSokkiaService at 57600" in err
    # the MPC555's two components share /dev/ttyS0 at one rate: that is no conflict
    assert "/dev/ttyS0" not in err


def test_check_reads_the_geometry_model_and_names_its_broken_line(tmp_path, capsys):
    """`config check` opens the files components read at setup: a geometry body file
    with a bad element fails the check with that file and line, not only at `run`."""
    import shutil
    shutil.copy(ROOT / "configs" / "050917raptor01.XML", tmp_path)
    shutil.copytree(ROOT / "configs" / "bodies", tmp_path / "bodies")
    path, _ = mutate(tmp_path, "<!--", "<!--")  # the shipped file, beside its copies
    code, out, err = run_cli(capsys, "config", "check", str(path))
    assert code == 0 and "valid" in out, err
    body = tmp_path / "bodies" / "digiclops.xml"
    lines = body.read_text().splitlines()
    line = next(i for i, text in enumerate(lines, 1) if "<frame " in text)
    lines[line - 1] = lines[line - 1].replace("<frame ", '<frame colour="red" ', 1)
    body.write_text("\n".join(lines) + "\n")
    code, out, err = run_cli(capsys, "config", "check", str(path))
    assert code == 2 and "valid (" not in out
    assert f"{body}:{line}: <frame> has no attribute 'colour'" in err, err
    assert "modelServer" in err and "cannot read their files" in err


async def test_a_shared_serial_port_refuses_a_second_baud_rate():
    """At run time the second component on a port opened at another rate gets EDevIO
    (and stays unhealthy) instead of silently talking at the first one's rate."""
    from afa.errors import EDevIO
    from afa.transport import DeviceOpener, PtyDeviceStream, SerialSpec

    device = PtyDeviceStream()
    opener = DeviceOpener()
    try:
        first = await opener.open("Imu", SerialSpec(device.path, 38400))
        same = await opener.open("Imu2", SerialSpec(device.path, 38400))
        with pytest.raises(EDevIO, match="shared with another component at 38400 baud"):
            await opener.open("Gps", SerialSpec(device.path, 57600))
        await first.close()
        await same.close()
    finally:
        await device.close()


@pytest.mark.parametrize("old, new", [
    ('<parameter name="EventName" value="Imu"/>', '<parameter name="EventName" value="Imu/>'),
    ('<parameter name="EventName" value="Imu"/>', '<parameter name="EventName" value=Imu/>'),
    ('<parameter name="Device" value="/dev/ttyUSB0"/>',
     '<parameter name="Device" value="/dev/ttyUSB0">'),
    # the last of its siblings: the next line is the parent's end tag, less indented
    ('<parameter name="Baudrate" value="38400"/>', '<parameter name="Baudrate" value="38400">'),
], ids=["unclosed quote", "unquoted value", "element left open", "last element left open"])
def test_an_xml_syntax_error_is_reported_at_the_line_that_caused_it(old, new, tmp_path,
                                                                    capsys):
    """Not at the end tag or the next line, where the parser noticed it."""
    path, line = mutate(tmp_path, old, new)
    code, _, err = run_cli(capsys, "config", "check", str(path))
    assert code == 2
    assert err.startswith(f"{path}:{line}: XML syntax error: "), (err, line)


@pytest.mark.parametrize("section", ["ImuConfig", "StereoConfig", "GpsSokkiaConfig"])
def test_a_deleted_section_suggests_no_unrelated_one(section, tmp_path, capsys):
    text = RAPTOR.read_text()
    start = text.index(f'<section name="{section}">')
    end = text.index("</section>", start) + len("</section>")
    path = tmp_path / "raptor.xml"
    path.write_text(text[:start] + text[end:])
    code, _, err = run_cli(capsys, "config", "check", str(path))
    assert code == 2
    assert f"section {section!r} is missing" in err
    assert "did you mean" not in err, err


def test_a_misspelt_section_is_still_suggested(tmp_path, capsys):
    path, _ = mutate(tmp_path, '<parameter name="Section" value="ImuConfig"/>',
                     '<parameter name="Section" value="ImuConfg"/>')
    code, _, err = run_cli(capsys, "config", "check", str(path))
    assert code == 2 and "did you mean 'ImuConfig'?" in err
