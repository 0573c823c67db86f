"""FindPath's planning core: D* Lite on an 8-connected cost grid, with an exact fallback.

Pure Python + numpy (+ scipy for the from-scratch fallback): no asyncio and no framework
imports. The FindPath component owns a :class:`DStarLite`, loads it from the Global
Map's cost grid, moves its start as the vehicle drives, feeds it the cells each map
update changed, and asks it for the path. The algorithm is the optimized D* Lite of
Koenig & Likhachev (AAAI 2002, Figure 4): the search runs backward from the goal, so
``g(s)`` estimates the cost from ``s`` to the goal and changes near the vehicle touch
little of the search tree.

Grid and edge model
-------------------
``cost[x, y]`` (float64, shape ``(nx, ny)``) is the cost of *entering* planning cell
``(x, y)``; every cost is ``>= 1`` or ``inf`` (impassable). Unknown cells are the
caller's business (the freespace assumption: pass ``1.0`` for them). Each cell has up to
eight neighbours; cells outside the grid do not exist. The directed edge from ``u`` to
a neighbour ``v`` costs::

    c(u, v) = cost[v] * 1          v is a 4-neighbour of u
    c(u, v) = cost[v] * sqrt(2)    v is a diagonal neighbour of u, unless corner-cut
    c(u, v) = inf                  cost[v] is inf, or the diagonal is corner-cut

A diagonal move from ``(x, y)`` to ``(x + dx, y + dy)`` is *corner-cut*, and forbidden,
when both cells it passes between, ``(x + dx, y)`` and ``(x, y + dy)``, are impassable:
the vehicle may brush past one obstacle corner but not squeeze between two. The cost
of the cell being left plays no part, so an impassable cell still has finite outgoing
edges (a vehicle the map puts inside an obstacle can drive out of it). Sums are formed
as ``cost[v] * step + g(v)``, the step multiplied first, which is also what a Dijkstra
over :func:`reverse_graph` does, so the incremental state, :meth:`DStarLite.rebuild` and
such an oracle agree bit for bit. A path's cost is the sum of its edges; the start
cell's own cost is not paid.

Heuristic: the octile distance between cells, ``max(|dx|,|dy|) + (sqrt(2) - 1) *
min(|dx|,|dy|)``, scaled down by ``1 - 1e-10`` so rounding can never make it exceed a
true cost. It is admissible and consistent because every cost is at least 1.

What the planner guarantees
---------------------------
After :meth:`DStarLite.compute` returns ``DONE``, ``g(start)`` is the exact cost to the
goal and :meth:`DStarLite.path` is a shortest path. Like every incremental search, the
planner stops as soon as the start is settled, so a cell far from the start may still
hold an out-of-date ``g`` even where ``g == rhs``; :meth:`DStarLite.cost_to_goal`
settles a cell on demand. :meth:`DStarLite.rebuild` replaces the whole state with the
exact solution of the entire grid (scipy's Dijkstra on the reversed graph, vectorised);
:meth:`DStarLite.replan` uses it when incremental repair would cost more (the rule and
its measurements are in ``docs/decisions/0016-dstar-fallback.md``).

Typical use (one planning cycle of the component)::

    planner = DStarLite(cost, start=(5, 5), goal=(150, 140))
    planner.replan()                         # the first plan
    ...
    planner.move_start(vehicle_cell)         # move ...
    planner.update_costs(xs, ys, new_costs)  # ... scan ...
    status = planner.replan()                # ... replan (order matters for k_m)
    if status is PlanStatus.DONE:
        cells = planner.path()

Exceptions::

    PlannerError                  base of everything this module raises
    ├── GridError (ValueError)    a cost array, cost value or cell argument is invalid
    └── PlanNotReadyError (RuntimeError)
                                  path() asked for while the start is not settled

plus the builtin ``ValueError`` for a negative expansion cap or budget.
"""

from __future__ import annotations

import enum
import functools
import heapq
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

__all__ = [
    "DStarLite",
    "GridError",
    "PlanNotReadyError",
    "PlanStatus",
    "PlannerError",
    "PlannerState",
    "PlannerStatistics",
    "SQRT2",
    "octile",
    "reverse_graph",
]

SQRT2 = math.sqrt(2.0)
_INF = math.inf
_H_SCALE = 1.0 - 1e-10  # keeps the float heuristic below every float path cost
_NOT_QUEUED = -1.0  # key sentinel: real keys are >= 0

# The fallback rule (docs/decisions/0016-dstar-fallback.md): replan() lets an incremental
# repair run for max(FALLBACK_MIN_EXPANSIONS, FALLBACK_EXPANSIONS_PER_CELL * cells)
# expansions, then rebuilds from scratch. Measured on a 2-core machine: a rebuild costs
# ~0.3 us per cell plus ~0.25 ms, an expansion 3-4 us (cost decreases) to 6-12 us (cost
# increases), so the break-even is 0.03-0.09 expansions per cell.
FALLBACK_EXPANSIONS_PER_CELL = 0.05
FALLBACK_MIN_EXPANSIONS = 64

Cell = tuple[int, int]
FloatArray = npt.NDArray[np.float64]


