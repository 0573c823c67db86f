"""Obstacle Avoidance's core (seed §3.3.2, Table A.10): every candidate arc scored on the
egocentric traversability map.

Pure Python + numpy: no asyncio, no framework. The component hands it each ``Traverse``
map (``EtravMapArrayEventIDL``) and publishes the :class:`~components.arcs.ArcVotes`.

Frames
------
Arcs start at the rear axle centre (``Raptor:RearAxleCenter``, x forward, y left; see
:mod:`components.arcs`). The ego map hangs from its own frame, ``Raptor:Front-BumperCenter``
in the Raptor's configuration, heading-aligned: map-frame point (x_m, y_m) is vehicle
point (x_m + f_x, y_m + f_y) with ``map_frame = (f_x, f_y)`` the map frame's origin in
the rear-axle frame (2.45 m, 0 for docs/geometry.md's Raptor; the component takes it from
ModelServer). Cell [i, j] covers map-frame x in [originX + i·g, originX + (i+1)·g) and y
in [originY + j·g, …) (:mod:`idl.maps`): rows run ahead, columns to the left. The map's
own gridsize is used; Table A.10's ``MapGridsize`` 0.01 "(mm)" cannot be a cell size.

The swept disc
--------------
A disc of radius ``VehicleRadius`` stands for the vehicle (the seed's "circle which
approximates the size of the vehicle"). It is centred on a body point ``a`` metres ahead
of the rear axle (``disc_offsets``, default the rear axle alone) and carried along the
arc; samples are taken every ``CurveMakingConst`` metres of rear-axle travel,
s = 0, c, 2c, … up to the arc's horizon. A cell is *under the disc* when its closed
square and the closed disc intersect (nearest point of the square within the radius): a
hazard anywhere in a cell may be anywhere in it, so the test is conservative. With a
``margin`` (``HazardMargin``) each square is first shrunk by it on every side, down to
its centre at half a cell: the Traversability Map marks the cells beside a step as
hazards too, so a hazard cell's obstacle lies half a cell or more beyond its centre
(decision 0024). Several
offsets give a union of discs; (0, 2.45) with radius 0.7 covers the Raptor's swept body
on every arc, since on a turn the front swings outside the rear axle's circle.

The Raptor's body is 1.4 m wide: Table A.10's default ``VehicleRadius`` 0.5 m is narrower
than the vehicle, so a 1.2 m gap passes. Use at least 0.7 m for the Raptor.

Evaluated rows and horizon
--------------------------
Only rows in [r0 + ``NearZone``, r0 + ``FarZone``) are looked at, r0 being the first row
wholly ahead of the map frame's origin (0 for a map starting at the bumper, as the
Raptor's does): "rows immediately in front of the vehicle". Each arc is swept for arc
length S_k = min(S, π/|κ|): S (``horizon``, default: the rear-axle travel after which
the rearmost disc of the straight arc has passed the last evaluated row) and at most half
a circle, after which an arc heads back the way it came.

Tables (once per map geometry)
------------------------------
:func:`build_sweep_tables` walks every arc once and keeps, per arc, the cells the discs
touch, each with the arc length at which it is *first* touched (its *reach*), ordered by
reach. Scoring a map is then a gather of the map's layers through these tables and a few
reductions (:class:`ArcSweepScorer`), microseconds for a 32 × 32 map.

Scoring (interpretation of Table A.10, decisions in docs/decisions/0015-arc-voting.md)
-------------------------------------------------------------------------------
- **Obstacle**: a cell with hazard ≥ ``hazard_threshold`` (default 1.0, the IDL's
  "1 = untraversable": the traversability map judges traversability, not this
  behaviour), or an unknown (NaN) cell when ``VetoUnknownCells``.
- **Veto**: an arc whose discs touch an obstacle within its horizon and the evaluated
  rows (the seed's Figure 10: "vetoed because of the discrete obstacles in their path").
  ``FarZone`` is how far that reaches, and ``VetoDistance`` (an afa addition, 2.5 m;
  inf: any obstacle within the horizon) how much rear-axle travel before the obstacle
  still vetoes: beyond it the obstacle only shortens the free distance. Vetoing a half
  circle for a wall it would meet 10 m on leaves a vehicle in a tight spot (a
  cul-de-sac, a forest) with no arc to turn on, although it re-decides every half
  second long before it gets there.
- **Obstacle distance** d_obs: the reach of the first obstacle (inf if none).
- **Free distance** d_free: the reach of the first obstacle, or of the first unknown
  cell when ``CostUnknownCells`` (unknown ground is a cost: it ends the distance known to
  be clear, without vetoing); the horizon S_k if none. With neither flag unknown cells
  count as free (the freespace assumption, as FindPath's).
- **Distance discount** (``DistFactor`` %, ``MinDistDiscount``): a metre of free
  distance, or a cell's hazard, s metres along the arc counts w(s) = max(m, 1 − a·s),
  a = DistFactor/100 per metre, m = MinDistDiscount: nearer ground matters more, never
  less than m. The seed defaults (0, 1) mean no discount. Obstacles are never discounted
  (a discount must not hide an untraversable cell from the veto).
- **Vote** = W(min(d_free, D)) / W(D) · (1 − r), W(d) = ∫₀ᵈ w, D the shortest horizon
  of the set (equal free distances get equal votes on every arc; an arc clear for D
  votes 1), r the largest discounted hazard h·w(reach) of the cells passed before
  d_free (rough but traversable ground lowers the vote). Vetoed arcs keep their vote,
  for displays; the arbiter ignores vetoed arcs.
- **Certainty**: the mean ``goodness`` of the cells reached up to d_free (those behind
  the verdict); 0 if the arc touched no evaluated cell.
- **Speed**: vetoed arcs 0; otherwise ``MaxVelocity``, or with ``DiscountSpeeds``
  ``MinVelocity + (MaxVelocity − MinVelocity)·vote`` (slower when the free distance is
  short or the ground rough, never below MinVelocity short of a veto).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from components.arcs import ArcSet, ArcVotes, arc_points
from components.obstacle_avoidance.parameters import ObstacleAvoidanceParameters

__all__ = [
    "MapGeometry",
    "SweepTables",
    "SweepScores",
    "ArcSweepScorer",
    "ArcSweeper",
    "build_sweep_tables",
    "distance_weight",
    "discounted_distance",
]


class _GridHeader(Protocol):
    rows: int
    cols: int
    gridsize: float
    originX: float
    originY: float


@dataclass(frozen=True)
class MapGeometry:
    """The grid of an ego map: size, cell edge (m) and the map-frame position (m) of the
    outer corner of cell [0, 0]. Hashable: the key under which tables are kept.

    Raises ValueError for an empty grid or a non-positive or non-finite cell size.
    """

    rows: int
    cols: int
    gridsize: float
    origin_x: float
    origin_y: float

    def __post_init__(self) -> None:
        if self.rows < 1 or self.cols < 1:
            raise ValueError(f"MapGeometry needs rows, cols ≥ 1, got {self.rows}x{self.cols}")
        if not (math.isfinite(self.gridsize) and self.gridsize > 0.0):
            raise ValueError(f"MapGeometry gridsize must be finite and > 0, got {self.gridsize}")
        if not (math.isfinite(self.origin_x) and math.isfinite(self.origin_y)):
            raise ValueError("MapGeometry origin must be finite")

    @classmethod
    def of(cls, header: _GridHeader) -> MapGeometry:
        """The geometry of a map event (anything with rows, cols, gridsize, originX/Y)."""
        return cls(int(header.rows), int(header.cols), float(header.gridsize),
                   float(header.originX), float(header.originY))

    @property
    def first_row_ahead(self) -> int:
        """r0: the first row wholly ahead of the map frame's origin (x_m ≥ 0)."""
        return max(0, math.ceil(-self.origin_x / self.gridsize - 1e-9))


