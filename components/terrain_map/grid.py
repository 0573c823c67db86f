"""The Terrain Map's numerical core: 2.5-D accumulator grids, the ego view, pose
interpolation and audit, and stereo/laser balancing. Pure numpy: no asyncio, no afa.

Grid convention (``idl.maps``): cell ``[i, j]`` covers map-frame x in
``[originX + i·g, originX + (i+1)·g)`` and y in ``[originY + j·g, originY + (j+1)·g)``;
rows run along +x, columns along +y. A point's cell is
``floor((x - originX) / g), floor((y - originY) / g)`` computed in float64, exactly as
:meth:`GridGeometry.cell_index` and :meth:`idl.maps._MapHeader.cell_index` do.

What lives here, and why:

- :class:`TerrainGrid` — the *global* terrain grid: north-up (frame ``World``),
  preallocated flat float64 accumulators per cell (count, Σz, Σz², min z, max z, time
  last seen). :meth:`TerrainGrid.fuse` bins a batch of map-frame points with
  ``np.add.at`` / ``np.minimum.at`` / ``np.maximum.at``, which apply the updates
  one point at a time in input order, so the result equals a per-point Python loop
  bit for bit. A cell's min and max cover only its recent points when the grid has
  a *window* (see :class:`TerrainGrid`): the extremes of noise that wanders grow with
  the time a cell is watched, and would read as a step under a parked vehicle.
  :meth:`TerrainGrid.recentre` scrolls the grid with the vehicle by whole cells:
  cells that stay inside keep their accumulators exactly, the exposed strips are
  cleared, nothing is ever interpolated. Origins are whole multiples of the cell
  size (``originX = kx·g``), so a world cell keeps one identity while it stays mapped.
- :class:`EgoView` — the *ego* map (frame ``Raptor:Front-BumperCenter``, heading-aligned)
  is a nearest-cell *view* of the global grid, re-sampled at each publication from
  the vehicle pose; see its docstring for the reasons.
- :func:`ego_map_pose` — ^W T_M of the ego map: gravity-aligned, yaw of the ground
  frame, origin on the ground ``BumperHeight`` below the bumper.
- :class:`PoseBuffer` and :class:`PoseAudit` — the world-from-vehicle transform at a
  scan's time stamp (linear translation, slerp rotation), "too old" / "future"
  reporting, and the Table A.6 plausibility audit (``MaxVelocity``, ``PoseInterval``,
  ``OrientationDevError``).
- :class:`StereoBalance` — the ``StereoPeriod`` rule that keeps a stereo frame from
  swamping the lasers' scan lines.

Variance. Σz and Σz² are float64; the variance ``Σz²/n - (Σz/n)²`` is clamped at 0.
Its absolute error is about ``n·ε·max z²`` in the worst case (ε = 2.2e-16): for map
heights within ±100 m of the world origin (the Pose's ``initialUTM`` keeps heights
small) and 10⁴ points in one cell, under 3e-8 m², far below any surface variance worth
reporting. Accumulating in float32 (ε = 6e-8) would lose centimetres of standard
deviation at those heights, so the accumulators are never float32; only the published
layers are.
"""

from __future__ import annotations

import bisect
import enum
import math
from collections import Counter, deque
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from afa.kernels import compiled

__all__ = [
    "GridGeometry",
    "TerrainLayers",
    "FuseStats",
    "TerrainGrid",
    "shift_cells",
    "transform_points",
    "SMALL_BATCH",
    "CHUNK",
    "EgoView",
    "ego_map_pose",
    "yaw_of",
    "PoseStatus",
    "PoseLookup",
    "PoseAudit",
    "AuditResult",
    "PoseBuffer",
    "interpolate_transform",
    "rotation_angle",
    "StereoBalance",
]

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


# --- geometry --------------------------------------------------------------------------


@dataclass(frozen=True)
class GridGeometry:
    """Placement of a grid in its map frame: ``rows`` × ``cols`` cells of edge
    ``gridsize`` metres, row 0's outer edge at map x ``origin_x``, column 0's at map y
    ``origin_y`` (the IDL's ``originX``/``originY``).

    Raises ValueError for a non-positive or non-finite size or origin.
    """

    origin_x: float
    origin_y: float
    gridsize: float
    rows: int
    cols: int

    def __post_init__(self) -> None:
        if not (math.isfinite(self.gridsize) and self.gridsize > 0):
            raise ValueError(f"gridsize must be finite and > 0, got {self.gridsize}")
        if self.rows < 1 or self.cols < 1:
            raise ValueError(f"a grid needs at least one cell, got {self.rows}x{self.cols}")
        if not (math.isfinite(self.origin_x) and math.isfinite(self.origin_y)):
            raise ValueError("grid origin must be finite")

    @classmethod
    def centred(cls, centre_x: float, centre_y: float, depth: float, width: float,
                gridsize: float) -> GridGeometry:
        """A grid ``depth`` m along x and ``width`` m along y (whole cells, rounded to
        the nearest count), its origin a whole multiple of ``gridsize`` and the cell
        holding (centre_x, centre_y) at row ``rows // 2``, column ``cols // 2``."""
        rows = max(1, int(round(depth / gridsize)))
        cols = max(1, int(round(width / gridsize)))
        kx, ky = centred_origin_index(centre_x, centre_y, gridsize, rows, cols)
        return cls(kx * gridsize, ky * gridsize, gridsize, rows, cols)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols)."""
        return (self.rows, self.cols)

    @property
    def size(self) -> int:
        """Number of cells."""
        return self.rows * self.cols

    def cell_index(self, x: ArrayLike, y: ArrayLike) -> tuple[IntArray, IntArray]:
        """Cells ``(i, j)`` holding map-frame points (floor semantics; may lie outside
        the grid). Raises ValueError for non-finite coordinates."""
        fx = np.floor((np.asarray(x, dtype=np.float64) - self.origin_x) / self.gridsize)
        fy = np.floor((np.asarray(y, dtype=np.float64) - self.origin_y) / self.gridsize)
        if not (np.all(np.isfinite(fx)) and np.all(np.isfinite(fy))):
            raise ValueError("cell_index needs finite coordinates")
        return fx.astype(np.intp), fy.astype(np.intp)

    def cell_center(self, i: ArrayLike, j: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Map-frame (x, y) of the centres of cells ``[i, j]``."""
        ii = np.asarray(i, dtype=np.float64)
        jj = np.asarray(j, dtype=np.float64)
        return (self.origin_x + (ii + 0.5) * self.gridsize,
                self.origin_y + (jj + 0.5) * self.gridsize)

    def centres(self) -> tuple[FloatArray, FloatArray]:
        """(rows, cols) arrays of the map-frame x and y of every cell centre."""
        x, y = self.cell_center(np.arange(self.rows)[:, None], np.arange(self.cols)[None, :])
        return np.broadcast_to(x, self.shape), np.broadcast_to(y, self.shape)

    def contains(self, i: ArrayLike, j: ArrayLike) -> NDArray[np.bool_]:
        """Whether cells ``[i, j]`` lie inside the grid."""
        ii, jj = np.asarray(i), np.asarray(j)
        result: NDArray[np.bool_] = (ii >= 0) & (ii < self.rows) & (jj >= 0) & (jj < self.cols)
        return result


