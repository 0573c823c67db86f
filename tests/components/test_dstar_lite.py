"""Tests for FindPath's D* Lite planner (components/find_path/dstar_lite.py).

The oracle is scipy's Dijkstra from the goal on the reversed graph, built here by a
plain loop over cells and neighbours from the edge model as the module docstring states
it (enter cost times step length, no diagonal between two impassable corners), not from
the planner's own graph code. After every compute the tests check, independently of the
planner's bookkeeping:

- the D* Lite invariants: ``rhs(goal) = 0``, ``rhs(s) = min c(s, s') + g(s')`` for every
  other cell (exactly: both sides use the same float operations), and the queue holds
  exactly the locally inconsistent cells;
- exactness where the theory promises it: every locally consistent cell whose key does
  not exceed the top key (the start among them) has ``g`` equal to the oracle; with an
  empty queue, every cell does. A consistent cell *outside* that key range may legitimately
  hold a stale ``g`` (the search stops as soon as the start is settled), so requiring
  ``g == oracle`` at every consistent cell would be a wrong test (see
  ``test_a_consistent_cell_beyond_the_top_key_may_hold_a_stale_cost``);
- the path: 8-connected, never entering an impassable cell, never cutting a corner, from
  the start to the goal, and costing exactly the oracle's shortest cost.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from components.find_path.dstar_lite import (
    DStarLite,
    GridError,
    PlannerError,
    PlanNotReadyError,
    PlanStatus,
    reverse_graph,
)

INF = math.inf
ROOT2 = math.sqrt(2.0)
NEIGHBOURS = [(dx, dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1) if (dx, dy) != (0, 0)]

Cell = tuple[int, int]


# ---------------------------------------------------------------------- the oracle

def edge_cost(cost: np.ndarray, a: Cell, b: Cell) -> float:
    """c(a, b) by the documented edge model, or inf; a and b must be neighbours."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    assert max(abs(dx), abs(dy)) == 1, (a, b)
    if math.isinf(cost[b]):
        return INF
    if dx and dy:
        if math.isinf(cost[a[0] + dx, a[1]]) and math.isinf(cost[a[0], a[1] + dy]):
            return INF  # squeezing between two impassable corners
        return float(cost[b]) * ROOT2
    return float(cost[b])


def neighbours(cost: np.ndarray, a: Cell) -> Iterator[Cell]:
    nx, ny = cost.shape
    for dx, dy in NEIGHBOURS:
        b = (a[0] + dx, a[1] + dy)
        if 0 <= b[0] < nx and 0 <= b[1] < ny:
            yield b


def edge_table(cost: np.ndarray) -> np.ndarray:
    """c((x, y), (x, y) + NEIGHBOURS[k]) at [x, y, k] (inf outside the grid), by loops."""
    nx, ny = cost.shape
    table = np.full((nx, ny, 8), INF)
    for x in range(nx):
        for y in range(ny):
            for k, (dx, dy) in enumerate(NEIGHBOURS):
                if 0 <= x + dx < nx and 0 <= y + dy < ny:
                    table[x, y, k] = edge_cost(cost, (x, y), (x + dx, y + dy))
    return table


_ORACLES: dict[tuple[bytes, tuple[int, int], Cell], tuple[np.ndarray, np.ndarray]] = {}


def oracle_and_edges(cost: np.ndarray, goal: Cell) -> tuple[np.ndarray, np.ndarray]:
    """Exact cost to the goal of every cell (Dijkstra from the goal, edges reversed), and
    the edge table it was built from; memoised, since a drive re-checks unchanged maps."""
    key = (cost.tobytes(), cost.shape, goal)
    if key not in _ORACLES:
        nx, ny = cost.shape
        table = edge_table(cost)
        rows, cols, weights = [], [], []
        for x in range(nx):
            for y in range(ny):
                for k, (dx, dy) in enumerate(NEIGHBOURS):
                    if table[x, y, k] < INF:
                        rows.append((x + dx) * ny + y + dy)  # reversed: (x, y) <- its successor
                        cols.append(x * ny + y)
                        weights.append(table[x, y, k])
        graph = coo_matrix((weights, (rows, cols)), shape=(nx * ny, nx * ny)).tocsr()
        dist = dijkstra(graph, directed=True, indices=goal[0] * ny + goal[1]).reshape(nx, ny)
        if len(_ORACLES) > 256:
            _ORACLES.clear()
        _ORACLES[key] = (dist, table)
    return _ORACLES[key]


