"""The Traversability Map's numerical core: terrain grid → hazard and goodness grids.
Pure numpy: no asyncio, no afa.

Pipeline (all vectorised over the whole grid; a per-cell Python reference lives in the
tests):

1. **Resample** the fine terrain grid (0.2 m) onto the coarse traversability grid
   (0.5 m). The ratio need not be an integer: each fine cell belongs to the coarse
   cell containing its *centre* (floor semantics, so every fine cell goes to exactly
   one coarse cell; at 0.2 → 0.5 m a coarse cell gets 2 or 3 fine cells per axis).
   Per coarse cell: points ``n`` = Σ counts, ``elevation`` = count-weighted mean (the
   mean of all its points), ``min``/``max`` of the fine minima/maxima, ``last_seen`` =
   newest fine time, and the count-weighted *centroid* of the fine cell centres. The
   centroid is where the mean elevation actually sits; the slope fit uses it, so the
   uneven 2-or-3 grouping does not bias slopes (up to 10 % at 0.2/0.5 otherwise).
2. **Step hazard** of a known cell: ``step = max(spread, max over known 8-neighbours
   (elevation - elevation_n), 0)`` where ``spread = max - min - rise``, ``rise`` being
   what the cell's fitted plane (rule 3, at most as steep as the slope limit) climbs
   across the extent of its points (``|g_x|·span_x + |g_y|·span_y``): a 15° ramp
   spreads a cell's points over up to 0.23 m (0.85 m across a diagonal), and a few
   centimetres of relief on top made every other cell of a legal slope a step (the
   2-or-3 grouping alternates the span). Only a neighbourhood that *is* a plane (RMS
   residual under a tenth of a step) lends its gradient: next to a rock the fit tilts
   and the cell keeps its whole spread. The within-cell spread catches a wall inside
   the cell; neighbour differences use mean elevations (not max - min across cells,
   which would read a traversable 19° ramp as a 0.3 m step over a diagonal). The
   *higher* side of a step between cells is marked (a rock's or a trunk's own cells, a
   ledge's or a ditch's lip); the *lower* side only when it lies a step below the
   surrounding ground (the median elevation of the known cells within ``2·r`` cells,
   ``r`` as in 5, each brought to the cell along the ground's *trend*: the mean
   gradient of the planar cells, rule 3, within ``2·r`` cells, no steeper than the
   slope limit; on a 14° slope the ground 2 m downhill lies 0.5 m lower, and is
   neither a pit nor the foot of anything): the foot of a ditch's wall, never the open
   ground in front of a rock (marking both sides grew a 0.6 m trunk into a 2 m
   obstacle, which closed the gaps of a forest; Obstacle Avoidance adds the vehicle's
   own radius). The *top* of a low,
   wide obstacle seen from one side has no lower neighbour in view (its near face is
   in the rim cells, its far side in shadow) and would read as a level plateau; a
   known cell is a step too when it lies within ``r`` cells of a step cell, is
   *bounded* (along some axis each side holds, within ``r`` cells, a cell a step lower
   than the trend explains, or an unknown cell: the ground beyond a ditch's lip runs on
   level towards the vehicle and is not bounded; the ground facing down a slope, with
   the map's edge behind it, is not bounded either), lies a step above the surrounding
   ground (the median as above; its step is that height) and is joined to a step cell
   through such cells (8-connected). A smooth hill's top has no step cell to join. With
   ``StepPercent`` 0 the hazard is binary, 1 when ``step >= T``; with ``StepPercent``
   1 it is graded, ``min(1, step / T)``: the step "as a percentage" of ``Stepheight``
   (which stays in millimetres).
3. **Slope hazard**: a least-squares plane ``z = a·x + b·y + c`` through the known
   cells of the 3×3 neighbourhood (at their centroids) less than a step above or below
   the cell (a step is the step rule's; a fit across it would tilt every plane around
   an obstacle into a slope hazard, the ring the step rule no longer marks), which must
   hold at least three cells not (nearly) on one line (the normal equations'
   determinant in cell units ≥ 0.25); angle = atan(√(a² + b²)); hazard
   ``min(1, angle / limit)``, graded so that the planner's cost rises with slope.
   Cells without a fit get no slope hazard.
4. **Far field** (distance from the cell centre to the vehicle position > ``Farfield``):
   the thresholds are *relaxed*: ``T·Farfieldscale`` and the slope limit
   ``Maxslope·Farfieldslopescale`` (capped at 89.9°). Far data is less accurate
   (grazing incidence, range noise, and orientation error growing with range:
   2° at 8 m is 0.28 m of height), so its spurious step and slope readings must not
   become phantom obstacles; a real obstacle is re-judged with near-field accuracy as
   the vehicle closes in, well before stopping distance. (A scale below 1 tightens.)
5. **Negative obstacles** (with ``StepOn``), over straight lines of up to
   ``r = ceil(hole_reach / g)`` cells either side of a cell along the four axes
   (x, y and both diagonals); ``d_k`` is the distance to cell ``k`` on the line,
   ``s = tan(slope limit)``:

   - *Sunken cell* (known): along some axis both sides have known cells and
     ``min(H+, H-) - elevation >= T`` with ``H = max_k (elevation_k - s·d_k)`` per side:
     ground a step below its banks on both sides even allowing the steepest legal
     slope (a ditch bottom wider than one cell, where the 8-neighbour step sees only
     bottom). On a plane no steeper than the limit ``H <= elevation``: it never fires
     on legal slopes. And the cell lies a step below the *surrounding ground*: the
     median elevation of the known cells within ``2·r`` cells. A ditch's floor lies
     below the ground around the ditch; the gap between two tall obstacles (a gate in a
     wall, two rocks or trunks) lies at the ground's own level and is not sunken (without
     this a 3 m gate in a wall was a sunken line across the gate). A ditch wider than
     the window is mostly floor and keeps its marked lips (the step rule's higher side)
     and holes.
   - *Walled pit* (known): along some axis each side holds, within ``r`` cells, a wall
     (a step cell or a hole), and the cell lies a step below the surrounding ground (as
     above). The legal-slope allowance of the sunken rule is ``s·d``: 0.73 m from a
     bank 2 m away, so the middle of a 1 m deep, 2.5 m wide ditch passed as "reachable
     down a 20° ramp" although the cells between are its flat floor and its wall. A
     ramp has no step cell; a ditch's lips are steps and its unseen parts holes.
   - *Hole* (unknown cell): along some axis, let ``b±`` be the nearest known cell on
     each side (both must exist), ``t`` the *trend*, the flatter of their fitted
     slopes (tan, at most the limit's), ``bank = elevation(b) - t·d_b`` on each side
     that holds no step cell (step >= T) within reach, and ``L = min_k (min_k + t·d_k)``
     the deepest evidence on either side. The cell is a hole when
     ``max(bank+, bank-) - L >= T``: a gap in the data with level ground on one side
     and a point a step lower across it than the terrain's own gradient explains.
     This catches a ditch seen from afar (the grazing laser sees only the upper part
     of its far wall, 0.5 m of a 1 m ditch at 8 m) and the unseen foot of a
     down-ledge. Why the trend and not the slope limit: a 20° ramp could "explain"
     0.5 m over the 2 m to that far wall, but level ground on both sides does not
     unseeingly dip 14°. Why a side with a step is no bank: the unseen shadow behind
     a rock has the rock's top as its nearest cell, which would read as a drop to the
     ground beyond; but that side also holds the rock's face (a step cell), while a
     ditch's lip or a ledge's top is level ground back to the vehicle. The cell
     becomes hazard 1 with goodness ``inferred_goodness ×`` the best goodness along its
     lines. Unknown cells without such evidence stay NaN (unknown, never free).
   - *Hole rim*: a known cell next to a hole (8-neighbours) whose fine cells are
     mostly (over half) without points joins the hole (hazard 1, and the goodness of
     the best hole next to it): it was seen only along an edge, like the lip strip of a
     cell that lies mostly over the ditch beyond an invisible near wall. (Its own
     goodness, small as it is, could not replace in the Global Map the "free" reading
     of that same edge taken before the hole was inferred.) A cell exactly half seen
     stays as seen: joining those too made the ditch crossing's ditch look longer at
     its north end than it is, and the planner went round its far end (1.76× the
     shortest course instead of 1.07×).
   - Known limitations: a shadow longer than ``hole_reach`` behind an obstacle whose
     face lies beyond reach of the shadow's far end can still read as a hole (against
     an obstacle that is impassable anyway); a ditch with a step (a rock, a kerb)
     within reach of its lip on every line is not marked from that lip; a ditch
     wider than ``2·hole_reach`` keeps an unknown middle, enclosed by its marked rim.
6. **Goodness** ``= (1 - exp(-n / goodness_points)) · f · exp(-age / goodness_time) · a``:
   how much data (n points, and the fraction ``f`` of the cell's fine cells that hold
   them: a cell seen along one edge, such as the lip of a ditch, says little about the
   rest of it), how recent (age = now - last seen; 1 if unknown), and how
   accurate (``a = min(1, 1 / Farfieldscale)`` in the far field, else 1). Unknown
   cells have goodness 0. The Global Map compares goodness to decide which
   observation of a cell to keep.

Hazard: the maximum of the enabled rules, in 0..1 (0 easy, 1 untraversable), NaN =
unknown; unknown cells are never free.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from components.terrain_map.grid import GridGeometry, TerrainLayers

__all__ = [
    "HazardRules",
    "CoarseCells",
    "TraversabilityLayers",
    "TraversabilityMapper",
    "LastSeenTracker",
    "resample",
    "compute_hazards",
    "FLAG_STEP",
    "FLAG_SLOPE",
    "FLAG_SUNKEN",
    "FLAG_HOLE",
    "FLAG_FAR",
    "AXES",
    "MIN_PLANE_DETERMINANT",
]

FloatArray = NDArray[np.float64]
#: The ground's trend: its gradient (m/m) along x and y at every cell (:func:`_trend`).
Trend = tuple[FloatArray, FloatArray]

#: Flag bits in :attr:`TraversabilityLayers.flags`: which rule reached hazard 1.
FLAG_STEP = 1
FLAG_SLOPE = 2
FLAG_SUNKEN = 4
FLAG_HOLE = 8
#: The cell lies in the far field (thresholds relaxed).
FLAG_FAR = 16

#: The four line directions of the negative-obstacle rules, in cells (di, dj).
AXES = ((1, 0), (0, 1), (1, 1), (1, -1))

#: Smallest determinant (cell units) of the plane fit's normal equations: rejects
#: fewer than three cells and three nearly collinear ones.
MIN_PLANE_DETERMINANT = 0.25


class _TraverseParameters(Protocol):
    StepOn: int
    SlopeOn: int
    StepPercent: int
    Stepheight: float
    Maxslope: float
    Farfield: float
    Farfieldscale: float
    Farfieldslopescale: float


@dataclass(frozen=True)
class HazardRules:
    """Hazard settings in SI units (metres, degrees, seconds).

    The first eight mirror Table A.7 (``from_parameters`` converts millimetres); the
    rest are afa additions the seed does not name:

    - ``hole_reach``: how far (m) the negative-obstacle rules look either side of a
      cell: the widest ditch whose unseen middle is still marked;
    - ``goodness_points``: points for goodness 0.63 from quantity (1 - 1/e);
    - ``goodness_time``: seconds for data to age to 1/e (pose drift makes old data
      less accurate);
    - ``inferred_goodness``: goodness factor of a hole marked from its surroundings;
    - ``min_points``: cells with fewer points count as unknown.

    Raises ValueError for values outside their ranges.
    """

    step_on: bool = True
    slope_on: bool = True
    step_percent: bool = False
    step_height: float = 0.3
    max_slope: float = 20.0
    far_field: float = 8.0
    far_field_scale: float = 1.5
    far_field_slope_scale: float = 1.5
    hole_reach: float = 2.0
    goodness_points: float = 5.0
    goodness_time: float = 30.0
    inferred_goodness: float = 0.5
    min_points: int = 1

    def __post_init__(self) -> None:
        positive = ("step_height", "far_field_scale", "far_field_slope_scale",
                    "goodness_points", "goodness_time")
        for name in positive:
            if not getattr(self, name) > 0:
                raise ValueError(f"HazardRules.{name} must be > 0")
        if not 0 < self.max_slope < 90:
            raise ValueError("HazardRules.max_slope must lie in (0, 90) degrees")
        if not (self.far_field >= 0 and self.hole_reach >= 0):
            raise ValueError("HazardRules.far_field and hole_reach must be >= 0")
        if not 0 <= self.inferred_goodness <= 1:
            raise ValueError("HazardRules.inferred_goodness must lie in 0..1")
        if self.min_points < 1:
            raise ValueError("HazardRules.min_points must be >= 1")

    @classmethod
    def from_parameters(cls, parameters: _TraverseParameters, **extra: Any) -> HazardRules:
        """From Table A.7 parameters (e.g. a ``TraversabilityMapParameters``); ``extra``
        sets the afa additions."""
        return cls(step_on=bool(parameters.StepOn), slope_on=bool(parameters.SlopeOn),
                   step_percent=bool(parameters.StepPercent),
                   step_height=parameters.Stepheight / 1000.0,
                   max_slope=parameters.Maxslope, far_field=parameters.Farfield / 1000.0,
                   far_field_scale=parameters.Farfieldscale,
                   far_field_slope_scale=parameters.Farfieldslopescale, **extra)

    @property
    def far_slope(self) -> float:
        """The far-field slope limit (deg)."""
        return min(self.max_slope * self.far_field_slope_scale, 89.9)

    @property
    def far_accuracy(self) -> float:
        """Goodness factor of far-field data."""
        return min(1.0, 1.0 / self.far_field_scale)


# --- resampling ------------------------------------------------------------------------


@dataclass(frozen=True)
class CoarseCells:
    """A terrain grid resampled onto the traversability grid (see the module doc).

    ``count`` is int64; ``elevation``, ``min_height``, ``max_height`` are float64, NaN
    where ``count`` is 0; ``last_seen`` NaN where unknown; ``offset_x``/``offset_y``
    are the centroid's offset (m) from the cell's nominal centre (0 where unknown);
    ``fine_known``/``fine_total`` count the fine cells with points / all fine cells
    assigned to each coarse cell; ``span_x``/``span_y`` (m) are the extent of its fine
    cells with points along x and y (0 where none): how far apart its points can lie.
    """

    geometry: GridGeometry
    count: NDArray[np.int64]
    elevation: FloatArray
    min_height: FloatArray
    max_height: FloatArray
    last_seen: FloatArray
    offset_x: FloatArray
    offset_y: FloatArray
    fine_known: NDArray[np.int64]
    fine_total: NDArray[np.int64]
    span_x: FloatArray
    span_y: FloatArray


class _Resampler:
    """Fine-to-coarse cell assignment for one pair of geometries (reused while they
    stay put)."""

    def __init__(self, fine: GridGeometry, coarse: GridGeometry) -> None:
        x, y = fine.centres()
        ci = np.floor((x - coarse.origin_x) / coarse.gridsize).ravel()
        cj = np.floor((y - coarse.origin_y) / coarse.gridsize).ravel()
        inside = (ci >= 0) & (ci < coarse.rows) & (cj >= 0) & (cj < coarse.cols)
        self.fine_index = np.flatnonzero(inside)
        i, j = ci[inside].astype(np.intp), cj[inside].astype(np.intp)
        self.coarse_index = i * coarse.cols + j
        cx, cy = coarse.cell_center(i, j)
        self.dx = x.ravel()[inside] - cx
        self.dy = y.ravel()[inside] - cy
        self.coarse = coarse
        self.fine_size = fine.gridsize
        self.fine_total = np.bincount(self.coarse_index, minlength=coarse.size)

    def __call__(self, terrain: TerrainLayers) -> CoarseCells:
        geo = self.coarse
        n = geo.size
        count = terrain.count.ravel().take(self.fine_index).astype(np.int64)
        known = count > 0
        idx = self.coarse_index[known]
        w = count[known].astype(np.float64)
        elev = terrain.elevation.ravel().take(self.fine_index)[known].astype(np.float64)
        total = np.bincount(idx, weights=w, minlength=n)
        with np.errstate(invalid="ignore", divide="ignore"):
            elevation = np.bincount(idx, weights=w * elev, minlength=n) / total
            offset_x = np.bincount(idx, weights=w * self.dx[known], minlength=n) / total
            offset_y = np.bincount(idx, weights=w * self.dy[known], minlength=n) / total
        # (ufunc.at leaves its fast path when the value and target dtypes differ: the
        # float32 layers are cast first, or this costs 40x more)
        low = np.full(n, np.inf)
        np.minimum.at(low, idx, terrain.min_height.ravel().take(self.fine_index)[known]
                      .astype(np.float64))
        high = np.full(n, -np.inf)
        np.maximum.at(high, idx, terrain.max_height.ravel().take(self.fine_index)[known]
                      .astype(np.float64))
        seen = np.full(n, -np.inf)
        if terrain.last_seen is not None:
            fine_seen = terrain.last_seen.ravel().take(self.fine_index)[known]
            np.maximum.at(seen, idx, np.where(np.isnan(fine_seen), -np.inf, fine_seen))
        spans = []
        for offsets in (self.dx[known], self.dy[known]):
            least = np.full(n, np.inf)
            np.minimum.at(least, idx, offsets)
            most = np.full(n, -np.inf)
            np.maximum.at(most, idx, offsets)
            with np.errstate(invalid="ignore"):
                spans.append(np.where(np.isfinite(least), most - least + self.fine_size, 0.0))
        points = total.astype(np.int64)
        empty = points == 0
        for array in (elevation, low, high):
            array[empty] = np.nan
        offset_x[empty] = 0.0
        offset_y[empty] = 0.0
        seen[~np.isfinite(seen)] = np.nan
        shape = geo.shape
        return CoarseCells(geo, points.reshape(shape), elevation.reshape(shape),
                           low.reshape(shape), high.reshape(shape), seen.reshape(shape),
                           offset_x.reshape(shape), offset_y.reshape(shape),
                           np.bincount(idx, minlength=n).reshape(shape),
                           self.fine_total.reshape(shape), spans[0].reshape(shape),
                           spans[1].reshape(shape))


def resample(terrain: TerrainLayers, coarse: GridGeometry) -> CoarseCells:
    """Resample ``terrain`` (any cell size) onto ``coarse`` (same map frame)."""
    return _Resampler(terrain.geometry, coarse)(terrain)


# --- hazards ---------------------------------------------------------------------------


@dataclass(frozen=True)
class TraversabilityLayers:
    """The traversability grid and what it was made from.

    ``hazard`` float32 0..1, NaN = unknown; ``goodness`` float32 0..1 (0 where
    unknown); ``step`` (m) and ``slope`` (deg) float32, NaN where not measured;
    ``flags`` uint8 of ``FLAG_*`` bits; ``count`` int32 points behind each cell.
    """

    geometry: GridGeometry
    hazard: NDArray[np.float32]
    goodness: NDArray[np.float32]
    step: NDArray[np.float32]
    slope: NDArray[np.float32]
    flags: NDArray[np.uint8]
    count: NDArray[np.int32]


def _padded(values: NDArray[Any], pad: int, fill: float | bool) -> NDArray[Any]:
    out = np.full((values.shape[0] + 2 * pad, values.shape[1] + 2 * pad), fill,
                  dtype=values.dtype)
    out[pad:pad + values.shape[0], pad:pad + values.shape[1]] = values
    return out


def _stacked(padded: NDArray[Any], pad: int, offsets: list[tuple[int, int]],
             shape: tuple[int, int]) -> NDArray[Any]:
    """``(len(offsets), rows, cols)``: layer m is the grid shifted so that cell [i, j]
    holds the value of cell [i + di_m, j + dj_m] (the padding's fill beyond the
    edge)."""
    rows, cols = shape
    return np.stack([padded[pad + di:pad + di + rows, pad + dj:pad + dj + cols]
                     for di, dj in offsets])


def _line(padded: NDArray[Any], pad: int, di: int, dj: int, reach: int,
          shape: tuple[int, int]) -> NDArray[Any]:
    """A read-only strided *view* ``(reach, rows, cols)``: layer ``k - 1`` is the grid
    shifted so that cell [i, j] holds cell [i + k·di, j + k·dj], k = 1..reach. The
    padding (``pad >= reach``) keeps every access inside ``padded``."""
    s0, s1 = padded.strides
    base = padded[pad + di:, pad + dj:]
    view: NDArray[Any] = np.lib.stride_tricks.as_strided(
        base, shape=(reach, *shape), strides=(di * s0 + dj * s1, s0, s1), writeable=False)
    return view


#: A neighbourhood is a plane (its gradient explains a cell's spread) when its cells'
#: RMS residual from the fit is under this fraction of a step (3 cm at 0.3 m): ground
#: relief fits that well, the edge of a rock partly in a cell does not (at a sixth, 5 cm,
#: the rock field's scripted drive lost 3 of its 56 rock cells).
PLANAR_RESIDUAL = 0.1

#: The eight neighbours and the 3x3 neighbourhood, as (di, dj) offsets.
NEIGHBOURS = [(di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj]
NEIGHBOURHOOD = [(di, dj) for di in (-1, 0, 1) for dj in (-1, 0, 1)]


def compute_hazards(cells: CoarseCells, rules: HazardRules, vehicle_xy: tuple[float, float],
                    now: float) -> TraversabilityLayers:
    """Hazard and goodness of every cell of ``cells`` (see the module doc).

    ``vehicle_xy`` is the vehicle position in the map frame (for the far field), ``now``
    the map time (s, for goodness). Raises ValueError for a non-finite position.
    """
    if not all(math.isfinite(v) for v in vehicle_xy):
        raise ValueError("vehicle position must be finite")
    geo = cells.geometry
    rows, cols = geo.shape
    g = geo.gridsize
    known = cells.count >= rules.min_points
    elev = np.where(known, cells.elevation, np.nan)
    low = np.where(known, cells.min_height, np.nan)
    high = np.where(known, cells.max_height, np.nan)

    cx, cy = geo.centres()
    far = np.hypot(cx - vehicle_xy[0], cy - vehicle_xy[1]) > rules.far_field
    threshold = np.where(far, rules.step_height * rules.far_field_scale, rules.step_height)
    limit = np.where(far, rules.far_slope, rules.max_slope)
    tan_limit = np.tan(np.radians(limit))

    reach = math.ceil(rules.hole_reach / g - 1e-9)  # cells of hole_reach (module doc, 5)

    # --- slope (first: the step rule takes the ground's own rise out of a cell's spread)
    slope, gradient_x, gradient_y = _plane_slopes(elev, cells.offset_x, cells.offset_y, g,
                                                  known, threshold)
    with np.errstate(invalid="ignore"):
        slope_hazard = np.minimum(slope / limit, 1.0)
        slope_full = slope >= limit
    # the rise of the fitted plane across a cell's points, at most a legal slope's
    with np.errstate(invalid="ignore", divide="ignore"):
        steepness = np.hypot(gradient_x, gradient_y)
        legal = np.where(steepness > tan_limit, tan_limit / steepness, 1.0)
        rise = np.nan_to_num(legal * (np.abs(gradient_x) * cells.span_x
                                      + np.abs(gradient_y) * cells.span_y))
    # the ground's trend, taken out where a cell is compared with the ground around it
    trend = _trend(gradient_x, gradient_y, tan_limit, 2 * reach)

    # --- step: only the higher side of a step is marked (see the module doc)
    around = _stacked(_padded(elev, 1, np.nan), 1, NEIGHBOURS, (rows, cols))
    differences = elev - around
    differences[np.isnan(differences)] = 0.0  # unknown neighbours add nothing
    upper = np.maximum(differences.max(axis=0), 0.0)  # a step above a neighbour
    lower = np.maximum(-differences.min(axis=0), 0.0)  # a step below a neighbour
    with np.errstate(invalid="ignore"):
        in_pit = _below_surroundings(known & (lower >= threshold), elev, threshold, 2 * reach,
                                     trend, g)
    spread = np.maximum(high - low - rise, 0.0)  # what the ground's slope does not explain
    step = np.where(known, np.maximum(spread, np.where(in_pit, np.maximum(upper, lower),
                                                       upper)), np.nan)
    with np.errstate(invalid="ignore"):
        step_full = known & (step >= threshold)
    if reach >= 1:  # the top of a low, wide obstacle: no lower neighbour in view
        top, above = _raised_tops(elev, known, step_full, threshold, reach, trend, g)
        step = np.where(top, np.maximum(step, above), step)
        step_full |= top
    if rules.step_percent:
        step_hazard = np.minimum(step / threshold, 1.0)
    else:
        step_hazard = np.where(step_full, 1.0, 0.0)

    # --- negative obstacles
    goodness = _goodness(cells, rules, known, far, now)
    sunken = np.zeros((rows, cols), dtype=bool)
    hole = np.zeros((rows, cols), dtype=bool)
    hole_goodness = np.zeros((rows, cols))
    if rules.step_on and reach >= 1:
        sunken, hole, hole_goodness = _negative_obstacles(
            elev, low, goodness, known, step_full, slope, tan_limit, threshold, g, reach, trend)
        sunken |= _walled_pits(known, step_full | hole, elev, threshold, reach, trend, g)

    hazard = np.zeros((rows, cols))
    if rules.step_on:
        np.maximum(hazard, step_hazard, out=hazard, where=known)
        hazard[sunken] = 1.0
    if rules.slope_on:
        np.fmax(hazard, slope_hazard, out=hazard, where=known)
    hazard[~known] = np.nan
    hazard[hole] = 1.0
    goodness = np.where(hole, rules.inferred_goodness * hole_goodness, goodness)
    if hole.any():  # the hole's rim: cells mostly unseen, seen along an edge
        beside = _stacked(_padded(hole, 1, False), 1, NEIGHBOURHOOD, (rows, cols)).any(axis=0)
        rim = known & beside & (2 * cells.fine_known < cells.fine_total)
        hazard[rim] = 1.0
        joined = _stacked(_padded(np.where(hole, goodness, 0.0), 1, 0.0), 1, NEIGHBOURHOOD,
                          (rows, cols)).max(axis=0)  # the goodness of the hole it joins
        goodness = np.where(rim, joined, goodness)
        hole |= rim

    flags = np.where(far, FLAG_FAR, 0).astype(np.uint8)
    if rules.step_on:
        flags |= np.where(step_full, FLAG_STEP, 0).astype(np.uint8)
        flags |= np.where(sunken, FLAG_SUNKEN, 0).astype(np.uint8)
        flags |= np.where(hole, FLAG_HOLE, 0).astype(np.uint8)
    if rules.slope_on:
        flags |= np.where(slope_full, FLAG_SLOPE, 0).astype(np.uint8)
    return TraversabilityLayers(
        geometry=geo, hazard=hazard.astype(np.float32), goodness=goodness.astype(np.float32),
        step=step.astype(np.float32), slope=slope.astype(np.float32), flags=flags,
        count=cells.count.astype(np.int32))


def _goodness(cells: CoarseCells, rules: HazardRules, known: NDArray[np.bool_],
              far: NDArray[np.bool_], now: float) -> FloatArray:
    quantity = 1.0 - np.exp(-cells.count / rules.goodness_points)
    with np.errstate(invalid="ignore", divide="ignore"):  # a cell seen in part
        quantity *= np.where(cells.fine_total > 0, cells.fine_known / cells.fine_total, 0.0)
    age = np.where(np.isnan(cells.last_seen), 0.0, np.maximum(now - cells.last_seen, 0.0))
    recency = np.exp(-age / rules.goodness_time)
    accuracy = np.where(far, rules.far_accuracy, 1.0)
    result: FloatArray = np.where(known, quantity * recency * accuracy, 0.0)
    return result


def _plane_slopes(elev: FloatArray, offset_x: FloatArray, offset_y: FloatArray, g: float,
                  known: NDArray[np.bool_], step: FloatArray
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Slope angle (deg) of the least-squares plane through the known cells of each
    known cell's 3x3 neighbourhood that lie less than a ``step`` above or below it (NaN
    where unknown or degenerate), and the plane's gradient along x and y (m/m) where
    the cells fit it within :data:`PLANAR_RESIDUAL` of a step RMS (NaN elsewhere)."""
    shape = elev.shape
    centre = np.where(known, elev, 0.0)
    z = _stacked(_padded(elev, 1, np.nan), 1, NEIGHBOURHOOD, shape) - centre  # relative
    with np.errstate(invalid="ignore"):
        w = np.abs(z) < step  # NaN (unknown) compares False
    di = np.array([d[0] for d in NEIGHBOURHOOD], dtype=np.float64)[:, None, None]
    dj = np.array([d[1] for d in NEIGHBOURHOOD], dtype=np.float64)[:, None, None]
    # positions in cells, centroid-corrected; unknown cells weigh nothing
    x = np.where(w, di + _stacked(_padded(offset_x / g, 1, 0.0), 1, NEIGHBOURHOOD, shape), 0.0)
    y = np.where(w, dj + _stacked(_padded(offset_y / g, 1, 0.0), 1, NEIGHBOURHOOD, shape), 0.0)
    z = np.where(w, z, 0.0)
    n = w.sum(axis=0, dtype=np.float64)
    sx, sy, sz = x.sum(axis=0), y.sum(axis=0), z.sum(axis=0)
    sxx, sxy, syy = (x * x).sum(axis=0), (x * y).sum(axis=0), (y * y).sum(axis=0)
    sxz, syz = (x * z).sum(axis=0), (y * z).sum(axis=0)
    # Cramer's rule on [[sxx sxy sx] [sxy syy sy] [sx sy n]] (a, b, c) = (sxz, syz, sz)
    m00 = syy * n - sy * sy
    m01 = sxy * n - sy * sx
    m02 = sxy * sy - syy * sx
    det = sxx * m00 - sxy * m01 + sx * m02
    ok = known & (det >= MIN_PLANE_DETERMINANT)
    safe = np.where(ok, det, 1.0)
    a = (sxz * m00 - sxy * (syz * n - sy * sz) + sx * (syz * sy - syy * sz)) / safe
    b = (sxx * (syz * n - sz * sy) - sxz * m01 + sx * (sxy * sz - syz * sx)) / safe
    slope = np.degrees(np.arctan(np.hypot(a, b) / g))  # per cell → per metre
    c = (sz - a * sx - b * sy) / np.where(n > 0, n, 1.0)
    residual = np.sqrt((np.where(w, z - a * x - b * y - c, 0.0) ** 2).sum(axis=0)
                       / np.where(n > 0, n, 1.0))
    # the gradient only where the neighbourhood is a plane (a rock's edge tilts the fit)
    planar = ok & (residual < PLANAR_RESIDUAL * step)
    return (np.where(ok, slope, np.nan), np.where(planar, a / g, np.nan),
            np.where(planar, b / g, np.nan))