def centred_origin_index(centre_x: float, centre_y: float, gridsize: float, rows: int,
                         cols: int) -> tuple[int, int]:
    """Origin indices (kx, ky) that put the cell holding (centre_x, centre_y) at
    ``[rows // 2, cols // 2]``, with origins ``kx·g``, ``ky·g``."""
    if not (math.isfinite(centre_x) and math.isfinite(centre_y)):
        raise ValueError("centre must be finite")
    return (math.floor(centre_x / gridsize) - rows // 2,
            math.floor(centre_y / gridsize) - cols // 2)


# --- layers ----------------------------------------------------------------------------


@dataclass(frozen=True)
class TerrainLayers:
    """Derived terrain layers of a grid (the IDL's ``_TerrainArray`` fields, plus the
    time each cell last received a point).

    ``elevation`` (mean height), ``min_height``, ``max_height``, ``variance`` are NaN
    where ``count`` is 0; ``last_seen`` is NaN for cells never seen, and may be None
    when unknown (a terrain map received as an IDL event carries no per-cell time).
    """

    geometry: GridGeometry
    elevation: NDArray[np.floating[Any]]
    min_height: NDArray[np.floating[Any]]
    max_height: NDArray[np.floating[Any]]
    count: NDArray[np.integer[Any]]
    variance: NDArray[np.floating[Any]]
    last_seen: NDArray[np.float64] | None = None

    def known(self) -> NDArray[np.bool_]:
        """Cells with at least one point."""
        result: NDArray[np.bool_] = self.count > 0
        return result


@dataclass(frozen=True)
class FuseStats:
    """What one :meth:`TerrainGrid.fuse` call did with its points."""

    fused: int
    outside: int
    nonfinite: int

    @property
    def total(self) -> int:
        """Points offered."""
        return self.fused + self.outside + self.nonfinite


#: Points fused per pass: a large batch goes through in chunks of this size, in order,
#: reusing preallocated scratch arrays (fresh multi-megabyte temporaries per call cost
#: page faults; chunks also stay in cache).
CHUNK = 32768


def _load_fuse_kernel() -> Any:
    """The compiled :meth:`TerrainGrid._fuse_chunk` (decision 0014), or None for the numpy
    form (:func:`afa.kernels.compiled`)."""
    return compiled("components.terrain_map._jit", "fuse_kernel")


#: The compiled fusion in use, None when the numpy form fuses.
FUSE_KERNEL: Any = _load_fuse_kernel()

#: Batches up to this many points are transformed with one matrix product; larger
#: ones column by column (BLAS is slow for an (n, 3) x (3, 3) product, and its threads
#: contend with everything else on a small machine).
SMALL_BATCH = 4096


def transform_points(transform: ArrayLike, points: ArrayLike) -> FloatArray:
    """Points ``(n, 3)`` mapped by the 4x4 homogeneous ``transform`` (``R p + t``), in
    float64. Deterministic for a given batch size: up to :data:`SMALL_BATCH` points use
    one matrix product, more use explicit column arithmetic (the Python expression
    ``R[r,0]·x + R[r,1]·y + R[r,2]·z + t[r]``, exactly); the two may differ in the last
    bit. Raises ValueError for bad shapes."""
    t = np.asarray(transform, dtype=np.float64)
    p = np.asarray(points)
    if t.shape != (4, 4):
        raise ValueError(f"transform must be 4x4, got {t.shape}")
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {p.shape}")
    return _transform(t, p, columns=p.shape[0] > SMALL_BATCH)


def _transform(t: FloatArray, points: NDArray[Any], *, columns: bool,
               result: FloatArray | None = None, scratch: FloatArray | None = None
               ) -> FloatArray:
    """transform_points' arithmetic; the column path writes into ``result`` (3, n) and
    ``scratch`` (n,) when given (float64 ``points`` expected there). Non-finite points
    give non-finite results without a warning (``inf · 0`` is NaN): fusion drops them."""
    p = points.astype(np.float64, copy=False)
    with np.errstate(invalid="ignore", over="ignore"):
        if not columns:
            out: FloatArray = p @ np.ascontiguousarray(t[:3, :3].T)
            out += t[:3, 3]
            return out
        n = p.shape[0]
        if result is None or scratch is None:
            result, scratch = np.empty((3, n)), np.empty(n)
        x, y, z = p[:, 0], p[:, 1], p[:, 2]
        for r in range(3):
            row = result[r]
            np.multiply(x, t[r, 0], out=row)
            np.multiply(y, t[r, 1], out=scratch)
            row += scratch
            np.multiply(z, t[r, 2], out=scratch)
            row += scratch
            row += t[r, 3]
    transposed: FloatArray = result.T
    return transposed


class TerrainGrid:
    """A preallocated 2.5-D accumulator grid (see the module doc).

    Accumulators are flat float64/int64 arrays of ``rows·cols`` cells (``count``,
    ``sum_z``, ``sum_z2``, ``last_seen``, and the extremes of the generations below);
    :meth:`layers` derives the published layers. Empty cells hold count 0, sums 0,
    minima +inf, maxima -inf and last_seen -inf, so fusion needs no special case for
    them.

    **Generations** (``window`` seconds; decision 0040). A cell's points fall into
    generations: a point opens a new one when it comes ``window`` seconds or more after
    the start (first point) of the cell's current generation. ``gen_min``, ``gen_max``
    and ``gen_start`` hold the current generation's extremes and start, ``prev_min`` and
    ``prev_max`` the extremes of the one before; ``min_z`` and ``max_z`` are the extremes
    of both, so they cover a cell's latest ``window`` to ``2·window`` seconds of
    observation, however long it has been watched; a cell nobody sees keeps its
    extremes for ever. Count, sums and ``last_seen`` cover every point. The default
    ``window`` (infinite) keeps a single generation: extremes over every point.
    """

    def __init__(self, geometry: GridGeometry, *, window: float = math.inf) -> None:
        if not window > 0:
            raise ValueError(f"window must be > 0 s, got {window}")
        self._geometry = geometry
        self.window = float(window)
        n = geometry.size
        self.count = np.zeros(n, dtype=np.int64)
        self.sum_z = np.zeros(n, dtype=np.float64)
        self.sum_z2 = np.zeros(n, dtype=np.float64)
        self.last_seen = np.full(n, -np.inf, dtype=np.float64)
        self.prev_min = np.full(n, np.inf, dtype=np.float64)
        self.prev_max = np.full(n, -np.inf, dtype=np.float64)
        self.gen_min = np.full(n, np.inf, dtype=np.float64)
        self.gen_max = np.full(n, -np.inf, dtype=np.float64)
        self.gen_start = np.full(n, -np.inf, dtype=np.float64)
        self._newest = -math.inf  # newest time ever fused (an upper bound of last_seen)
        # scratch for one chunk of points, reused by every fuse
        self._fi, self._fj, self._low, self._z = (np.empty(CHUNK) for _ in range(4))
        self._flat = np.empty(CHUNK, dtype=np.intp)
        self._inside = np.empty(CHUNK, dtype=bool)
        self._test = np.empty(CHUNK, dtype=bool)
        self._points = np.empty((CHUNK, 3))
        self._rows = np.empty((3, CHUNK))
        #: Points fused, dropped outside the grid, dropped as non-finite, since creation.
        self.fused_total = 0
        self.outside_total = 0
        self.nonfinite_total = 0

    @classmethod
    def centred(cls, centre_x: float, centre_y: float, depth: float, width: float,
                gridsize: float, *, window: float = math.inf) -> TerrainGrid:
        """A grid of ``depth`` × ``width`` metres centred on (centre_x, centre_y); see
        :meth:`GridGeometry.centred`."""
        return cls(GridGeometry.centred(centre_x, centre_y, depth, width, gridsize),
                   window=window)

    @property
    def geometry(self) -> GridGeometry:
        """The grid's current placement (changes on :meth:`recentre`)."""
        return self._geometry

    @property
    def min_z(self) -> FloatArray:
        """Each cell's least height over its last two generations (+inf where empty)."""
        result: FloatArray = np.minimum(self.prev_min, self.gen_min)
        return result

    @property
    def max_z(self) -> FloatArray:
        """Each cell's greatest height over its last two generations (-inf where empty)."""
        result: FloatArray = np.maximum(self.prev_max, self.gen_max)
        return result

    def _accumulators(self) -> tuple[NDArray[Any], ...]:
        return (self.count, self.sum_z, self.sum_z2, self.last_seen, self.prev_min,
                self.prev_max, self.gen_min, self.gen_max, self.gen_start)

    _EMPTY = (0, 0.0, 0.0, -np.inf, np.inf, -np.inf, np.inf, -np.inf, -np.inf)

    def reset(self) -> None:
        """Forget every point, in place (no allocation)."""
        for array, empty in zip(self._accumulators(), self._EMPTY, strict=True):
            array.fill(empty)

    # ------------------------------------------------------------------ fusion
    def fuse(self, points: ArrayLike, time: float) -> FuseStats:
        """Add map-frame points ``(n, 3)`` seen at ``time`` (s).

        Points with a non-finite coordinate are dropped and counted as ``nonfinite``;
        points whose cell lies outside the grid are dropped and counted as
        ``outside``. Equal, bit for bit, to adding each remaining point in input
        order with Python floats (see the module doc); large batches go through in
        order, :data:`CHUNK` points at a time, which keeps that order. Raises
        ValueError for a bad shape or a non-finite ``time``.
        """
        p = np.asarray(points)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"points must have shape (n, 3), got {p.shape}")
        if not math.isfinite(time):
            raise ValueError("time must be finite")
        n = p.shape[0]
        fused = nonfinite = 0
        for start in range(0, n, CHUNK):
            f, bad = self._fuse_chunk(self._float64(p[start:start + CHUNK]), time)
            fused += f
            nonfinite += bad
        outside = n - fused - nonfinite
        self.fused_total += fused
        self.outside_total += outside
        self.nonfinite_total += nonfinite
        return FuseStats(fused=fused, outside=outside, nonfinite=nonfinite)

    def _float64(self, chunk: NDArray[Any]) -> NDArray[np.float64]:
        """A chunk as float64, copied into scratch if needed: ufuncs on float32 input
        compute in float32, even into a float64 output."""
        if chunk.dtype == np.float64:
            return chunk
        out = self._points[:chunk.shape[0]]
        np.copyto(out, chunk)
        return out

    def _fuse_chunk(self, p: NDArray[np.float64], time: float) -> tuple[int, int]:
        """Fuse up to CHUNK float64 points through the scratch buffers; returns
        (fused, nonfinite)."""
        n = p.shape[0]
        geo = self._geometry
        if FUSE_KERNEL is not None:  # the same, compiled: one loop over the points
            assign = time >= self._newest
            fused, nonfinite = FUSE_KERNEL(
                np.ascontiguousarray(p), float(geo.origin_x), float(geo.origin_y),
                float(geo.gridsize), int(geo.rows), int(geo.cols), float(time), assign,
                self.window, self.count, self.sum_z, self.sum_z2, self.last_seen,
                self.prev_min, self.prev_max, self.gen_min, self.gen_max, self.gen_start)
            if fused and assign:
                self._newest = time
            return int(fused), int(nonfinite)
        fi, fj, low, z = (self._fi[:n], self._fj[:n], self._low[:n], self._z[:n])
        inside, test = self._inside[:n], self._test[:n]
        np.copyto(z, p[:, 2])  # contiguous: ufunc.at is ~2x faster than on a strided column
        # Cell coordinates as floats: NaN and ±inf fail every comparison below, so the
        # bounds mask drops them before anything is cast to an integer. (A finite
        # coordinate near 1e308 may overflow to inf here: it is outside either way.)
        with np.errstate(over="ignore", invalid="ignore"):
            np.subtract(p[:, 0], geo.origin_x, out=fi)
            fi /= geo.gridsize
            np.subtract(p[:, 1], geo.origin_y, out=fj)
            fj /= geo.gridsize
        np.floor(fi, out=fi)
        np.floor(fj, out=fj)
        np.greater_equal(np.minimum(fi, fj, out=low), 0, out=inside)  # NaN: False
        inside &= np.less(fi, geo.rows, out=test)
        inside &= np.less(fj, geo.cols, out=test)
        inside &= np.isfinite(z, out=test)
        fused = int(np.count_nonzero(inside))
        if fused == n:  # the common case: nothing to compress
            nonfinite = 0
            fi *= geo.cols
            fi += fj
            flat = self._flat[:n]
            np.copyto(flat, fi, casting="unsafe")  # whole non-negative values: exact
            zs = z
        else:
            finite = np.isfinite(p[:, 0])
            finite &= np.isfinite(p[:, 1])
            finite &= np.isfinite(z)
            nonfinite = n - int(np.count_nonzero(finite))
            cells = fi[inside]
            cells *= geo.cols
            cells += fj[inside]
            flat = cells.astype(np.intp)
            zs = z[inside]
        if fused:
            np.add.at(self.count, flat, 1)
            np.add.at(self.sum_z, flat, zs)
            np.add.at(self.sum_z2, flat, np.multiply(zs, zs, out=low[:fused]))
            # A cell opens a new generation at its first point here when its current one
            # began `window` or more before `time`: the one before is then dropped, the
            # current one becomes the one before.
            opening = flat[time - self.gen_start.take(flat) >= self.window]
            if opening.size:
                self.prev_min[opening] = self.gen_min[opening]
                self.prev_max[opening] = self.gen_max[opening]
                self.gen_min[opening] = np.inf
                self.gen_max[opening] = -np.inf
                self.gen_start[opening] = time
            np.minimum.at(self.gen_min, flat, zs)
            np.maximum.at(self.gen_max, flat, zs)
            if time >= self._newest:  # every stored time is older: plain assignment
                self.last_seen[flat] = time
                self._newest = time
            else:  # a late batch must not make a cell look older than it is
                np.maximum.at(self.last_seen, flat, time)
        return fused, nonfinite

    def fuse_transformed(self, points: ArrayLike, map_from_sensor: ArrayLike,
                         time: float) -> FuseStats:
        """``fuse(transform_points(map_from_sensor, points), time)``, exactly, chunk by
        chunk (no full-size temporaries). Compose ^M T_V · ^V T_S once per scan, not
        per point. Raises ValueError as both do."""
        t = np.asarray(map_from_sensor, dtype=np.float64)
        p = np.asarray(points)
        if t.shape != (4, 4):
            raise ValueError(f"transform must be 4x4, got {t.shape}")
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f"points must have shape (n, 3), got {p.shape}")
        if not math.isfinite(time):
            raise ValueError("time must be finite")
        columns = p.shape[0] > SMALL_BATCH  # the path transform_points takes for them all
        fused = nonfinite = 0
        for start in range(0, p.shape[0], CHUNK):
            chunk = self._float64(p[start:start + CHUNK])
            m = chunk.shape[0]
            f, bad = self._fuse_chunk(_transform(t, chunk, columns=columns,
                                                 result=self._rows[:, :m],
                                                 scratch=self._low[:m]), time)
            fused += f
            nonfinite += bad
        outside = p.shape[0] - fused - nonfinite
        self.fused_total += fused
        self.outside_total += outside
        self.nonfinite_total += nonfinite
        return FuseStats(fused=fused, outside=outside, nonfinite=nonfinite)

    # ------------------------------------------------------------------ scrolling
    def recentre(self, x: float, y: float, *, slack: int = 0) -> tuple[int, int]:
        """Scroll so that the cell holding map point (x, y) sits at the centre cell.

        Scrolls by whole cells only, and only when the point has drifted more than
        ``slack`` cells from the centre along either axis (0: every cell crossed).
        Cells that stay inside keep their accumulators exactly; the exposed strips
        are cleared. Returns the shift (di, dj) in cells applied to the origin (0, 0
        if none). Raises ValueError for a non-finite point, or if the grid's origin is
        not a whole number of cells (build it with :meth:`centred`).
        """
        geo = self._geometry
        kx0 = round(geo.origin_x / geo.gridsize)
        ky0 = round(geo.origin_y / geo.gridsize)
        if (abs(geo.origin_x - kx0 * geo.gridsize) > 1e-9 * geo.gridsize
                or abs(geo.origin_y - ky0 * geo.gridsize) > 1e-9 * geo.gridsize):
            raise ValueError("recentre needs an origin on whole cells (GridGeometry.centred)")
        kx, ky = centred_origin_index(x, y, geo.gridsize, geo.rows, geo.cols)
        di, dj = kx - kx0, ky - ky0
        if abs(di) <= slack and abs(dj) <= slack:
            return (0, 0)
        self._shift(di, dj)
        self._geometry = GridGeometry(kx * geo.gridsize, ky * geo.gridsize, geo.gridsize,
                                      geo.rows, geo.cols)
        return (di, dj)

    def _shift(self, di: int, dj: int) -> None:
        """Move contents so that new cell [i, j] holds old cell [i + di, j + dj]."""
        shape = self._geometry.shape
        for array, empty in zip(self._accumulators(), self._EMPTY, strict=True):
            shift_cells(array.reshape(shape), di, dj, empty)

    # ------------------------------------------------------------------ layers
    def layers(self) -> TerrainLayers:
        """The derived layers as fresh (rows, cols) arrays: float32 heights and
        variance (NaN where empty), int32 counts, float64 ``last_seen`` (NaN where
        never seen)."""
        rows, cols = self._geometry.shape
        count = self.count
        known = count > 0
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = self.sum_z / count
            variance = self.sum_z2 / count - mean * mean
        np.maximum(variance, 0.0, out=variance)
        variance[~known] = np.nan
        mean[~known] = np.nan
        low = np.where(known, self.min_z, np.nan)
        high = np.where(known, self.max_z, np.nan)
        seen = np.where(np.isfinite(self.last_seen), self.last_seen, np.nan)
        return TerrainLayers(
            geometry=self._geometry,
            elevation=mean.astype(np.float32).reshape(rows, cols),
            min_height=low.astype(np.float32).reshape(rows, cols),
            max_height=high.astype(np.float32).reshape(rows, cols),
            count=count.astype(np.int32).reshape(rows, cols),
            variance=variance.astype(np.float32).reshape(rows, cols),
            last_seen=seen.reshape(rows, cols))