def distance_weight(s: ArrayLike, dist_factor: float, min_discount: float) -> NDArray[np.float64]:
    """w(s) = max(MinDistDiscount, 1 − DistFactor/100 · s): what something s metres
    along an arc counts for (module docstring)."""
    s_arr = np.asarray(s, dtype=np.float64)
    return np.maximum(min_discount, 1.0 - (dist_factor / 100.0) * s_arr)


def discounted_distance(d: ArrayLike, dist_factor: float,
                        min_discount: float) -> NDArray[np.float64]:
    """W(d) = ∫₀ᵈ w(s) ds in closed form (d ≥ 0, may be inf)."""
    d_arr = np.asarray(d, dtype=np.float64)
    a = dist_factor / 100.0
    if a == 0.0 or min_discount >= 1.0:
        return d_arr.copy()
    knee = (1.0 - min_discount) / a
    near = np.minimum(d_arr, knee)
    with np.errstate(invalid="ignore"):
        far = np.where(d_arr > knee, d_arr - knee, 0.0)
    return near - 0.5 * a * near * near + min_discount * far


@dataclass(frozen=True, eq=False)
class SweepTables:
    """The arc-to-cell tables of one map geometry (:func:`build_sweep_tables`).

    ``cells[k]`` holds the flat indices (i·cols + j) of the cells arc k's discs touch,
    ordered by ``reach[k]``, the arc length (m) at which each is first touched; rows are
    padded to a common length, with at least one pad entry each, with the index
    ``rows·cols`` (one past the grid) and reach inf. ``horizons[k]`` is the arc length
    S_k swept.
    """

    arcs: ArcSet
    geometry: MapGeometry
    map_frame: tuple[float, float]
    radius: float
    step: float
    row_range: tuple[int, int]
    disc_offsets: tuple[float, ...]
    horizons: NDArray[np.float64]
    cells: NDArray[np.intp]
    reach: NDArray[np.float64]
    counts: NDArray[np.intp]

    @property
    def pad_index(self) -> int:
        """The flat index padding the tables (one past the last cell)."""
        return self.geometry.rows * self.geometry.cols

    def arc_cells(self, k: int) -> tuple[NDArray[np.intp], NDArray[np.intp],
                                         NDArray[np.float64]]:
        """Arc k's cells as (rows, cols, reach), ordered by reach."""
        n = int(self.counts[k])
        flat = self.cells[k, :n]
        return flat // self.geometry.cols, flat % self.geometry.cols, self.reach[k, :n]