def oracle(cost: np.ndarray, goal: Cell) -> np.ndarray:
    return oracle_and_edges(cost, goal)[0]


def path_cost(cost: np.ndarray, path: list[Cell]) -> float:
    return sum(edge_cost(cost, a, b) for a, b in zip(path, path[1:], strict=False))


def octile(a: Cell, b: Cell) -> float:
    dx, dy = abs(a[0] - b[0]), abs(a[1] - b[1])
    return max(dx, dy) + (ROOT2 - 1.0) * min(dx, dy)


def check_planner(planner: DStarLite, cost: np.ndarray) -> np.ndarray:
    """Assert the invariants, exactness and the path (module docstring); return the oracle."""
    truth, table = oracle_and_edges(cost, planner.goal)
    state = planner.state()
    g, rhs = state.g, state.rhs
    nx, ny = cost.shape
    goal, start = planner.goal, planner.start
    assert rhs[goal] == 0.0
    # rhs(s) = min_k c(s, s + d_k) + g(s + d_k), exactly, for every cell but the goal
    padded = np.full((nx + 2, ny + 2), INF)
    padded[1:-1, 1:-1] = g
    successors_g = np.stack([padded[1 + dx:nx + 1 + dx, 1 + dy:ny + 1 + dy]
                             for dx, dy in NEIGHBOURS], axis=-1)
    expected = (table + successors_g).min(axis=-1)
    expected[goal] = 0.0
    broken = np.argwhere(rhs != expected)
    assert broken.size == 0, f"rhs invariant broken at {broken[:5].tolist()}"
    np.testing.assert_array_equal(state.queued, g != rhs, "queue != inconsistent cells")

    consistent = g == rhs
    if not state.queued.any():
        np.testing.assert_allclose(g, truth, rtol=1e-12, atol=1e-9)
    else:
        # key <= top key, lexicographically; this test's h is the unscaled octile distance,
        # a hair above the planner's, so it errs on the side of checking fewer cells
        top1, top2 = state.top_key
        key2 = np.minimum(g, rhs)
        key1 = np.array([[key2[x, y] + octile(start, (x, y)) + state.k_m for y in range(ny)]
                         for x in range(nx)])
        settled = consistent & ((key1 < top1) | ((key1 == top1) & (key2 <= top2)))
        assert settled[start], "the start is not settled after compute"
        np.testing.assert_allclose(g[settled], truth[settled], rtol=1e-12, atol=1e-9)
    assert g[start] == rhs[start]
    assert math.isclose(g[start], truth[start], rel_tol=1e-12, abs_tol=1e-9) or (
        math.isinf(g[start]) and math.isinf(truth[start]))
    assert planner.cost_to_goal() == g[start]

    path = planner.path()
    if math.isinf(truth[start]):
        assert path == []
    else:
        assert path[0] == start and path[-1] == goal
        for a, b in zip(path, path[1:], strict=False):
            assert edge_cost(cost, a, b) < INF, f"invalid step {a} -> {b}"
        assert math.isclose(path_cost(cost, path), truth[start], rel_tol=1e-12, abs_tol=1e-9)
    return truth


# ---------------------------------------------------------------------- maps

def random_map(rng: np.random.Generator, nx: int, ny: int, blocked: float = 0.2) -> np.ndarray:
    cost = rng.choice([1.0, 1.0, 1.0, 1.5, 2.0, 4.0], size=(nx, ny))
    cost[rng.random((nx, ny)) < blocked] = INF
    return cost


def free_cell(rng: np.random.Generator, cost: np.ndarray) -> Cell:
    free = np.argwhere(np.isfinite(cost))
    x, y = free[rng.integers(len(free))]
    return (int(x), int(y))


def apply(planner: DStarLite, cost: np.ndarray, xs: np.ndarray, ys: np.ndarray,
          values: np.ndarray) -> None:
    planner.update_costs(xs, ys, values)
    for x, y, v in zip(xs.tolist(), ys.tolist(), values.tolist(), strict=True):
        cost[x, y] = v  # last one wins, as in the planner


# ---------------------------------------------------------------------- oracle tests