def shift_cells(grid: NDArray[Any], di: int, dj: int, empty: Any) -> None:
    """Move a (rows, cols) layer in place so that cell [i, j] holds what cell
    [i + di, j + dj] held; cells with no source get ``empty``."""
    rows, cols = grid.shape
    if abs(di) >= rows or abs(dj) >= cols:
        grid.fill(empty)
        return
    dst_i, src_i = _overlap(di, rows)
    dst_j, src_j = _overlap(dj, cols)
    # numpy buffers overlapping copies, so this is a safe in-place move
    grid[dst_i, dst_j] = grid[src_i, src_j]
    if di:
        grid[slice(rows - di, rows) if di > 0 else slice(0, -di), :] = empty
    if dj:
        grid[:, slice(cols - dj, cols) if dj > 0 else slice(0, -dj)] = empty


def _overlap(shift: int, n: int) -> tuple[slice, slice]:
    """Destination and source slices of a shift by ``shift`` cells along an axis of n."""
    if shift >= 0:
        return slice(0, n - shift), slice(shift, n)
    return slice(-shift, n), slice(0, n + shift)


# --- the ego map -----------------------------------------------------------------------


def yaw_of(transform: ArrayLike) -> float:
    """Heading (rad, counter-clockwise about z from map x) of a transform's x axis
    projected onto the horizontal plane."""
    t = np.asarray(transform, dtype=np.float64)
    return math.atan2(float(t[1, 0]), float(t[0, 0]))