class PlannerError(Exception):
    """Base of every error raised by the planner."""


class GridError(PlannerError, ValueError):
    """A cost array, a cost value or a cell argument is invalid (shape, range, bounds)."""


class PlanNotReadyError(PlannerError, RuntimeError):
    """The start is not settled: changes or a move are pending, or compute was capped."""


class PlanStatus(enum.Enum):
    """Outcome of :meth:`DStarLite.compute`, :meth:`~DStarLite.rebuild`, ``replan``."""

    DONE = "done"  # the start is settled and a path exists
    NO_PATH = "no path"  # the start is settled and the goal is unreachable
    CAPPED = "capped"  # the expansion cap was reached; call compute() again or rebuild()


@dataclass(frozen=True)
class PlannerStatistics:
    """Counters since construction (or the last :meth:`DStarLite.set_goal`).

    ``last_expansions`` counts the vertices the last compute expanded (made consistent or
    reset to underconsistent), ``last_reinsertions`` the queue entries it only re-keyed;
    a rebuild leaves both alone, so after a fallback they describe the capped attempt.
    """

    last_expansions: int
    last_reinsertions: int
    total_expansions: int
    computes: int  # compute() calls, including those made by replan()
    replans: int  # computes that started with changed costs or a moved start
    capped: int  # computes stopped by their cap
    rebuilds: int  # from-scratch rebuilds
    queue_length: int  # locally inconsistent vertices waiting in the queue
    heap_entries: int  # queue entries including stale ones not yet discarded
    k_m: float


@dataclass(frozen=True)
class PlannerState:
    """A copy of the planner's state, for inspection, plots and tests (O(cells) to make).

    ``g`` and ``rhs`` have the grid's shape; ``key1``/``key2`` hold the stored queue key of
    each queued cell and NaN elsewhere (stored keys may be lower than current ones, which
    is allowed); ``top_key`` is the smallest stored key, ``(inf, inf)`` for an empty queue.
    """

    g: FloatArray
    rhs: FloatArray
    queued: npt.NDArray[np.bool_]
    key1: FloatArray
    key2: FloatArray
    top_key: tuple[float, float]
    k_m: float
    start: Cell
    goal: Cell


def octile(a: Cell, b: Cell) -> float:
    """The planner's heuristic between two cells (octile distance, scaled by 1 - 1e-10)."""
    dx = abs(a[0] - b[0])
    dy = abs(a[1] - b[1])
    return (dx + dy + (SQRT2 - 2.0) * (dx if dx < dy else dy)) * _H_SCALE