@pytest.mark.parametrize("seed", range(6))
def test_initial_plan_matches_the_oracle(seed: int) -> None:
    rng = np.random.default_rng(seed)
    cost = random_map(rng, 18, 14, blocked=0.25)
    planner = DStarLite(cost, free_cell(rng, cost), free_cell(rng, cost))
    assert planner.compute() in (PlanStatus.DONE, PlanStatus.NO_PATH)
    check_planner(planner, cost)


@pytest.mark.parametrize("seed", range(8))
def test_replans_match_the_oracle(seed: int) -> None:
    """Blocks near the goal, freed cells, raised and lowered costs, moves along the path."""
    rng = np.random.default_rng(100 + seed)
    nx, ny = 20, 16
    cost = random_map(rng, nx, ny)
    goal = free_cell(rng, cost)
    planner = DStarLite(cost, free_cell(rng, cost), goal)
    planner.compute()
    check_planner(planner, cost)
    for step in range(14):
        kind = step % 5
        if kind == 0:  # a block of impassable cells right beside the goal
            k = int(rng.integers(1, 4))
            cx = int(np.clip(goal[0] + rng.integers(-2, 3), 0, nx - 1))
            cy = int(np.clip(goal[1] + rng.integers(-2, 3), 0, ny - 1))
            xs, ys = np.meshgrid(np.arange(cx, min(nx, cx + k)), np.arange(cy, min(ny, cy + k)),
                                 indexing="ij")
            xs, ys = xs.ravel(), ys.ravel()
            apply(planner, cost, xs, ys, np.full(xs.size, INF))
        elif kind == 1:  # free some impassable cells
            blocked = np.argwhere(np.isinf(cost))
            pick = blocked[rng.permutation(len(blocked))[:6]]
            apply(planner, cost, pick[:, 0], pick[:, 1], np.ones(len(pick)))
        elif kind == 2:  # raise and lower costs at random (some repeated cells)
            xs = rng.integers(0, nx, 12)
            ys = rng.integers(0, ny, 12)
            apply(planner, cost, xs, ys, rng.choice([1.0, 1.2, 3.0, 9.0, INF], size=12))
        elif kind == 3:  # drive a few cells along the path
            for cell in planner.path()[1:4]:
                planner.move_start(cell)
        else:  # costs along the current path (the cells the search tree leans on)
            path = planner.path()
            if len(path) > 2:
                mid = path[1:-1]
                xs = np.array([c[0] for c in mid])
                ys = np.array([c[1] for c in mid])
                apply(planner, cost, xs, ys, rng.choice([2.5, INF], size=len(mid)))
        status = planner.compute()
        assert status in (PlanStatus.DONE, PlanStatus.NO_PATH)
        check_planner(planner, cost)


def test_a_block_on_the_path_next_to_the_goal() -> None:
    cost = np.ones((24, 24))
    planner = DStarLite(cost, (1, 1), (20, 20))
    planner.compute()
    check_planner(planner, cost)
    xs, ys = np.meshgrid(np.arange(17, 20), np.arange(17, 20), indexing="ij")
    apply(planner, cost, xs.ravel(), ys.ravel(), np.full(9, INF))
    planner.compute()
    check_planner(planner, cost)
    apply(planner, cost, xs.ravel(), ys.ravel(), np.ones(9))  # and gone again
    planner.compute()
    truth = check_planner(planner, cost)
    assert planner.cost_to_goal() == pytest.approx(19 * ROOT2) == truth[1, 1]


def test_a_consistent_cell_beyond_the_top_key_may_hold_a_stale_cost() -> None:
    """Why the oracle check is limited to the key range: a corridor, goal next to the start.

    After the cost of cell 5 rises, cell 6 is queued (its best route went through 5) but
    its key is far above the start's, so compute stops at once. Cell 7 still leans on the
    old g(6): locally consistent, and wrong. cost_to_goal settles it on demand.
    """
    cost = np.ones((10, 1))
    planner = DStarLite(cost, (0, 0), (1, 0))
    planner.rebuild()
    apply(planner, cost, np.array([5]), np.array([0]), np.array([10.0]))
    assert planner.compute() is PlanStatus.DONE
    assert planner.statistics().last_expansions == 0
    state = planner.state()
    assert state.queued[6, 0] and not state.queued[7, 0]
    assert state.g[7, 0] == state.rhs[7, 0] == 6.0  # consistent ...
    assert oracle(cost, (1, 0))[7, 0] == 15.0  # ... and stale
    check_planner(planner, cost)  # which the key-range check allows
    assert planner.cost_to_goal((7, 0)) == 15.0