def ego_map_pose(world_from_vehicle: ArrayLike, vehicle_from_ground_frame: ArrayLike,
                 bumper_height: float) -> FloatArray:
    """^W T_M of the ego map: gravity-aligned, rotated about z by the yaw of the
    ground frame (``GroundFrame``, e.g. ``Raptor:Front-BumperCenter``), its origin on
    the ground: ``bumper_height`` metres (Table A.6 ``BumperHeight``/1000, -0.5) along
    the ground frame's own z from its origin (the vehicle stands on the ground, so a
    pitched vehicle's ground lies along its own z, not the world's).

    Heights in the ego map are then heights above that ground point: level ground
    under the bumper reads 0.
    """
    wg = np.asarray(world_from_vehicle, dtype=np.float64) @ np.asarray(
        vehicle_from_ground_frame, dtype=np.float64)
    origin = wg[:3, 3] + wg[:3, 2] * bumper_height
    yaw = yaw_of(wg)
    c, s = math.cos(yaw), math.sin(yaw)
    pose = np.eye(4)
    pose[:2, :2] = [[c, -s], [s, c]]
    pose[:3, 3] = origin
    return pose


class EgoView:
    """The egocentric terrain map as a nearest-cell view of the global grid.

    Why a view and not a second accumulator: the seed's ego map is what the terrain
    looks like "from the front bumper", and the bumper moves while the ground does
    not. An accumulator in the vehicle frame would have to be re-registered at every
    pose change, i.e. resampled into itself, blurring it a little more each time and
    forgetting whatever fell off its edge. Sampling the world-fixed grid at
    publication time touches each published cell once (16 m × 16 m at 0.2 m: 6,400
    cells, well under a millisecond), never feeds back into the data, and keeps both
    maps consistent.

    Sampling: each ego cell takes every layer of the global cell containing its
    centre (nearest cell, no interpolation, so counts, minima and maxima stay real
    measurements); heights are shifted into the ego frame (``z - origin z``). With equal
    cell sizes a rotated grid repeats some global cells and skips others; that
    aliasing is bounded by one cell (0.2 m) and needs no extra data.

    Default placement: rows ahead of the bumper ground point from x = 0 (the bumper
    at the bottom of the seed's local map display), columns centred left-right.
    """

    def __init__(self, geometry: GridGeometry) -> None:
        self.geometry = geometry
        x, y = geometry.centres()
        self._cx = np.ascontiguousarray(x).ravel()
        self._cy = np.ascontiguousarray(y).ravel()

    @classmethod
    def ahead(cls, depth: float, width: float, gridsize: float,
              behind: float = 0.0) -> EgoView:
        """An ego view ``depth`` m ahead (plus ``behind`` m behind the origin) and
        ``width`` m across, centred left-right."""
        rows = int(round((depth + behind) / gridsize))
        cols = int(round(width / gridsize))
        return cls(GridGeometry(-behind, -cols * gridsize / 2.0, gridsize, rows, cols))

    def sample(self, grid: TerrainGrid, world_from_map: ArrayLike) -> TerrainLayers:
        """The ego layers for ego map pose ``world_from_map`` (^W T_M, as from
        :func:`ego_map_pose`; only its yaw and translation are used)."""
        pose = np.asarray(world_from_map, dtype=np.float64)
        c, s = pose[0, 0], pose[1, 0]
        norm = math.hypot(c, s)
        c, s = c / norm, s / norm
        tx, ty, tz = pose[:3, 3]
        geo = grid.geometry
        wx = tx + c * self._cx - s * self._cy
        wy = ty + s * self._cx + c * self._cy
        fi = np.floor((wx - geo.origin_x) / geo.gridsize)
        fj = np.floor((wy - geo.origin_y) / geo.gridsize)
        inside = (fi >= 0) & (fi < geo.rows) & (fj >= 0) & (fj < geo.cols)
        flat = np.where(inside, fi * geo.cols + fj, 0).astype(np.intp)
        count = np.where(inside, grid.count.take(flat), 0)
        known = count > 0
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = grid.sum_z.take(flat) / count
            variance = grid.sum_z2.take(flat) / count - mean * mean
        np.maximum(variance, 0.0, out=variance)
        nan = np.nan
        seen = np.where(inside, grid.last_seen.take(flat), -np.inf)
        shape = self.geometry.shape
        return TerrainLayers(
            geometry=self.geometry,
            elevation=np.where(known, mean - tz, nan).astype(np.float32).reshape(shape),
            min_height=np.where(known, grid.min_z.take(flat) - tz, nan)
            .astype(np.float32).reshape(shape),
            max_height=np.where(known, grid.max_z.take(flat) - tz, nan)
            .astype(np.float32).reshape(shape),
            count=count.astype(np.int32).reshape(shape),
            variance=np.where(known, variance, nan).astype(np.float32).reshape(shape),
            last_seen=np.where(np.isfinite(seen), seen, nan).reshape(shape))