def _negative_obstacles(elev: FloatArray, low: FloatArray, goodness: FloatArray,
                        known: NDArray[np.bool_], stepped: NDArray[np.bool_],
                        slope: FloatArray, tan_limit: FloatArray, threshold: FloatArray,
                        g: float, reach: int, ground: Trend
                        ) -> tuple[NDArray[np.bool_], NDArray[np.bool_], FloatArray]:
    """Sunken known cells, holes (unknown cells across a drop) and each hole's best
    bounding goodness; see the module doc. ``ground`` is the ground's trend
    (:func:`_trend`), for the sunken cells' surroundings."""
    shape = elev.shape
    fitted = np.tan(np.radians(slope))
    padded = {
        "elev": _padded(elev, reach, np.nan),
        "low": _padded(low, reach, np.nan),
        "good": _padded(goodness, reach, 0.0),
        "known": _padded(known, reach, False),
        "step": _padded(stepped, reach, False),
        "tan": _padded(np.where(np.isnan(fitted), np.inf, fitted), reach, np.inf),
    }
    unknown = ~known
    sunken = np.zeros(shape, dtype=bool)
    hole = np.zeros(shape, dtype=bool)
    hole_goodness = np.zeros(shape)
    steps = np.arange(1, reach + 1, dtype=np.float64)[:, None, None]  # k
    rows_index, cols_index = np.indices(shape)
    for di, dj in AXES:
        ramp = steps * (math.hypot(di, dj) * g)  # (reach, 1, 1): distance d_k
        sides = [{name: _line(values, reach, sign * di, sign * dj, reach, shape)
                  for name, values in padded.items()} for sign in (1, -1)]
        # sunken: the highest bank a legal slope allows, each side (fmax skips NaN)
        highs = [np.fmax.reduce(side["elev"] - tan_limit * ramp, axis=0) for side in sides]
        both = ~np.isnan(highs[0]) & ~np.isnan(highs[1])
        with np.errstate(invalid="ignore"):
            sunken |= known & both & (np.minimum(highs[0], highs[1]) - elev >= threshold)
        # holes: the nearest known cell each side
        nearest = []
        for side in sides:
            first = side["known"].argmax(axis=0)  # nearest known (0 when none: masked)
            at = (first, rows_index, cols_index)
            nearest.append((side["known"].any(axis=0), side["elev"][at], ramp[first, 0, 0],
                            side["tan"][at], side["step"].any(axis=0)))
        (f1, b1, d1, t1, s1), (f2, b2, d2, t2, s2) = nearest
        trend = np.minimum(np.minimum(t1, t2), tan_limit)
        deepest = np.fmin(np.fmin.reduce(sides[0]["low"] + trend * ramp, axis=0),
                          np.fmin.reduce(sides[1]["low"] + trend * ramp, axis=0))
        best = np.maximum(sides[0]["good"].max(axis=0), sides[1]["good"].max(axis=0))
        bank1 = np.where(s1, -np.inf, b1 - trend * d1)  # a side with a face is no bank
        bank2 = np.where(s2, -np.inf, b2 - trend * d2)
        with np.errstate(invalid="ignore"):
            drop = unknown & f1 & f2 & (np.fmax(bank1, bank2) - deepest >= threshold)
        hole |= drop
        np.maximum(hole_goodness, np.where(drop, best, 0.0), out=hole_goodness)
    return (_below_surroundings(sunken, elev, threshold, 2 * reach, ground, g), hole,
            hole_goodness)