# ---------------------------------------------------------------------- the edge model

def test_a_diagonal_may_not_squeeze_between_two_impassable_corners() -> None:
    cost = np.ones((2, 2))
    cost[1, 0] = cost[0, 1] = INF
    planner = DStarLite(cost, (0, 0), (1, 1))
    assert planner.compute() is PlanStatus.NO_PATH
    assert planner.path() == []
    assert planner.cost_to_goal() == INF


def test_a_diagonal_may_brush_past_one_impassable_corner() -> None:
    cost = np.ones((2, 2))
    cost[1, 0] = INF
    planner = DStarLite(cost, (0, 0), (1, 1))
    assert planner.compute() is PlanStatus.DONE
    assert planner.path() == [(0, 0), (1, 1)]
    assert planner.cost_to_goal() == ROOT2


def test_entering_pays_the_cost_of_the_cell_entered_times_the_step() -> None:
    cost = np.array([[1.0, 3.0], [5.0, 2.0]])
    planner = DStarLite(cost, (0, 0), (1, 1))
    planner.compute()
    assert planner.cost_to_goal() == 2.0 * ROOT2
    assert planner.cost_to_goal((0, 1)) == 2.0
    assert planner.cost_to_goal((1, 1)) == 0.0


def test_a_start_inside_an_impassable_cell_can_drive_out() -> None:
    cost = np.ones((5, 5))
    cost[0, 0] = INF
    planner = DStarLite(cost, (0, 0), (4, 4))
    assert planner.compute() is PlanStatus.DONE
    path = planner.path()
    assert path[0] == (0, 0) and all(cost[c] < INF for c in path[1:])
    check_planner(planner, cost)


def test_reverse_graph_agrees_with_the_oracle() -> None:
    rng = np.random.default_rng(7)
    cost = random_map(rng, 13, 9, blocked=0.3)
    goal = free_cell(rng, cost)
    dist = dijkstra(reverse_graph(cost), directed=True, indices=goal[0] * 9 + goal[1])
    np.testing.assert_array_equal(dist.reshape(13, 9), oracle(cost, goal))


# ---------------------------------------------------------------------- no path

def test_an_enclosed_goal_has_no_path_and_opening_the_wall_finds_one() -> None:
    cost = np.ones((12, 12))
    cost[6:11, 6] = cost[6:11, 10] = cost[6, 6:11] = cost[10, 6:11] = INF
    planner = DStarLite(cost, (0, 0), (8, 8))
    assert planner.compute() is PlanStatus.NO_PATH
    assert planner.path() == []
    assert planner.compute() is PlanStatus.NO_PATH  # again: no work, no loop
    assert planner.statistics().last_expansions == 0
    check_planner(planner, cost)
    apply(planner, cost, np.array([6]), np.array([8]), np.array([1.0]))
    assert planner.compute() is PlanStatus.DONE
    check_planner(planner, cost)


def test_an_enclosed_start_has_no_path() -> None:
    cost = np.ones((9, 9))
    cost[0:3, 2] = cost[2, 0:3] = INF
    planner = DStarLite(cost, (0, 0), (8, 8))
    assert planner.compute() is PlanStatus.NO_PATH
    assert planner.path() == []
    check_planner(planner, cost)
    assert planner.rebuild() is PlanStatus.NO_PATH
    check_planner(planner, cost)


def test_an_impassable_goal_has_no_path() -> None:
    cost = np.ones((6, 6))
    cost[3, 3] = INF
    planner = DStarLite(cost, (0, 0), (3, 3))
    assert planner.compute() is PlanStatus.NO_PATH
    check_planner(planner, cost)


# ---------------------------------------------------------------------- the cap

def _big_change_scenario() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(5)
    cost = random_map(rng, 30, 30, blocked=0.15)
    cost[0, 0] = cost[29, 29] = 1.0
    xs, ys = np.meshgrid(np.arange(25, 29), np.arange(25, 29), indexing="ij")
    return cost, xs.ravel(), ys.ravel()


