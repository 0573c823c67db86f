"""FindPath's prior for unknown cells (CostGrid.update_prior): an unknown cell is assumed
to cost what the median known passable cell costs. On a hillside every unseen cell is
slope too, and a first plan through the unseen ground at cost 1 went round the patch of
slope in view, behind the vehicle (decision 0035).

Expected values follow from the definitions: grids built by hand, medians by hand, and
D* Lite's paths compared with the straight line."""

from __future__ import annotations

import math

import numpy as np
import pytest

from components.find_path.component import CostGrid
from components.find_path.dstar_lite import DStarLite
from idl import PlanMapEventIDL, PlanningBoundaryIDL, Position3DIDL, TimeIDL

N = 40


def plan_map(sensed: np.ndarray, a_priori: np.ndarray | None = None) -> PlanMapEventIDL:
    """A planning map: cells with a finite or infinite ``sensed`` cost are known (hazard
    from the cost), NaN cells unknown (their a priori cost: 1 unless given)."""
    known = ~np.isnan(sensed)
    hazard = np.where(known, np.where(np.isinf(sensed), 1.0, 0.5), np.nan)
    rows, cols = sensed.shape
    return PlanMapEventIDL(
        time=TimeIDL.from_seconds(100.0), frame="World", mapPose=np.eye(4),
        initialUTM=np.array([500_000.0, 5_500_000.0, 100.0]), gridsize=0.5,
        originX=0.0, originY=0.0, rows=rows, cols=cols,
        hazard=hazard.astype(np.float32), goodness=np.where(known, 1.0, 0.0).astype(np.float32),
        vehiclePosition=Position3DIDL(x=1.0, y=10.0, z=0.0), vehicleHeading=0.0,
        aPrioriCost=(np.ones_like(sensed) if a_priori is None else a_priori).astype(np.float32),
        sensedCost=np.where(known, sensed, 1.0).astype(np.float32),
        planningBoundary=PlanningBoundaryIDL(minX=0, minY=0, maxX=rows - 1, maxY=cols - 1))


def grid(sensed: np.ndarray, a_priori: np.ndarray | None = None) -> CostGrid:
    return CostGrid(plan_map(sensed, a_priori), inflation=0.0, margin=0.0, margin_cost=1.0)


def test_unknown_cells_cost_the_median_known_passable_cell():
    sensed = np.full((N, N), np.nan)
    sensed[:10, 10:30] = 4.8          # a patch of slope in view
    sensed[:10, 0:2] = 1.5
    sensed[5, 15] = math.inf          # a rock: not passable, not in the median
    g = grid(sensed)
    assert g.update_prior()
    passable = sensed[np.isfinite(sensed)]
    assert g.prior == pytest.approx(float(np.median(passable)))
    unknown = np.isnan(sensed)
    assert np.all(g.cost[unknown] == pytest.approx(4.8))
    assert np.all(g.cost[:10, 0:2] == pytest.approx(1.5))  # known cells keep their cost
    assert math.isinf(g.cost[5, 15])
    assert not g.update_prior()  # nothing moved


def test_flat_ground_keeps_unknown_cells_at_one_and_a_priori_costs_stay():
    sensed = np.full((N, N), np.nan)
    sensed[:10, :] = 1.0
    a_priori = np.ones((N, N))
    a_priori[30, 30] = 7.0  # a cell the operator marked expensive
    g = grid(sensed, a_priori)
    assert not g.update_prior()
    assert g.cost[20, 20] == 1.0 and g.cost[30, 30] == 7.0
    sensed[:10, :] = 3.0
    g = grid(sensed, a_priori)
    assert g.update_prior()
    assert g.cost[20, 20] == pytest.approx(3.0) and g.cost[30, 30] == pytest.approx(7.0)


def test_a_small_change_of_the_median_is_not_applied():
    sensed = np.full((N, N), np.nan)
    sensed[:10, :] = 2.0
    g = grid(sensed)
    assert g.update_prior() and g.prior == pytest.approx(2.0)
    sensed[:10, :] = 2.1  # 5 %: within the 10 % dead band
    g.raw[:10, :] = 2.1
    assert not g.update_prior() and g.prior == pytest.approx(2.0)


def test_on_a_slope_the_plan_crosses_the_slope_in_view_instead_of_going_round_it():
    """The vehicle at the west edge of a 6-cell-wide patch of known slope (cost 4.8),
    the goal 30 cells east in unknown ground. With unknown cells at 1 the plan leaves the
    patch to one side; with the prior it runs straight east."""
    sensed = np.full((N, N), np.nan)
    sensed[:, 17:23] = np.nan
    sensed[2:10, 17:23] = 4.8
    start, goal = (2, 20), (36, 20)

    def path_of(g: CostGrid) -> list[tuple[int, int]]:
        planner = DStarLite(g.cost, start, goal)
        planner.replan()
        return planner.path()

    optimistic = path_of(grid(sensed))
    g = grid(sensed)
    assert g.update_prior()
    prior = path_of(g)
    assert max(abs(c[1] - 20) for c in prior) == 0  # straight along the row
    assert max(abs(c[1] - 20) for c in optimistic) >= 3  # round the patch
