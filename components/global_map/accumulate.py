"""The Global Map's numerical core: the mission-area planning grid. Pure numpy: no
asyncio, no afa.

The grid (default 250 m × 250 m at 0.5 m: 500 × 500 cells, frame ``World``, rows
along x = east, columns along y = north, as every map in ``idl.maps``) holds

- an **a priori cost** layer (operator knowledge; ``UnknownCellCost`` by default),
- the **sensed** layers: the last accepted hazard, its goodness and time, whether the
  cell was ever sensed, and the **sensed cost** derived from the hazard.

The planner's cost of a cell is the sensed cost once sensed, else the a priori cost
(``PlanPointIDL.cost``).

Design choices:

- **Cost** (:class:`CostMapping`): ``1 + (max_cost - 1)·hazard^exponent`` for hazard
  below ``lethal``, ``inf`` at or above it; unknown → ``unknown`` (``UnknownCellCost``,
  ≥ 1). Every finite cost is ≥ 1, so D* Lite's octile heuristic (which prices a step of
  length s at s) stays admissible. The default exponent 2 keeps mild hazards (gentle
  slopes, rough ground) cheap and makes near-lethal ones dear (hazard 0.5 → 3.25,
  0.9 → 8.3 at max_cost 10), so the planner does not detour around every bump.
- **Placement**: each incoming cell's centre is carried into the world by the map's
  ``mapPose`` (rotation about z and translation) and lands in the planning cell that
  contains it (floor semantics). With the default equal, aligned 0.5 m grids this
  is one-to-one; if several incoming cells land in one planning cell (a rotated or
  finer map), the highest hazard among them is taken.
- **Combination of repeated observations**: an incoming observation replaces the
  stored one when ``goodness_new >= goodness_old · exp(-(t_new - t_old) / age_constant)``:
  better data wins, and stored data loses its claim as it ages; an observation older
  than the stored one (an event arriving out of order) never replaces it. Why not the
  alternatives: "latest wins" would let far-field re-evaluations (relaxed
  thresholds, lower goodness) of cells the vehicle has driven past erase obstacles
  it saw up close; "max" never forgets a phantom obstacle (a pose glitch, dust) and
  keeps costs from ever falling. An incoming map's unknown cells (NaN) never erase
  anything.
- **Changes** (:class:`MapChange`): each merge reports the cells whose planning cost
  changed, with old and new cost (what D* Lite needs to update edge costs
  incrementally), their bounding box, and the bounding box of every cell written (so
  a PlanMap event can carry only that region when it is smaller than the grid).
- **Transforms**: the planning frame is the grid in cell units: node (x, y) is cell
  [x, y], covering planning coordinates [x, x+1) × [y, y+1). ^P T_W scales by
  1/gridsize (uniformly, a similarity) after moving the grid's origin to 0.
- **Moving** (:meth:`PlanningGrid.shift`): by whole cells, so a world cell keeps its
  layers while it stays inside; cells that come in are unknown.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from components.terrain_map.grid import GridGeometry, shift_cells

__all__ = ["CostMapping", "Region", "MapChange", "PlanningGrid", "cost_floor_is_admissible",
           "mission_shift"]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass(frozen=True)
class CostMapping:
    """Hazard (0..1, NaN unknown) → traversal cost (≥ 1 or inf); see the module doc.

    Raises ValueError unless ``max_cost >= 1``, ``0 < lethal <= 1``, ``exponent > 0``
    and ``unknown >= 1``.
    """

    max_cost: float = 10.0
    lethal: float = 1.0
    exponent: float = 2.0
    unknown: float = 1.0

    def __post_init__(self) -> None:
        if not (self.max_cost >= 1 and 0 < self.lethal <= 1 and self.exponent > 0
                and self.unknown >= 1):
            raise ValueError("CostMapping needs max_cost >= 1, 0 < lethal <= 1, "
                             "exponent > 0 and unknown >= 1")

    def __call__(self, hazard: ArrayLike) -> FloatArray:
        h = np.asarray(hazard, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            cost = 1.0 + (self.max_cost - 1.0) * np.clip(h, 0.0, 1.0) ** self.exponent
            cost = np.where(h >= self.lethal, np.inf, cost)
        result: FloatArray = np.where(np.isnan(h), self.unknown, cost)
        return result

    def hazard_of(self, cost: ArrayLike) -> FloatArray:
        """The hazard whose cost is ``cost`` (the inverse of the mapping; inf → 1)."""
        c = np.asarray(cost, dtype=np.float64)
        with np.errstate(invalid="ignore", divide="ignore"):
            share = np.clip((c - 1.0) / (self.max_cost - 1.0), 0.0, 1.0) \
                if self.max_cost > 1.0 else np.zeros_like(c)
            hazard = share ** (1.0 / self.exponent) * min(self.lethal, 1.0)
        result: FloatArray = np.where(np.isinf(c), 1.0, np.minimum(hazard, 0.999999))
        return result


@dataclass(frozen=True)
class Region:
    """Cells ``[i0, i1) × [j0, j1)`` of a grid (half-open, like slices)."""

    i0: int
    i1: int
    j0: int
    j1: int

    @classmethod
    def bounding(cls, i: NDArray[np.integer], j: NDArray[np.integer]) -> Region | None:
        """The smallest region holding cells (i, j); None for no cells."""
        if len(i) == 0:
            return None
        return cls(int(i.min()), int(i.max()) + 1, int(j.min()), int(j.max()) + 1)

    @property
    def slices(self) -> tuple[slice, slice]:
        """Index a (rows, cols) layer with this to cut the region out."""
        return (slice(self.i0, self.i1), slice(self.j0, self.j1))

    @property
    def shape(self) -> tuple[int, int]:
        return (self.i1 - self.i0, self.j1 - self.j0)

    @property
    def size(self) -> int:
        return (self.i1 - self.i0) * (self.j1 - self.j0)

    def geometry(self, parent: GridGeometry) -> GridGeometry:
        """The placement of this region as a grid of its own (for a PlanMap event
        that carries only the region)."""
        g = parent.gridsize
        return GridGeometry(parent.origin_x + self.i0 * g, parent.origin_y + self.j0 * g, g,
                            self.i1 - self.i0, self.j1 - self.j0)


@dataclass(frozen=True)
class MapChange:
    """What a merge or an a priori update changed.

    ``rows``, ``cols``: cells whose planning cost changed; ``old_cost``, ``new_cost``:
    their costs before and after. ``cost_region`` bounds those cells, ``region`` every
    cell written (None when empty). ``merged``: incoming known cells inside the grid;
    ``outside``: incoming known cells that fell outside it; ``kept``: planning cells
    where the stored observation won.
    """

    rows: IntArray
    cols: IntArray
    old_cost: FloatArray
    new_cost: FloatArray
    cost_region: Region | None
    region: Region | None
    merged: int = 0
    outside: int = 0
    kept: int = 0

    def __len__(self) -> int:
        return len(self.rows)


class PlanningGrid:
    """The Global Map's cumulative grid (see the module doc).

    Layers are (rows, cols) float64 arrays (``sensed`` bool): ``a_priori``,
    ``sensed_cost`` (the unknown cost where never sensed), ``hazard`` (NaN where never
    sensed), ``goodness``, ``stamp`` (time of the stored observation, -inf never).
    """

    def __init__(self, geometry: GridGeometry, cost: CostMapping | None = None,
                 age_constant: float = 30.0) -> None:
        if not age_constant > 0:
            raise ValueError("age_constant must be > 0")
        self.geometry = geometry
        self.cost_mapping = cost or CostMapping()
        self.age_constant = age_constant
        shape = geometry.shape
        unknown = self.cost_mapping.unknown
        self.a_priori = np.full(shape, unknown)
        self.sensed_cost = np.full(shape, unknown)
        self.sensed = np.zeros(shape, dtype=bool)
        self.hazard = np.full(shape, np.nan)
        self.goodness = np.zeros(shape)
        self.stamp = np.full(shape, -np.inf)
        self._scratch = np.empty(geometry.size, dtype=np.intp)

    @classmethod
    def centred(cls, centre_x: float, centre_y: float, width: float, depth: float,
                gridsize: float, cost: CostMapping | None = None,
                age_constant: float = 30.0) -> PlanningGrid:
        """A grid ``width`` m east-west (rows, along x) and ``depth`` m north-south
        (columns, along y), centred on (centre_x, centre_y), as GlobalMapParameters'
        ``Width``/``Depth``/``Gridsize`` (in metres here) describe it."""
        rows = int(round(width / gridsize))
        cols = int(round(depth / gridsize))
        geometry = GridGeometry(centre_x - rows * gridsize / 2.0,
                                centre_y - cols * gridsize / 2.0, gridsize, rows, cols)
        return cls(geometry, cost, age_constant)

    # ------------------------------------------------------------------ transforms
    def world_to_cell(self, x: ArrayLike, y: ArrayLike) -> tuple[IntArray, IntArray]:
        """Planning cells (i, j) holding world points (floor semantics; may lie
        outside: check with :meth:`contains`). Raises ValueError for non-finite input."""
        return self.geometry.cell_index(x, y)

    def cell_to_world(self, i: ArrayLike, j: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """World (x, y) of the centres of planning cells (i, j)."""
        return self.geometry.cell_center(i, j)

    def contains(self, i: ArrayLike, j: ArrayLike) -> NDArray[np.bool_]:
        """Whether planning cells (i, j) lie inside the grid."""
        return self.geometry.contains(i, j)

    def planning_from_world(self) -> FloatArray:
        """^P T_W (4x4): world metres to planning-grid units."""
        g = self.geometry.gridsize
        t = np.diag([1.0 / g, 1.0 / g, 1.0 / g, 1.0])
        t[0, 3] = -self.geometry.origin_x / g
        t[1, 3] = -self.geometry.origin_y / g
        return t

    def world_from_planning(self) -> FloatArray:
        """^W T_P (4x4): planning-grid units to world metres."""
        g = self.geometry.gridsize
        t = np.diag([g, g, g, 1.0])
        t[0, 3] = self.geometry.origin_x
        t[1, 3] = self.geometry.origin_y
        return t

    def shift(self, di: int, dj: int) -> None:
        """Move the grid by whole cells (its origin by ``di``, ``dj`` cells): a world
        cell inside both placements keeps every layer; the cells that come in are
        unknown (a priori cost ``unknown``, never sensed)."""
        if not (di or dj):
            return
        unknown = self.cost_mapping.unknown
        for layer, empty in ((self.a_priori, unknown), (self.sensed_cost, unknown),
                             (self.sensed, False), (self.hazard, np.nan),
                             (self.goodness, 0.0), (self.stamp, -np.inf)):
            shift_cells(layer, di, dj, empty)
        g = self.geometry
        self.geometry = GridGeometry(g.origin_x + di * g.gridsize, g.origin_y + dj * g.gridsize,
                                     g.gridsize, g.rows, g.cols)

    # ------------------------------------------------------------------ costs
    def cost(self) -> FloatArray:
        """The planning cost of every cell: sensed cost once sensed, else a priori."""
        result: FloatArray = np.where(self.sensed, self.sensed_cost, self.a_priori)
        return result

    def cost_at(self, i: IntArray, j: IntArray) -> FloatArray:
        """:meth:`cost` of cells (i, j) only (inside the grid)."""
        result: FloatArray = np.where(self.sensed[i, j], self.sensed_cost[i, j],
                                      self.a_priori[i, j])
        return result

    def set_a_priori(self, i: ArrayLike, j: ArrayLike, cost: ArrayLike) -> MapChange:
        """Set the a priori cost of cells (i, j) (broadcast). Cells outside the grid
        are skipped (counted in ``outside``). Raises ValueError for a cost below 1 or
        NaN."""
        ii, jj, cc = np.broadcast_arrays(np.asarray(i, dtype=np.intp),
                                         np.asarray(j, dtype=np.intp),
                                         np.asarray(cost, dtype=np.float64))
        ii, jj, cc = ii.ravel(), jj.ravel(), cc.ravel()
        if not np.all(cc >= 1.0):  # NaN fails too
            raise ValueError("a priori costs must be >= 1 or inf")
        inside = self.contains(ii, jj)
        ii, jj, cc = ii[inside], jj[inside], cc[inside]
        old = self.cost_at(ii, jj)
        self.a_priori[ii, jj] = cc
        return self._change(ii, jj, old, ii, jj, outside=int((~inside).sum()))

    def set_sensed(self, i: ArrayLike, j: ArrayLike, cost: ArrayLike, time: float) -> MapChange:
        """Set the sensed cost of cells (i, j) directly (an operator's correction, seed
        Table 18 ``setSensingMap``), as a full-goodness observation at ``time``: the
        stored hazard becomes the one whose cost this is. Cells outside are skipped.
        Raises ValueError for a cost below 1 or NaN."""
        ii, jj, cc = np.broadcast_arrays(np.asarray(i, dtype=np.intp),
                                         np.asarray(j, dtype=np.intp),
                                         np.asarray(cost, dtype=np.float64))
        ii, jj, cc = ii.ravel(), jj.ravel(), cc.ravel()
        if not np.all(cc >= 1.0):
            raise ValueError("sensed costs must be >= 1 or inf")
        inside = self.contains(ii, jj)
        ii, jj, cc = ii[inside], jj[inside], cc[inside]
        old = self.cost_at(ii, jj)
        self.sensed_cost[ii, jj] = cc
        self.hazard[ii, jj] = self.cost_mapping.hazard_of(cc)
        self.goodness[ii, jj] = 1.0
        self.stamp[ii, jj] = time
        self.sensed[ii, jj] = True
        return self._change(ii, jj, old, ii, jj, outside=int((~inside).sum()))

    # ------------------------------------------------------------------ merging
    def merge(self, hazard: ArrayLike, goodness: ArrayLike, map_pose: ArrayLike,
              origin_x: float, origin_y: float, gridsize: float, time: float) -> MapChange:
        """Merge a traversability map (a ``TravMapArrayEventIDL``'s ``hazard``,
        ``goodness``, ``mapPose``, ``originX``, ``originY``, ``gridsize``, ``time`` in
        seconds) into the sensed layers; see the module doc for placement and the
        combination rule. Raises ValueError for mismatched layer shapes."""
        h = np.asarray(hazard, dtype=np.float64)
        q = np.asarray(goodness, dtype=np.float64)
        if h.ndim != 2 or h.shape != q.shape:
            raise ValueError(f"hazard {h.shape} and goodness {q.shape} must be one 2-D shape")
        pose = np.asarray(map_pose, dtype=np.float64)
        mi, mj = np.nonzero(~np.isnan(h))
        hv, qv = h[mi, mj], np.clip(q[mi, mj], 0.0, 1.0)
        mx = origin_x + (mi + 0.5) * gridsize
        my = origin_y + (mj + 0.5) * gridsize
        wx = pose[0, 0] * mx + pose[0, 1] * my + pose[0, 3]
        wy = pose[1, 0] * mx + pose[1, 1] * my + pose[1, 3]
        geo = self.geometry
        fi = np.floor((wx - geo.origin_x) / geo.gridsize)
        fj = np.floor((wy - geo.origin_y) / geo.gridsize)
        inside = (fi >= 0) & (fi < geo.rows) & (fj >= 0) & (fj < geo.cols)
        outside = int(np.count_nonzero(~inside))
        flat = (fi[inside] * geo.cols + fj[inside]).astype(np.intp)
        hv, qv = hv[inside], qv[inside]
        if len(flat) > 1 and self._has_duplicates(flat):
            # one observation per planning cell: the highest hazard, then goodness
            order = np.lexsort((qv, hv, flat))
            flat, hv, qv = flat[order], hv[order], qv[order]
            last = np.ones(len(flat), dtype=bool)
            np.not_equal(flat[1:], flat[:-1], out=last[:-1])
            flat, hv, qv = flat[last], hv[last], qv[last]
        ti, tj = np.divmod(flat, geo.cols)
        age = time - self.stamp[ti, tj]  # inf where never sensed
        stored = self.goodness[ti, tj] * np.exp(-np.maximum(age, 0.0) / self.age_constant)
        wins = ~self.sensed[ti, tj] | ((qv >= stored) & (age >= 0))
        kept = int(np.count_nonzero(~wins))
        ti, tj, hv, qv = ti[wins], tj[wins], hv[wins], qv[wins]
        old = self.cost_at(ti, tj)
        self.hazard[ti, tj] = hv
        self.goodness[ti, tj] = qv
        self.stamp[ti, tj] = time
        self.sensed[ti, tj] = True
        self.sensed_cost[ti, tj] = self.cost_mapping(hv)
        return self._change(ti, tj, old, ti, tj, merged=len(flat), outside=outside, kept=kept)

    def _has_duplicates(self, flat: IntArray) -> bool:
        """Whether a cell index repeats (a rotated or finer map): O(n) with a scratch
        array, so the aligned case skips the sort."""
        order = np.arange(len(flat))
        self._scratch[flat] = order  # with repeats, one write per cell survives
        return bool(np.any(self._scratch[flat] != order))

    def _change(self, ti: IntArray, tj: IntArray, old: FloatArray, wi: IntArray,
                wj: IntArray, *, merged: int = 0, outside: int = 0,
                kept: int = 0) -> MapChange:
        new = self.cost_at(ti, tj)
        changed = old != new  # inf == inf: unchanged
        ci, cj = ti[changed], tj[changed]
        return MapChange(rows=ci, cols=cj, old_cost=old[changed], new_cost=new[changed],
                         cost_region=Region.bounding(ci, cj), region=Region.bounding(wi, wj),
                         merged=merged, outside=outside, kept=kept)

    # ------------------------------------------------------------------ export
    def layers(self, region: Region | None = None) -> dict[str, NDArray[np.float32]]:
        """The PlanMapEventIDL layers as float32 (``hazard`` NaN where unknown,
        ``goodness``, ``aPrioriCost``, ``sensedCost``), whole or cut to ``region``
        (whose placement :meth:`Region.geometry` gives)."""
        window = region.slices if region is not None else (slice(None), slice(None))
        return {
            "hazard": self.hazard[window].astype(np.float32),
            "goodness": self.goodness[window].astype(np.float32),
            "aPrioriCost": self.a_priori[window].astype(np.float32),
            "sensedCost": self.sensed_cost[window].astype(np.float32),
        }


def cost_floor_is_admissible(costs: ArrayLike) -> bool:
    """Whether every cost is ≥ 1 or inf (what an octile heuristic needs)."""
    c = np.asarray(costs)
    return bool(np.all(c >= 1.0))


def mission_shift(geometry: GridGeometry, vehicle: tuple[float, float],
                  waypoints: list[tuple[float, float]], margin: float) -> tuple[int, int]:
    """The whole-cell move (di, dj) of a grid at ``geometry`` that keeps the mission
    inside it, at least ``margin`` metres from its edges; (0, 0) when no move is needed.

    ``waypoints`` are the mission's ahead of the vehicle, in the order it will drive
    them (world x, y). The grid should hold the vehicle and the longest run of them,
    from the first, that fits: when those are inside, nothing moves; otherwise the grid
    is centred on their bounding box. When even the first one does not fit with the
    vehicle (a leg longer than the grid), the grid is placed along the way to it, the
    vehicle ``margin`` from the trailing edge, and placed again when less than half of
    that lead is left ahead of the vehicle.
    """
    g = geometry.gridsize
    size = np.array([geometry.rows * g, geometry.cols * g])
    low_edge = np.array([geometry.origin_x, geometry.origin_y])
    here = np.asarray(vehicle, dtype=np.float64)

    def fits(points: NDArray[np.float64]) -> bool:
        return bool(np.all(points.max(axis=0) - points.min(axis=0) <= size - 2 * margin))

    ahead = np.asarray(waypoints, dtype=np.float64).reshape(-1, 2)
    k = len(ahead)
    while k and not fits(np.vstack([here, ahead[:k]])):
        k -= 1
    points = np.vstack([here, ahead[:k]])
    held = bool(np.all(points >= low_edge + margin)
                and np.all(points <= low_edge + size - margin))
    if k or not len(ahead):
        if held:
            return (0, 0)
        centre = (points.min(axis=0) + points.max(axis=0)) / 2
    else:  # a leg longer than the grid: the grid ahead of the vehicle, along the leg
        direction = ahead[0] - here
        direction /= np.linalg.norm(direction)
        lead = size / 2 - margin  # the vehicle `margin` from the trailing edge
        if held and np.all(np.abs(low_edge + size / 2 - here) <= lead) \
                and np.dot(low_edge + size / 2 - here, direction) >= np.min(lead) / 2:
            return (0, 0)  # still at least half the lead ahead of the vehicle
        centre = here + direction * lead
    di, dj = np.round((centre - size / 2 - low_edge) / g).astype(int)
    return (int(di), int(dj))