def build_sweep_tables(arcs: ArcSet, geometry: MapGeometry, *, radius: float, step: float,
                       near_zone: int, far_zone: int, map_frame: tuple[float, float],
                       disc_offsets: Sequence[float] = (0.0,),
                       horizon: float | None = None, margin: float = 0.0) -> SweepTables:
    """Walk every arc once and tabulate the cells its discs touch (module docstring).

    ``radius`` is ``VehicleRadius``, ``step`` ``CurveMakingConst`` (m); ``near_zone`` /
    ``far_zone`` the rows ignored / evaluated; ``map_frame`` the map frame's origin in
    the rear-axle frame (m); ``disc_offsets`` the body points (m ahead of the rear axle)
    carrying a disc; ``horizon`` the arc length S (default: the straight arc's rearmost
    disc clears the last evaluated row).

    Raises ValueError for a non-positive radius or step, an empty offset list, a negative
    zone or a negative horizon.
    """
    if not (radius > 0.0 and step > 0.0 and math.isfinite(radius) and math.isfinite(step)):
        raise ValueError(f"radius and step must be finite and > 0, got {radius}, {step}")
    offsets = tuple(float(a) for a in disc_offsets)
    if not offsets or not all(math.isfinite(a) for a in offsets):
        raise ValueError("disc_offsets must name at least one finite body point")
    if near_zone < 0 or far_zone < 0:
        raise ValueError(f"zones must be ≥ 0, got NearZone {near_zone}, FarZone {far_zone}")
    g = geometry.gridsize
    fx, fy = float(map_frame[0]), float(map_frame[1])
    r0 = geometry.first_row_ahead
    row_lo = min(r0 + near_zone, geometry.rows)
    row_hi = max(min(r0 + far_zone, geometry.rows), row_lo)
    if horizon is None:
        far_edge = fx + geometry.origin_x + row_hi * g
        horizon = max(0.0, far_edge + radius - min(offsets))
    if not (horizon >= 0.0 and math.isfinite(horizon)):
        raise ValueError(f"horizon must be finite and ≥ 0, got {horizon}")

    horizons = np.array([horizon if kappa == 0.0 else min(horizon, math.pi / abs(kappa))
                         for kappa in arcs.curvatures.tolist()])
    per_arc = [_arc_cells(kappa, s_k, step, offsets, geometry, (fx, fy), radius,
                          (row_lo, row_hi), margin)
               for kappa, s_k in zip(arcs.curvatures.tolist(), horizons.tolist(), strict=True)]

    width = max(len(c) for c, _ in per_arc) + 1  # every row ends in a pad entry
    pad = geometry.rows * geometry.cols
    cells = np.full((len(arcs), width), pad, dtype=np.intp)
    reach_table = np.full((len(arcs), width), np.inf)
    counts = np.zeros(len(arcs), dtype=np.intp)
    for k, (c, r) in enumerate(per_arc):
        cells[k, :len(c)] = c
        reach_table[k, :len(r)] = r
        counts[k] = len(c)
    for array in (cells, reach_table, counts, horizons):
        array.flags.writeable = False
    return SweepTables(arcs=arcs, geometry=geometry, map_frame=(fx, fy), radius=float(radius),
                       step=float(step), row_range=(row_lo, row_hi), disc_offsets=offsets,
                       horizons=horizons, cells=cells, reach=reach_table, counts=counts)


