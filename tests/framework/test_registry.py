"""Plug-ins by entry point, imported lazily: only what a configuration uses is imported,
a missing optional extra breaks only the configurations that need it, and the simulator
and `afa decode` loop over registrations."""

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from afa import ComponentError, ConfigError, System, registry

ROOT = Path(__file__).resolve().parents[2]
RAPTOR = ROOT / "configs" / "raptor.xml"


@pytest.fixture
def broken_plugin(tmp_path, monkeypatch):
    """An installed package whose component needs an extra that is not installed."""
    dist = tmp_path / "afa_console_demo-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: afa-console-demo\n"
                                   "Version: 0.1\n")
    (dist / "entry_points.txt").write_text(textwrap.dedent("""\
        [afa.components]
        Console = afa_console_demo:Console [console]
        [afa.parameters]
        Demo::ConsoleParameters = afa_console_demo_parameters:ConsoleParameters
        """))
    (tmp_path / "afa_console_demo.py").write_text("import aiohttp_that_is_not_installed\n")
    (tmp_path / "afa_console_demo_parameters.py").write_text(textwrap.dedent("""\
        from afa.config.parameters import Parameters, param
        class ConsoleParameters(Parameters):
            namespace = "Demo"
            Port: int = param(8080, unit="-", description="port")
        """))
    monkeypatch.syspath_prepend(str(tmp_path))
    registry._group.cache_clear()
    yield tmp_path
    registry._group.cache_clear()


def test_a_broken_plugin_does_not_break_the_shipped_configuration(broken_plugin):
    assert "Console" in registry.component_types()
    system = System.from_xml(RAPTOR)  # does not enable Console: never imported
    assert "modelServer" in system.components
    assert "afa_console_demo" not in sys.modules


def test_a_configuration_that_uses_it_names_the_extra_to_install(broken_plugin, tmp_path):
    text = RAPTOR.read_text().replace(
        '<parameter name="Type" value="ArcArbiter"/>', '<parameter name="Type" value="Console"/>')
    text = text.replace('<section name="ArcArbiter">', '<section name="ConsoleConfig">\n'
                        '    <parameter name="Demo::ConsoleParameters"/>\n  </section>\n'
                        '  <section name="ArcArbiter">')
    text = text.replace('<parameter name="Section" value="ArcArbiter"/>',
                        '<parameter name="Section" value="ConsoleConfig"/>')
    config = tmp_path / "with-console.xml"
    config.write_text(text.replace('value="050917raptor01.XML"',
                                   f'value="{RAPTOR.parent / "050917raptor01.XML"}"'))
    with pytest.raises(ConfigError, match=r"with-console.xml:\d+: Launcher arcArbiter: "
                                          r".*pip install 'afa\[console\]'"):
        System.from_xml(config)


def test_an_unknown_type_is_a_config_error_with_a_suggestion():
    with pytest.raises(ConfigError, match="did you mean 'GpsSokkia'"):
        registry.load_component("GPSSokkia")
    with pytest.raises(ConfigError, match="no decoder for 'gsp'.*did you mean 'gps'"):
        registry.load_decoder("gsp")


def test_a_broken_entry_point_names_itself(broken_plugin):
    with pytest.raises(ComponentError, match="Console.*afa\\[console\\]"):
        registry.load_component("Console")


def test_building_the_raptor_imports_only_what_it_enables():
    code = textwrap.dedent(f"""\
        import sys
        from afa import System
        System.from_xml({str(RAPTOR)!r})
        print(" ".join(sorted(m for m in sys.modules if m.startswith("components."))))
    """)
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    modules = set(result.stdout.split())
    assert "components.model_server.component" in modules
    assert not any("emulator" in m for m in modules)  # the simulator is not loaded
    assert "components.simulation" not in modules


def test_every_device_package_registers_its_decoder_and_emulator():
    assert registry.decoders() == ["gps", "imu", "mpc555", "sick"]
    for type_name in ("GpsSokkia", "Imu", "WheelOdometry", "VehicleControl", "NodLaser",
                      "Stereo"):
        assert callable(registry.emulator_for(type_name)), type_name
    assert registry.emulator_for("ModelServer") is None


def test_parameter_entry_points_name_their_models():
    for miro_type, model in registry.load_all_parameters().items():
        assert model.miro_type == miro_type
