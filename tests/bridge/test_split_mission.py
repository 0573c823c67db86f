"""The Raptor split in two processes (``afa run CONFIG --process vehicle`` and ``...
--process autonomy``) in lock-step virtual time drives the simulated mission to the same
outcome as one process: distance, collisions, waypoints, the vehicle's final state, the
pose error, and every event stream (per-name digests), with ModelServer in the second
process consuming GPS and IMU from the first and its Pose stream crossing back."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from tests.bridge.conftest import ROOT, Peer
from tests.bridge.parts import endpoint, free_port

RAPTOR = ROOT / "configs" / "raptor.xml"
DURATION = "4"


def split_config(tmp_path: Path) -> Path:
    """raptor.xml with modelServer moved to the autonomy process (its geometry file by
    absolute path, since the copy lives elsewhere)."""
    text = RAPTOR.read_text()
    entry = re.search(r'<parameter name="Name" value="modelServer"/>.*?'
                      r'<parameter name="Process" value="vehicle"/>', text, re.S)
    assert entry is not None
    moved = entry.group(0).replace('value="vehicle"', 'value="autonomy"')
    text = text.replace(entry.group(0), moved)
    text = text.replace('value="050917raptor01.XML"',
                        f'value="{RAPTOR.parent / "050917raptor01.XML"}"')
    path = tmp_path / "raptor-split.xml"
    path.write_text(text)
    return path


def afa_run(config: Path, summary: Path, *extra: str) -> Peer:
    return Peer(["-m", "afa", "run", str(config), "--sim", "--fast", "--summary",
                 str(summary), *extra], ready="ran ")


def test_the_split_raptor_drives_the_mission_as_one_process_does(
        tmp_path: Path, peers: list[Peer]) -> None:
    config = split_config(tmp_path)
    port, other = free_port(), free_port()
    one = afa_run(RAPTOR, tmp_path / "one.json", "--duration", DURATION)
    vehicle = afa_run(config, tmp_path / "vehicle.json", "--duration", DURATION,
                      "--process", "vehicle", "--listen", endpoint(port))
    autonomy = afa_run(config, tmp_path / "autonomy.json", "--process", "autonomy",
                       "--listen", endpoint(other), "--connect", endpoint(port))
    peers += [one, vehicle, autonomy]
    assert one.wait(120) == 0, one.errors[-5:]
    assert vehicle.wait(120) == 0, vehicle.errors[-5:]
    assert autonomy.wait(120) == 0, autonomy.errors[-5:]  # ended by the time master
    alone = json.loads((tmp_path / "one.json").read_text())
    split = json.loads((tmp_path / "vehicle.json").read_text())
    other_half = json.loads((tmp_path / "autonomy.json").read_text())
    for key in ("sim_time_s", "distance_m", "collisions", "waypoints_reached", "vehicle",
                "pose_error", "events"):
        assert split[key] == alone[key], key
    assert split["event_digests"] == alone["event_digests"]  # every stream, Pose included
    assert alone["distance_m"] > 1.0 and alone["pose_error"]["samples"] > 50
    # the parts ran where the configuration says, and talked over the bridge
    assert "modelServer" in other_half["components"]
    assert "modelServer" not in split["components"]
    assert split["bridge"]["imported"]["Pose"] == alone["events"]["Pose"]
    assert other_half["bridge"]["imported"]["Gps"] == alone["events"]["Gps"]
    assert split["bridge"]["lockstep"]["role"] == "master"
    assert other_half["bridge"]["lockstep"]["role"] == "follower"
    assert split["bridge"]["commands_refused"] == 0  # the arbiter may command: allowed


@pytest.mark.parametrize("group", ["vehicle", "autonomy"])
def test_each_process_group_checks_and_graphs_as_the_whole(group: str) -> None:
    from afa.system import System

    system = System.from_xml(RAPTOR, process=group, bridge=False, real_devices=False)
    catalog = system.catalog()
    local = {c for c in catalog.components() if c in system.components}
    assert local == set(system.components)
    remote = {p.component for p in catalog.ports if p.process}
    assert remote and not remote & local  # the other group's components, marked
    assert {p.process for p in catalog.ports if p.process} == (
        {"autonomy"} if group == "vehicle" else {"vehicle"})