def _walled_pits(candidates: NDArray[np.bool_], walls: NDArray[np.bool_], elev: FloatArray,
                 threshold: FloatArray, reach: int, trend: Trend, g: float
                 ) -> NDArray[np.bool_]:
    """The candidates with, along some axis, a wall (a step cell or a hole) within
    ``reach`` cells on each side, lying a step below the surrounding ground
    (:func:`_below_surroundings`): the floor of a ditch between its lips (module doc,
    5)."""
    shape = elev.shape
    padded = _padded(walls, reach, False)
    enclosed = np.zeros(shape, dtype=bool)
    for di, dj in AXES:
        both = candidates.copy()
        for sign in (1, -1):
            both &= _line(padded, reach, sign * di, sign * dj, reach, shape).any(axis=0)
        enclosed |= both
    return _below_surroundings(enclosed, elev, threshold, 2 * reach, trend, g)


def _trend(gradient_x: FloatArray, gradient_y: FloatArray, tan_limit: FloatArray,
           radius: int) -> Trend:
    """The ground's trend around each cell (m/m along x and y): the mean gradient of the
    planar cells within ``radius`` cells (0 where there are none), no steeper than a
    legal slope. The rules that compare a cell with the ground around it (a raised top,
    a pit, a sunken cell) take it out: on a 14° slope the ground 2 m downhill lies 0.5 m
    lower, which is neither a ditch below nor an obstacle's top above."""
    size = 2 * radius + 1
    planar = np.isfinite(gradient_x) & np.isfinite(gradient_y)
    count = ndimage.uniform_filter(planar.astype(np.float64), size, mode="constant")
    mean_x = ndimage.uniform_filter(np.where(planar, gradient_x, 0.0), size, mode="constant")
    mean_y = ndimage.uniform_filter(np.where(planar, gradient_y, 0.0), size, mode="constant")
    some = count > 0.5 / size ** 2  # at least one planar cell (uniform_filter's rounding)
    with np.errstate(invalid="ignore", divide="ignore"):
        tx = np.where(some, mean_x / count, 0.0)
        ty = np.where(some, mean_y / count, 0.0)
        steepness = np.hypot(tx, ty)
        legal = np.where(steepness > tan_limit, tan_limit / steepness, 1.0)
    return tx * legal, ty * legal