def test_a_capped_compute_resumes_to_the_uncapped_result() -> None:
    cost, xs, ys = _big_change_scenario()
    results = []
    for cap in (None, 3):
        planner = DStarLite(cost, (0, 0), (29, 29))
        statuses = [planner.compute(cap)]
        while statuses[-1] is PlanStatus.CAPPED:
            with pytest.raises(PlanNotReadyError):
                planner.path()
            statuses.append(planner.compute(cap))
        planner.update_costs(xs, ys, np.full(xs.size, INF))
        statuses.append(planner.compute(cap))
        while statuses[-1] is PlanStatus.CAPPED:
            statuses.append(planner.compute(cap))
        if cap is not None:
            assert statuses.count(PlanStatus.CAPPED) > 10
            assert planner.statistics().capped == statuses.count(PlanStatus.CAPPED)
        assert statuses[-1] is PlanStatus.DONE
        results.append((planner.state(), planner.path(), planner.statistics()))
    (uncapped, path_a, stats_a), (capped, path_b, stats_b) = results
    np.testing.assert_array_equal(uncapped.g, capped.g)
    np.testing.assert_array_equal(uncapped.rhs, capped.rhs)
    np.testing.assert_array_equal(uncapped.queued, capped.queued)
    assert path_a == path_b
    assert stats_a.total_expansions == stats_b.total_expansions


def test_a_zero_cap_does_nothing_and_a_negative_cap_is_refused() -> None:
    planner = DStarLite(np.ones((4, 4)), (0, 0), (3, 3))
    assert planner.compute(0) is PlanStatus.CAPPED
    assert planner.statistics().last_expansions == 0
    with pytest.raises(ValueError):
        planner.compute(-1)
    assert planner.compute() is PlanStatus.DONE
    assert planner.compute(0) is PlanStatus.DONE  # settled already: nothing to do


# ---------------------------------------------------------------------- the fallback

def test_rebuild_gives_the_exact_state_everywhere_and_increments_stay_exact() -> None:
    rng = np.random.default_rng(11)
    cost = random_map(rng, 22, 17, blocked=0.25)
    planner = DStarLite(cost, free_cell(rng, cost), free_cell(rng, cost))
    planner.compute()
    apply(planner, cost, np.array([3, 4, 5]), np.array([3, 3, 3]), np.full(3, INF))
    planner.move_start(free_cell(rng, cost))
    assert planner.rebuild() in (PlanStatus.DONE, PlanStatus.NO_PATH)
    state = planner.state()
    assert not state.queued.any() and state.k_m == 0.0
    np.testing.assert_array_equal(state.g, oracle(cost, planner.goal))  # bit-equal
    check_planner(planner, cost)
    for step in range(8):
        if step % 2:
            for cell in planner.path()[1:3]:
                planner.move_start(cell)
        xs = rng.integers(0, 22, 8)
        ys = rng.integers(0, 17, 8)
        apply(planner, cost, xs, ys, rng.choice([1.0, 2.0, INF], size=8))
        planner.compute()
        check_planner(planner, cost)
    assert planner.statistics().rebuilds == 1


def test_replan_falls_back_to_a_rebuild_when_the_budget_runs_out() -> None:
    cost, xs, ys = _big_change_scenario()
    planner = DStarLite(cost, (0, 0), (29, 29))
    assert planner.compute() is PlanStatus.DONE
    planner.update_costs(xs, ys, np.full(xs.size, INF))
    cost[xs, ys] = INF
    assert planner.replan(max_expansions=5) is PlanStatus.DONE
    stats = planner.statistics()
    assert stats.rebuilds == 1 and stats.capped == 1
    check_planner(planner, cost)
    planner.update_costs([10], [10], [3.0])  # small change: incremental
    cost[10, 10] = 3.0
    assert planner.replan(max_expansions=10_000) is PlanStatus.DONE
    assert planner.statistics().rebuilds == 1
    check_planner(planner, cost)


