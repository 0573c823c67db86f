"""FindPath's kinematic refinement (components/find_path/kinematic.py): a drivable path
into a gate the D* path turns into square.

The checks are plain geometry, independent of the refiner's grid: every motion is an arc
no tighter than the limit (consecutive poses are recomputed from the arc's formula), and
the Raptor's body rectangle (the simulator's: 2.85 m × 1.4 m from 0.4 m behind the rear
axle), sampled every 0.05 m along the path, never overlaps a wall (the true wall, not its
cells). The maps given to the refiner mark what the Traversability Map marks: the cells a
wall overlaps and their neighbours (the step beside it).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage

from components.arcs import max_curvature
from components.find_path.kinematic import Refiner

CELL = 0.5
ORIGIN = (-20.0, -20.0)
CELLS = 80
K_MAX = max_curvature(30.0, 1.9)
OFFSETS = (0.0, 0.8, 1.6, 2.4)
INFLATION = 1.5  # cells, FindPath's default grown obstacles
RADIUS = 0.81  # m, FindPath's DiscRadius
BODY = (-0.4, 2.45, 0.7)  # rear, front (m from the rear axle), half width


def walls_with_gate(gate_low: float, gate_high: float) -> list[tuple[float, float, float, float]]:
    """A 0.6 m wall along x = 0 across the whole map with a gate between two heights:
    rectangles (xmin, xmax, ymin, ymax)."""
    return [(-0.3, 0.3, -20.0, gate_low), (-0.3, 0.3, gate_high, 20.0)]


def grids(walls: list[tuple[float, float, float, float]]) -> tuple[np.ndarray, np.ndarray]:
    """The blocked cells as the Traversability Map marks them (any cell a wall overlaps
    and, the step to a neighbour, its 8 neighbours) and FindPath's grown cost (inf within
    the inflation, 3 within three cells, else 1), as CostGrid builds them."""
    edges = ORIGIN[0] + CELL * np.arange(CELLS + 1)
    blocked = np.zeros((CELLS, CELLS), dtype=bool)
    for x0, x1, y0, y1 in walls:
        i = (edges[:-1] < x1) & (edges[1:] > x0)
        j = (edges[:-1] < y1) & (edges[1:] > y0)
        blocked |= np.outer(i, j)
    blocked = ndimage.binary_dilation(blocked, structure=np.ones((3, 3), dtype=bool))
    distance = ndimage.distance_transform_edt(~blocked)
    cost = np.where(distance <= 3.0, 3.0, 1.0)
    cost[distance <= INFLATION] = np.inf
    return blocked, cost


def body_points(x: float, y: float, heading: float) -> np.ndarray:
    rear, front, half = BODY
    a, b = np.meshgrid(np.arange(rear, front + 1e-9, 0.05), np.arange(-half, half + 1e-9, 0.05))
    c, s = math.cos(heading), math.sin(heading)
    return np.stack([x + a * c - b * s, y + a * s + b * c], axis=-1).reshape(-1, 2)


def overlaps(points: np.ndarray, walls: list[tuple[float, float, float, float]]) -> bool:
    return any(bool(np.any((points[:, 0] > x0) & (points[:, 0] < x1) &
                           (points[:, 1] > y0) & (points[:, 1] < y1)))
               for x0, x1, y0, y1 in walls)


def drive(poses: list[tuple[float, float, float]], curvatures: list[float], step: float,
          directions: tuple[int, ...] = ()) -> list[tuple[float, float, float]]:
    """Every 0.05 m along the motions, recomputed from each start pose and curvature, in
    each motion's direction (1 forwards, -1 backwards; none given: all forwards); and
    check that each motion ends at the next pose."""
    dense = []
    assert len(curvatures) == len(poses) - 1
    for m, ((x, y, h), k, nxt) in enumerate(zip(poses[:-1], curvatures, poses[1:],
                                                strict=True)):
        assert abs(k) <= K_MAX + 1e-12
        sign = directions[m] if directions else 1
        for s in sign * np.append(np.arange(0.0, step, 0.05), step):
            if abs(k) < 1e-12:
                px, py = x + s * math.cos(h), y + s * math.sin(h)
            else:
                px = x + (math.sin(h + k * s) - math.sin(h)) / k
                py = y - (math.cos(h + k * s) - math.cos(h)) / k
            dense.append((px, py, h + k * s))
        end = dense[-1]
        assert math.hypot(end[0] - nxt[0], end[1] - nxt[1]) < 1e-9
        assert abs(math.remainder(end[2] - nxt[2], 2 * math.pi)) < 1e-9
    return dense


@pytest.mark.parametrize("start", [
    (-3.0, -2.0, math.pi / 2),    # along the wall, 2.7 m from it: must swing wide
    (-4.0, 2.0, math.pi / 2),     # farther from it and nearer the gate
    (-8.0, 0.0, 0.0),             # square to the wall, off the gate's line
    (-3.0, -5.0, math.pi / 2),    # far down the wall
    (-6.0, 14.0, -math.pi / 2),   # coming down from the north
])
def test_a_drivable_path_through_a_3m_gate(start):
    walls = walls_with_gate(8.0, 11.0)
    blocked, cost = grids(walls)
    refiner = Refiner(0.9 * K_MAX, OFFSETS, RADIUS, hazard_margin=0.5 * CELL)
    target = (4.0, 9.5, 0.0)
    refined = refiner.plan(blocked, cost, ORIGIN, CELL, start, target)
    assert refined is not None
    assert refined.poses[0] == start
    end = refined.poses[-1]
    assert math.hypot(end[0] - target[0], end[1] - target[1]) <= refiner.position_tolerance
    assert abs(math.remainder(end[2] - target[2], 2 * math.pi)) <= refiner.heading_tolerance
    for x, y, h in drive(refined.poses, refined.curvatures, refiner.step):
        assert not overlaps(body_points(x, y, h), walls), (x, y, math.degrees(h))
    # the point FindPath steers by lies on the path: at whole motions, the poses
    for k, pose in enumerate(refined.poses):
        assert math.dist(refined.at(k * refiner.step), pose[:2]) < 1e-9
    # it goes through the gate, not round the map's edge
    assert max(abs(p[1]) for p in refined.poses) < 16.0


def test_a_gate_narrower_than_the_body_has_no_path():
    walls = walls_with_gate(8.8, 10.2)  # 1.4 m: the body's width, no room
    blocked, cost = grids(walls)
    refiner = Refiner(0.9 * K_MAX, OFFSETS, RADIUS, hazard_margin=0.5 * CELL)
    assert refiner.plan(blocked, cost, ORIGIN, CELL, (-6.0, 9.5, 0.0), (4.0, 9.5, 0.0)) is None


def test_in_the_open_the_path_is_nearly_straight_and_cheap():
    blocked = np.zeros((CELLS, CELLS), dtype=bool)
    cost = np.ones((CELLS, CELLS))
    refiner = Refiner(0.9 * K_MAX, OFFSETS, RADIUS, hazard_margin=0.5 * CELL)
    refined = refiner.plan(blocked, cost, ORIGIN, CELL, (-8.0, 1.0, 0.2), (4.0, 0.0, None))
    assert refined is not None
    length = refiner.step * (len(refined.poses) - 1)
    assert length <= 1.1 * math.hypot(12.0, 1.0)
    assert refined.expansions < 100


def test_a_target_behind_a_closed_wall_is_not_reached():
    walls = [(-0.3, 0.3, -20.0, 20.0)]
    blocked, cost = grids(walls)
    refiner = Refiner(0.9 * K_MAX, OFFSETS, RADIUS, hazard_margin=0.5 * CELL)
    assert refiner.plan(blocked, cost, ORIGIN, CELL, (-6.0, 0.0, 0.0), (4.0, 0.0, 0.0)) is None


def test_a_waypoint_short_of_a_wall_is_reached_by_the_bumper():
    # The waypoint 1.2 m short of a wall, the vehicle 12 m off facing it: the rear
    # axle can reach the waypoint's cell only side-on to the wall, by a swing; the
    # bumper comes to the waypoint straight.
    walls = [(-0.3, 0.3, -20.0, 20.0)]
    blocked, cost = grids(walls)
    waypoint, radius = (-1.5, 0.0), 1.5
    start = (-12.0, 0.2, 0.0)
    target = (-1.75, 0.25, None)  # the passable cell nearest it, as FindPath's goal
    refiner = Refiner(0.9 * K_MAX, OFFSETS, RADIUS, hazard_margin=0.5 * CELL)
    swing = refiner.plan(blocked, cost, ORIGIN, CELL, start, target, open_cost=6.0)
    assert swing is not None and abs(swing.poses[-1][2]) > 1.0
    refined = refiner.plan(blocked, cost, ORIGIN, CELL, start, target, open_cost=6.0,
                           arrival=(*waypoint, radius, BODY[1], 0.0))
    assert refined is not None
    x, y, h = refined.poses[-1]
    bumper = (x + BODY[1] * math.cos(h), y + BODY[1] * math.sin(h))
    assert math.dist(bumper, waypoint) <= radius
    assert math.dist((x, y), waypoint) > radius  # the bumper's test, not the axle's
    assert refiner.step * (len(refined.poses) - 1) <= 1.1 * math.dist(start[:2], bumper)
    for px, py, ph in drive(refined.poses, refined.curvatures, refiner.step):
        assert not overlaps(body_points(px, py, ph), walls)


def test_the_arrival_test_starts_after_the_first_motion():
    # a vehicle already within the region gets a path that moves it (the Global Map,
    # with the whole tolerance, will have counted the waypoint before FindPath asks)
    blocked = np.zeros((CELLS, CELLS), dtype=bool)
    cost = np.ones((CELLS, CELLS))
    refiner = Refiner(0.9 * K_MAX, OFFSETS, RADIUS, hazard_margin=0.5 * CELL)
    refined = refiner.plan(blocked, cost, ORIGIN, CELL, (0.0, 0.0, 0.0), (5.25, 0.25, None),
                           arrival=(0.0, 0.0, 1.0, BODY[1], 0.0))
    assert refined is not None and len(refined.poses) == 2


def random_scene(rng: np.random.Generator) -> tuple[list[tuple[float, float, float, float]],
                                                    tuple[float, float, float],
                                                    tuple[float, float, float | None],
                                                    float | None,
                                                    tuple[float, float, float, float, float]
                                                    | None]:
    """Random boxes (and sometimes a wall with a gate), a start clear of them, a target
    ahead, with or without a heading, a current curvature and an arrival region."""
    walls: list[tuple[float, float, float, float]] = []
    if rng.random() < 0.5:
        low = float(rng.uniform(-8.0, 6.0))
        walls += walls_with_gate(low, low + float(rng.uniform(1.2, 5.0)))
    for _ in range(int(rng.integers(0, 12))):
        x, y = rng.uniform(-14.0, 14.0, size=2)
        w, h = rng.uniform(0.3, 3.0, size=2)
        walls.append((float(x), float(x + w), float(y), float(y + h)))
    while True:
        start = (float(rng.uniform(-12.0, -3.0)), float(rng.uniform(-10.0, 10.0)),
                 float(rng.uniform(-math.pi, math.pi)))
        if not overlaps(body_points(*start), walls):
            break
    heading = float(rng.uniform(-math.pi, math.pi)) if rng.random() < 0.5 else None
    target = (float(rng.uniform(2.0, 10.0)), float(rng.uniform(-10.0, 10.0)), heading)
    curvature = float(rng.uniform(-K_MAX, K_MAX)) if rng.random() < 0.7 else None
    arrival = ((target[0] + float(rng.uniform(-1.0, 1.0)),
                target[1] + float(rng.uniform(-1.0, 1.0)), float(rng.uniform(0.5, 2.0)),
                BODY[1], float(rng.uniform(-0.3, 0.3))) if rng.random() < 0.4 else None)
    return walls, start, target, curvature, arrival


@pytest.mark.skipif(Refiner(K_MAX, OFFSETS, RADIUS).kernel is None,
                    reason="no compiled search (numba missing, or AFA_KERNELS=numpy)")
@pytest.mark.parametrize("reverse", [0.0, 3.0])
def test_the_compiled_search_returns_the_python_loops_path_bit_for_bit(reverse: float):
    rng = np.random.default_rng(2026)
    found = missing = backing = 0
    for _ in range(60):
        walls, start, target, curvature, arrival = random_scene(rng)
        blocked, cost = grids(walls)
        seen = rng.random(blocked.shape) < 0.8 if reverse else None
        results = []
        for compiled in (True, False):
            refiner = Refiner(0.9 * K_MAX, OFFSETS, RADIUS, hazard_margin=0.5 * CELL,
                              max_expansions=int(rng.integers(200, 3000)) if compiled
                              else results[0][1], reverse_cost=reverse, switch_cost=3.0)
            if not compiled:
                refiner.kernel = None
            refined = refiner.plan(blocked, cost, ORIGIN, CELL, start, target,
                                   curvature=curvature, open_cost=6.0, arrival=arrival,
                                   seen=seen)
            results.append((refined, refiner.max_expansions))
        fast, slow = results[0][0], results[1][0]
        if slow is None:
            missing += 1
            assert fast is None
            continue
        found += 1
        assert fast is not None
        assert fast.poses == slow.poses  # exact floats
        assert fast.curvatures == slow.curvatures
        assert fast.expansions == slow.expansions
        assert fast.directions == slow.directions
        backing += -1 in fast.directions
    assert found >= 20 and missing >= 5  # both outcomes were exercised
    assert (backing > 0) == (reverse > 0)