class DStarLite:
    """Incremental shortest paths from a moving start to a fixed goal on a cost grid.

    The constructor only initialises (``g = rhs = inf``, ``rhs(goal) = 0``, the goal
    queued); plan with :meth:`replan` (incremental within a budget, else from scratch),
    :meth:`compute` (incremental only, optionally capped) or :meth:`rebuild` (from scratch
    only). The cost array is copied; later changes go through :meth:`update_costs` or
    :meth:`update_grid`. ``fallback_expansions`` overrides :meth:`replan`'s default budget
    (``max(64, 0.05 * cells)``, see the module constants).

    Raises:
        GridError: ``cost`` is not a non-empty 2-D array of finite values >= 1 or +inf,
            or ``start``/``goal`` is not a cell of the grid.
        ValueError: ``fallback_expansions`` is negative.
    """

    def __init__(self, cost: npt.ArrayLike, start: Sequence[int], goal: Sequence[int], *,
                 fallback_expansions: int | None = None) -> None:
        try:
            grid = np.array(cost, dtype=np.float64)  # a copy, never the caller's array
        except (TypeError, ValueError) as exc:
            raise GridError(f"cost must be a 2-D array of numbers: {exc}") from exc
        if grid.ndim != 2 or grid.size == 0:
            raise GridError(f"cost must be a non-empty 2-D array, got shape {grid.shape}")
        _check_costs(grid)
        self._nx, self._ny = int(grid.shape[0]), int(grid.shape[1])
        w = self._ny + 2  # row length of the padded grid
        self._w = w
        self._padded = np.full((self._nx + 2, w), np.inf)
        self._padded[1:-1, 1:-1] = grid
        self._cost: list[float] = self._padded.ravel().tolist()
        n = self._padded.size
        xs, ys = np.divmod(np.arange(n), w)
        self._xs: list[int] = xs.tolist()
        self._ys: list[int] = ys.tolist()
        # Neighbour table, ascending flat offsets (the documented tie-break order):
        # (offset, diagonal, corner a, corner b). A move from s to s + (ox, oy) passes the
        # corners s + (ox, 0) and s + (0, oy). The same numbers serve the backward view:
        # for the predecessor p = u + (ox, oy) of u, the move p -> u passes u + (ox, 0)
        # and u + (0, oy), again the table's corner offsets, now taken from u.
        self._nbrs: tuple[tuple[int, bool, int, int], ...] = tuple(
            (ox * w + oy, ox != 0 and oy != 0, ox * w, oy)
            for ox in (-1, 0, 1) for oy in (-1, 0, 1) if (ox, oy) != (0, 0))
        border = np.ones(self._padded.shape, dtype=bool)
        border[1:-1, 1:-1] = False
        self._border = border.ravel()
        self._start = self._flat(start, "start")
        self._goal = self._flat(goal, "goal")
        if fallback_expansions is None:
            fallback_expansions = max(FALLBACK_MIN_EXPANSIONS,
                                      int(FALLBACK_EXPANSIONS_PER_CELL * self._nx * self._ny))
        elif fallback_expansions < 0:
            raise ValueError(f"fallback_expansions must be >= 0, got {fallback_expansions}")
        self._fallback_expansions = fallback_expansions
        # search state, set by _reset() and rebuild(); qk1/qk2 hold each queued vertex's
        # stored key (_NOT_QUEUED otherwise), heap entries (k1, k2, vertex) may be stale
        self._g: list[float] = []
        self._rhs: list[float] = []
        self._qk1: list[float] = []
        self._qk2: list[float] = []
        self._heap: list[tuple[float, float, int]] = []
        self._frozen = bytearray()
        self._live = 0
        self._km = 0.0
        self._last = self._start
        self._changed_since_compute = False
        self._dirty = True
        self._last_expansions = 0
        self._last_reinsertions = 0
        self._total_expansions = 0
        self._computes = 0
        self._replans = 0
        self._capped = 0
        self._rebuilds = 0
        self._reset()

    # ------------------------------------------------------------------ properties

    @property
    def shape(self) -> tuple[int, int]:
        """The grid's shape ``(nx, ny)``."""
        return (self._nx, self._ny)

    @property
    def start(self) -> Cell:
        """The current start cell (the vehicle's cell)."""
        return self._cell(self._start)

    @property
    def goal(self) -> Cell:
        """The goal cell."""
        return self._cell(self._goal)

    @property
    def cost(self) -> FloatArray:
        """A read-only view of the planner's cost grid (shape ``(nx, ny)``)."""
        view = self._padded[1:-1, 1:-1]
        view.flags.writeable = False
        return view

    @property
    def fallback_expansions(self) -> int:
        """The expansion budget :meth:`replan` gives an incremental repair (see module)."""
        return self._fallback_expansions

    @property
    def settled(self) -> bool:
        """True when the start is settled: ``path()`` and ``g(start)`` are exact."""
        return not self._dirty

    def statistics(self) -> PlannerStatistics:
        """Counters of the work done (see :class:`PlannerStatistics`)."""
        return PlannerStatistics(
            last_expansions=self._last_expansions,
            last_reinsertions=self._last_reinsertions,
            total_expansions=self._total_expansions,
            computes=self._computes,
            replans=self._replans,
            capped=self._capped,
            rebuilds=self._rebuilds,
            queue_length=self._live,
            heap_entries=len(self._heap),
            k_m=self._km,
        )

    # ------------------------------------------------------------------ changes

    def move_start(self, start: Sequence[int]) -> None:
        """Move the start to ``start`` (any cell, usually the next one on the path).

        The key modifier ``k_m`` is brought up to date lazily, at the next cost update or
        compute (``k_m += h(s_last, s_start)``), so a drive of many cells between changes
        adds one ``h`` term, not many. Call :meth:`compute` (or :meth:`replan`) before
        the next :meth:`path`; after a move along the path it expands nothing.

        Raises:
            GridError: ``start`` is not a cell of the grid.
        """
        new = self._flat(start, "start")
        if new != self._start:
            self._start = new
            self._changed_since_compute = True
            self._dirty = True

    def update_costs(self, xs: npt.ArrayLike, ys: npt.ArrayLike,
                     costs: npt.ArrayLike) -> int:
        """Set ``cost[xs[i], ys[i]] = costs[i]``; return how many cells really changed.

        Vectorised: three 1-D arrays (or scalars, broadcast) of equal length. A cell given
        more than once takes its last value. Unchanged cells cost nothing; each changed
        cell updates the right-hand sides of the up to eight cells whose outgoing edges it
        touches (edges into it, and diagonals passing its corner) with the optimized rule:
        a cheaper edge can only lower ``rhs`` (``rhs = min(rhs, c + g)``), a dearer edge
        forces a full recomputation only when it was the vertex's best.

        Raises:
            GridError: the arrays differ in length, a cell is outside the grid, or a cost
                is NaN, below 1 or -inf. Nothing is changed then.
        """
        try:
            x = np.atleast_1d(np.asarray(xs))
            y = np.atleast_1d(np.asarray(ys))
            c = np.atleast_1d(np.asarray(costs, dtype=np.float64))
            x, y, c = np.broadcast_arrays(x, y, c)
        except (TypeError, ValueError) as exc:
            raise GridError(f"xs, ys and costs must be numeric arrays of one length: "
                            f"{exc}") from exc
        if x.ndim != 1:
            raise GridError("xs, ys and costs must be one-dimensional")
        if x.size == 0:
            return 0
        if not (np.issubdtype(x.dtype, np.integer) and np.issubdtype(y.dtype, np.integer)):
            raise GridError(f"cell indices must be integers, got {x.dtype} and {y.dtype}")
        outside = (x < 0) | (x >= self._nx) | (y < 0) | (y >= self._ny)
        if outside.any():
            i = int(np.flatnonzero(outside)[0])
            raise GridError(f"cell ({int(x[i])}, {int(y[i])}) is outside the "
                            f"{self._nx} x {self._ny} grid")
        _check_costs(c)
        flat = (x.astype(np.int64) + 1) * self._w + (y.astype(np.int64) + 1)
        # the last occurrence of each cell wins: unique over the reversed arrays
        flat_r = flat[::-1]
        cells, first = np.unique(flat_r, return_index=True)
        new = c[::-1][first]
        padded = self._padded.reshape(-1)
        changed = padded[cells] != new
        if not changed.any():
            return 0
        cells = cells[changed]
        self._apply_cost_changes(cells.tolist(), new[changed].tolist())
        return int(cells.size)

    def update_grid(self, cost: npt.ArrayLike) -> int:
        """Replace the whole cost grid; only the cells that differ are processed.

        Returns the number of changed cells.

        Raises:
            GridError: ``cost`` has another shape or holds an invalid cost.
        """
        try:
            grid = np.asarray(cost, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise GridError(f"cost must be a 2-D array of numbers: {exc}") from exc
        if grid.shape != (self._nx, self._ny):
            raise GridError(f"cost grid has shape {grid.shape}, the planner "
                            f"{(self._nx, self._ny)}")
        _check_costs(grid)
        xs, ys = np.nonzero(grid != self._padded[1:-1, 1:-1])
        if xs.size == 0:
            return 0
        return self.update_costs(xs, ys, grid[xs, ys])

    def set_goal(self, goal: Sequence[int]) -> None:
        """Make ``goal`` the goal and forget every search result (plan again afterwards).

        Statistics restart too.

        Raises:
            GridError: ``goal`` is not a cell of the grid.
        """
        self._goal = self._flat(goal, "goal")
        self._total_expansions = self._computes = self._replans = 0
        self._capped = self._rebuilds = 0
        self._reset()

    # ------------------------------------------------------------------ planning

    def compute(self, max_expansions: int | None = None) -> PlanStatus:
        """Repair the search until the start is settled, or for ``max_expansions`` at most.

        ``CAPPED`` leaves a valid intermediate state: call ``compute`` again (the result is
        the same as one uncapped call) or :meth:`rebuild`. The loop runs while the top key
        is below the start's key or the start is locally inconsistent (either way round,
        so ``g(start)`` itself is exact afterwards).

        Raises:
            ValueError: ``max_expansions`` is negative.
        """
        if max_expansions is not None and max_expansions < 0:
            raise ValueError(f"max_expansions must be >= 0, got {max_expansions}")
        self._computes += 1
        if self._changed_since_compute:
            self._replans += 1
            self._changed_since_compute = False
        self._sync_km()
        done = self._settle(self._start, max_expansions)
        if not done:
            self._capped += 1
            self._dirty = True
            return PlanStatus.CAPPED
        self._dirty = False
        return PlanStatus.DONE if self._g[self._start] < _INF else PlanStatus.NO_PATH

    def replan(self, max_expansions: int | None = None) -> PlanStatus:
        """:meth:`compute` with the from-scratch fallback: never ``CAPPED``.

        The incremental repair gets ``max_expansions`` expansions (default
        :attr:`fallback_expansions`, about the measured break-even with a rebuild); if
        that is not enough, the state is rebuilt from scratch. A replan thus costs at most
        the budget plus a rebuild (measured: up to ~3 rebuilds, since an expansion costs
        3-12 us depending on the change), and usually far less. Deterministic: the
        decision counts expansions, not time.

        Raises:
            ValueError: ``max_expansions`` is negative.
        """
        budget = self._fallback_expansions if max_expansions is None else max_expansions
        status = self.compute(budget)
        if status is PlanStatus.CAPPED:
            status = self.rebuild()
        return status

    def rebuild(self) -> PlanStatus:
        """Replace the state with the exact solution of the whole grid (from scratch).

        Runs scipy's Dijkstra from the goal on the reversed graph (built vectorised from
        the cost grid with the module's edge model), then sets ``g = rhs =`` exact cost to
        goal for every cell, empties the queue and resets ``k_m``. Every cell is settled
        afterwards, so later incremental repairs start from a perfect state.
        """
        dist = dijkstra(reverse_graph(self._padded[1:-1, 1:-1]), directed=True,
                        indices=self._interior_index(self._goal))
        padded = np.full(self._padded.shape, np.inf)
        padded[1:-1, 1:-1] = np.asarray(dist, dtype=np.float64).reshape(self._nx, self._ny)
        self._g = padded.ravel().tolist()
        self._rhs = list(self._g)
        self._rhs[self._goal] = 0.0
        self._g[self._goal] = 0.0
        self._qk1 = [_NOT_QUEUED] * len(self._g)
        self._qk2 = [_NOT_QUEUED] * len(self._g)
        self._heap = []
        self._live = 0
        self._km = 0.0
        self._last = self._start
        self._changed_since_compute = False
        self._dirty = False
        self._rebuilds += 1
        return PlanStatus.DONE if self._g[self._start] < _INF else PlanStatus.NO_PATH

    # ------------------------------------------------------------------ results

    def path(self, max_cells: int | None = None) -> list[Cell]:
        """The shortest path from the start to the goal, both included; ``[]`` if none.

        Greedy descent: from each cell take the neighbour minimising ``c(s, s') + g(s')``;
        ties go to the first neighbour in the fixed order (-1,-1), (-1,0), (-1,1), (0,-1),
        (0,1), (1,-1), (1,0), (1,1), so equal inputs give equal paths. ``max_cells`` stops
        after that many cells (the component needs only the lookahead).

        Raises:
            PlanNotReadyError: the start is not settled (changes or a move since the last
                compute, or the last compute was capped).
            ValueError: ``max_cells`` is below 1.
            PlannerError: the descent got stuck, which means the state is corrupt (a bug,
                never expected).
        """
        if self._dirty:
            raise PlanNotReadyError("the start is not settled: call compute() (or replan()) "
                                    "after changing costs or moving off the path")
        if max_cells is not None and max_cells < 1:
            raise ValueError(f"max_cells must be >= 1, got {max_cells}")
        g = self._g
        s = self._start
        if g[s] == _INF:
            return []
        limit = self._nx * self._ny if max_cells is None else max_cells
        out = [self._cell(s)]
        goal = self._goal
        while s != goal and len(out) < limit:
            nxt = self._best_successor(s)
            if nxt < 0 or g[nxt] >= g[s]:  # cannot happen on a settled state (costs >= 1)
                raise PlannerError(f"descent stuck at {self._cell(s)}: planner state corrupt")
            s = nxt
            out.append(self._cell(s))
        return out

    def cost_to_goal(self, cell: Sequence[int] | None = None) -> float:
        """The exact cost from ``cell`` (default: the start) to the goal, ``inf`` if none.

        A cell other than the start may not be settled yet; the search is then continued
        (uncapped) until it is, which keeps every other result valid.

        Raises:
            GridError: ``cell`` is not a cell of the grid.
        """
        s = self._start if cell is None else self._flat(cell, "cell")
        if s != self._start or self._dirty:
            self._sync_km()
            self._settle(s, None)
            if s == self._start:
                self._dirty = False
        return self._g[s]

    def state(self) -> PlannerState:
        """A copy of ``g``, ``rhs`` and the queue (see :class:`PlannerState`)."""
        shape = self._padded.shape
        g = np.array(self._g).reshape(shape)[1:-1, 1:-1].copy()
        rhs = np.array(self._rhs).reshape(shape)[1:-1, 1:-1].copy()
        k1 = np.array(self._qk1).reshape(shape)[1:-1, 1:-1].copy()
        k2 = np.array(self._qk2).reshape(shape)[1:-1, 1:-1].copy()
        queued = k1 >= 0.0
        k1[~queued] = np.nan
        k2[~queued] = np.nan
        return PlannerState(g=g, rhs=rhs, queued=queued, key1=k1, key2=k2,
                            top_key=self._top_key(), k_m=self._km,
                            start=self.start, goal=self.goal)

    # ------------------------------------------------------------------ internals

    def _flat(self, cell: Sequence[int], what: str) -> int:
        try:
            x, y = (int(v) for v in cell)
        except (TypeError, ValueError) as exc:
            raise GridError(f"{what} must be a cell (x, y), got {cell!r}") from exc
        if not (0 <= x < self._nx and 0 <= y < self._ny):
            raise GridError(f"{what} {(x, y)} is outside the {self._nx} x {self._ny} grid")
        return (x + 1) * self._w + (y + 1)

    def _cell(self, flat: int) -> Cell:
        return (self._xs[flat] - 1, self._ys[flat] - 1)

    def _interior_index(self, flat: int) -> int:
        return (self._xs[flat] - 1) * self._ny + (self._ys[flat] - 1)

    def _reset(self) -> None:
        n = len(self._cost)
        self._g = [_INF] * n
        self._rhs = [_INF] * n
        self._qk1 = [_NOT_QUEUED] * n
        self._qk2 = [_NOT_QUEUED] * n
        self._heap = []
        self._live = 0
        # border cells and the goal: their rhs is never recomputed
        self._frozen = bytearray(self._border.astype(np.uint8).tobytes())
        self._frozen[self._goal] = 1
        self._km = 0.0
        self._last = self._start
        self._changed_since_compute = False
        self._dirty = True
        self._last_expansions = 0
        self._last_reinsertions = 0
        self._rhs[self._goal] = 0.0
        self._push(self._goal)

    def _h(self, a: int, b: int) -> float:
        dx = abs(self._xs[a] - self._xs[b])
        dy = abs(self._ys[a] - self._ys[b])
        return (dx + dy + (SQRT2 - 2.0) * (dx if dx < dy else dy)) * _H_SCALE

    def _sync_km(self) -> None:
        """k_m += h(s_last, s_start) once the start has moved (paper, before updates)."""
        if self._start != self._last:
            self._km += self._h(self._last, self._start)
            self._last = self._start

    def _push(self, s: int) -> None:
        """UpdateVertex(s) for an inconsistent s: (re)queue it with its current key."""
        gs = self._g[s]
        rs = self._rhs[s]
        m = gs if gs < rs else rs
        k1 = m + self._h(self._start, s) + self._km
        if self._qk1[s] < 0.0:
            self._live += 1
        elif self._qk1[s] == k1 and self._qk2[s] == m:
            return
        self._qk1[s] = k1
        self._qk2[s] = m
        heapq.heappush(self._heap, (k1, m, s))

    def _update_vertex(self, s: int) -> None:
        if self._g[s] != self._rhs[s]:
            self._push(s)
        elif self._qk1[s] >= 0.0:
            self._qk1[s] = _NOT_QUEUED
            self._live -= 1

    def _top_key(self) -> tuple[float, float]:
        heap = self._heap
        qk1 = self._qk1
        qk2 = self._qk2
        while heap:
            k1, k2, u = heap[0]
            if qk1[u] == k1 and qk2[u] == k2:
                return (k1, k2)
            heapq.heappop(heap)
        return (_INF, _INF)

    def _edge(self, s: int, t: int, diag: bool, ca: int, cb: int) -> float:
        """c(s, t) for neighbour t of s (corner offsets relative to s)."""
        cost = self._cost
        ct = cost[t]
        if diag:
            if cost[s + ca] == _INF and cost[s + cb] == _INF:
                return _INF
            return ct * SQRT2
        return ct

    def _best_rhs(self, s: int) -> float:
        """min over successors t of c(s, t) + g(t)."""
        cost = self._cost
        g = self._g
        best = _INF
        for off, diag, ca, cb in self._nbrs:
            t = s + off
            gt = g[t]
            if gt == _INF:
                continue
            ct = cost[t]
            if ct == _INF:
                continue
            if diag:
                if cost[s + ca] == _INF and cost[s + cb] == _INF:
                    continue
                v = ct * SQRT2 + gt
            else:
                v = ct + gt
            if v < best:
                best = v
        return best

    def _best_successor(self, s: int) -> int:
        """argmin over successors t of c(s, t) + g(t), first in neighbour order; -1 if none."""
        g = self._g
        best = _INF
        arg = -1
        for off, diag, ca, cb in self._nbrs:
            t = s + off
            if g[t] == _INF:
                continue
            v = self._edge(s, t, diag, ca, cb) + g[t]
            if v < best:
                best = v
                arg = t
        return arg

    def _apply_cost_changes(self, cells: list[int], new: list[float]) -> None:
        """Set the costs of distinct padded ``cells`` and repair the affected rhs values.

        The edges whose cost can change are those entering a changed cell, and, when a cell
        turns impassable or passable, the diagonals that have it as a corner. Each source
        vertex with a changed edge then gets the optimized rule (module docstring of
        :meth:`update_costs`). Plain Python: a scan changes tens of cells, where numpy's
        per-call overhead would dominate.
        """
        self._sync_km()
        cost = self._cost
        frozen = self._frozen
        nbrs = self._nbrs
        inf = _INF
        # the changed edges (source, direction) -> old cost; the edge model of _edge, inlined
        old: dict[tuple[int, int], float] = {}
        for v, value in zip(cells, new, strict=True):
            cv = cost[v]
            for k, (off, diag, ca, cb) in enumerate(nbrs):
                s = v - off  # the edge s -> v
                if frozen[s] or (s, k) in old:
                    continue
                if diag:
                    old[(s, k)] = (inf if cost[s + ca] == inf and cost[s + cb] == inf
                                   else cv * SQRT2)
                else:
                    old[(s, k)] = cv
            if (cv == inf) != (value == inf):
                for k, (off, diag, ca, cb) in enumerate(nbrs):
                    if not diag:
                        continue
                    for s in (v - ca, v - cb):  # v is a corner of the move s -> s + off
                        if frozen[s] or (s, k) in old:
                            continue
                        old[(s, k)] = (inf if cost[s + ca] == inf and cost[s + cb] == inf
                                       else cost[s + off] * SQRT2)
        for v, value in zip(cells, new, strict=True):
            cost[v] = value
        self._padded.reshape(-1)[cells] = new
        g = self._g
        rhs = self._rhs
        # per source: the lowest new candidate, or a full recomputation if a dearer edge
        # was the source's best
        best: dict[int, float] = {}
        full: set[int] = set()
        for (s, k), c_old in old.items():
            off, diag, ca, cb = nbrs[k]
            if diag:
                c_new = (inf if cost[s + ca] == inf and cost[s + cb] == inf
                         else cost[s + off] * SQRT2)
            else:
                c_new = cost[s + off]
            if c_new == c_old or s in full:
                continue
            g_t = g[s + off]
            if c_new < c_old:
                candidate = c_new + g_t
                if candidate < best.get(s, rhs[s]):
                    best[s] = candidate
            elif rhs[s] != inf and rhs[s] == c_old + g_t:
                full.add(s)
        for s in sorted(full | best.keys()):
            rhs[s] = self._best_rhs(s) if s in full else best[s]
            self._update_vertex(s)
        self._changed_since_compute = True
        self._dirty = True

    def _settle(self, target: int, max_expansions: int | None) -> bool:
        """ComputeShortestPath (optimized, Figure 4) until ``target`` is settled.

        Returns False if stopped by ``max_expansions``. The inner loop binds everything to
        locals and inlines UpdateVertex; keep it in step with :meth:`_push`,
        :meth:`_update_vertex` and :meth:`_best_rhs`.
        """
        heap = self._heap
        g = self._g
        rhs = self._rhs
        qk1 = self._qk1
        qk2 = self._qk2
        cost = self._cost
        frozen = self._frozen
        xs = self._xs
        ys = self._ys
        nbrs = self._nbrs
        heappop = heapq.heappop
        heappush = heapq.heappush
        heapreplace = heapq.heapreplace
        inf = _INF
        km = self._km
        sx = xs[self._start]
        sy = ys[self._start]
        kd = SQRT2 - 2.0
        hs = _H_SCALE
        limit = -1 if max_expansions is None else max_expansions
        expansions = 0
        reinsertions = 0
        live = self._live
        tx = xs[target]
        ty = ys[target]
        dx = abs(tx - sx)
        dy = abs(ty - sy)
        h_target = (dx + dy + kd * (dx if dx < dy else dy)) * hs
        done = True
        while True:
            # the top entry, skipping stale ones (lazy deletion)
            while heap:
                k1, k2, u = heap[0]
                if qk1[u] == k1 and qk2[u] == k2:
                    break
                heappop(heap)
            else:
                k1 = k2 = inf
                u = -1
            gt = g[target]
            rt = rhs[target]
            mt = gt if gt < rt else rt
            t1 = mt + h_target + km
            if not (k1 < t1 or (k1 == t1 and k2 < mt) or gt != rt):
                break
            if u < 0:  # cannot happen: an inconsistent target is always queued
                break
            if expansions == limit:
                done = False
                break
            gu = g[u]
            ru = rhs[u]
            mu = gu if gu < ru else ru
            dx = xs[u] - sx
            dy = ys[u] - sy
            if dx < 0:
                dx = -dx
            if dy < 0:
                dy = -dy
            hu = (dx + dy + kd * (dx if dx < dy else dy)) * hs
            n1 = mu + hu + km
            if k1 < n1 or (k1 == n1 and k2 < mu):
                # the stored key was a stale lower bound: re-key in place
                qk1[u] = n1
                qk2[u] = mu
                heapreplace(heap, (n1, mu, u))
                reinsertions += 1
                continue
            expansions += 1
            cu = cost[u]
            if gu > ru:
                # overconsistent: settle u, then rhs(p) = min(rhs(p), c(p, u) + g(u))
                g[u] = ru
                qk1[u] = _NOT_QUEUED
                live -= 1
                heappop(heap)
                if cu == inf:
                    continue  # nothing can enter u
                cd = cu * SQRT2
                for off, diag, ca, cb in nbrs:
                    s = u + off
                    if frozen[s]:
                        continue
                    if diag:
                        if cost[u + ca] == inf and cost[u + cb] == inf:
                            continue
                        v = cd + ru
                    else:
                        v = cu + ru
                    if v < rhs[s]:
                        rhs[s] = v
                        gs = g[s]
                        if gs != v:
                            m = v if v < gs else gs
                            dx = xs[s] - sx
                            dy = ys[s] - sy
                            if dx < 0:
                                dx = -dx
                            if dy < 0:
                                dy = -dy
                            s1 = m + (dx + dy + kd * (dx if dx < dy else dy)) * hs + km
                            q1 = qk1[s]
                            if q1 < 0.0:
                                live += 1
                            elif q1 == s1 and qk2[s] == m:
                                continue
                            qk1[s] = s1
                            qk2[s] = m
                            heappush(heap, (s1, m, s))
                        elif qk1[s] >= 0.0:
                            qk1[s] = _NOT_QUEUED
                            live -= 1
            else:
                # underconsistent: g(u) = inf, then repair u and every p that used u
                g[u] = inf
                if ru != inf:
                    n1 = ru + hu + km
                    qk1[u] = n1
                    qk2[u] = ru
                    heapreplace(heap, (n1, ru, u))
                else:
                    qk1[u] = _NOT_QUEUED
                    live -= 1
                    heappop(heap)
                if cu == inf:
                    continue
                cd = cu * SQRT2
                for off, diag, ca, cb in nbrs:
                    s = u + off
                    if frozen[s]:
                        continue
                    if diag:
                        if cost[u + ca] == inf and cost[u + cb] == inf:
                            continue
                        v = cd + gu
                    else:
                        v = cu + gu
                    if rhs[s] != v:
                        continue
                    # u was s's best successor: recompute rhs(s) over all successors
                    best = inf
                    for off2, diag2, ca2, cb2 in nbrs:
                        t = s + off2
                        g2 = g[t]
                        if g2 == inf:
                            continue
                        c2 = cost[t]
                        if c2 == inf:
                            continue
                        if diag2:
                            if cost[s + ca2] == inf and cost[s + cb2] == inf:
                                continue
                            c2 = c2 * SQRT2 + g2
                        else:
                            c2 = c2 + g2
                        if c2 < best:
                            best = c2
                    rhs[s] = best
                    gs = g[s]
                    if gs != best:
                        m = best if best < gs else gs
                        dx = xs[s] - sx
                        dy = ys[s] - sy
                        if dx < 0:
                            dx = -dx
                        if dy < 0:
                            dy = -dy
                        s1 = m + (dx + dy + kd * (dx if dx < dy else dy)) * hs + km
                        q1 = qk1[s]
                        if q1 < 0.0:
                            live += 1
                        elif q1 == s1 and qk2[s] == m:
                            continue
                        qk1[s] = s1
                        qk2[s] = m
                        heappush(heap, (s1, m, s))
                    elif qk1[s] >= 0.0:
                        qk1[s] = _NOT_QUEUED
                        live -= 1
        self._live = live
        self._last_expansions = expansions
        self._last_reinsertions = reinsertions
        self._total_expansions += expansions
        if len(heap) > 4 * live + 4096:
            self._compact()
        return done

    def _compact(self) -> None:
        """Drop stale heap entries (keeps the heap proportional to the live queue)."""
        qk1 = self._qk1
        qk2 = self._qk2
        live = {u: (k1, k2) for k1, k2, u in self._heap if qk1[u] == k1 and qk2[u] == k2}
        self._heap = [(k1, k2, u) for u, (k1, k2) in live.items()]
        heapq.heapify(self._heap)


_DIRECTIONS = tuple((ox, oy) for ox in (-1, 0, 1) for oy in (-1, 0, 1) if (ox, oy) != (0, 0))
_STEPS = np.array([SQRT2 if ox and oy else 1.0 for ox, oy in _DIRECTIONS])


def reverse_graph(cost: npt.ArrayLike) -> csr_matrix:
    """The reversed edge graph of a cost grid, for scipy's shortest-path routines.

    Node ``x * ny + y`` is cell ``(x, y)``; row ``v`` holds, for each of the eight
    directions, the edge into ``v`` from its neighbour ``u`` with weight ``c(u, v)`` of
    the module's edge model, so ``dijkstra(graph, indices=goal)`` gives every cell's
    exact cost *to* the goal. Every row has exactly eight entries: impassable and
    corner-cut edges, and neighbours outside the grid (as self-loops), are stored with
    weight ``inf``, which no shortest path uses. That keeps the structure fixed per grid
    shape (cached), so a build is a few vectorised passes over the costs.

    Raises:
        GridError: ``cost`` is not a non-empty 2-D array of costs >= 1 or +inf.
    """
    try:
        cv = np.asarray(cost, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise GridError(f"cost must be a 2-D array of numbers: {exc}") from exc
    if cv.ndim != 2 or cv.size == 0:
        raise GridError(f"cost must be a non-empty 2-D array, got shape {cv.shape}")
    _check_costs(cv)
    nx, ny = cv.shape
    indices, indptr, outside = _graph_structure(nx, ny)
    blocked = np.ones((nx + 2, ny + 2), dtype=bool)
    blocked[1:-1, 1:-1] = np.isinf(cv)
    data = np.multiply.outer(cv, _STEPS)  # (nx, ny, 8): c(u, v) = cost[v] * step
    data[outside] = np.inf
    for k, (ox, oy) in enumerate(_DIRECTIONS):
        if ox and oy:
            # u = v + (ox, oy); the corners of the move u -> v are v + (ox, 0), v + (0, oy)
            cut = blocked[1 + ox:nx + 1 + ox, 1:-1] & blocked[1:-1, 1 + oy:ny + 1 + oy]
            data[:, :, k][cut] = np.inf
    return csr_matrix((data.reshape(-1), indices, indptr), shape=(nx * ny, nx * ny))


@functools.lru_cache(maxsize=4)
def _graph_structure(nx: int, ny: int) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.int32],
                                                npt.NDArray[np.bool_]]:
    """Column indices, row pointers and outside-the-grid mask of reverse_graph (read-only)."""
    if 8 * nx * ny >= 2**31:
        raise GridError(f"a {nx} x {ny} grid is too large for 32-bit graph indices")
    v = np.arange(nx * ny, dtype=np.int64).reshape(nx, ny)
    xs = np.arange(nx)[:, None]
    ys = np.arange(ny)[None, :]
    indices = np.empty((nx, ny, 8), dtype=np.int32)
    outside = np.empty((nx, ny, 8), dtype=bool)
    for k, (ox, oy) in enumerate(_DIRECTIONS):
        inside = (xs + ox >= 0) & (xs + ox < nx) & (ys + oy >= 0) & (ys + oy < ny)
        indices[:, :, k] = np.where(inside, v + (ox * ny + oy), v)
        outside[:, :, k] = ~inside
    indptr = np.arange(0, 8 * nx * ny + 1, 8, dtype=np.int32)
    flat_indices = indices.reshape(-1)
    for array in (flat_indices, indptr, outside):
        array.flags.writeable = False
    return flat_indices, indptr, outside


def _check_costs(values: npt.NDArray[Any]) -> None:
    """Raise GridError unless every value is >= 1 (finite) or +inf."""
    bad = np.isnan(values) | (values < 1.0)
    if bad.any():
        v = values[bad].ravel()[0]
        raise GridError(f"costs must be >= 1 or +inf (impassable), got {v}")