def _arc_cells(kappa: float, s_k: float, step: float, offsets: tuple[float, ...],
               geometry: MapGeometry, map_frame: tuple[float, float], radius: float,
               rows: tuple[int, int], margin: float = 0.0
               ) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """One arc's table row: the cells its discs touch (flat indices) and each one's reach
    (the first sample's arc length), ordered by reach, then cell.

    The discs of every body point are tested in one pass over all their samples, and a
    cell's reach is the least over them (a dense per-cell minimum, not a sort of every
    touch: the samples outnumber the cells a hundredfold).
    """
    row_lo, row_hi = rows
    s = np.arange(math.floor(s_k / step + 1e-9) + 1) * step
    if row_hi <= row_lo:
        return np.empty(0, dtype=np.intp), np.empty(0)
    points = [arc_points(s, kappa, offset) for offset in offsets]
    xm = np.concatenate([x for x, _, _ in points]) - map_frame[0]
    ym = np.concatenate([y for _, y, _ in points]) - map_frame[1]
    sample, flat = _touched(xm, ym, geometry, radius, rows, margin)
    pad = geometry.rows * geometry.cols
    first = np.full(pad, np.inf)
    np.minimum.at(first, flat, s[sample % s.shape[0]])
    cells = np.flatnonzero(first < np.inf)
    reach = first[cells]
    order = np.lexsort((cells, reach))
    return cells[order].astype(np.intp), reach[order]