# --- poses -----------------------------------------------------------------------------


class PoseStatus(enum.Enum):
    """Outcome of a :meth:`PoseBuffer.lookup`."""

    OK = "ok"                    #: interpolated (or exact) transform available
    EMPTY = "empty"              #: no pose received yet
    TOO_OLD = "too old"          #: older than the oldest pose held
    FUTURE = "future"            #: newer than the newest pose: wait for the next one
    IMPLAUSIBLE = "implausible"  #: bracketed by a pose change the audit rejected


@dataclass(frozen=True)
class PoseLookup:
    """A lookup's status and, when ``status`` is OK, the 4x4 world-from-vehicle
    transform at the requested time."""

    status: PoseStatus
    transform: FloatArray | None = None


class _AuditParameters(Protocol):
    MaxVelocity: float
    PoseInterval: float
    OrientationDevError: float


@dataclass(frozen=True)
class AuditResult:
    """One pose change as the audit saw it: distance and rotation angle against the
    allowances."""

    ok: bool
    dt: float
    distance: float
    allowed_distance: float
    angle: float
    allowed_angle: float


@dataclass(frozen=True)
class PoseAudit:
    """Plausibility of a pose change (Table A.6), all SI (m/s, s, rad, rad/s).

    Between poses at t0 and t1 (dt = t1 - t0 > 0) the change is plausible when both

    - translation: ``|p1 - p0| <= max_velocity · (dt + pose_interval)``. The margin of
      one ``PoseInterval`` of travel absorbs a pose stamped up to one update period
      away from the moment it describes (the filter's update granularity);
    - rotation: the geodesic angle of ``R0ᵀ R1`` (yaw, pitch and roll together) is at
      most ``max_turn_rate · (dt + pose_interval) + 2 · orientation_error``: the vehicle's
      fastest plausible rotation over the same widened interval, plus the stated
      orientation error (``OrientationDevError``) of each of the two poses.

    ``max_turn_rate`` is an afa addition (the seed gives no rate): 120 °/s by default,
    above the Raptor's kinematic full-lock yaw rate at MaxVelocity
    (6 m/s · tan 30° / 1.9 m = 104 °/s) and the pitch rate of driving over a bump, so
    only glitches (a GPS heading flip, an IMU reset) are rejected.
    """

    max_velocity: float = 6.0
    pose_interval: float = 0.1
    orientation_error: float = math.radians(2.0)
    max_turn_rate: float = math.radians(120.0)

    @classmethod
    def from_parameters(cls, parameters: _AuditParameters,
                        max_turn_rate_deg: float = 120.0) -> PoseAudit:
        """From Table A.6 parameters (``MaxVelocity`` mm/s, ``PoseInterval`` s,
        ``OrientationDevError`` deg), e.g. a ``TerrainMapParameters``."""
        return cls(max_velocity=parameters.MaxVelocity / 1000.0,
                   pose_interval=parameters.PoseInterval,
                   orientation_error=math.radians(parameters.OrientationDevError),
                   max_turn_rate=math.radians(max_turn_rate_deg))

    def check(self, t0: float, pose0: ArrayLike, t1: float, pose1: ArrayLike) -> AuditResult:
        """Audit the change from (t0, pose0) to (t1, pose1); raises ValueError unless
        t1 > t0."""
        dt = t1 - t0
        if not dt > 0:
            raise ValueError(f"pose times must increase, got {t0} then {t1}")
        a = np.asarray(pose0, dtype=np.float64)
        b = np.asarray(pose1, dtype=np.float64)
        distance = float(np.linalg.norm(b[:3, 3] - a[:3, 3]))
        angle = rotation_angle(a[:3, :3].T @ b[:3, :3])
        widened = dt + self.pose_interval
        allowed_distance = self.max_velocity * widened
        allowed_angle = self.max_turn_rate * widened + 2.0 * self.orientation_error
        return AuditResult(ok=distance <= allowed_distance and angle <= allowed_angle,
                           dt=dt, distance=distance, allowed_distance=allowed_distance,
                           angle=angle, allowed_angle=allowed_angle)


