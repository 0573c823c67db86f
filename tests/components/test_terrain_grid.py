"""Terrain grid core (components/terrain_map/grid.py): fusion against a per-point
loop, scrolling, the ego view, pose interpolation and audit, stereo balancing."""

from __future__ import annotations

import math

import numpy as np
import pytest

import components.terrain_map.grid as grid_module
from components.terrain_map.grid import (
    CHUNK,
    SMALL_BATCH,
    EgoView,
    GridGeometry,
    PoseAudit,
    PoseBuffer,
    PoseStatus,
    StereoBalance,
    TerrainGrid,
    ego_map_pose,
    interpolate_transform,
    rotation_angle,
    transform_points,
    yaw_of,
)
from components.terrain_map.parameters import TerrainMapParameters


def pose(x: float = 0.0, y: float = 0.0, z: float = 0.0, yaw: float = 0.0,
         pitch: float = 0.0, roll: float = 0.0) -> np.ndarray:
    """World-from-body transform, R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    t = np.eye(4)
    t[:3, :3] = [[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                 [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                 [-sp, cp * sr, cp * cr]]
    t[:3, 3] = (x, y, z)
    return t


# --- the oracle ------------------------------------------------------------------------


class LoopGrid:
    """The plain definition: one point at a time, Python floats. Each cell keeps the
    list of its generations, each a start time and the heights it got; the extremes are
    those of the last two."""

    def __init__(self, geometry: GridGeometry, window: float = math.inf) -> None:
        self.g = geometry
        self.window = window
        n = geometry.size
        self.count = [0] * n
        self.sum_z = [0.0] * n
        self.sum_z2 = [0.0] * n
        self.last_seen = [-math.inf] * n
        self.generations: list[list[tuple[float, list[float]]]] = [[] for _ in range(n)]

    def _heights(self, c: int) -> list[float]:
        return [z for _, heights in self.generations[c][-2:] for z in heights]

    @property
    def min_z(self) -> list[float]:
        return [min(self._heights(c), default=math.inf) for c in range(self.g.size)]

    @property
    def max_z(self) -> list[float]:
        return [max(self._heights(c), default=-math.inf) for c in range(self.g.size)]

    def fuse(self, points: np.ndarray, time: float) -> tuple[int, int, int]:
        fused = outside = nonfinite = 0
        g = self.g
        for x, y, z in points.tolist():
            if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
                nonfinite += 1
                continue
            qi = (x - g.origin_x) / g.gridsize
            qj = (y - g.origin_y) / g.gridsize
            if not (math.isfinite(qi) and math.isfinite(qj)):
                outside += 1
                continue
            i, j = math.floor(qi), math.floor(qj)
            if not (0 <= i < g.rows and 0 <= j < g.cols):
                outside += 1
                continue
            c = i * g.cols + j
            self.count[c] += 1
            self.sum_z[c] += z
            self.sum_z2[c] += z * z
            generations = self.generations[c]
            if not generations or time - generations[-1][0] >= self.window:
                generations.append((time, []))
            generations[-1][1].append(z)
            self.last_seen[c] = max(self.last_seen[c], time)
            fused += 1
        return fused, outside, nonfinite

    def assert_equal(self, grid: TerrainGrid) -> None:
        for name in ("count", "sum_z", "sum_z2", "min_z", "max_z", "last_seen"):
            expected = np.array(getattr(self, name))
            actual = getattr(grid, name)
            assert np.array_equal(actual, expected), name  # exact, not approximate


def random_scan(rng: np.random.Generator, geometry: GridGeometry, n: int) -> np.ndarray:
    """Sensor-frame points, some on exact cell edges, NaN/inf, outside and huge."""
    pts = rng.uniform(-12.0, 12.0, (n, 3))
    pts[:, 2] = rng.normal(0.0, 1.0, n)
    k = n // 8
    # exactly on cell edges of the map (after an identity transform: see caller)
    pts[:k, 0] = geometry.origin_x + rng.integers(-2, geometry.rows + 3, k) * geometry.gridsize
    pts[k:2 * k, 1] = geometry.origin_y + rng.integers(0, geometry.cols + 1, k) \
        * geometry.gridsize
    bad = rng.choice(n, 12, replace=False)
    pts[bad[:4], rng.integers(0, 3, 4)] = np.nan
    pts[bad[4:8], rng.integers(0, 3, 4)] = np.inf
    pts[bad[8:10], 0] = -np.inf
    pts[bad[10:], 0] = 1.7e308  # finite, overflows to inf when binned
    return pts


@pytest.mark.parametrize(("gridsize", "window"), [(0.2, math.inf), (0.25, math.inf),
                                                  (0.2, 0.5), (0.25, 0.3)])
def test_fusion_equals_the_per_point_loop_exactly(gridsize: float, window: float) -> None:
    rng = np.random.default_rng(20240611)
    geometry = GridGeometry.centred(0.3, -0.7, 16.0, 12.0, gridsize)
    grid = TerrainGrid(geometry, window=window)
    oracle = LoopGrid(geometry, window)
    times = [1.0, 1.25, 1.5, 0.75, 2.0, 2.25, 2.5, 3.0]  # one late batch
    for k, t in enumerate(times):
        scan = random_scan(rng, geometry, 361 if k % 2 else 1000)
        if k == 0:
            world = scan  # identity pose: the edge points stay on edges
        else:
            world_from_sensor = pose(rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(0, 2),
                                     yaw=rng.uniform(-math.pi, math.pi),
                                     pitch=rng.uniform(-0.2, 0.2), roll=rng.uniform(-0.2, 0.2))
            with np.errstate(invalid="ignore", over="ignore"):  # inf·0 in the transform
                world = transform_points(world_from_sensor, scan)
            world[:20, 0] = geometry.origin_x + rng.integers(0, geometry.rows, 20) * gridsize
        stats = grid.fuse(world, t)
        assert (stats.fused, stats.outside, stats.nonfinite) == oracle.fuse(world, t)
        assert stats.total == len(world)
        oracle.assert_equal(grid)
    assert grid.fused_total > 1000 and grid.outside_total > 100 and grid.nonfinite_total > 40


def test_a_watched_cell_keeps_its_recent_extremes_and_an_unwatched_one_keeps_all() -> None:
    """A parked vehicle watches the same cells for minutes while the placement's error
    wanders: with generations of 10 s, a cell whose heights drift 1 cm/s for 100 s
    spreads over its last 10-20 s (0.1-0.2 m), not the 1 m of the whole drift; a cell
    seen once keeps its 0.5 m step however long the other is watched."""
    geometry = GridGeometry.centred(0.0, 0.0, 4.0, 4.0, 0.2)
    windowed = TerrainGrid(geometry, window=10.0)
    whole = TerrainGrid(geometry)
    for k in range(1001):
        t = k / 10
        points = [(0.1, 0.1, 0.01 * t)]
        if k == 0:
            points += [(1.1, 1.1, 0.0), (1.1, 1.1, 0.5)]
        for grid in (windowed, whole):
            grid.fuse(np.array(points), t)
    (wi, wj), (si, sj) = (geometry.cell_index(0.1, 0.1), geometry.cell_index(1.1, 1.1))
    for grid, low, high in ((windowed, 0.1, 0.2 + 1e-9), (whole, 1.0 - 1e-9, 1.0 + 1e-9)):
        layers = grid.layers()
        spread = float(layers.max_height[wi, wj] - layers.min_height[wi, wj])
        assert low <= spread <= high
        assert layers.max_height[si, sj] - layers.min_height[si, sj] == pytest.approx(0.5)
        assert layers.count[wi, wj] == 1001  # counts and means cover every point
        assert layers.elevation[wi, wj] == pytest.approx(0.5, abs=1e-6)
    with pytest.raises(ValueError, match="window"):
        TerrainGrid(geometry, window=0.0)


def test_transform_points_small_and_large_batches() -> None:
    rng = np.random.default_rng(17)
    t = pose(1.0, -2.0, 0.5, yaw=0.7, pitch=0.1, roll=-0.2)
    pts = rng.normal(0.0, 5.0, (SMALL_BATCH + 10, 3)).astype(np.float32)
    large = transform_points(t, pts)
    small = transform_points(t, pts[:100])
    np.testing.assert_allclose(small, large[:100], rtol=0, atol=1e-12)
    # the large path is the Python expression R p + t, left to right, exactly
    for (x, y, z), out in zip(pts[:50].astype(np.float64).tolist(), large[:50], strict=True):
        expected = [t[r, 0] * x + t[r, 1] * y + t[r, 2] * z + t[r, 3] for r in range(3)]
        assert out.tolist() == expected
    with pytest.raises(ValueError):
        transform_points(np.eye(3), pts)


def test_all_inside_fast_path_equals_the_loop() -> None:
    rng = np.random.default_rng(7)
    geometry = GridGeometry.centred(0.0, 0.0, 32.0, 32.0, 0.2)
    grid, oracle = TerrainGrid(geometry), LoopGrid(geometry)
    for t in (1.0, 2.0):
        pts = rng.uniform(-15.9, 15.9, (361, 3)).astype(np.float32)  # float32 as a scan
        stats = grid.fuse(pts, t)
        assert stats.fused == 361
        oracle.fuse(pts.astype(np.float64), t)
    oracle.assert_equal(grid)


def test_float32_points_are_binned_in_float64() -> None:
    """float32 scans near cell edges, against an origin float32 cannot represent, and
    a batch spanning several chunks: float64 arithmetic throughout, as the loop."""
    rng = np.random.default_rng(23)
    geometry = GridGeometry(0.1, -0.3, 0.2, 40, 40)
    edges = 0.1 + 0.2 * rng.integers(0, 40, CHUNK + 5000)
    pts = np.column_stack([edges + rng.normal(0.0, 2e-7, len(edges)),
                           rng.uniform(-0.3, 7.7, len(edges)),
                           rng.normal(0.0, 1.0, len(edges))]).astype(np.float32)
    grid, oracle = TerrainGrid(geometry), LoopGrid(geometry)
    assert grid.fuse(pts, 1.0).total == len(pts)
    oracle.fuse(pts.astype(np.float64), 1.0)
    oracle.assert_equal(grid)


def test_fuse_transformed_is_fuse_of_transform_points() -> None:
    rng = np.random.default_rng(29)
    t = pose(0.4, -0.2, 1.9, yaw=2.0, pitch=0.05)
    for n in (361, SMALL_BATCH + 1, CHUNK + 1000):
        pts = rng.uniform(-9, 9, (n, 3)).astype(np.float32)
        pts[::97] = np.nan
        a = TerrainGrid.centred(0, 0, 16, 16, 0.2)
        b = TerrainGrid.centred(0, 0, 16, 16, 0.2)
        assert a.fuse_transformed(pts, t, 2.0) == b.fuse(transform_points(t, pts), 2.0)
        for name in ("count", "sum_z", "sum_z2", "min_z", "max_z", "last_seen"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), (n, name)


@pytest.mark.parametrize("n", [361, SMALL_BATCH + 1])
def test_infinite_points_are_dropped_without_a_warning(n: int) -> None:
    """``inf · 0`` in the rotation is NaN: counted as non-finite, and no RuntimeWarning
    (pytest turns warnings into errors; a component once failed on one)."""
    t = pose(0.4, -0.2, 1.9, yaw=2.0, pitch=0.05)
    pts = np.zeros((n, 3), dtype=np.float32)
    pts[:, 0] = np.linspace(1.0, 5.0, n)
    pts[0] = (np.inf, 0.0, 0.0)
    pts[1] = (0.0, -np.inf, np.inf)
    pts[2] = (np.nan, 1.0, 1.0)
    grid = TerrainGrid.centred(0, 0, 16, 16, 0.2)
    stats = grid.fuse_transformed(pts, t, 1.0)
    assert (stats.fused, stats.nonfinite) == (n - 3, 3)
    assert np.all(np.isfinite(grid.sum_z)) and np.all(np.isfinite(grid.sum_z2))


def test_floor_semantics_on_exact_edges() -> None:
    geometry = GridGeometry(-2.0, -1.0, 0.25, 16, 8)  # binary-exact edges
    grid = TerrainGrid(geometry)
    below = np.nextafter(-2.0 + 3 * 0.25, -np.inf)
    pts = np.array([
        [-2.0 + 3 * 0.25, -1.0, 1.0],          # on the edge: row 3, column 0
        [below, -1.0 + 0.25 * 7, 2.0],         # just below: row 2, column 7
        [-2.0 + 16 * 0.25, 0.0, 3.0],          # x on the far edge: outside
        [-2.0, -1.0 + 8 * 0.25, 4.0],          # y on the far edge: outside
        [np.nextafter(-2.0, -np.inf), 0.0, 5.0],  # just before the origin: outside
    ])
    stats = grid.fuse(pts, 0.0)
    assert (stats.fused, stats.outside, stats.nonfinite) == (2, 3, 0)
    layers = grid.layers()
    assert layers.count[3, 0] == 1 and layers.elevation[3, 0] == 1.0
    assert layers.count[2, 7] == 1 and layers.elevation[2, 7] == 2.0
    assert layers.count.sum() == 2
    i, j = geometry.cell_index(pts[:2, 0], pts[:2, 1])
    assert i.tolist() == [3, 2] and j.tolist() == [0, 7]


def test_layers_and_float64_variance() -> None:
    rng = np.random.default_rng(3)
    geometry = GridGeometry(0.0, 0.0, 1.0, 2, 2)
    grid = TerrainGrid(geometry)
    z = 100.0 + rng.normal(0.0, 0.01, 5000)  # small spread far from zero
    pts = np.column_stack([np.full(5000, 0.5), np.full(5000, 1.5), z])
    for chunk in np.array_split(pts, 7):
        grid.fuse(chunk, 4.0)
    layers = grid.layers()
    assert layers.count.dtype == np.int32 and layers.elevation.dtype == np.float32
    assert layers.count[0, 1] == 5000
    assert layers.variance[0, 1] == pytest.approx(np.var(z), rel=1e-6)
    assert layers.elevation[0, 1] == pytest.approx(np.mean(z), abs=1e-5)
    assert layers.min_height[0, 1] == np.float32(z.min())
    assert layers.max_height[0, 1] == np.float32(z.max())
    assert layers.last_seen is not None and layers.last_seen[0, 1] == 4.0
    for name in ("elevation", "min_height", "max_height", "variance", "last_seen"):
        assert np.isnan(getattr(layers, name)[0, 0]), name
    # one point: variance exactly 0, never negative
    grid.fuse(np.array([[1.5, 0.5, 0.1]]), 5.0)
    assert grid.layers().variance[1, 0] == 0.0


def test_reset_is_in_place() -> None:
    grid = TerrainGrid.centred(0, 0, 4, 4, 0.5)
    arrays = grid._accumulators()  # every stored array (min_z and max_z derive from them)
    grid.fuse(np.random.default_rng(0).uniform(-2, 2, (50, 3)), 1.0)
    grid.reset()
    assert [id(a) for a in arrays] == [id(a) for a in grid._accumulators()]
    assert len(arrays) == 9
    assert grid.count.sum() == 0 and np.all(grid.min_z == np.inf)
    assert np.all(grid.max_z == -np.inf) and np.all(grid.last_seen == -np.inf)


def test_bad_input_raises() -> None:
    grid = TerrainGrid.centred(0, 0, 4, 4, 0.5)
    with pytest.raises(ValueError):
        grid.fuse(np.zeros((3, 2)), 0.0)
    with pytest.raises(ValueError):
        grid.fuse(np.zeros((3, 3)), math.nan)
    with pytest.raises(ValueError):
        GridGeometry(0, 0, 0.0, 3, 3)
    with pytest.raises(ValueError):
        TerrainGrid(GridGeometry(0.1, 0, 0.25, 4, 4)).recentre(0, 0)


# --- scrolling -------------------------------------------------------------------------


def snapshot(grid: TerrainGrid) -> dict[tuple[int, int], tuple[float, ...]]:
    """Accumulators keyed by world cell index (origin index + grid index)."""
    geo = grid.geometry
    kx, ky = round(geo.origin_x / geo.gridsize), round(geo.origin_y / geo.gridsize)
    out = {}
    for c in range(geo.size):
        i, j = divmod(c, geo.cols)
        out[(kx + i, ky + j)] = (grid.count[c], grid.sum_z[c], grid.sum_z2[c], grid.min_z[c],
                                 grid.max_z[c], grid.last_seen[c])
    return out


EMPTY = (0, 0.0, 0.0, math.inf, -math.inf, -math.inf)


@pytest.mark.parametrize("move", [(0.9, 0.0), (-1.3, 0.45), (0.0, -2.1), (3.3, 3.7),
                                  (-0.1, 0.1), (40.0, 0.0), (-5.9, -5.9)])
def test_scrolling_keeps_every_cell_that_stays_inside(move: tuple[float, float]) -> None:
    rng = np.random.default_rng(11)
    grid = TerrainGrid.centred(10.0, -4.0, 6.0, 5.0, 0.2)  # 30 x 25 cells
    grid.fuse(rng.uniform(-3, 3, (4000, 3)) + [10.0, -4.0, 0.0], 1.0)
    before = snapshot(grid)
    shift = grid.recentre(10.0 + move[0], -4.0 + move[1])
    geo = grid.geometry
    assert geo.cell_index(10.0 + move[0], -4.0 + move[1]) == (geo.rows // 2, geo.cols // 2)
    after = snapshot(grid)
    kept = exposed = 0
    for key, values in after.items():
        if key in before:
            assert values == before[key], key
            kept += 1
        else:
            assert values == EMPTY, key
            exposed += 1
    assert kept + exposed == geo.size
    assert (shift == (0, 0)) == (exposed == 0)
    if move == (40.0, 0.0):
        assert kept == 0


def test_recentre_slack_and_fusion_after_scrolling() -> None:
    rng = np.random.default_rng(5)
    grid = TerrainGrid.centred(0.0, 0.0, 4.0, 4.0, 0.25)
    assert grid.recentre(0.3, -0.3, slack=2) == (0, 0)  # one cell: within the slack
    assert grid.recentre(0.8, 0.0, slack=2) == (3, 0)
    # a scrolled grid is indistinguishable from one built there and fed the kept data
    pts = rng.uniform(-1.0, 2.5, (500, 3))
    grid.fuse(pts, 2.0)
    fresh = TerrainGrid(grid.geometry)
    oracle = LoopGrid(grid.geometry)
    grid2 = TerrainGrid.centred(0.0, 0.0, 4.0, 4.0, 0.25)
    grid2.recentre(0.8, 0.0)
    grid2.fuse(pts, 2.0)
    fresh.fuse(pts, 2.0)
    oracle.fuse(pts, 2.0)
    oracle.assert_equal(fresh)
    oracle.assert_equal(grid2)


# --- the ego view ----------------------------------------------------------------------


def test_ego_view_samples_the_global_cell_under_each_ego_cell_centre() -> None:
    rng = np.random.default_rng(9)
    grid = TerrainGrid.centred(5.0, 3.0, 30.0, 30.0, 0.2)
    pts = rng.uniform(-15, 15, (60000, 3)) + [5.0, 3.0, 10.0]
    pts[:, 2] = 10.0 + 0.1 * pts[:, 0] - 0.05 * pts[:, 1] + rng.normal(0, 0.02, len(pts))
    grid.fuse(pts, 3.0)
    view = EgoView.ahead(depth=8.0, width=6.0, gridsize=0.2)
    assert view.geometry.origin_x == 0.0 and view.geometry.origin_y == pytest.approx(-3.0)
    vehicle = pose(6.0, 2.0, 10.3, yaw=math.radians(35), pitch=0.05)
    bumper = pose(2.45, 0.0, 0.17)
    map_pose = ego_map_pose(vehicle, bumper, -0.5)
    ego = view.sample(grid, map_pose)
    full = grid.layers()
    geo = grid.geometry
    yaw = math.radians(35)
    tz = map_pose[2, 3]
    checked = 0
    for i in range(view.geometry.rows):
        for j in range(view.geometry.cols):
            cx, cy = view.geometry.cell_center(i, j)
            wx = map_pose[0, 3] + math.cos(yaw) * cx - math.sin(yaw) * cy
            wy = map_pose[1, 3] + math.sin(yaw) * cx + math.cos(yaw) * cy
            gi = math.floor((wx - geo.origin_x) / geo.gridsize)
            gj = math.floor((wy - geo.origin_y) / geo.gridsize)
            if not (0 <= gi < geo.rows and 0 <= gj < geo.cols):
                assert ego.count[i, j] == 0 and np.isnan(ego.elevation[i, j])
                continue
            assert ego.count[i, j] == full.count[gi, gj]
            if full.count[gi, gj] == 0:
                assert np.isnan(ego.elevation[i, j]) and np.isnan(ego.max_height[i, j])
                continue
            assert ego.elevation[i, j] == pytest.approx(full.elevation[gi, gj] - tz, abs=1e-5)
            assert ego.max_height[i, j] == pytest.approx(full.max_height[gi, gj] - tz,
                                                         abs=1e-5)
            checked += 1
    assert checked > 0.9 * view.geometry.size
    # level ground under the bumper reads about 0 in the ego frame (ground 0.5 m below)
    assert map_pose[:3, :3] @ [0, 0, 1] == pytest.approx([0, 0, 1])
    assert yaw_of(map_pose) == pytest.approx(yaw)


def test_ego_map_pose_places_the_ground_along_the_bumper_frame_z() -> None:
    vehicle = pose(1.0, 2.0, 0.33, yaw=0.3, pitch=0.2)
    bumper = pose(2.45, 0.0, 0.17)
    map_pose = ego_map_pose(vehicle, bumper, -0.5)
    wb = vehicle @ bumper
    assert map_pose[:3, 3] == pytest.approx(wb[:3, 3] - 0.5 * wb[:3, 2])
    assert yaw_of(map_pose) == pytest.approx(0.3)
    level = ego_map_pose(pose(0, 0, 0.33), bumper, -0.5)
    assert level[:3, 3] == pytest.approx([2.45, 0.0, 0.0])  # on the ground


# --- poses -----------------------------------------------------------------------------


def test_interpolation_is_linear_in_translation_and_slerp_in_rotation() -> None:
    a = pose(0.0, 0.0, 0.0, yaw=0.2)
    b = pose(1.0, -2.0, 0.5, yaw=0.2 + math.radians(50))
    mid = interpolate_transform(a, b, 0.3)
    assert mid[:3, 3] == pytest.approx([0.3, -0.6, 0.15])
    assert yaw_of(mid) == pytest.approx(0.2 + 0.3 * math.radians(50))
    # general axis: equal angles either side, and on the geodesic
    c = pose(yaw=1.0, pitch=0.4, roll=-0.3)
    m = interpolate_transform(a, c, 0.5)
    whole = rotation_angle(a[:3, :3].T @ c[:3, :3])
    assert rotation_angle(a[:3, :3].T @ m[:3, :3]) == pytest.approx(whole / 2)
    assert rotation_angle(m[:3, :3].T @ c[:3, :3]) == pytest.approx(whole / 2)
    assert np.allclose(interpolate_transform(a, c, 0.0), a)
    assert np.allclose(interpolate_transform(a, c, 1.0), c)
    # across ±pi the short way round
    d = interpolate_transform(pose(yaw=math.pi - 0.1), pose(yaw=-math.pi + 0.1), 0.5)
    assert abs(yaw_of(d)) == pytest.approx(math.pi)


def _slerp_array_form(a: np.ndarray, b: np.ndarray, s: float) -> np.ndarray:
    """The interpolation written with numpy arrays throughout (the form the float-by-
    float implementation replaced): the reference for bit-for-bit equality."""
    q0 = grid_module._quaternion(a[:3, :3])
    q1 = grid_module._quaternion(b[:3, :3])
    dot = float(q0 @ q1)
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 0.9999995:
        q = q0 + s * (q1 - q0)
    else:
        theta = math.acos(dot)
        q = (math.sin((1 - s) * theta) * q0 + math.sin(s * theta) * q1) / math.sin(theta)
    w, x, y, z = q / np.linalg.norm(q)
    out = np.eye(4)
    out[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                   [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                   [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]]
    out[:3, 3] = a[:3, 3] + s * (b[:3, 3] - a[:3, 3])
    return out


def test_interpolation_equals_the_array_form_bit_for_bit() -> None:
    rng = np.random.default_rng(12)
    for _ in range(400):
        yaw, pitch, roll = rng.uniform(-math.pi, math.pi), *rng.uniform(-0.5, 0.5, 2)
        a = pose(*rng.normal(size=3) * 50, yaw=yaw, pitch=pitch, roll=roll)
        turn = 10.0 ** rng.uniform(-7, 0.5)  # both the linear blend and slerp
        b = pose(*(a[:3, 3] + rng.normal(size=3)), yaw=yaw + turn * rng.choice([-1, 1]),
                 pitch=pitch + turn * rng.uniform(-1, 1), roll=roll)
        s = float(rng.uniform())
        assert np.array_equal(interpolate_transform(a, b, s), _slerp_array_form(a, b, s))


def test_pose_buffer_lookups() -> None:
    buffer = PoseBuffer(capacity=4)
    assert buffer.lookup(0.0).status is PoseStatus.EMPTY
    for k in range(6):  # 0.1 s apart, 0.5 m/s east
        assert buffer.add(0.1 * k, pose(0.05 * k, 0.0, 0.0, yaw=0.02 * k))
    assert buffer.span == (pytest.approx(0.2), pytest.approx(0.5))
    assert buffer.lookup(0.15).status is PoseStatus.TOO_OLD  # dropped from the buffer
    assert buffer.lookup(0.55).status is PoseStatus.FUTURE
    result = buffer.lookup(0.45)
    assert result.status is PoseStatus.OK and result.transform is not None
    assert result.transform[0, 3] == pytest.approx(0.225)
    assert yaw_of(result.transform) == pytest.approx(0.09)
    exact = buffer.lookup(0.3)
    assert exact.transform is not None and np.array_equal(exact.transform,
                                                          pose(0.15, 0.0, 0.0, yaw=0.06))
    assert not buffer.add(0.5, pose())  # not newer: dropped
    assert buffer.statistics["out_of_order"] == 1
    assert buffer.statistics["lookup ok"] == 2 and buffer.statistics["lookup future"] == 1


def test_audit_margins() -> None:
    audit = PoseAudit.from_parameters(TerrainMapParameters())
    assert audit.max_velocity == 6.0 and audit.pose_interval == 0.1
    assert audit.orientation_error == pytest.approx(math.radians(2.0))
    # 6 m/s over 0.1 s plus one PoseInterval of margin: 1.2 m allowed
    assert audit.check(0.0, pose(), 0.1, pose(1.19)).ok
    assert not audit.check(0.0, pose(), 0.1, pose(1.21)).ok
    # rotation: 120 deg/s over 0.2 s + 2 x 2 deg = 28 deg, any axis
    assert audit.check(0.0, pose(), 0.1, pose(yaw=math.radians(27.9))).ok
    assert not audit.check(0.0, pose(), 0.1, pose(yaw=math.radians(28.1))).ok
    assert not audit.check(0.0, pose(), 0.1, pose(roll=math.radians(28.1))).ok
    result = audit.check(0.0, pose(), 1.0, pose(6.5))  # a long gap widens the allowance
    assert result.ok and result.allowed_distance == pytest.approx(6.6)
    with pytest.raises(ValueError):
        audit.check(1.0, pose(), 1.0, pose())


def test_a_jump_refuses_only_its_own_interval() -> None:
    buffer = PoseBuffer(capacity=16, audit=PoseAudit())
    for k in range(3):
        assert buffer.add(0.1 * k, pose(0.3 * k))
    assert not buffer.add(0.3, pose(5.0))          # GPS correction: a 4.4 m jump
    assert buffer.add(0.4, pose(5.3))              # ... after which poses agree again
    assert buffer.lookup(0.25).status is PoseStatus.IMPLAUSIBLE
    assert buffer.lookup(0.3).status is PoseStatus.IMPLAUSIBLE
    assert buffer.lookup(0.35).status is PoseStatus.OK
    assert buffer.lookup(0.15).status is PoseStatus.OK
    # a one-pose glitch (out and back) refuses both intervals around it
    assert not buffer.add(0.5, pose(5.6, yaw=math.pi))
    assert not buffer.add(0.6, pose(5.9))
    assert buffer.lookup(0.45).status is PoseStatus.IMPLAUSIBLE
    assert buffer.lookup(0.55).status is PoseStatus.IMPLAUSIBLE
    assert buffer.statistics["implausible"] == 3
    assert buffer.statistics["lookup implausible"] == 4
    with pytest.raises(ValueError):
        buffer.add(0.7, np.full((4, 4), np.nan))


# --- stereo balance --------------------------------------------------------------------


def test_stereo_balance() -> None:
    balance = StereoBalance(stereo_period=0.5, window=1.0)
    assert balance.stride(0.0, 76800) == 1  # no lasers yet: keep everything
    t = 0.0
    for k in range(75):  # two lasers, 37.5 lines/s, 361 points each, over one second
        t = k / 75.0
        balance.note_laser(t, 361)
    budget = balance.budget(t)
    assert budget == round(75 * 361 * 0.5)
    assert balance.stride(t, 76800) == 6
    assert balance.stride(t, 4800) == 1
    frame = np.arange(76800 * 3, dtype=np.float32).reshape(76800, 3)
    kept = balance.select(t, frame)
    assert len(kept) == 12800 and np.shares_memory(kept, frame)
    assert balance.budget(t + 5.0) is None  # the lasers went quiet


# -- the compiled fusion (decision 0014) against the numpy form ---------------------------------


@pytest.mark.skipif(grid_module.FUSE_KERNEL is None,
                    reason="no compiled fusion (numba missing, or AFA_KERNELS=numpy)")
def test_compiled_fusion_is_bit_for_bit_the_numpy_one(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(11)
    grids = [TerrainGrid.centred(3.0, -2.0, 20.0, 30.0, 0.25, window=4.0) for _ in range(2)]
    kernel = grid_module.FUSE_KERNEL
    for step in range(40):
        n = int(rng.integers(0, 3000))
        points = rng.normal(scale=6.0, size=(n, 3))
        points[:, 2] = np.where(rng.random(n) < 0.3, 0.0, points[:, 2])
        points[:, 2] *= rng.choice([1.0, -1.0], n)  # ties between 0.0 and -0.0
        if n:
            spoil = rng.integers(0, n, size=max(1, n // 50))
            points[spoil, rng.integers(0, 3, size=spoil.size)] = rng.choice(
                [np.nan, np.inf, -np.inf], size=spoil.size)
            points[spoil[::2], 0] = 1e30  # finite, far outside
        time = float(step) if step % 7 else step - 3.5  # now and then a late batch
        transform = np.eye(4)
        transform[:3, 3] = rng.normal(size=3)
        stats = []
        for grid, compiled in zip(grids, (True, False), strict=True):
            monkeypatch.setattr(grid_module, "FUSE_KERNEL", kernel if compiled else None)
            if step % 2:
                stats.append(grid.fuse(points.astype(np.float32), time))
            else:
                stats.append(grid.fuse_transformed(points, transform, time))
            if step == 20:
                grid.recentre(6.0, 1.0)
        assert stats[0] == stats[1]
    for a, b in zip(grids[0]._accumulators(), grids[1]._accumulators(), strict=True):
        assert a.tobytes() == b.tobytes()
    assert grids[0].fused_total > 10_000 and grids[0].nonfinite_total > 100
