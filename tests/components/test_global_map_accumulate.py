"""Global Map core (components/global_map/accumulate.py): placement, the combination
rule, changed-region reporting, costs and transforms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from components.global_map.accumulate import (
    CostMapping,
    PlanningGrid,
    Region,
    cost_floor_is_admissible,
    mission_shift,
)
from components.global_map.parameters import GlobalMapParameters


def map_pose(x: float, y: float, yaw: float = 0.0) -> np.ndarray:
    t = np.eye(4)
    c, s = math.cos(yaw), math.sin(yaw)
    t[:2, :2] = [[c, -s], [s, c]]
    t[:2, 3] = (x, y)
    return t


def placement_by_loop(grid: PlanningGrid, shape: tuple[int, int], pose: np.ndarray,
                      ox: float, oy: float, g: float) -> dict[tuple[int, int], tuple[int, int]]:
    """Incoming cell → planning cell, one at a time."""
    out = {}
    geo = grid.geometry
    for i in range(shape[0]):
        for j in range(shape[1]):
            mx, my = ox + (i + 0.5) * g, oy + (j + 0.5) * g
            wx = pose[0, 0] * mx + pose[0, 1] * my + pose[0, 3]
            wy = pose[1, 0] * mx + pose[1, 1] * my + pose[1, 3]
            pi = math.floor((wx - geo.origin_x) / geo.gridsize)
            pj = math.floor((wy - geo.origin_y) / geo.gridsize)
            if 0 <= pi < geo.rows and 0 <= pj < geo.cols:
                out[(i, j)] = (pi, pj)
    return out


def test_defaults_give_a_500_by_500_mission_grid() -> None:
    p = GlobalMapParameters()
    grid = PlanningGrid.centred(0.0, 0.0, p.Width / 1000, p.Depth / 1000, p.Gridsize / 1000,
                                cost=CostMapping(unknown=p.UnknownCellCost))
    assert grid.geometry.shape == (500, 500)
    assert grid.geometry.origin_x == -125.0 and grid.geometry.origin_y == -125.0
    assert np.all(grid.cost() == 1.0)


def test_aligned_placement() -> None:
    grid = PlanningGrid.centred(0.0, 0.0, 20.0, 10.0, 0.5)  # 40 rows (east) x 20 cols
    hazard = np.array([[0.0, 0.5, np.nan], [1.0, 0.2, 0.0]], dtype=np.float32)
    goodness = np.full(hazard.shape, 0.8, dtype=np.float32)
    change = grid.merge(hazard, goodness, map_pose(3.0, -2.0), -1.0, 0.5, 0.5, 1.0)
    # cell [i, j] centre: (3 - 1 + 0.5 i + 0.25, -2 + 0.5 + 0.5 j + 0.25) -> planning
    # floor((x + 10) / 0.5), floor((y + 5) / 0.5) = (24 + i, 7 + j)
    for (i, j), h in np.ndenumerate(hazard):
        if np.isnan(h):
            assert not grid.sensed[24 + i, 7 + j]
            continue
        assert grid.sensed[24 + i, 7 + j] and grid.hazard[24 + i, 7 + j] == h
    assert grid.sensed.sum() == 5 and change.merged == 5 and change.outside == 0
    assert grid.cost()[25, 7] == math.inf
    assert grid.cost()[24, 8] == pytest.approx(1 + 9 * 0.25)
    # cost changed where the hazard is not 0; written region covers all five cells
    assert sorted(zip(change.rows.tolist(), change.cols.tolist(), strict=True)) == \
        [(24, 8), (25, 7), (25, 8)]
    assert change.region == Region(24, 26, 7, 10)
    assert change.cost_region == Region(24, 26, 7, 9)
    assert np.all(change.old_cost == 1.0)


@pytest.mark.parametrize("yaw,g", [(math.radians(90), 0.5), (math.radians(33), 0.5),
                                   (0.0, 0.25), (math.radians(-120), 0.2)])
def test_rotated_and_finer_maps_land_where_their_centres_fall(yaw: float, g: float) -> None:
    rng = np.random.default_rng(4)
    grid = PlanningGrid.centred(0.0, 0.0, 30.0, 30.0, 0.5)
    shape = (24, 20)
    hazard = rng.uniform(0, 1, shape)
    hazard[rng.random(shape) < 0.2] = np.nan
    goodness = rng.uniform(0.1, 1, shape)
    pose = map_pose(14.5, -14.5, yaw)  # at the grid's corner: some cells fall outside
    change = grid.merge(hazard, goodness, pose, -3.0, -2.5, g, 5.0)
    expected: dict[tuple[int, int], tuple[float, float]] = {}
    placed = placement_by_loop(grid, shape, pose, -3.0, -2.5, g)
    known = int((~np.isnan(hazard)).sum())
    assert change.outside == known - sum(1 for c in placed if not np.isnan(hazard[c]))
    assert change.outside > 0
    for (i, j), target in placed.items():
        if np.isnan(hazard[i, j]):
            continue
        best = expected.get(target)
        candidate = (hazard[i, j], goodness[i, j])
        if best is None or candidate > best:
            expected[target] = candidate
    assert change.merged == len(expected)
    assert grid.sensed.sum() == len(expected)
    for (pi, pj), (h, q) in expected.items():
        assert grid.hazard[pi, pj] == h and grid.goodness[pi, pj] == q


def test_outside_cells_are_counted() -> None:
    grid = PlanningGrid.centred(0.0, 0.0, 5.0, 5.0, 0.5)
    change = grid.merge(np.zeros((4, 4)), np.ones((4, 4)), map_pose(2.0, 2.0), 0.0, 0.0,
                        0.5, 0.0)
    assert change.merged == 1 and change.outside == 15  # only cell [0, 0] at (2.25, 2.25)


def test_combination_rule_better_data_wins_and_claims_age() -> None:
    grid = PlanningGrid.centred(0.0, 0.0, 10.0, 10.0, 0.5, age_constant=30.0)
    one = np.ones((1, 1))
    grid.merge(one, one * 0.9, map_pose(0, 0), 0.0, 0.0, 0.5, 0.0)  # seen close: lethal
    assert grid.cost()[10, 10] == math.inf
    # driven past: the far field re-reads it as easy, with goodness 0.9/1.5
    change = grid.merge(one * 0.0, one * 0.6, map_pose(0, 0), 0.0, 0.0, 0.5, 1.0)
    assert change.kept == 1 and len(change) == 0 and change.region is None
    assert grid.cost()[10, 10] == math.inf
    # unknown never erases
    grid.merge(one * np.nan, one, map_pose(0, 0), 0.0, 0.0, 0.5, 2.0)
    assert grid.hazard[10, 10] == 1.0
    # 0.9 · exp(-t/30) falls below 0.6 after 30 ln 1.5 = 12.2 s
    assert grid.merge(one * 0.0, one * 0.6, map_pose(0, 0), 0.0, 0.0, 0.5, 12.0).kept == 1
    change = grid.merge(one * 0.0, one * 0.6, map_pose(0, 0), 0.0, 0.0, 0.5, 12.5)
    assert change.kept == 0 and len(change) == 1
    assert change.old_cost[0] == math.inf and change.new_cost[0] == 1.0
    # equal data: the latest observation wins
    change = grid.merge(one * 0.3, one * 0.6, map_pose(0, 0), 0.0, 0.0, 0.5, 12.5)
    assert change.kept == 0 and grid.hazard[10, 10] == pytest.approx(0.3)
    # an older observation arriving late never replaces a newer one, however good
    change = grid.merge(one * 1.0, one * 1.0, map_pose(0, 0), 0.0, 0.0, 0.5, 5.0)
    assert change.kept == 1 and grid.hazard[10, 10] == pytest.approx(0.3)
    assert grid.merge(one, one, map_pose(0, 0), 0.0, 0.0, 0.5, 1e9).kept == 0  # no overflow


def test_repeated_identical_merge_writes_but_changes_no_cost() -> None:
    grid = PlanningGrid.centred(0.0, 0.0, 250.0, 250.0, 0.5)
    rng = np.random.default_rng(8)
    hazard = rng.uniform(0, 1, (64, 64))
    goodness = np.full((64, 64), 0.8)
    first = grid.merge(hazard, goodness, map_pose(10.0, 20.0), -16.0, -16.0, 0.5, 1.0)
    assert first.region == Region(238, 302, 258, 322) and first.region.size == 64 * 64
    assert len(first) == int((hazard > 0).sum())
    again = grid.merge(hazard, goodness, map_pose(10.0, 20.0), -16.0, -16.0, 0.5, 1.0)
    assert len(again) == 0 and again.cost_region is None and again.region == first.region
    sub = grid.layers(first.region)
    assert sub["hazard"].shape == (64, 64)
    np.testing.assert_array_equal(sub["hazard"], hazard.astype(np.float32))
    geo = first.region.geometry(grid.geometry)
    assert (geo.origin_x, geo.origin_y) == (-6.0, 4.0)


def test_costs_are_at_least_one_or_infinite() -> None:
    mapping = CostMapping()
    hazard = np.concatenate([np.linspace(0, 1, 101), [np.nan, 0.999999, 1.0]])
    cost = mapping(hazard)
    assert cost_floor_is_admissible(cost)
    assert cost[0] == 1.0 and cost[-1] == math.inf and cost[-3] == 1.0  # NaN → unknown
    assert np.all(np.diff(cost[:100]) > 0)  # rising with hazard
    assert cost[50] == pytest.approx(1 + 9 * 0.25)
    assert CostMapping(lethal=0.8)(0.8) == math.inf
    assert CostMapping(unknown=2.0)(np.nan) == 2.0
    assert not cost_floor_is_admissible([1.0, 0.5])
    assert not cost_floor_is_admissible([np.nan])
    with pytest.raises(ValueError):
        CostMapping(max_cost=0.5)


def test_a_priori_costs() -> None:
    grid = PlanningGrid.centred(0.0, 0.0, 10.0, 10.0, 0.5)
    grid.merge(np.zeros((1, 1)), np.ones((1, 1)), map_pose(0, 0), 0.0, 0.0, 0.5, 0.0)
    change = grid.set_a_priori([10, 3, 99], [10, 3, 0], [5.0, math.inf, 2.0])
    assert change.outside == 1
    assert grid.cost()[10, 10] == 1.0  # sensed: the sensed cost rules
    assert grid.cost()[3, 3] == math.inf
    assert len(change) == 1 and (change.rows[0], change.cols[0]) == (3, 3)
    assert change.region == Region(3, 11, 3, 11)
    for bad in (0.5, math.nan):
        with pytest.raises(ValueError):
            grid.set_a_priori(0, 0, bad)
    assert grid.layers()["aPrioriCost"][3, 3] == np.float32(np.inf)


def test_planning_transforms() -> None:
    grid = PlanningGrid.centred(100.0, -50.0, 40.0, 20.0, 0.5)
    p_w = grid.planning_from_world()
    w_p = grid.world_from_planning()
    np.testing.assert_allclose(p_w @ w_p, np.eye(4), atol=1e-12)
    rng = np.random.default_rng(2)
    xy = rng.uniform([80, -60], [120, -40], (100, 2))
    planning = (p_w @ np.column_stack([xy, np.zeros(100), np.ones(100)]).T).T
    i, j = grid.world_to_cell(xy[:, 0], xy[:, 1])
    np.testing.assert_array_equal(np.floor(planning[:, 0]).astype(int), i)
    np.testing.assert_array_equal(np.floor(planning[:, 1]).astype(int), j)
    assert grid.contains(i, j).all()
    cx, cy = grid.cell_to_world(i, j)
    centre = (p_w @ np.column_stack([cx, cy, np.zeros(100), np.ones(100)]).T).T
    np.testing.assert_allclose(centre[:, 0], i + 0.5, atol=1e-9)
    np.testing.assert_allclose(centre[:, 1], j + 0.5, atol=1e-9)
    with pytest.raises(ValueError):
        grid.world_to_cell(math.nan, 0.0)


# --- moving the grid ----------------------------------------------------------------------


def by_world_cell(grid: PlanningGrid) -> dict[tuple[int, int], tuple[float, ...]]:
    """Every cell's layers keyed by the world cell it covers (whole-cell indices of the
    world frame), NaN written as a string so that dictionaries compare."""
    g = grid.geometry
    out = {}
    for i in range(g.rows):
        for j in range(g.cols):
            key = (round(g.origin_x / g.gridsize) + i, round(g.origin_y / g.gridsize) + j)
            out[key] = tuple("nan" if isinstance(v, float) and math.isnan(v) else v
                             for v in (float(grid.a_priori[i, j]), float(grid.sensed_cost[i, j]),
                                       bool(grid.sensed[i, j]), float(grid.hazard[i, j]),
                                       float(grid.goodness[i, j]), float(grid.stamp[i, j])))
    return out


@pytest.mark.parametrize("move", [(3, -2), (-7, 0), (0, 5), (12, 1), (-1, -9)])
def test_a_moved_grid_keeps_every_world_cell_that_stays_inside(move):
    rng = np.random.default_rng(5)
    grid = PlanningGrid.centred(0.0, 0.0, 5.0, 4.0, 0.5, CostMapping(unknown=2.0))
    hazard = rng.uniform(0, 1.2, (10, 8))
    hazard[rng.random((10, 8)) < 0.3] = np.nan
    grid.merge(hazard, rng.uniform(0.2, 1, (10, 8)), np.eye(4), -2.5, -2.0, 0.5, 3.0)
    grid.set_a_priori([1, 4], [2, 6], [5.0, np.inf])
    before = by_world_cell(grid)
    grid.shift(*move)
    after = by_world_cell(grid)
    unknown = (2.0, 2.0, False, "nan", 0.0, -math.inf)
    assert len(after) == 80
    kept = 0
    for key, layers in after.items():
        if key in before:
            assert layers == before[key]
            kept += 1
        else:
            assert layers == unknown
    assert kept == max(0, 10 - abs(move[0])) * max(0, 8 - abs(move[1]))


def inside(geometry, points, margin: float) -> bool:
    x0, y0 = geometry.origin_x, geometry.origin_y
    x1, y1 = x0 + geometry.rows * geometry.gridsize, y0 + geometry.cols * geometry.gridsize
    return all(x0 + margin <= x <= x1 - margin and y0 + margin <= y <= y1 - margin
               for x, y in points)


def moved(geometry, shift):
    grid = PlanningGrid(geometry)
    grid.shift(*shift)
    return grid.geometry


def test_the_mission_shift_keeps_the_mission_inside():
    geometry = PlanningGrid.centred(0.0, 0.0, 100.0, 100.0, 0.5).geometry  # -50 .. 50
    margin = 10.0
    # everything inside already: no move
    assert mission_shift(geometry, (0.0, 0.0), [(30.0, 0.0), (-35.0, 39.0)], margin) == (0, 0)
    # the second waypoint beyond the edge, the mission 70 m long: it all fits, centred
    course = [(20.0, 0.0), (70.0, 10.0)]
    shift = mission_shift(geometry, (0.0, 0.0), course, margin)
    assert shift != (0, 0)
    assert inside(moved(geometry, shift), [(0.0, 0.0), *course], margin - 0.5)
    # the third does not fit with the others: the grid holds the vehicle and the two
    course3 = [*course, (150.0, -60.0)]
    assert mission_shift(geometry, (0.0, 0.0), course3, margin) == shift
    # once the vehicle is at the second, the third and the vehicle fit: held together
    later = mission_shift(moved(geometry, shift), (70.0, 10.0), course3[2:], margin)
    assert inside(moved(moved(geometry, shift), later), [(70.0, 10.0), (150.0, -60.0)],
                  margin - 0.5)


def test_a_leg_longer_than_the_grid_places_the_grid_along_it():
    geometry = PlanningGrid.centred(0.0, 0.0, 100.0, 100.0, 0.5).geometry
    margin = 10.0
    for vehicle, goal in [((0.0, 0.0), (400.0, 0.0)), ((0.0, 0.0), (-300.0, -300.0)),
                          ((45.0, 0.0), (500.0, 0.0))]:
        there = moved(geometry, mission_shift(geometry, vehicle, [goal], margin))
        assert inside(there, [vehicle], margin - 0.5)
        centre = np.array([there.origin_x + 50.0, there.origin_y + 50.0])
        towards = np.subtract(goal, vehicle) / np.linalg.norm(np.subtract(goal, vehicle))
        # most of the grid lies ahead of the vehicle, towards the goal
        assert np.dot(centre - vehicle, towards) >= 30.0
        # driving on along the leg: the grid stays until half its lead is used up
        for step in (10.0, 19.0):
            on = tuple(np.add(vehicle, towards * step))
            assert mission_shift(there, on, [goal], margin) == (0, 0)
        on = tuple(np.add(vehicle, towards * 40.0))
        again = moved(there, mission_shift(there, on, [goal], margin))
        assert np.dot(np.array([again.origin_x + 50.0, again.origin_y + 50.0]) - on,
                      towards) >= 30.0
    # a vehicle with nothing ahead, outside the grid: the grid comes to it
    there = moved(geometry, mission_shift(geometry, (120.0, 0.0), [], margin))
    assert inside(there, [(120.0, 0.0)], margin)

