"""The catalog: every port with its component, direction and type, known from the
configuration alone; wiring warnings; the data-flow graph."""

import subprocess
import sys
from pathlib import Path

import pytest

from afa import Catalog, SubscribePublishServer, System
from afa.ports import Direction, PortInfo
from idl import GpsIDL, ImuIDL, Platform, PoseTransformIDL, WheelDataIDL, type_name

ROOT = Path(__file__).resolve().parents[2]
RAPTOR = ROOT / "configs" / "raptor.xml"


def test_the_raptor_catalog_is_known_before_anything_runs():
    system = System.from_xml(RAPTOR)
    catalog = system.catalog()
    assert system.components["modelServer"].state.value == "created"
    model = {(p.direction, p.name, p.types) for p in catalog.ports
             if p.component == "modelServer"}
    assert (Direction.SUBSCRIBES, "Gps", (type_name(GpsIDL),)) in model
    assert (Direction.SUBSCRIBES, "Imu", (type_name(ImuIDL),)) in model
    assert (Direction.PUBLISHES, "Pose", (type_name(PoseTransformIDL),)) in model
    assert (Direction.SERVES, "ModelService", ("idl.interfaces.Platform",)) in model
    assert ("GpsSokkiaService", "modelServer", "Gps: GpsIDL", "event") in catalog.edges()


class Consumer(SubscribePublishServer):
    def __init__(self, name, event, body, uses=None):
        super().__init__(name)
        self.subscribes(event, body, lambda e: None)
        if uses:
            self.uses(Platform, uses)


class Producer(SubscribePublishServer):
    def __init__(self, name, event, body):
        super().__init__(name)
        self.publishes(event, body)


def test_wiring_warnings_name_what_is_missing_or_mismatched():
    system = System([Producer("GpsA", "Gps", GpsIDL), Producer("GpsB", "Gps", ImuIDL),
                     Consumer("Filter", "Gps", GpsIDL, uses="ModelService"),
                     Consumer("Lonely", "Laser*", GpsIDL)])
    problems = system.catalog().problems()
    assert any("event 'Gps' carries two types" in p and "GpsA, GpsB" in p for p in problems)
    assert any("Filter subscribes to 'Gps' taking idl.sensors.GpsIDL@1, but it is published "
               "as idl.sensors.ImuIDL@1" in p for p in problems)
    assert any("Lonely subscribes to 'Laser*', which nobody publishes" in p for p in problems)
    assert any("Filter uses 'ModelService'" in p and "nobody serves" in p for p in problems)


def test_a_subscriber_of_a_base_type_accepts_a_published_subtype():
    from idl import WheelEventIDL

    system = System([Producer("Odometry", "RaptorOdometry", WheelEventIDL),
                     Consumer("Filter", "RaptorOdometry", WheelDataIDL)])
    assert system.catalog().problems() == []


def test_graph_formats():
    catalog = Catalog([
        PortInfo("A", Direction.PUBLISHES, "Gps", (type_name(GpsIDL),), classes=(GpsIDL,)),
        PortInfo("B", Direction.SUBSCRIBES, "Gps", (type_name(GpsIDL),), classes=(GpsIDL,)),
        PortInfo("B", Direction.USES, "ModelService", ("idl.interfaces.Platform",)),
        PortInfo("C", Direction.SERVES, "ModelService", ("idl.interfaces.Platform",)),
    ])
    assert "  A -> B  [Gps: GpsIDL]" in catalog.text()
    assert "  B => C  [ModelService: Platform]" in catalog.text()
    mermaid = catalog.mermaid()
    assert mermaid.startswith("flowchart LR") and '-->|"Gps: GpsIDL"|' in mermaid
    assert '"A" -> "B" [label="Gps: GpsIDL", style=solid]' in catalog.dot()
    assert '"B" -> "C" [label="ModelService: Platform", style=dashed]' in catalog.dot()


@pytest.mark.parametrize("fmt", ["text", "mermaid", "dot", "json"])
def test_afa_graph_prints_the_raptor_data_flow(fmt):
    result = subprocess.run([sys.executable, "-m", "afa", "graph", str(RAPTOR), "--format", fmt],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "modelServer" in result.stdout and "GpsSokkiaService" in result.stdout


def test_config_check_warns_about_the_wiring(tmp_path):
    text = RAPTOR.read_text().replace(
        '<parameter name="Name" value="Gps"/>', '<parameter name="Name" value="Gpz"/>', 1)
    config = tmp_path / "raptor.xml"
    config.write_text(text.replace('value="050917raptor01.XML"',
                                   f'value="{RAPTOR.parent / "050917raptor01.XML"}"'))
    result = subprocess.run([sys.executable, "-m", "afa", "config", "check", str(config)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0
    assert "warning: modelServer subscribes to 'Gpz', which nobody publishes" in result.stderr