def rotation_angle(rotation: ArrayLike) -> float:
    """Angle (rad, 0..π) of a 3x3 rotation matrix."""
    r = np.asarray(rotation, dtype=np.float64)
    # atan2 of |axis·sinθ| and cosθ: accurate near 0 and π, unlike acos of the trace
    cos_angle = (r[0, 0] + r[1, 1] + r[2, 2] - 1.0) / 2.0
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / 2.0
    return math.atan2(float(np.linalg.norm(axis)), cos_angle)


def _quaternion(r: FloatArray) -> FloatArray:
    """Unit quaternion (w, x, y, z) of a rotation matrix (largest-component method)."""
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    candidates = (trace, r[0, 0], r[1, 1], r[2, 2])
    k = int(np.argmax(candidates))
    if k == 0:
        s = math.sqrt(1.0 + trace) * 2.0
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s,
             (r[1, 0] - r[0, 1]) / s]
    elif k == 1:
        s = math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2.0
        q = [(r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s,
             (r[0, 2] + r[2, 0]) / s]
    elif k == 2:
        s = math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2.0
        q = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s,
             (r[1, 2] + r[2, 1]) / s]
    else:
        s = math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2.0
        q = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s,
             0.25 * s]
    quat = np.array(q)
    result: FloatArray = quat / np.linalg.norm(quat)
    return result