def _below_surroundings(candidates: NDArray[np.bool_], elev: FloatArray,
                        threshold: FloatArray, radius: int, trend: Trend, g: float
                        ) -> NDArray[np.bool_]:
    """The candidates (known cells) lying a step (``threshold``) or more below the
    median elevation of the known cells within ``radius`` cells (a square window
    clipped at the grid's edge), the ground's trend taken out: below the level of the
    ground around them, in a pit or a ditch (module doc)."""
    size = 2 * radius + 1  # only a cell with a known one a step above can pass (cheap)
    highest = ndimage.maximum_filter(np.where(np.isnan(elev), -np.inf, elev), size,
                                     mode="constant", cval=-np.inf)
    with np.errstate(invalid="ignore"):
        candidates = candidates & (highest - elev >= threshold)
        below: NDArray[np.bool_] = candidates & (
            -_above_surroundings(candidates, elev, radius, trend, g) >= threshold)
    return below


def _above_surroundings(candidates: NDArray[np.bool_], elev: FloatArray,
                        radius: int, trend: Trend, g: float) -> FloatArray:
    """How far each candidate (a known cell) lies above the median elevation of the
    known cells within ``radius`` cells (a square window clipped at the grid's edge),
    each taken along the candidate's ground trend to the candidate (on a legal slope
    the ground ahead is lower and behind higher, and neither is an obstacle), the level
    of the ground around it; NaN elsewhere."""
    result = np.full(elev.shape, np.nan)
    where = np.argwhere(candidates)
    if len(where) == 0:
        return result
    size = 2 * radius + 1
    windows = np.lib.stride_tricks.sliding_window_view(_padded(elev, radius, np.nan),
                                                       (size, size))
    i, j = where[:, 0], where[:, 1]
    offsets = (np.arange(size, dtype=np.float64) - radius) * g
    levelled = (windows[i, j] - trend[0][i, j][:, None, None] * offsets[None, :, None]
                - trend[1][i, j][:, None, None] * offsets[None, None, :])
    result[i, j] = elev[i, j] - _nan_medians(levelled.reshape(len(where), -1))
    return result


