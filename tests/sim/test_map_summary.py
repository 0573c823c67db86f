"""The run summary's ``maps`` section (components/map_quality.py): the maps of a short
simulated run scored against the world's ground truth, and figures that move when the
map is wrong."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from afa import VirtualClock
from afa.sim.terrain import Terrain
from afa.sim.world import Origin, parse_world
from components.gps_sokkia.codec import latlon_to_utm
from components.map_quality import MapFrame, map_summary, truth_in_map_frame
from components.simulation import TRACK_STEP, RaptorSimulation

RAPTOR = Path(__file__).resolve().parents[2] / "configs" / "raptor.xml"
ORIGIN = Origin(50.2717, -111.1766, 750.0)

# Flat ground; a 0.8 m box 4 m left of a straight drive east, a 0.8 m deep ditch 4 m to
# its right further on; the vehicle drives 36 m in 24 s from 20 m west of the origin.
WORLD = b"""<?xml version="1.0" encoding="UTF-8"?>
<world name="map-check">
  <origin latitude="50.2717" longitude="-111.1766" elevation="750.0"/>
  <terrain width="80" depth="40" resolution="0.1" roughness="0.02" seed="1">
    <slope east="0.0" north="0.0"/>
  </terrain>
  <obstacle type="box" east="0" north="4" length="2" width="1.5" height="0.8" heading="0"/>
  <obstacle type="ditch" east="8" north="-4.5" length="3" width="2" depth="0.8" heading="90"/>
  <vehicle east="-20" north="0" heading="90"/>
  <drive>
    <command time="0" speed="1.5" steering="0"/>
    <command time="24" speed="0" steering="0"/>
  </drive>