def _rotation_rows(w: float, x: float, y: float, z: float) -> list[list[float]]:
    """The rotation matrix of unit quaternion (w, x, y, z), as rows of Python floats."""
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]


def interpolate_transform(pose0: ArrayLike, pose1: ArrayLike, s: float) -> FloatArray:
    """The 4x4 transform a fraction ``s`` (0..1) of the way from pose0 to pose1:
    translation linear, rotation by spherical linear interpolation (slerp: constant
    angular rate about the fixed axis of ``R0ᵀ R1``, the shorter way round)."""
    a = np.asarray(pose0, dtype=np.float64)
    b = np.asarray(pose1, dtype=np.float64)
    return _interpolate(a, _quaternion(a[:3, :3]), b, _quaternion(b[:3, :3]), s)


def _interpolate(a: FloatArray, q0: FloatArray, b: FloatArray, q1: FloatArray,
                 s: float) -> FloatArray:
    """:func:`interpolate_transform` of poses ``a`` and ``b`` whose rotations' unit
    quaternions (:func:`_quaternion`) are ``q0`` and ``q1``.

    A scan is placed with this once, so it works on Python floats, element by element
    with the operations of the array form (the same IEEE results, without numpy's
    per-call cost on 4-vectors); the two dot products stay numpy's, whose summation
    order is BLAS's."""
    dot = float(q0 @ q1)
    sign = 1.0
    if dot < 0.0:  # q and -q are one rotation: take the shorter arc
        sign, dot = -1.0, -dot
    p0 = q0.tolist()
    p1 = [sign * c for c in q1.tolist()]  # exact: a sign flip
    if dot > 0.9999995:  # under ~0.1°: linear blend is exact to rounding
        q = [c0 + s * (c1 - c0) for c0, c1 in zip(p0, p1, strict=True)]
    else:
        theta = math.acos(dot)
        f0, f1, f = math.sin((1 - s) * theta), math.sin(s * theta), math.sin(theta)
        q = [(f0 * c0 + f1 * c1) / f for c0, c1 in zip(p0, p1, strict=True)]
    quat = np.array(q)
    norm = math.sqrt(float(quat.dot(quat)))  # np.linalg.norm of a vector, exactly
    rows = _rotation_rows(*(c / norm for c in q))
    ta, tb = a[:3, 3].tolist(), b[:3, 3].tolist()
    for row, t0, t1 in zip(rows, ta, tb, strict=True):
        row.append(t0 + s * (t1 - t0))
    rows.append([0.0, 0.0, 0.0, 1.0])
    return np.array(rows)