def _nan_medians(rows: FloatArray) -> FloatArray:
    """The median of the non-NaN values of each row (the mean of the two middle ones
    for an even count; NaN for none): ``np.nanmedian(rows, axis=1)``, without its
    masked-array path, which costs a millisecond a call on these small rows."""
    ordered = np.sort(rows, axis=1)  # NaN sorts last
    n = np.count_nonzero(~np.isnan(rows), axis=1)
    index = np.arange(len(rows))
    low = ordered[index, np.maximum(n - 1, 0) // 2]
    high = ordered[index, np.maximum(n, 1) // 2 - (n == 0)]
    medians: FloatArray = np.where(n > 0, (low + high) / 2, np.nan)
    return medians


def _raised_tops(elev: FloatArray, known: NDArray[np.bool_], stepped: NDArray[np.bool_],
                 threshold: FloatArray, reach: int, trend: Trend, g: float
                 ) -> tuple[NDArray[np.bool_], FloatArray]:
    """The tops of obstacles that the step rule cannot see (module doc, 2): known cells
    without a step of their own, within ``reach`` cells of a step cell, *bounded* (along
    some axis each side holds, within ``reach``, a cell a step lower than the ground's
    trend explains, or an unknown one),
    lying a step above the surrounding ground (:func:`_above_surroundings` over
    ``2·reach``), and joined to a step cell through such cells (8-connected). Returns
    the tops and their height above the surroundings (NaN elsewhere)."""
    shape = elev.shape
    none = np.zeros(shape, dtype=bool)
    ring = np.ones((3, 3), dtype=bool)
    near = known & ~stepped & ndimage.binary_dilation(stepped, ring, iterations=reach)
    if not near.any():
        return none, np.full(shape, np.nan)
    padded_elev = _padded(elev, reach, np.nan)
    padded_known = _padded(known, reach, False)
    bounded = none.copy()
    steps = np.arange(1, reach + 1, dtype=np.float64)[:, None, None] * g  # k·g
    for di, dj in AXES:
        closed = near.copy()
        for sign in (1, -1):
            heights = _line(padded_elev, reach, sign * di, sign * dj, reach, shape)
            seen = _line(padded_known, reach, sign * di, sign * dj, reach, shape)
            expected = sign * steps * (di * trend[0] + dj * trend[1])  # the trend's rise
            with np.errstate(invalid="ignore"):
                closed &= (~seen | (heights - expected <= elev - threshold)).any(axis=0)
        bounded |= closed
    size = 4 * reach + 1  # only a cell with a known one a step below can pass (cheap)
    lowest = ndimage.minimum_filter(np.where(np.isnan(elev), np.inf, elev), size,
                                    mode="constant", cval=np.inf)
    with np.errstate(invalid="ignore"):
        bounded &= elev - lowest >= threshold
    above = _above_surroundings(bounded, elev, 2 * reach, trend, g)
    with np.errstate(invalid="ignore"):
        raised = bounded & (above >= threshold)
    labels, _ = ndimage.label(raised | stepped, ring)
    joined = np.unique(labels[stepped])
    tops: NDArray[np.bool_] = raised & np.isin(labels, joined[joined > 0])
    return tops, above


class TraversabilityMapper:
    """Turns terrain layers into traversability layers, reusing the fine-to-coarse
    assignment while the two grids stay put (it is rebuilt when either moves)."""

    def __init__(self, rules: HazardRules) -> None:
        self.rules = rules
        self._resampler: _Resampler | None = None
        self._key: tuple[GridGeometry, GridGeometry] | None = None

    def resample(self, terrain: TerrainLayers, geometry: GridGeometry) -> CoarseCells:
        """:func:`resample`, cached per pair of geometries."""
        key = (terrain.geometry, geometry)
        if self._resampler is None or key != self._key:
            self._resampler = _Resampler(terrain.geometry, geometry)
            self._key = key
        return self._resampler(terrain)

    def update(self, terrain: TerrainLayers, geometry: GridGeometry,
               vehicle_xy: tuple[float, float], now: float) -> TraversabilityLayers:
        """The traversability grid ``geometry`` (same map frame as ``terrain``) with
        the vehicle at ``vehicle_xy`` at time ``now``."""
        return compute_hazards(self.resample(terrain, geometry), self.rules, vehicle_xy, now)


class LastSeenTracker:
    """Per-cell "last seen" times for terrain maps that carry none.

    The IDL's terrain events hold point counts but no times; a cell whose count
    changed since the previous event (after aligning a whole-cell scroll) and is
    non-zero was seen at the new event's time. Cells present in the first event, or
    scrolled in, are taken as seen at that event's time (their true age is unknown).
    """

    def __init__(self) -> None:
        self._geometry: GridGeometry | None = None
        self._count: NDArray[np.int64] | None = None
        self._seen: FloatArray | None = None

    def update(self, geometry: GridGeometry, count: NDArray[Any], time: float) -> FloatArray:
        """The last-seen times (rows, cols) after an event of ``count`` at ``time``; NaN
        where the count is 0."""
        count = np.asarray(count, dtype=np.int64)
        previous = self._aligned_previous(geometry)
        if previous is None:
            seen = np.where(count > 0, time, np.nan)
        else:
            old_count, old_seen = previous
            changed = (count != old_count) | np.isnan(old_seen)
            seen = np.where(count > 0, np.where(changed, time, old_seen), np.nan)
        self._geometry, self._count, self._seen = geometry, count.copy(), seen
        return seen.copy()

    def _aligned_previous(self, geometry: GridGeometry
                          ) -> tuple[NDArray[np.int64], FloatArray] | None:
        old = self._geometry
        if old is None or self._count is None or self._seen is None:
            return None
        if old.gridsize != geometry.gridsize or old.shape != geometry.shape:
            return None
        di = (geometry.origin_x - old.origin_x) / geometry.gridsize
        dj = (geometry.origin_y - old.origin_y) / geometry.gridsize
        si, sj = round(di), round(dj)
        if abs(di - si) > 1e-6 or abs(dj - sj) > 1e-6:
            return None
        rows, cols = geometry.shape
        count = np.zeros((rows, cols), dtype=np.int64)
        seen = np.full((rows, cols), np.nan)
        if abs(si) < rows and abs(sj) < cols:
            dst = (slice(max(0, -si), rows - max(0, si)), slice(max(0, -sj), cols - max(0, sj)))
            src = (slice(max(0, si), rows - max(0, -si)), slice(max(0, sj), cols - max(0, -sj)))
            count[dst] = self._count[src]
            seen[dst] = self._seen[src]
        return count, seen
