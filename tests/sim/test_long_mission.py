"""A mission longer than the Global Map's grid (decision 0041): the grid moves along it,
FindPath plans beyond it by way of its edge, and the Raptor gets there. The grid is
shrunk to 40 m (a 5 m margin) so that a 70 m mission needs it moved more than once;
the box on the way lies beyond the first placement, so only a moved grid maps it."""

from pathlib import Path

from lxml import etree

from afa import VirtualClock
from components.simulation import RaptorSimulation

ROOT = Path(__file__).resolve().parents[2]

WORLD = b"""<?xml version="1.0" encoding="UTF-8"?>
<world name="beyond-the-grid">
  <origin latitude="50.2717" longitude="-111.1766" elevation="750.0"/>
  <terrain width="100" depth="30" resolution="0.1" roughness="0.02" seed="2">
    <slope east="0.0" north="0.0"/>
  </terrain>
  <obstacle type="box" east="15" north="0.5" length="3" width="2" height="1.0" heading="0"/>
  <vehicle east="-35" north="0" heading="90"/>
  <mission patrol="false">
    <waypoint east="35" north="0"/>
  </mission>
</world>
"""


def small_grid_config(tmp_path: Path, metres: int) -> Path:
    """configs/raptor.xml with the Global Map's grid ``metres`` on a side (and the
    geometry file it names by its full path)."""
    tree = etree.parse(str(ROOT / "configs" / "raptor.xml"))
    for name in ("Width", "Depth"):
        (parameter,) = tree.xpath(f"//section[@name='GlobalMapConfig']"
                                  f"//parameter[@name='{name}']")
        parameter.set("value", str(metres * 1000))
    (model,) = tree.xpath("//section[@name='ModelServer']//parameter[@name='ModelFileName']")
    model.set("value", str(ROOT / "configs" / model.get("value")))
    config = tmp_path / "raptor.xml"
    tree.write(str(config))
    return config


async def test_a_mission_longer_than_the_global_map_is_driven_to_its_end(tmp_path):
    world = tmp_path / "beyond.xml"
    world.write_bytes(WORLD)
    simulation = RaptorSimulation.from_xml(small_grid_config(tmp_path, 40), world,
                                           clock=VirtualClock(), seed=0)
    async with simulation:
        await simulation.run_mission()
        moves = simulation.system.components["GlobalMapService"].statistics()["grid_moves"]
    summary = {**simulation.summary(), **simulation.course_reference()}
    outcome = {k: summary[k] for k in ("waypoints_reached", "collisions", "path_ratio",
                                       "clearance_m", "mission_complete_time_s")}
    assert summary["mission_complete"], outcome
    assert summary["collisions"] == [], outcome
    assert summary["path_ratio"] <= 1.25, outcome
    assert moves >= 2