class PoseBuffer:
    """The latest ``capacity`` world-from-vehicle poses, audited, for looking up the
    vehicle pose at a scan's time stamp.

    :meth:`add` audits each pose against the previous one *received* (not the previous
    accepted one: after a genuine jump, such as a GPS correction, the following poses
    agree with each other again and are fused; only the interval that contains the
    jump is refused). A lookup inside an interval whose closing pose failed the audit
    reports IMPLAUSIBLE, so the scan is counted and not fused. Poses that do not
    advance in time are dropped and counted (``out_of_order``). Lookups older than
    the oldest pose report TOO_OLD; newer than the newest, FUTURE (the caller holds the
    scan until the next pose arrives; nothing is extrapolated).
    """

    def __init__(self, capacity: int = 64, audit: PoseAudit | None = None) -> None:
        if capacity < 2:
            raise ValueError("a pose buffer needs a capacity of at least 2")
        self.audit = audit or PoseAudit()
        self._times: deque[float] = deque(maxlen=capacity)
        self._poses: deque[FloatArray] = deque(maxlen=capacity)
        # each pose's rotation as a quaternion, computed once (a lookup interpolates
        # between two stored poses; scans outnumber poses)
        self._quaternions: deque[FloatArray] = deque(maxlen=capacity)
        self._plausible: deque[bool] = deque(maxlen=capacity)
        self.statistics: Counter[str] = Counter()
        self.last_audit: AuditResult | None = None

    def __len__(self) -> int:
        return len(self._times)

    @property
    def span(self) -> tuple[float, float] | None:
        """(oldest, newest) pose time held, None when empty."""
        return (self._times[0], self._times[-1]) if self._times else None

    def add(self, time: float, world_from_vehicle: ArrayLike) -> bool:
        """Store a pose; returns whether its change from the previous pose passed the
        audit (the first pose always does). Returns False, storing nothing, for a
        pose not newer than the newest. Raises ValueError for a non-finite time or
        transform, or a shape other than 4x4."""
        pose = np.array(world_from_vehicle, dtype=np.float64)
        if pose.shape != (4, 4) or not np.all(np.isfinite(pose)) or not math.isfinite(time):
            raise ValueError("a pose needs a finite time and a finite 4x4 transform")
        if self._times and time <= self._times[-1]:
            self.statistics["out_of_order"] += 1
            return False
        ok = True
        if self._times:
            self.last_audit = self.audit.check(self._times[-1], self._poses[-1], time, pose)
            ok = self.last_audit.ok
        self._times.append(time)
        self._poses.append(pose)
        self._quaternions.append(_quaternion(pose[:3, :3]))
        self._plausible.append(ok)
        self.statistics["accepted" if ok else "implausible"] += 1
        return ok

    def lookup(self, time: float) -> PoseLookup:
        """The pose at ``time`` (see the class doc); counts each outcome in
        ``statistics`` under ``lookup <status>``."""
        result = self._lookup(time)
        self.statistics[f"lookup {result.status.value}"] += 1
        return result

    def _lookup(self, time: float) -> PoseLookup:
        times = self._times
        if not times:
            return PoseLookup(PoseStatus.EMPTY)
        if time < times[0]:
            return PoseLookup(PoseStatus.TOO_OLD)
        if time > times[-1]:
            return PoseLookup(PoseStatus.FUTURE)
        k = bisect.bisect_left(times, time)
        if not self._plausible[k]:
            return PoseLookup(PoseStatus.IMPLAUSIBLE)
        if times[k] == time:
            return PoseLookup(PoseStatus.OK, self._poses[k].copy())
        t0, t1 = times[k - 1], times[k]
        s = (time - t0) / (t1 - t0)
        return PoseLookup(PoseStatus.OK,
                          _interpolate(self._poses[k - 1], self._quaternions[k - 1],
                                       self._poses[k], self._quaternions[k], s))


# --- stereo / laser balance ------------------------------------------------------------


class StereoBalance:
    """Keeps a stereo frame from swamping the lasers (Table A.6 ``StereoPeriod``).

    Rule: a stereo frame stands for ``stereo_period`` seconds of sensing, so it may add
    at most as many points as the lasers delivered in that much time. The laser rate
    is measured over the last ``window`` seconds of laser time stamps (both lasers,
    points actually offered for fusion). A larger frame is decimated by a whole
    stride, ``points[::k]`` with ``k = ceil(n / budget)``, which keeps real points (so
    counts stay integers and min/max/variance stay measurements, unlike
    down-weighting) and costs nothing to fuse. With no laser data in the window (lasers
    off or not yet running) stereo is the only sensor and is kept whole.

    At the defaults (two SICKs, ~37.6 scan lines/s of ≤ 361 points each, StereoPeriod
    0.5 s) the budget is about 13,500 points: an 80x60 depth image is kept whole, a
    320x240 one (76,800 points) keeps every 6th point.
    """

    def __init__(self, stereo_period: float, window: float = 1.0) -> None:
        if not (stereo_period > 0 and window > 0):
            raise ValueError("stereo_period and window must be > 0")
        self.stereo_period = stereo_period
        self.window = window
        self._laser: deque[tuple[float, int]] = deque()
        self._in_window = 0

    def note_laser(self, time: float, points: int) -> None:
        """Record a laser scan of ``points`` points stamped ``time``."""
        self._laser.append((time, points))
        self._in_window += points
        self._expire(time)

    def _expire(self, now: float) -> None:
        while self._laser and self._laser[0][0] <= now - self.window:
            self._in_window -= self._laser.popleft()[1]

    def budget(self, time: float) -> int | None:
        """Most stereo points a frame stamped ``time`` may add; None without laser
        data in the window."""
        self._expire(time)
        if not self._laser:
            return None
        return max(1, round(self._in_window / self.window * self.stereo_period))

    def stride(self, time: float, points: int) -> int:
        """The decimation stride for a stereo frame of ``points`` points (1 = keep all)."""
        budget = self.budget(time)
        if budget is None or points <= budget:
            return 1
        return -(-points // budget)

    def select(self, time: float, points: NDArray[Any]) -> NDArray[Any]:
        """The points of a stereo frame to fuse (a strided view, no copy)."""
        return points[:: self.stride(time, len(points))]
