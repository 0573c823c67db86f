"""End to end through the map cores: two nodding lasers ray-cast over a simulated
terrain with a rock and a ditch, poses through the pose buffer, fusion into a scrolling
terrain grid, hazards, the Global Map merge, and the quality figures against truth."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from afa.sim import Obstacle, Terrain, TerrainSpec, cast_rays
from components.global_map.accumulate import PlanningGrid
from components.terrain_map.grid import (
    GridGeometry,
    PoseBuffer,
    PoseStatus,
    TerrainGrid,
    TerrainLayers,
)
from components.traversability_map.hazards import (
    FLAG_HOLE,
    HazardRules,
    TraversabilityLayers,
    TraversabilityMapper,
)
from components.traversability_map.quality import GroundTruth, MapQuality, assess

SPEED = 2.0          # m/s north along east = 0
DRIVE = 4.0          # s driving, then standing
STAND = 2.0          # s standing: one full nod sweep
WHEEL = 0.33         # rear axle above ground
LINE_RATE = 37.5     # scan lines per second per laser
NOD_RATE = 15.0      # deg/s, between -40 and -10 (Table A.1)
MAX_RANGE = 8.183    # m
RANGE_NOISE = 0.01   # m, 1 sigma (SICK LMS 2xx in millimetre mode: about 1 cm)
BEARINGS = np.radians(np.arange(-90.0, 90.25, 0.5))  # 361 beams
LASERS = {  # vehicle-frame mount (docs/geometry.md): x, y, z, yaw; nod phase (deg)
    "left": ((2.20, 0.35, 1.67), math.radians(5.0), 0.0),
    "right": ((2.20, -0.35, 1.67), math.radians(-5.0), 15.0),
}
ROCK, DITCH = 0, 1


def rz(yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def nod_angle(t: float, phase: float) -> float:
    """Triangle wave between -10 and -40 degrees at NOD_RATE."""
    span = 30.0
    u = (t * NOD_RATE + phase) % (2 * span)
    return math.radians(-10.0 - (u if u < span else 2 * span - u))


@dataclass
class Run:
    terrain: Terrain
    grid: TerrainGrid
    layers: TerrainLayers
    trav: TraversabilityLayers
    track: np.ndarray
    plan: PlanningGrid
    quality: MapQuality
    statuses: dict[PoseStatus, int]


def simulate() -> Run:
    """Drive, scan, fuse, map and score (the fixture below shares one run)."""
    spec = TerrainSpec(width=60.0, depth=60.0, resolution=0.1, roughness=0.03, seed=5)
    obstacles = [Obstacle("box", east=-1.8, north=12.5, length=1.0, width=1.0, height=0.6),
                 Obstacle("ditch", east=2.2, north=13.0, length=1.5, width=3.0, depth=1.0)]
    terrain = Terrain.from_spec(spec, obstacles)

    def true_pose(t: float) -> np.ndarray:
        north = SPEED * min(t, DRIVE)
        pose = np.eye(4)
        pose[:3, :3] = rz(math.pi / 2)  # heading north
        pose[:3, 3] = (0.0, north, terrain.height_at(0.0, north) + WHEEL)
        return pose

    end = DRIVE + STAND
    buffer = PoseBuffer(capacity=128)
    times = np.arange(0.0, end + 0.1 + 1e-9, 0.1)  # 10 Hz poses
    for t in times:
        assert buffer.add(float(t), true_pose(float(t)))
    track = np.array([true_pose(float(t))[:2, 3] for t in times])

    grid = TerrainGrid.centred(0.0, 0.0, 32.0, 32.0, 0.2)
    statuses: dict[PoseStatus, int] = {}
    rng = np.random.default_rng(12)
    scans = []
    for k in range(int(end * LINE_RATE)):
        for (x, y, z), yaw, phase in LASERS.values():
            scans.append((k / LINE_RATE + (0.5 / LINE_RATE if phase else 0.0),
                          (x, y, z), yaw, phase))
    scans.sort(key=lambda s: s[0])
    for t, (x, y, z), yaw, phase in scans:
        n = nod_angle(t, phase)
        local = np.column_stack([np.cos(BEARINGS) * math.cos(n), np.sin(BEARINGS),
                                 np.cos(BEARINGS) * math.sin(n)])
        vehicle_from_laser = np.eye(4)
        vehicle_from_laser[:3, :3] = rz(yaw)
        vehicle_from_laser[:3, 3] = (x, y, z)
        world_from_laser = true_pose(t) @ vehicle_from_laser
        ranges = cast_rays(terrain, world_from_laser[:3, 3], local @ world_from_laser[:3, :3].T,
                           MAX_RANGE)
        ranges += rng.normal(0.0, RANGE_NOISE, len(ranges))
        points = (local * ranges[:, None]).astype(np.float32)  # NaN: no return
        lookup = buffer.lookup(t)
        statuses[lookup.status] = statuses.get(lookup.status, 0) + 1
        if lookup.transform is None:
            continue
        grid.recentre(*lookup.transform[:2, 3])
        grid.fuse_transformed(points, lookup.transform @ vehicle_from_laser, t)

    vehicle = track[-1]
    layers = grid.layers()
    geometry = GridGeometry.centred(vehicle[0], vehicle[1], 32.0, 32.0, 0.5)
    trav = TraversabilityMapper(HazardRules()).update(layers, geometry, tuple(vehicle), end)
    plan = PlanningGrid.centred(0.0, 0.0, 100.0, 100.0, 0.5)
    plan.merge(trav.hazard, trav.goodness, np.eye(4), geometry.origin_x, geometry.origin_y,
               geometry.gridsize, end)
    quality = assess(hazard=trav.hazard, hazard_geometry=geometry,
                     truth=GroundTruth.from_terrain(terrain), track=track,
                     terrain_elevation=layers.elevation, terrain_count=layers.count,
                     terrain_geometry=layers.geometry)
    return Run(terrain, grid, layers, trav, track, plan, quality, statuses)


@pytest.fixture(scope="module")
def run() -> Run:
    return simulate()


def test_every_scan_found_its_pose(run: Run) -> None:
    assert run.statuses == {PoseStatus.OK: int((DRIVE + STAND) * LINE_RATE) * 2}
    assert run.grid.fused_total > 50_000 and run.grid.nonfinite_total > 10_000


def test_terrain_heights_match_the_ground(run: Run) -> None:
    q = run.quality
    assert q.observed_terrain_cells > 2000
    assert q.rms_height_error_ground < 0.02  # m, cells clear of obstacles


def test_obstacles_detected_and_open_ground_free(run: Run) -> None:
    q = run.quality
    assert q.obstacle_cells >= 15
    assert q.detection_fraction >= 0.95, q
    assert q.free_observed_cells > 500
    assert q.false_hazard_fraction <= 0.01, q


@pytest.mark.parametrize("index", [ROCK, DITCH])
def test_each_obstacle_is_detected(run: Run, index: int) -> None:
    geometry = run.trav.geometry
    q = assess(hazard=run.trav.hazard, hazard_geometry=geometry,
               truth=GroundTruth.from_terrain(run.terrain, only=[index]), track=run.track)
    assert q.obstacle_cells >= 6
    assert q.detection_fraction >= 0.95, q


def test_the_ditch_middle_is_inferred_not_seen(run: Run) -> None:
    """The laser never sees most of the ditch: its cells are holes, not measurements."""
    holes = (run.trav.flags & FLAG_HOLE) != 0
    i, j = run.trav.geometry.cell_index(np.array([2.2]), np.array([13.0]))
    assert holes.any()
    assert run.trav.hazard[i[0], j[0]] == 1.0


def test_the_plan_map_blocks_the_obstacles(run: Run) -> None:
    cost = run.plan.cost()
    for east, north in ((-1.8, 12.5), (2.2, 13.0)):
        i, j = run.plan.world_to_cell(east, north)
        assert cost[int(i), int(j)] == math.inf
    i, j = run.plan.world_to_cell(0.0, 5.0)  # the road driven
    assert 1.0 <= cost[int(i), int(j)] < 2.0