def test_the_budget_scales_with_the_grid_and_can_be_set() -> None:
    small = DStarLite(np.ones((10, 10)), (0, 0), (9, 9))
    large = DStarLite(np.ones((400, 400)), (0, 0), (9, 9))
    assert 1 <= small.fallback_expansions < large.fallback_expansions
    chosen = DStarLite(np.ones((4, 4)), (0, 0), (3, 3), fallback_expansions=7)
    assert chosen.fallback_expansions == 7
    with pytest.raises(ValueError):
        DStarLite(np.ones((4, 4)), (0, 0), (3, 3), fallback_expansions=-1)
    cost, xs, ys = _big_change_scenario()
    planner = DStarLite(cost, (0, 0), (29, 29), fallback_expansions=0)
    assert planner.replan() is PlanStatus.DONE  # a zero budget: always from scratch
    assert planner.statistics().rebuilds == 1
    check_planner(planner, cost)


# ---------------------------------------------------------------------- the moving robot

def _drive(truth: np.ndarray, start: Cell, goal: Cell,
           radius: int) -> tuple[list[Cell], list[bool], int]:
    """Drive through unknown terrain (freespace assumption), checking every cycle.

    Returns the cells visited, per cell whether the scan made there changed the map, and
    the planner's total expansions.
    """
    nx, ny = truth.shape
    known = np.ones_like(truth)
    r = np.arange(-radius, radius + 1)
    ox, oy = (a.ravel() for a in np.meshgrid(r, r, indexing="ij"))
    disc = ox * ox + oy * oy <= radius * radius
    ox, oy = ox[disc], oy[disc]

    def scan(cell: Cell) -> bool:
        xs, ys = ox + cell[0], oy + cell[1]
        keep = (xs >= 0) & (xs < nx) & (ys >= 0) & (ys < ny)
        changed = bool((known[xs[keep], ys[keep]] != truth[xs[keep], ys[keep]]).any())
        apply(planner, known, xs[keep], ys[keep], truth[xs[keep], ys[keep]])
        return changed

    planner = DStarLite(known, start, goal)
    position = start
    visited = [position]
    news = [scan(position)]
    status = planner.compute()
    for _ in range(4 * nx * ny):
        assert status is PlanStatus.DONE
        best = check_planner(planner, known)  # g(start) and the path optimal on the known map
        if position == goal:
            break
        step = planner.path()[1]
        assert truth[step] < INF, "drove into an obstacle"
        # the move is optimal on the map known when it was made
        assert math.isclose(edge_cost(known, position, step) + best[step], best[position],
                            rel_tol=1e-12, abs_tol=1e-9)
        position = step
        visited.append(position)
        planner.move_start(position)  # move, scan, replan: the paper's order
        news.append(scan(position))
        status = planner.compute()
    assert position == goal
    return visited, news, planner.statistics().total_expansions