def _touched(xm: NDArray[np.float64], ym: NDArray[np.float64], geometry: MapGeometry,
             radius: float, rows: tuple[int, int], margin: float = 0.0
             ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Every (sample, flat cell) pair such that the closed disc of ``radius`` around map
    point (xm, ym)[sample] meets the cell's closed square, for cells in the evaluated
    ``rows`` and the map's columns."""
    g = geometry.gridsize
    span = np.arange(math.ceil(2.0 * radius / g) + 1)
    i = np.floor((xm - radius - geometry.origin_x) / g).astype(np.intp)[:, None] + span
    j = np.floor((ym - radius - geometry.origin_y) / g).astype(np.intp)[:, None] + span
    x0 = geometry.origin_x + i * g
    y0 = geometry.origin_y + j * g
    m = min(max(margin, 0.0), 0.5 * g)  # the square shrunk by the margin on every side
    dx = np.maximum(np.maximum(x0 + m - xm[:, None], xm[:, None] - (x0 + g - m)), 0.0)
    dy = np.maximum(np.maximum(y0 + m - ym[:, None], ym[:, None] - (y0 + g - m)), 0.0)
    dx2, dy2 = dx * dx, dy * dy
    dx2[(i < rows[0]) | (i >= rows[1])] = np.inf  # outside: never within the radius
    dy2[(j < 0) | (j >= geometry.cols)] = np.inf
    sample, a, b = np.nonzero(dx2[:, :, None] + dy2[:, None, :] <= radius * radius)
    return sample, i[sample, a] * geometry.cols + j[sample, b]


@dataclass(frozen=True, eq=False)
class SweepScores:
    """Obstacle Avoidance's verdict on every arc of one map.

    ``votes`` is what the component publishes; ``obstacle_distance`` (m, inf if none)
    and ``free_distance`` (m) are the arc lengths defined in the module docstring,
    ``horizons`` each arc's swept length, for displays and tests.
    """

    votes: ArcVotes
    obstacle_distance: NDArray[np.float64]
    free_distance: NDArray[np.float64]
    horizons: NDArray[np.float64]


class ArcSweepScorer:
    """Scores traversability maps of one geometry through precomputed :class:`SweepTables`.

    ``parameters`` supplies the scoring flags and speeds (Table A.10); ``hazard_threshold``
    the hazard at and above which a cell is an obstacle. Raises ValueError if the
    threshold is not in (0, 1]. The scorer reuses its own buffers: one scorer per
    component task, not shared across threads.
    """

    def __init__(self, tables: SweepTables, parameters: ObstacleAvoidanceParameters, *,
                 hazard_threshold: float = 1.0) -> None:
        if not 0.0 < hazard_threshold <= 1.0:
            raise ValueError(f"hazard_threshold must be in (0, 1], got {hazard_threshold}")
        self.tables = tables
        self.parameters = parameters
        self.hazard_threshold = float(hazard_threshold)
        p = parameters
        self._shape = (tables.geometry.rows, tables.geometry.cols)
        size = tables.pad_index + 1
        self._hazard = np.zeros(size)    # the pad cell: known, free
        self._goodness = np.zeros(size)  # ... and without evidence
        self._reach = np.asarray(tables.reach)
        self._weight = np.where(np.isfinite(self._reach),
                                distance_weight(np.where(np.isfinite(self._reach),
                                                         self._reach, 0.0),
                                                p.DistFactor, p.MinDistDiscount), 0.0)
        self._horizons = np.asarray(tables.horizons)
        reference = float(self._horizons.min()) if self._horizons.size else 0.0
        self._norm = float(discounted_distance(reference, p.DistFactor, p.MinDistDiscount))
        self._reference = reference
        self._certainty_ones = np.ones(len(tables.arcs))
        self._row_start = np.arange(len(tables.arcs)) * tables.cells.shape[1]
        self._reach_flat = self._reach.reshape(-1)
        self._discounted = p.DistFactor > 0.0 and p.MinDistDiscount < 1.0
        self._max_speed = np.full(len(tables.arcs), p.MaxVelocity)

    def _first(self, mask: NDArray[np.bool_]) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
        """Per row: whether ``mask`` has a True, and the reach of the first (inf if none)."""
        flat = mask.argmax(axis=1) + self._row_start
        found = mask.reshape(-1).take(flat)
        distance = self._reach_flat.take(flat)
        distance[~found] = np.inf
        return found, distance

    def score(self, hazard: NDArray[Any], goodness: NDArray[Any]) -> SweepScores:
        """Score every arc on one map's ``hazard`` (0..1, NaN unknown) and ``goodness``
        (0..1) layers, both (rows, cols) of the tables' geometry.

        Raises ValueError if a layer's shape is not the geometry's.
        """
        if hazard.shape != self._shape or goodness.shape != self._shape:
            raise ValueError(f"map layers {hazard.shape} / {goodness.shape} do not match the "
                             f"tables' geometry {self._shape}")
        p = self.parameters
        self._hazard[:-1] = hazard.reshape(-1)
        self._goodness[:-1] = goodness.reshape(-1)
        cells = self.tables.cells
        reach = self._reach
        h = self._hazard.take(cells)
        obstacle = h >= self.hazard_threshold  # NaN compares False
        if p.VetoUnknownCells or p.CostUnknownCells:
            unknown = np.isnan(h)
            blocked = obstacle | unknown
            if p.VetoUnknownCells:
                obstacle = blocked
        else:
            blocked = obstacle
        # Each table row is sorted by reach: the first True is the nearest.
        hit, obstacle_distance = self._first(obstacle)
        if blocked is obstacle:
            free = np.minimum(obstacle_distance, self._horizons)
        else:
            free = np.minimum(self._first(blocked)[1], self._horizons)
        # fmax skips NaN: an unknown cell (not an obstacle here) adds no roughness. The
        # pad cells have hazard 0, so without a discount the weights need no multiply.
        passed = reach < free[:, None]
        weighted = h * self._weight if self._discounted else h
        rough = np.fmax.reduce(weighted * passed, axis=1, initial=0.0)
        used = reach <= free[:, None]
        n_used = used.argmin(axis=1)  # a prefix, and every row ends in an inf pad
        # Means of values in 0..1 stay in 0..1 in floating point (rounding is monotonic).
        certainty = np.add.reduce(self._goodness.take(cells) * used, axis=1)
        certainty /= np.maximum(n_used, 1)
        if self._discounted:
            clear = discounted_distance(np.minimum(free, self._reference), p.DistFactor,
                                        p.MinDistDiscount) / self._norm
        elif self._norm > 0.0:
            clear = np.minimum(free, self._reference) / self._norm
        else:
            clear = self._certainty_ones
        vote = clear * (1.0 - rough)  # both factors in 0..1
        veto = hit & (obstacle_distance <= p.VetoDistance)
        if p.DiscountSpeeds:
            speed = p.MinVelocity + (p.MaxVelocity - p.MinVelocity) * vote
        else:
            speed = self._max_speed.copy()
        speed[veto] = 0.0
        votes = ArcVotes.unchecked(veto, vote, certainty, speed)
        return SweepScores(votes=votes,
                           obstacle_distance=obstacle_distance, free_distance=free,
                           horizons=self._horizons)


class ArcSweeper:
    """The component-facing entry: scores each map, rebuilding the tables only when the
    map geometry changes (normally once).

    ``map_frame`` is the ego map frame's origin (x, y) in the rear-axle frame (m);
    ``disc_offsets``, ``horizon`` and ``hazard_threshold`` as in
    :func:`build_sweep_tables` and :class:`ArcSweepScorer`.
    """

    def __init__(self, arcs: ArcSet, parameters: ObstacleAvoidanceParameters, *,
                 map_frame: tuple[float, float], disc_offsets: Sequence[float] = (0.0,),
                 horizon: float | None = None, hazard_threshold: float = 1.0) -> None:
        self.arcs = arcs
        self.parameters = parameters
        self.map_frame = (float(map_frame[0]), float(map_frame[1]))
        self.disc_offsets = tuple(disc_offsets)
        self.horizon = horizon
        self.hazard_threshold = hazard_threshold
        self._scorer: ArcSweepScorer | None = None
        self.tables_built = 0

    def scorer(self, geometry: MapGeometry) -> ArcSweepScorer:
        """The scorer for ``geometry``, building its tables if it is new."""
        if self._scorer is None or self._scorer.tables.geometry != geometry:
            p = self.parameters
            tables = build_sweep_tables(
                self.arcs, geometry, radius=p.VehicleRadius, step=p.CurveMakingConst,
                near_zone=p.NearZone, far_zone=p.FarZone, map_frame=self.map_frame,
                disc_offsets=self.disc_offsets, horizon=self.horizon,
                margin=p.HazardMargin)
            self._scorer = ArcSweepScorer(tables, p, hazard_threshold=self.hazard_threshold)
            self.tables_built += 1
        return self._scorer

    def score(self, geometry: MapGeometry, hazard: NDArray[Any],
              goodness: NDArray[Any]) -> SweepScores:
        """Score one map given as geometry and layers (see :meth:`ArcSweepScorer.score`)."""
        return self.scorer(geometry).score(hazard, goodness)

    def score_map(self, trav_map: Any) -> SweepScores:
        """Score an ``EtravMapArrayEventIDL`` (its header, ``hazard`` and ``goodness``)."""
        return self.score(MapGeometry.of(trav_map), trav_map.hazard, trav_map.goodness)