</world>
"""


def utm_of(origin: Origin, east: float, north: float) -> np.ndarray:
    fix = latlon_to_utm(*origin.to_geodetic(east, north))
    return np.array([fix.easting_m, fix.northing_m])


# --- the frames ---------------------------------------------------------------------------


def test_the_map_frame_is_utm_from_initial_utm_to_a_millimetre():
    start = utm_of(ORIGIN, -20.0, 3.0)
    initial = np.array([start[0], start[1], 751.25])
    frame = MapFrame.of(ORIGIN, initial)
    rng = np.random.default_rng(3)
    for east, north in rng.uniform(-250.0, 250.0, (20, 2)):
        x, y = frame.to_map(east, north)
        assert np.hypot(*(utm_of(ORIGIN, east, north) - start - (x, y))) < 1e-3
        assert frame.to_world(x, y) == pytest.approx((east, north), abs=1e-9)
    assert frame.dz == -1.25
    # the UTM grid is turned from true north here: 0.1 to 0.2 degrees, so a tangent-plane
    # frame would misplace a cell 100 m away by a fifth of a metre
    x, y = frame.to_map(-20.0, 103.0)
    assert 0.1 < abs(math.degrees(math.atan2(x, y))) < 0.2


def test_truth_is_resampled_into_the_map_frame():
    world = parse_world(WORLD)
    terrain = Terrain.from_spec(world.terrain, world.obstacles)
    start = utm_of(world.origin, -20.0, 0.0)
    frame = MapFrame.of(world.origin, [start[0], start[1], 750.5])
    truth = truth_in_map_frame(terrain, frame, (-5.0, 40.0), (-10.0, 10.0))
    east, north = truth.coordinates()
    surface = truth.surface.ravel()
    box = truth.obstacle.ravel() & (surface > 0.0)  # heights in the map frame: 0.5 down
    ditch = truth.obstacle.ravel() & (surface < -1.0)
    for samples, (e0, e1, n0, n1) in ((box, (-0.75, 0.75, 3.0, 5.0)),
                                      (ditch, (6.5, 9.5, -5.5, -3.5))):
        world_e, world_n = frame.to_world(east[samples], north[samples])
        assert (world_e.min(), world_e.max()) == pytest.approx((e0, e1), abs=0.11)
        assert (world_n.min(), world_n.max()) == pytest.approx((n0, n1), abs=0.11)
    assert surface[box].mean() == pytest.approx(0.8 - 0.5, abs=0.05)
    with pytest.raises(ValueError, match="does not overlap"):
        truth_in_map_frame(terrain, frame, (500.0, 600.0), (-10.0, 10.0))
    assert surface[ditch].mean() == pytest.approx(-0.8 - 0.5, abs=0.05)
    assert len(surface) == truth.surface.size == 451 * 201


# --- a simulated run ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def run():
    import asyncio

    async def simulate():
        simulation = RaptorSimulation.from_xml(RAPTOR, parse_world(WORLD), clock=VirtualClock(),
                                               seed=0, teleop=True)
        async with simulation:
            await simulation.system.run(28.0)
            summary = simulation.summary()
        return simulation, summary

    return asyncio.run(simulate())


def test_the_track_is_recorded_every_half_metre(run):
    simulation, summary = run
    track = np.array(simulation.track)
    steps = np.hypot(*np.diff(track, axis=0).T)
    assert TRACK_STEP == 0.5
    assert len(track) == summary["maps"]["track_points"]
    assert len(track) == pytest.approx(summary["distance_m"] / TRACK_STEP, abs=2)
    assert steps.min() >= 0.5 - 0.04 and steps.max() <= 0.5 + 0.04  # one physics step
    assert track[0] == pytest.approx((-20.0, 0.0), abs=0.05)


def test_the_summary_scores_the_maps_against_the_world(run):
    _, summary = run
    maps = summary["maps"]
    terrain, hazards = maps["terrain"], maps["hazards"]
    assert terrain["map"] == "TerrainService" and hazards["map"] == "GlobalMapService"
    assert terrain["observed_cells"] > 5000
    assert terrain["rms_height_error_centred_m"] < 0.1
    assert abs(terrain["height_offset_m"]) < 0.5
    assert hazards["obstacle_cells"] >= 15  # the box (12 cells) and the ditch
    assert hazards["detection_fraction"] >= 0.9
    assert (hazards["obstacles"], hazards["detected_obstacles"]) == (2, 2)
    assert hazards["obstacle_detection_fraction"] == 1.0
    assert hazards["free_observed_cells"] > 1000
    assert hazards["false_hazard_fraction"] <= 0.01
    assert maps["detection_range_m"] == 8.0
    assert maps["targets"] == {"detection_fraction": 0.95, "obstacle_detection_fraction": 0.95,
                               "false_hazard_fraction": 0.01}


def _world_cell(simulation, east: float, north: float) -> tuple[int, int]:
    """The Global Map cell holding world point (east, north)."""
    component = simulation.system.components["GlobalMapService"]
    frame = MapFrame.of(simulation.world.origin, component.initial_utm)
    x, y = frame.to_map(east, north)
    i, j = component.grid.world_to_cell(x, y)
    return int(i), int(j)


def test_a_planted_false_hazard_and_a_missed_obstacle_move_the_figures(run):
    simulation, summary = run
    grid = simulation.system.components["GlobalMapService"].grid
    before = summary["maps"]["hazards"]
    free = _world_cell(simulation, -8.0, -2.0)  # open ground the vehicle drove past
    rock = _world_cell(simulation, 0.0, 4.0)    # the middle of the box
    assert grid.hazard[free] < 1.0 and grid.hazard[rock] == 1.0
    saved = grid.hazard.copy()
    try:
        grid.hazard[free] = 1.0
        planted = map_summary(simulation.system, simulation)["hazards"]
        grid.hazard[free] = saved[free]
        grid.hazard[rock] = 0.2
        missed = map_summary(simulation.system, simulation)["hazards"]
        grid.hazard[rock] = np.nan
        unseen = map_summary(simulation.system, simulation)["hazards"]
    finally:
        grid.hazard[:] = saved
    assert planted["false_hazard_cells"] == before["false_hazard_cells"] + 1
    assert planted["free_observed_cells"] == before["free_observed_cells"]
    assert missed["detected_cells"] == before["detected_cells"] - 1
    assert missed["detection_fraction_in_range"] == pytest.approx(
        (before["detected_cells"] - 1) / before["obstacle_cells"], abs=1e-4)
    assert missed["detection_fraction"] == pytest.approx(
        (before["detected_cells"] - 1) / (before["obstacle_cells"]
                                          - before["unobserved_obstacle_cells"]), abs=1e-4)
    assert missed["detected_obstacles"] == before["detected_obstacles"]  # the rest of it
    assert unseen["unobserved_obstacle_cells"] == before["unobserved_obstacle_cells"] + 1
    assert unseen["detection_fraction"] == pytest.approx(
        (before["detected_cells"] - 1) / (before["obstacle_cells"]
                                          - before["unobserved_obstacle_cells"] - 1),
        abs=1e-4)


def test_a_terrain_map_off_by_a_height_moves_the_offset_not_the_shape(run):
    simulation, summary = run
    component = simulation.system.components["TerrainService"]
    slot = component.latest_map
    original = slot.get()
    try:
        slot.set(original.model_copy(update={"elevation": original.elevation + 0.5}))
        raised = map_summary(simulation.system, simulation)["terrain"]
    finally:
        slot.set(original)
    before = summary["maps"]["terrain"]
    assert raised["height_offset_m"] == pytest.approx(before["height_offset_m"] + 0.5,
                                                      abs=1e-3)
    assert raised["rms_height_error_centred_m"] == pytest.approx(
        before["rms_height_error_centred_m"], abs=1e-3)
    assert raised["rms_height_error_m"] > before["rms_height_error_m"] + 0.3


def test_the_cli_prints_the_maps_in_one_line(run):
    from afa.cli import _maps_line

    _, summary = run
    line = _maps_line(summary["maps"])
    hazards = summary["maps"]["hazards"]
    assert line.startswith("maps: terrain RMS height error ")
    assert (f"detected {hazards['detected_cells']}/{hazards['obstacle_cells']}" in line)
    assert _maps_line({"terrain": None, "hazards": None}) == "maps: none built"


def test_a_map_that_cannot_be_scored_says_why():
    from afa.cli import _maps_line

    line = _maps_line({"terrain": {"map": "TerrainService", "error": "off the terrain"},
                       "hazards": None})
    assert line == "maps: terrain: off the terrain"