def _field(seed: int, wall: bool) -> np.ndarray:
    """A 26 x 26 map of rough cells and obstacle discs, optionally a wall with a gap."""
    rng = np.random.default_rng(seed)
    nx = ny = 26
    truth = random_map(rng, nx, ny, blocked=0.0)
    xx, yy = np.mgrid[0:nx, 0:ny]
    for _ in range(12 if wall else 14):
        cx, cy = rng.integers(0, nx, 2)
        truth[(xx - cx) ** 2 + (yy - cy) ** 2 <= rng.uniform(1, 3) ** 2] = INF
    if wall:
        gap = int(rng.integers(2, ny - 2))
        truth[nx // 2, :] = INF
        truth[nx // 2, gap - 1:gap + 2] = 1.0
    truth[1, 1] = truth[nx - 2, ny - 2] = 1.0
    assert math.isfinite(oracle(truth, (nx - 2, ny - 2))[1, 1]), "the map must be solvable"
    return truth


# Total expansions of each seeded drive today, plus 10 %: a guard on work, not time. The
# counts are deterministic. Expanding entries with stale keys instead of re-keying them
# first (the paper's "k_old < k_new" step) still gives exact results but costs 20-45 %
# more on these drives, and this catches it.
DRIVE_EXPANSIONS = {300: 335, 301: 325, 303: 425, 200: 1090, 201: 425, 202: 1200}


@pytest.mark.parametrize("seed", [300, 301, 303])
def test_a_robot_drives_through_unknown_terrain_without_turning_back(seed: int) -> None:
    """Obstacle discs the sensor sees in time: the drive never goes a -> b -> a."""
    visited, _, expansions = _drive(_field(seed, wall=False), (1, 1), (24, 24), radius=3)
    assert [i for i in range(len(visited) - 2) if visited[i] == visited[i + 2]] == []
    assert len(visited) <= 2 * 26
    assert expansions <= DRIVE_EXPANSIONS[seed]


@pytest.mark.parametrize("seed", range(200, 203))
def test_a_robot_turns_back_only_on_news_and_never_oscillates(seed: int) -> None:
    """A wall with one gap: dead ends are found late and the robot may turn back.

    Turning back (a -> b -> a) is right only when the scan at b revealed something: on an
    unchanged map, g(a) = c(a, b) + g(b) and g(b) = c(b, a) + g(a) cannot both hold with
    positive costs, so a reversal without news is the classic wrong move/scan/replan
    order or k_m bug. Hopping between two cells (a -> b -> a -> b) is never right here.
    """
    visited, news, expansions = _drive(_field(seed, wall=True), (1, 1), (24, 24), radius=3)
    reversals = [i for i in range(len(visited) - 2) if visited[i] == visited[i + 2]]
    assert all(news[i + 1] for i in reversals), "turned back without new information"
    assert not any(visited[i] == visited[i + 2] and visited[i + 1] == visited[i + 3]
                   for i in range(len(visited) - 3)), "oscillating between two cells"
    assert len(visited) <= 6 * 26
    assert expansions <= DRIVE_EXPANSIONS[seed]


# ---------------------------------------------------------------------- API details

def test_same_inputs_give_the_same_path() -> None:
    rng = np.random.default_rng(3)
    cost = random_map(rng, 30, 30, blocked=0.1)
    cost[0, 0] = cost[29, 29] = 1.0
    paths = []
    for use_rebuild in (False, True, False):
        planner = DStarLite(cost, (0, 0), (29, 29))
        planner.rebuild() if use_rebuild else planner.compute()
        paths.append(planner.path())
    assert paths[0] == paths[1] == paths[2]
    # ties on an open grid: the documented neighbour order decides
    open_grid = DStarLite(np.ones((3, 3)), (0, 0), (2, 1))
    open_grid.compute()
    assert open_grid.path() == [(0, 0), (1, 0), (2, 1)]


def test_path_needs_a_settled_start() -> None:
    planner = DStarLite(np.ones((6, 6)), (0, 0), (5, 5))
    with pytest.raises(PlanNotReadyError):
        planner.path()
    planner.compute()
    planner.move_start((1, 1))
    with pytest.raises(PlanNotReadyError):
        planner.path()
    assert planner.compute() is PlanStatus.DONE
    assert planner.statistics().last_expansions == 0  # a move along the path costs nothing
    assert planner.path(max_cells=2) == [(1, 1), (2, 2)]
    planner.update_costs([3], [3], [2.0])
    assert not planner.settled
    with pytest.raises(PlanNotReadyError):
        planner.path()
    planner.compute()
    with pytest.raises(ValueError):
        planner.path(max_cells=0)


def test_cost_to_goal_settles_any_cell_on_demand() -> None:
    rng = np.random.default_rng(21)
    cost = random_map(rng, 20, 20)
    cost[0, 0] = cost[19, 19] = 1.0
    planner = DStarLite(cost, (19, 19), (15, 15))  # start near the goal: little is expanded
    planner.compute()
    truth = oracle(cost, (15, 15))
    for cell in [(0, 0), (3, 17), (19, 0), (10, 10)]:
        assert planner.cost_to_goal(cell) == pytest.approx(truth[cell], rel=1e-12)
    assert planner.settled
    check_planner(planner, cost)


def test_set_goal_plans_afresh() -> None:
    rng = np.random.default_rng(8)
    cost = random_map(rng, 15, 15)
    cost[0, 0] = cost[14, 14] = cost[14, 0] = 1.0
    planner = DStarLite(cost, (0, 0), (14, 14))
    planner.compute()
    planner.set_goal((14, 0))
    assert planner.goal == (14, 0) and not planner.settled
    planner.compute()
    check_planner(planner, cost)


def test_update_costs_processes_only_real_changes_and_the_last_duplicate_wins() -> None:
    planner = DStarLite(np.ones((5, 5)), (0, 0), (4, 4))
    planner.compute()
    assert planner.update_costs([1, 2], [1, 2], [1.0, 1.0]) == 0
    assert planner.settled
    assert planner.update_costs(np.array([1, 1, 2]), np.array([1, 1, 2]),
                                np.array([5.0, 3.0, 1.0])) == 1
    assert planner.cost[1, 1] == 3.0
    assert planner.update_costs(2, np.array([0, 1, 2]), 7.0) == 3  # scalars broadcast
    assert planner.update_grid(np.ones((5, 5))) == 4
    assert not planner.cost.flags.writeable


@pytest.mark.parametrize(("xs", "ys", "costs"), [
    ([5], [0], [1.0]),  # outside
    ([-1], [0], [1.0]),
    ([0], [0], [0.5]),  # below 1
    ([0], [0], [math.nan]),
    ([0], [0], [-INF]),
    ([0, 1], [0], [1.0, 1.0, 1.0]),  # lengths differ
    ([0.5], [0], [1.0]),  # not integers
])
def test_update_costs_refuses_bad_input_and_changes_nothing(xs, ys, costs) -> None:
    planner = DStarLite(np.ones((5, 5)), (0, 0), (4, 4))
    planner.compute()
    with pytest.raises(GridError):
        planner.update_costs(xs, ys, costs)
    assert planner.settled
    np.testing.assert_array_equal(planner.cost, np.ones((5, 5)))


@pytest.mark.parametrize(("cost", "start", "goal"), [
    (np.ones(5), (0, 0), (0, 0)),
    (np.ones((0, 3)), (0, 0), (0, 0)),
    (np.full((3, 3), 0.0), (0, 0), (1, 1)),
    (np.ones((3, 3)), (3, 0), (1, 1)),
    (np.ones((3, 3)), (0, 0), (1, -1)),
    (np.ones((3, 3)), (0, 0), "ab"),
])
def test_bad_grids_and_cells_are_refused(cost, start, goal) -> None:
    with pytest.raises(GridError) as excinfo:
        DStarLite(cost, start, goal)
    assert isinstance(excinfo.value, ValueError) and isinstance(excinfo.value, PlannerError)


def test_the_constructor_copies_the_cost_array() -> None:
    cost = np.ones((4, 4))
    planner = DStarLite(cost, (0, 0), (3, 3))
    cost[1, 1] = INF
    assert planner.cost[1, 1] == 1.0


# ---------------------------------------------------------------------- properties

COSTS = st.sampled_from([1.0, 1.0, 1.5, 2.0, 7.0, INF])


@st.composite
def scenarios(draw: st.DrawFn) -> tuple[np.ndarray, Cell, Cell, list[tuple]]:
    nx = draw(st.integers(2, 9))
    ny = draw(st.integers(2, 9))
    cost = np.array(draw(st.lists(COSTS, min_size=nx * ny, max_size=nx * ny))).reshape(nx, ny)
    cell = st.tuples(st.integers(0, nx - 1), st.integers(0, ny - 1))
    start, goal = draw(cell), draw(cell)
    change = st.tuples(st.just("costs"), st.lists(st.tuples(cell, COSTS), min_size=1,
                                                  max_size=6))
    move = st.tuples(st.just("move"), st.integers(1, 3))
    jump = st.tuples(st.just("jump"), cell)
    ops = draw(st.lists(st.one_of(change, move, jump, st.just(("rebuild",)),
                                  st.tuples(st.just("cap"), st.integers(0, 4))), max_size=8))
    return cost, start, goal, ops


@settings(max_examples=60, deadline=None)
@given(scenarios())
def test_any_sequence_of_changes_and_moves_stays_exact(scenario) -> None:
    cost, start, goal, ops = scenario
    cost = cost.copy()
    planner = DStarLite(cost, start, goal)
    planner.compute()
    check_planner(planner, cost)
    for op in ops:
        if op[0] == "costs":
            xs = np.array([c[0][0] for c in op[1]])
            ys = np.array([c[0][1] for c in op[1]])
            apply(planner, cost, xs, ys, np.array([c[1] for c in op[1]]))
        elif op[0] == "move":
            for cell in planner.path()[1:1 + op[1]]:
                planner.move_start(cell)
        elif op[0] == "jump":  # the vehicle is somewhere else (relocalised)
            planner.move_start(op[1])
        elif op[0] == "rebuild":
            planner.rebuild()
        else:  # a capped compute first, then finish
            planner.compute(op[1])
        while planner.compute(3) is PlanStatus.CAPPED:
            pass
        check_planner(planner, cost)
