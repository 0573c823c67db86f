"""Traversability core (components/traversability_map/hazards.py) against a plain
per-cell reference on synthetic terrains: flat, steps, ramps, ditches, a wall, the far
field, and random rough terrain with holes."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from components.terrain_map.grid import GridGeometry, TerrainLayers
from components.traversability_map.hazards import (
    AXES,
    FLAG_FAR,
    FLAG_HOLE,
    FLAG_SLOPE,
    FLAG_STEP,
    FLAG_SUNKEN,
    HazardRules,
    LastSeenTracker,
    TraversabilityLayers,
    TraversabilityMapper,
    resample,
)
from components.traversability_map.parameters import TraversabilityMapParameters

# fine terrain 0.2 m, coarse 0.5 m; x from -4 to 20 m (vehicle at 0, far field beyond 8)
FINE = GridGeometry(-4.0, -6.0, 0.2, 120, 60)
COARSE = GridGeometry(-4.0, -6.0, 0.5, 48, 24)
VEHICLE = (0.0, 0.0)
NOW = 10.0

Height = Callable[[np.ndarray, np.ndarray], np.ndarray]


def terrain_from(height: Height, known: np.ndarray | None = None, *, count: int = 4,
                 seen: float = NOW, lows: Height | None = None,
                 geometry: GridGeometry = FINE) -> TerrainLayers:
    """Fine layers of a height function: elevation at the centre, min/max over nine
    samples inside the cell (±0.45 g), optional deeper minima ``lows``."""
    x, y = geometry.centres()
    g = geometry.gridsize
    samples = np.stack([height(x + a * g, y + b * g) for a in (-0.45, 0.0, 0.45)
                        for b in (-0.45, 0.0, 0.45)])
    low = samples.min(axis=0)
    if lows is not None:
        low = np.minimum(low, lows(x, y))
    mask = np.ones(geometry.shape, bool) if known is None else known
    nan = np.float32(np.nan)
    return TerrainLayers(
        geometry=geometry,
        elevation=np.where(mask, height(x, y), nan).astype(np.float32),
        min_height=np.where(mask, low, nan).astype(np.float32),
        max_height=np.where(mask, samples.max(axis=0), nan).astype(np.float32),
        count=np.where(mask, count, 0).astype(np.int32),
        variance=np.where(mask, 0.0, nan).astype(np.float32),
        last_seen=np.where(mask, seen, np.nan))


# --- the reference ---------------------------------------------------------------------


def reference(terrain: TerrainLayers, coarse: GridGeometry, rules: HazardRules,
              vehicle: tuple[float, float], now: float) -> dict[str, np.ndarray]:
    """Per-cell loops written from the module doc, independently of the code."""
    fine, g = terrain.geometry, coarse.gridsize
    rows, cols = coarse.shape
    acc: dict[tuple[int, int], list[float]] = {}
    fine_cells: dict[tuple[int, int], list[int]] = {}  # [with points, all]
    extents: dict[tuple[int, int], list[float]] = {}  # fine centres with points: x, y range
    for fi in range(fine.rows):
        for fj in range(fine.cols):
            n = int(terrain.count[fi, fj])
            x = fine.origin_x + (fi + 0.5) * fine.gridsize
            y = fine.origin_y + (fj + 0.5) * fine.gridsize
            i = math.floor((x - coarse.origin_x) / g)
            j = math.floor((y - coarse.origin_y) / g)
            if not (0 <= i < rows and 0 <= j < cols):
                continue
            tally = fine_cells.setdefault((i, j), [0, 0])
            tally[1] += 1
            if n == 0:
                continue
            tally[0] += 1
            box = extents.setdefault((i, j), [math.inf, -math.inf, math.inf, -math.inf])
            box[:] = [min(box[0], x), max(box[1], x), min(box[2], y), max(box[3], y)]
            cx, cy = coarse.origin_x + (i + 0.5) * g, coarse.origin_y + (j + 0.5) * g
            a = acc.setdefault((i, j), [0, 0.0, 0.0, 0.0, math.inf, -math.inf, -math.inf])
            a[0] += n
            a[1] += n * float(terrain.elevation[fi, fj])
            a[2] += n * (x - cx)
            a[3] += n * (y - cy)
            a[4] = min(a[4], float(terrain.min_height[fi, fj]))
            a[5] = max(a[5], float(terrain.max_height[fi, fj]))
            if terrain.last_seen is not None and not math.isnan(terrain.last_seen[fi, fj]):
                a[6] = max(a[6], float(terrain.last_seen[fi, fj]))

    def cell(i: int, j: int) -> list[float] | None:
        a = acc.get((i, j))
        return a if a is not None and a[0] >= rules.min_points else None

    def elev(i: int, j: int) -> float:
        a = cell(i, j)
        assert a is not None
        return a[1] / a[0]

    out = {name: np.full((rows, cols), np.nan) for name in ("hazard", "step", "slope")}
    out["goodness"] = np.zeros((rows, cols))
    out["flags"] = np.zeros((rows, cols), dtype=np.uint8)
    reach = math.ceil(rules.hole_reach / g - 1e-9)

    def params(i: int, j: int) -> tuple[bool, float, float]:
        cx, cy = coarse.origin_x + (i + 0.5) * g, coarse.origin_y + (j + 0.5) * g
        far = math.hypot(cx - vehicle[0], cy - vehicle[1]) > rules.far_field
        t = rules.step_height * (rules.far_field_scale if far else 1.0)
        limit = min(rules.max_slope * rules.far_field_slope_scale, 89.9) if far \
            else rules.max_slope
        return far, t, limit

    def goodness(i: int, j: int) -> float:
        a = cell(i, j)
        if a is None:
            return 0.0
        far, _, _ = params(i, j)
        age = 0.0 if a[6] == -math.inf else max(now - a[6], 0.0)
        accuracy = min(1.0, 1.0 / rules.far_field_scale) if far else 1.0
        with_points, total = fine_cells[(i, j)]
        return (1 - math.exp(-a[0] / rules.goodness_points)) * with_points / total \
            * math.exp(-age / rules.goodness_time) * accuracy

    good = {(i, j): goodness(i, j) for i in range(rows) for j in range(cols)}
    slopes: dict[tuple[int, int], float] = {}  # fitted slope (deg) of known cells
    gradients: dict[tuple[int, int], tuple[float, float]] = {}  # of the fit, m/m
    for i in range(rows):
        for j in range(cols):
            if cell(i, j) is None:
                continue
            e = elev(i, j)
            points = []
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    ii, jj = i + di, j + dj
                    b = cell(ii, jj) if (0 <= ii < rows and 0 <= jj < cols) else None
                    if b is not None and abs(b[1] / b[0] - e) < params(i, j)[1]:
                        points.append((di + b[2] / b[0] / g, dj + b[3] / b[0] / g,
                                       b[1] / b[0] - e))
            design = np.array([[p[0], p[1], 1.0] for p in points])
            if len(points) >= 3 and np.linalg.det(design.T @ design) >= 0.25:
                heights = np.array([p[2] for p in points])
                solution = np.linalg.lstsq(design, heights, rcond=None)[0]
                slopes[(i, j)] = math.degrees(math.atan(math.hypot(solution[0],
                                                                   solution[1]) / g))
                misfit = math.sqrt(float(np.mean((design @ solution - heights) ** 2)))
                if misfit < params(i, j)[1] * 0.1:  # a plane: its gradient lifts the spread
                    gradients[(i, j)] = (solution[0] / g, solution[1] / g)

    def within(i: int, j: int) -> float:
        """The cell's spread less the fitted plane's rise across its points' extent
        (the plane no steeper than the slope limit for this rise); 0 at least."""
        a = cell(i, j)
        assert a is not None
        rise = 0.0
        if (i, j) in gradients:
            gx, gy = gradients[(i, j)]
            limit = math.tan(math.radians(params(i, j)[2]))
            legal = min(1.0, limit / math.hypot(gx, gy)) if math.hypot(gx, gy) > 0 else 1.0
            x0, x1, y0, y1 = extents[(i, j)]
            rise = legal * (abs(gx) * (x1 - x0 + fine.gridsize)
                            + abs(gy) * (y1 - y0 + fine.gridsize))
        return max(a[5] - a[4] - rise, 0.0)

    def line(i: int, j: int, di: int, dj: int, sign: int) -> list[tuple[float, list[float]]]:
        """(distance, cell) of the known cells on one side, nearest first."""
        found = []
        for k in range(1, reach + 1):
            ii, jj = i + sign * k * di, j + sign * k * dj
            b = cell(ii, jj) if (0 <= ii < rows and 0 <= jj < cols) else None
            if b is not None:
                found.append((k * math.hypot(di, dj) * g, b, (ii, jj)))
        return found

    def side_goodness(i: int, j: int, di: int, dj: int, sign: int) -> float:
        best = 0.0
        for k in range(1, reach + 1):
            ii, jj = i + sign * k * di, j + sign * k * dj
            if 0 <= ii < rows and 0 <= jj < cols:
                best = max(best, good[(ii, jj)])
        return best

    def ground_trend(i: int, j: int) -> tuple[float, float]:
        """The ground's trend: the mean gradient of the planar cells within 2·reach
        cells (0 if none), no steeper than the cell's slope limit."""
        found = [gradients[(ii, jj)] for ii in range(i - 2 * reach, i + 2 * reach + 1)
                 for jj in range(j - 2 * reach, j + 2 * reach + 1) if (ii, jj) in gradients]
        if not found:
            return 0.0, 0.0
        tx = sum(f[0] for f in found) / len(found)
        ty = sum(f[1] for f in found) / len(found)
        limit = math.tan(math.radians(params(i, j)[2]))
        steep = math.hypot(tx, ty)
        if steep > limit:
            tx, ty = tx * limit / steep, ty * limit / steep
        return tx, ty

    def ground_median(i: int, j: int) -> float:
        """The median of the known elevations within 2·reach cells, each brought along
        the cell's ground trend to the cell."""
        tx, ty = ground_trend(i, j)
        around = sorted(elev(ii, jj) - tx * (ii - i) * g - ty * (jj - j) * g
                        for ii in range(i - 2 * reach, i + 2 * reach + 1)
                        for jj in range(j - 2 * reach, j + 2 * reach + 1)
                        if 0 <= ii < rows and 0 <= jj < cols and cell(ii, jj) is not None)
        n = len(around)
        return around[n // 2] if n % 2 else (around[n // 2 - 1] + around[n // 2]) / 2

    def below_ground(i: int, j: int, t: float) -> bool:
        """A step below the ground around (ground_median)."""
        return ground_median(i, j) - elev(i, j) >= t

    stepped: set[tuple[int, int]] = set()  # known cells with step >= T
    for i in range(rows):
        for j in range(cols):
            a = cell(i, j)
            if a is None:
                continue
            e = elev(i, j)
            spread = within(i, j)
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    ii, jj = i + di, j + dj
                    b = cell(ii, jj) if (0 <= ii < rows and 0 <= jj < cols) else None
                    if b is not None:
                        spread = max(spread, e - b[1] / b[0])  # the higher side
                        if b[1] / b[0] - e >= params(i, j)[1] \
                                and below_ground(i, j, params(i, j)[1]):  # in a pit
                            spread = max(spread, b[1] / b[0] - e)
            if spread >= params(i, j)[1]:
                stepped.add((i, j))

    # the tops of low, wide obstacles: near a step, bounded, a step above the ground
    # around them, joined to a step cell through such cells
    def above_ground(i: int, j: int) -> float:
        return elev(i, j) - ground_median(i, j)

    def off_level(i: int, j: int, di: int, dj: int, sign: int, t: float) -> bool:
        """A cell a step lower than the trend explains, or an unknown one, on this side."""
        tx, ty = ground_trend(i, j)
        for k in range(1, reach + 1):
            ii, jj = i + sign * k * di, j + sign * k * dj
            b = cell(ii, jj) if (0 <= ii < rows and 0 <= jj < cols) else None
            if b is None:
                return True
            expected = sign * k * g * (di * tx + dj * ty)
            if b[1] / b[0] - expected <= elev(i, j) - t:
                return True
        return False

    raised: dict[tuple[int, int], float] = {}
    for i in range(rows):
        for j in range(cols):
            if cell(i, j) is None or (i, j) in stepped or reach < 1:
                continue
            t = params(i, j)[1]
            if not any((ii, jj) in stepped for ii in range(i - reach, i + reach + 1)
                       for jj in range(j - reach, j + reach + 1)):
                continue
            if not any(off_level(i, j, di, dj, 1, t) and off_level(i, j, di, dj, -1, t)
                       for di, dj in AXES):
                continue
            if above_ground(i, j) >= t:
                raised[(i, j)] = above_ground(i, j)
    tops: set[tuple[int, int]] = set()
    frontier = list(stepped)
    while frontier:
        i, j = frontier.pop()
        for di in (-1, 0, 1):
            for dj in (-1, 0, 1):
                if (i + di, j + dj) in raised and (i + di, j + dj) not in tops:
                    tops.add((i + di, j + dj))
                    frontier.append((i + di, j + dj))
    stepped |= tops

    def faced(i: int, j: int, di: int, dj: int, sign: int) -> bool:
        return any((i + sign * k * di, j + sign * k * dj) in stepped
                   for k in range(1, reach + 1))

    for i in range(rows):
        for j in range(cols):
            far, t, limit = params(i, j)
            flags = FLAG_FAR if far else 0
            a = cell(i, j)
            s = math.tan(math.radians(limit))
            sunken = hole = False
            hole_good = 0.0
            for di, dj in AXES if rules.step_on else ():
                one, two = line(i, j, di, dj, 1), line(i, j, di, dj, -1)
                if not (one and two):
                    continue
                if a is not None:
                    h1 = max(b[1] / b[0] - s * d for d, b, _ in one)
                    h2 = max(b[1] / b[0] - s * d for d, b, _ in two)
                    sunken |= min(h1, h2) - elev(i, j) >= t
                    continue
                trend = s
                for side in (one, two):
                    if side[0][2] in slopes:
                        trend = min(trend, math.tan(math.radians(slopes[side[0][2]])))
                high = -math.inf
                for sign, side in ((1, one), (-1, two)):
                    d, b, _ = side[0]
                    if not faced(i, j, di, dj, sign):
                        high = max(high, b[1] / b[0] - trend * d)
                low = min(b[4] + trend * d for d, b, _ in one + two)
                if high - low >= t:
                    hole = True
                    hole_good = max(hole_good, side_goodness(i, j, di, dj, 1),
                                    side_goodness(i, j, di, dj, -1))
            if a is None:
                if hole:
                    out["hazard"][i, j] = 1.0
                    out["goodness"][i, j] = rules.inferred_goodness * hole_good
                    flags |= FLAG_HOLE
                out["flags"][i, j] = flags
                continue
            e = elev(i, j)
            neighbour = 0.0
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    ii, jj = i + di, j + dj
                    b = cell(ii, jj) if (0 <= ii < rows and 0 <= jj < cols) else None
                    if b is not None and (di or dj):
                        neighbour = max(neighbour, e - b[1] / b[0])  # higher side
                        if b[1] / b[0] - e >= t and below_ground(i, j, t):  # in a pit
                            neighbour = max(neighbour, b[1] / b[0] - e)
            step = max(within(i, j), neighbour)
            if (i, j) in tops:
                step = max(step, raised[(i, j)])
            out["step"][i, j] = step
            hazard = 0.0
            if rules.step_on:
                if step >= t:
                    flags |= FLAG_STEP
                hazard = min(step / t, 1.0) if rules.step_percent else float(step >= t)
                if sunken and below_ground(i, j, t):  # a ditch floor, not a gap
                    hazard = 1.0
                    flags |= FLAG_SUNKEN
            if (i, j) in slopes:
                slope = slopes[(i, j)]
                out["slope"][i, j] = slope
                if rules.slope_on:
                    hazard = max(hazard, min(slope / limit, 1.0))
                    if slope >= limit:
                        flags |= FLAG_SLOPE
            out["hazard"][i, j] = hazard
            out["goodness"][i, j] = good[(i, j)]
            out["flags"][i, j] = flags
    holes = (out["flags"] & FLAG_HOLE) != 0
    hole_good = np.where(holes, out["goodness"], 0.0)
    walls = stepped | {(int(i), int(j)) for i, j in np.argwhere(holes)}
    for i in range(rows):  # walled pits: a wall within reach each side, below the ground
        for j in range(cols):
            if cell(i, j) is None or not rules.step_on or reach < 1:
                continue
            if any(all(any((i + sign * k * di, j + sign * k * dj) in walls
                           for k in range(1, reach + 1)) for sign in (1, -1))
                   for di, dj in AXES) and below_ground(i, j, params(i, j)[1]):
                out["hazard"][i, j] = 1.0
                out["flags"][i, j] |= FLAG_SUNKEN
    for i in range(rows):
        for j in range(cols):
            with_points, total = fine_cells.get((i, j), [0, 0])
            if cell(i, j) is None or 2 * with_points >= total:
                continue
            if holes[max(i - 1, 0):i + 2, max(j - 1, 0):j + 2].any():
                out["hazard"][i, j] = 1.0  # joins the hole, with the best one's goodness
                out["goodness"][i, j] = hole_good[max(i - 1, 0):i + 2,
                                                  max(j - 1, 0):j + 2].max()
                out["flags"][i, j] |= FLAG_HOLE
    return out


def check_against_reference(terrain: TerrainLayers, rules: HazardRules | None = None,
                            vehicle: tuple[float, float] = VEHICLE) -> TraversabilityLayers:
    rules = rules or HazardRules()
    got = TraversabilityMapper(rules).update(terrain, COARSE, vehicle, NOW)
    want = reference(terrain, COARSE, rules, vehicle, NOW)
    for name in ("hazard", "goodness", "step", "slope"):
        np.testing.assert_allclose(getattr(got, name), want[name], rtol=1e-5, atol=1e-5,
                                   equal_nan=True, err_msg=name)
    np.testing.assert_array_equal(got.flags, want["flags"])
    known = ~np.isnan(got.hazard)
    assert np.all((got.hazard[known] >= 0) & (got.hazard[known] <= 1))
    assert np.all((got.goodness >= 0) & (got.goodness <= 1))
    return got


def flagged(layers: TraversabilityLayers, flag: int) -> np.ndarray:
    return (layers.flags & flag) != 0


def rows_at(x0: float, x1: float) -> slice:
    """Coarse rows whose centres lie in [x0, x1)."""
    return slice(math.ceil((x0 - COARSE.origin_x) / 0.5 - 0.5),
                 math.ceil((x1 - COARSE.origin_x) / 0.5 - 0.5))


# --- synthetic terrains ----------------------------------------------------------------


def test_flat_ground_is_easy_everywhere() -> None:
    layers = check_against_reference(terrain_from(lambda x, y: 0.0 * x + 1.0))
    assert np.all(layers.hazard == 0.0)
    assert np.all(layers.slope == 0.0)
    far = flagged(layers, FLAG_FAR)
    assert far.any() and (~far).any()
    # goodness: 4 points per fine cell, 4..9 fine cells per coarse cell, all fresh
    assert layers.goodness[~far].min() > 0.95
    assert layers.goodness[far].max() < 1 / 1.5 + 1e-6


@pytest.mark.parametrize("height,x_step,expect", [
    (0.29, 3.0, False), (0.31, 3.0, True),      # near field: T = 0.30 m
    (0.40, 12.0, False), (0.46, 12.0, True),    # far field: T = 0.45 m (relaxed)
])
def test_step_just_under_and_over_stepheight(height: float, x_step: float,
                                             expect: bool) -> None:
    layers = check_against_reference(terrain_from(
        lambda x, y: np.where(x >= x_step + 0.05, height, 0.0)))
    steps = flagged(layers, FLAG_STEP)
    assert steps.any() == expect
    if expect:
        band = steps[rows_at(x_step - 0.6, x_step + 0.6)]
        assert band.any(axis=0).all()  # the whole step line
        assert steps.sum() == band.sum()
        assert not steps[rows_at(x_step - 0.6, x_step)].any()  # the lower side is open ground
        assert np.all(layers.hazard[steps] == 1.0)
    else:  # binary: no step hazard; the plane fit still sees a steep ramp there
        assert layers.hazard.max() < 1.0


def test_step_percent_grades_the_step() -> None:
    rules = HazardRules(step_percent=True, slope_on=False)
    layers = check_against_reference(
        terrain_from(lambda x, y: np.where(x >= 3.05, 0.15, 0.0)), rules)
    band = layers.hazard[rows_at(2.4, 3.6)]
    assert band.max() == pytest.approx(0.5, abs=1e-6)  # 0.15 m of a 0.30 m step
    assert layers.hazard.max() < 1.0


@pytest.mark.parametrize("angle,axis,expect", [(19.0, "x", False), (21.0, "x", True),
                                               (19.0, "y", False), (21.0, "y", True),
                                               (19.5, "xy", False)])
def test_ramp_just_under_and_over_maxslope(angle: float, axis: str, expect: bool) -> None:
    grade = math.tan(math.radians(angle))
    along = {"x": lambda x, y: x, "y": lambda x, y: y,
             "xy": lambda x, y: (x + y) / math.sqrt(2)}[axis]  # xy: the worst case, where
    layers = check_against_reference(  # a 0.6 m group spans 0.85 m of the ramp (0.29 m)
        terrain_from(lambda x, y: grade * along(x, y)), vehicle=(0.0, 0.0))
    near = ~flagged(layers, FLAG_FAR)
    interior = np.zeros(COARSE.shape, bool)
    interior[1:-1, 1:-1] = True
    slopes = layers.slope[near & interior]
    assert slopes == pytest.approx(angle, abs=1e-3)  # centroids: no 2-or-3 cell bias
    assert not flagged(layers, FLAG_STEP).any()  # a ramp is not a step
    assert flagged(layers, FLAG_SLOPE)[near & interior].all() == expect
    if not expect:
        assert layers.hazard[near].max() == pytest.approx(angle / 20.0, abs=1e-4)
    # far field: the limit relaxes to 30 degrees
    assert not flagged(layers, FLAG_SLOPE)[~near].any()


def relief(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Smooth ground relief of about 3 cm RMS, its own slopes under 12° (a few waves
    1-2.3 m long), the kind the simulator's ``roughness`` makes."""
    return (0.04 * np.sin(2.7 * x + 0.4) * np.cos(3.1 * y) + 0.02 * np.sin(4.3 * x - 3.1 * y)
            + 0.015 * np.cos(6.1 * x + 2.0 * y + 1.0) + 0.015 * np.sin(5.1 * y - 0.7))


@pytest.mark.parametrize("angle,axis", [(12.0, "xy"), (15.0, "x"), (15.0, "xy")])
def test_a_rough_legal_ramp_has_no_steps(angle: float, axis: str) -> None:
    # a cell's points span up to 0.6 m (0.85 m across a diagonal) of the ramp: on a 15°
    # ramp that is up to 0.23 m of spread that is slope, not step; with a few
    # centimetres of relief on top it crossed the 0.3 m step height
    grade = math.tan(math.radians(angle))
    along = {"x": lambda x, y: x, "xy": lambda x, y: (x + y) / math.sqrt(2)}[axis]
    layers = check_against_reference(
        terrain_from(lambda x, y: grade * along(x, y) + relief(x, y)), vehicle=(0.0, 0.0))
    assert not flagged(layers, FLAG_STEP).any()
    assert not flagged(layers, FLAG_SLOPE)[~flagged(layers, FLAG_FAR)].any()


@pytest.mark.parametrize("height,expect", [(0.0, False), (0.45, True)])
def test_a_rock_on_a_steep_ramp_is_still_a_step(height: float, expect: bool) -> None:
    # a 0.6 m square rock on a rough 15° ramp: the ramp's rise is taken out of a cell's
    # spread, the rock's own height is not
    grade = math.tan(math.radians(15.0))

    def ground(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        rock = (np.abs(x - 3.05) <= 0.3) & (np.abs(y - 0.05) <= 0.3)
        return grade * (x + y) / math.sqrt(2) + relief(x, y) + np.where(rock, height, 0.0)

    layers = check_against_reference(terrain_from(ground), vehicle=(0.0, 0.0))
    steps = flagged(layers, FLAG_STEP)
    assert steps.any() == expect
    if expect:
        rows, cols = np.nonzero(steps)
        x = COARSE.origin_x + (rows + 0.5) * COARSE.gridsize
        y = COARSE.origin_y + (cols + 0.5) * COARSE.gridsize
        assert np.all(np.hypot(x - 3.05, y - 0.05) < 1.0)  # the rock's cells, nothing else


def test_a_ditch_seen_from_afar_marks_its_unseen_middle() -> None:
    """Lip at x = 5, a 2 m wide and 1 m deep trench: the grazing laser sees neither its
    near wall nor its bottom, only the far wall's upper half (min heights down to
    -0.5 m) and the ground beyond."""
    ditch = (5.0, 7.0)

    def ground(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return 0.0 * x

    x, _ = FINE.centres()
    unseen = (x > ditch[0]) & (x < ditch[1] - 0.2)
    wall = (x > ditch[1] - 0.2) & (x < ditch[1])
    terrain = terrain_from(ground, known=~unseen,
                           lows=lambda x, y: np.where((x > ditch[1] - 0.2) & (x < ditch[1]),
                                                      -0.5, np.inf))
    assert wall.any()
    layers = check_against_reference(terrain)
    middle = rows_at(ditch[0] + 0.3, ditch[1] - 0.3)
    assert flagged(layers, FLAG_HOLE)[middle].all()
    assert np.all(layers.hazard[middle] == 1.0)
    assert np.all(layers.goodness[middle] > 0.4)
    # open ground before the lip and beyond the far wall stays easy
    assert np.all(layers.hazard[rows_at(-4.0, ditch[0] - 0.5)] == 0.0)
    assert np.all(layers.hazard[rows_at(ditch[1] + 1.0, 8.0)] == 0.0)


def test_the_unseen_foot_of_a_down_ledge_is_a_hole() -> None:
    """Level ground to x = 5, then 1 m lower; the strip at the ledge's foot is unseen."""
    x, _ = FINE.centres()
    layers = check_against_reference(terrain_from(
        lambda x, y: np.where(x > 5.0, -1.0, 0.0), known=~((x > 5.0) & (x < 6.6))))
    assert flagged(layers, FLAG_HOLE)[rows_at(5.3, 6.4)].all()


def test_the_unseen_shadow_behind_a_rock_is_not_a_hole() -> None:
    """A 0.8 m rock 1 m deep at x = 4..5; the 1.6 m behind it are unseen."""
    x, y = FINE.centres()
    rock = (np.abs(y) < 1.0)

    def height(xx: np.ndarray, yy: np.ndarray) -> np.ndarray:
        return np.where((xx > 4.0) & (xx < 5.0) & (np.abs(yy) < 1.0), 0.8, 0.0)

    layers = check_against_reference(terrain_from(
        height, known=~((x > 5.0) & (x < 6.6) & rock)))
    shadow = layers.hazard[rows_at(5.3, 6.4), COARSE.cols // 2 - 1:COARSE.cols // 2 + 1]
    assert np.isnan(shadow).all()  # unknown, neither free nor a hazard
    assert not flagged(layers, FLAG_HOLE).any()
    assert flagged(layers, FLAG_STEP)[rows_at(3.6, 5.0)].any()


def test_the_rim_of_a_hole_seen_only_along_its_edge_joins_it() -> None:
    """As the ditch above, the lip at x = 5.6: the cell [5.5, 6.0) holds one seen row of
    fine cells (x = 5.5) and two unseen ones over the ditch."""
    x, _ = FINE.centres()
    unseen = (x > 5.6) & (x < 7.2)
    terrain = terrain_from(lambda x, y: 0.0 * x, known=~unseen,
                           lows=lambda x, y: np.where((x > 7.2) & (x < 7.4), -0.5, np.inf))
    layers = check_against_reference(terrain)
    rim = rows_at(5.6, 5.9)
    assert np.all(layers.count[rim] > 0)  # seen, along an edge
    assert flagged(layers, FLAG_HOLE)[rim].all() and np.all(layers.hazard[rim] == 1.0)
    assert np.all(layers.hazard[rows_at(-4.0, 5.4)] == 0.0)  # fully seen ground stays easy


def test_a_hole_on_flat_ground_stays_unknown() -> None:
    x, y = FINE.centres()
    gap = (np.abs(x - 4.0) < 1.0) & (np.abs(y) < 1.0)  # missing data, no drop
    layers = check_against_reference(terrain_from(lambda x, y: 0.02 * x, known=~gap))
    unknown = np.isnan(layers.hazard)
    assert unknown.sum() >= 9
    assert np.all(layers.goodness[unknown] == 0.0)
    assert not flagged(layers, FLAG_HOLE).any()


def test_a_seen_ditch_bottom_is_sunken() -> None:
    """The same trench seen close up: bottom known at -1 m, 2 m wide (4 cells)."""
    layers = check_against_reference(
        terrain_from(lambda x, y: np.where((x > 3.0) & (x < 5.0), -1.0, 0.0)))
    bottom = rows_at(3.3, 4.7)
    assert np.all(layers.hazard[bottom] == 1.0)
    assert (flagged(layers, FLAG_SUNKEN) | flagged(layers, FLAG_STEP))[bottom].all()
    assert flagged(layers, FLAG_SUNKEN)[bottom].any()  # beyond the 8-neighbour step


def test_a_wall() -> None:
    layers = check_against_reference(
        terrain_from(lambda x, y: np.where((x > 4.0) & (x < 4.4) & (np.abs(y) < 3.0),
                                           1.2, 0.0)))
    wall = rows_at(3.9, 4.6)
    j = slice(COARSE.cols // 2 - 4, COARSE.cols // 2 + 4)
    assert np.all(layers.hazard[wall, j] == 1.0)
    assert flagged(layers, FLAG_STEP)[wall, j].all()
    assert layers.hazard[rows_at(-4.0, 3.0)].max() == 0.0


def test_switches() -> None:
    terrain = terrain_from(lambda x, y: np.where(x >= 3.05, 0.5, 0.0) + 0.5 * y)
    slope_only = check_against_reference(terrain, HazardRules(step_on=False))
    assert not flagged(slope_only, FLAG_STEP).any() and flagged(slope_only, FLAG_SLOPE).any()
    step_only = check_against_reference(terrain, HazardRules(slope_on=False))
    assert flagged(step_only, FLAG_STEP).any() and not flagged(step_only, FLAG_SLOPE).any()
    neither = check_against_reference(terrain, HazardRules(step_on=False, slope_on=False))
    assert np.nanmax(neither.hazard) == 0.0


def test_random_rough_terrain_with_holes_and_ages() -> None:
    rng = np.random.default_rng(42)
    base = rng.normal(0.0, 0.15, FINE.shape)
    x, _ = FINE.centres()

    def height(xx: np.ndarray, yy: np.ndarray) -> np.ndarray:
        i = np.clip(((xx - FINE.origin_x) / 0.2).astype(int), 0, FINE.rows - 1)
        j = np.clip(((yy - FINE.origin_y) / 0.2).astype(int), 0, FINE.cols - 1)
        return base[i, j] + 0.05 * xx

    known = rng.random(FINE.shape) > 0.3
    known[40:55, 20:35] = False  # a hole big enough for the hole rule
    terrain = terrain_from(height, known=known)
    terrain = TerrainLayers(terrain.geometry, terrain.elevation, terrain.min_height,
                            terrain.max_height,
                            np.where(known, rng.integers(1, 9, FINE.shape), 0).astype(np.int32),
                            terrain.variance,
                            np.where(known, rng.uniform(0.0, NOW, FINE.shape), np.nan))
    for rules in (HazardRules(), HazardRules(step_percent=True, min_points=3, hole_reach=1.0)):
        layers = check_against_reference(terrain, rules, vehicle=(2.0, -1.0))
        assert flagged(layers, FLAG_STEP).any() and (layers.hazard < 1).any()


def test_resampling_conserves_points_and_extremes() -> None:
    rng = np.random.default_rng(1)
    terrain = terrain_from(lambda x, y: np.sin(x) + np.cos(y))
    terrain = TerrainLayers(terrain.geometry, terrain.elevation, terrain.min_height,
                            terrain.max_height,
                            rng.integers(0, 5, FINE.shape).astype(np.int32),
                            terrain.variance, terrain.last_seen)
    cells = resample(terrain, COARSE)
    assert cells.count.sum() == terrain.count.sum()  # the grids cover the same area
    known = terrain.count > 0
    assert np.nanmax(cells.max_height) == terrain.max_height[known].max()
    assert np.nanmin(cells.min_height) == terrain.min_height[known].min()


def test_rules_from_table_a7() -> None:
    rules = HazardRules.from_parameters(TraversabilityMapParameters(), hole_reach=1.5)
    assert rules == HazardRules(hole_reach=1.5)
    assert rules.far_slope == 30.0 and rules.far_accuracy == pytest.approx(1 / 1.5)
    with pytest.raises(ValueError):
        HazardRules(max_slope=90.0)
    with pytest.raises(ValueError):
        TraversabilityMapper(HazardRules()).update(terrain_from(lambda x, y: 0 * x), COARSE,
                                                   (math.nan, 0.0), NOW)


def test_last_seen_tracker_follows_scrolls_and_changes() -> None:
    tracker = LastSeenTracker()
    geo = GridGeometry(0.0, 0.0, 0.2, 4, 4)
    count = np.zeros((4, 4), np.int32)
    count[1, 1] = count[2, 2] = 3
    seen = tracker.update(geo, count, 1.0)
    assert seen[1, 1] == 1.0 and np.isnan(seen[0, 0])
    # scroll one cell along +x: old [2, 2] is new [1, 2]; old [1, 1] is new [0, 1]
    moved = GridGeometry(0.2, 0.0, 0.2, 4, 4)
    count2 = np.zeros((4, 4), np.int32)
    count2[0, 1] = 3       # unchanged
    count2[1, 2] = 5       # more points
    count2[3, 3] = 1       # new
    seen2 = tracker.update(moved, count2, 2.0)
    assert seen2[0, 1] == 1.0 and seen2[1, 2] == 2.0 and seen2[3, 3] == 2.0
    assert np.isnan(seen2[2, 2])


def test_a_gate_in_a_wall_is_open_ground_not_a_sunken_cell() -> None:
    """A 1.5 m wall along x = 4.0-4.4 with a 3 m gate (|y| < 1.5): the gate lies at the
    ground's own level between two tall banks, and must stay free to drive through."""
    layers = check_against_reference(terrain_from(
        lambda x, y: np.where((x > 4.0) & (x < 4.4) & (np.abs(y) >= 1.5), 1.5, 0.0)))
    gate = (rows_at(3.5, 5.0), slice(*[round((v - COARSE.origin_y) / 0.5) for v in (-1.0, 1.0)]))
    assert not flagged(layers, FLAG_SUNKEN).any()
    assert np.all(layers.hazard[gate] < 1.0)


def test_the_top_of_a_low_wide_box_seen_from_one_side_is_a_hazard() -> None:
    """A 0.4 m box 2 m deep (x = 4..6) and 3 m wide; the 1.6 m behind it are unseen, so
    the cells on its top have no lower neighbour in view: a plateau, not open ground."""
    x, y = FINE.centres()

    def height(xx: np.ndarray, yy: np.ndarray) -> np.ndarray:
        return np.where((xx > 4.0) & (xx < 6.0) & (np.abs(yy) < 1.5), 0.4, 0.0)

    layers = check_against_reference(terrain_from(
        height, known=~((x > 6.0) & (x < 7.6) & (np.abs(y) < 1.5))))
    j = slice(COARSE.cols // 2 - 2, COARSE.cols // 2 + 2)
    top = rows_at(4.6, 5.9)
    assert np.all(layers.hazard[top, j] == 1.0) and flagged(layers, FLAG_STEP)[top, j].all()
    assert np.all(layers.hazard[rows_at(-4.0, 3.4)] == 0.0)  # the ground in front
    assert not flagged(layers, FLAG_HOLE).any()


@pytest.mark.parametrize("angle", [8.0, 14.0, 18.0])
def test_downhill_ground_by_a_rock_is_not_an_obstacle_top(angle: float) -> None:
    """The ego map starts at the bumper (nothing known behind it) and the vehicle faces
    down a legal slope with a 1 m rock 2 m ahead: the ground between them lies above the
    ground further down, and on this side is bounded by the map's edge, but it is the
    slope's own level, not the top of an obstacle. (Compared with the raw median of the
    ground around, it read as a plateau: a 6 m wide band of steps at the bumper that
    vetoed every arc and kept the vehicle backing and returning there for ever.)"""
    grade = math.tan(math.radians(angle))
    x, y = FINE.centres()

    def ground(xx: np.ndarray, yy: np.ndarray) -> np.ndarray:
        rock = np.hypot(xx - 2.0, yy - 1.7) <= 0.4
        return -grade * xx + relief(xx, yy) + np.where(rock, 1.0, 0.0)

    layers = check_against_reference(terrain_from(ground, known=x >= 0.0),
                                     vehicle=(-2.5, 0.0))
    rows, cols = np.nonzero(flagged(layers, FLAG_STEP) | flagged(layers, FLAG_SUNKEN))
    cx = COARSE.origin_x + (rows + 0.5) * COARSE.gridsize
    cy = COARSE.origin_y + (cols + 0.5) * COARSE.gridsize
    assert len(rows) and np.all(np.hypot(cx - 2.0, cy - 1.7) < 1.2)  # the rock's cells


def test_a_smooth_hill_top_is_not_an_obstacle_top() -> None:
    """A 1 m hill (slopes under 15 degrees) beside a 0.6 m rock: the hill top lies far
    above the ground around it, but no face bounds it, so it stays easy."""
    def height(xx: np.ndarray, yy: np.ndarray) -> np.ndarray:
        hill = 1.0 * np.exp(-((xx - 5.0) ** 2 + yy ** 2) / (2 * 2.5 ** 2))
        rock = np.where((np.abs(xx - 2.0) < 0.5) & (np.abs(yy - 4.0) < 0.5), 0.6, 0.0)
        return hill + rock

    layers = check_against_reference(terrain_from(height))
    assert layers.hazard[rows_at(4.0, 6.0), COARSE.cols // 2 - 2:COARSE.cols // 2 + 2].max() \
        < 1.0
    assert flagged(layers, FLAG_STEP).any()  # the rock


def test_the_flat_floor_of_a_wide_ditch_between_its_lips_is_a_pit() -> None:
    """A 1 m deep ditch 2.5 m wide (x = 4..6.5), its near strip unseen: from the far lip
    2 m away a 20° ramp could descend 0.73 m, so the sunken rule's slope allowance
    passes its middle; but its lips are steps and its unseen strip a hole."""
    x, _ = FINE.centres()
    layers = check_against_reference(terrain_from(
        lambda x, y: np.where((x > 4.0) & (x < 6.5), -1.0, 0.0),
        known=~((x > 4.0) & (x < 4.8))))
    floor = rows_at(5.1, 5.9)
    assert np.all(layers.hazard[floor] == 1.0)
    assert flagged(layers, FLAG_SUNKEN)[floor].all()
    assert np.all(layers.hazard[rows_at(-4.0, 3.4)] == 0.0)
