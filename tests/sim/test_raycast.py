"""Ray casting: planes by hand, box faces, depth images, and a brute-force oracle."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from afa.sim import Obstacle, Terrain, TerrainSpec, cast_rays, depth_image, laser_scan, raycast
from afa.sim.world import load_world

WORLDS = Path(__file__).resolve().parents[2] / "configs" / "worlds"

FLAT = TerrainSpec(width=80, depth=80, resolution=0.1)


def pitch_down(angle_deg: float) -> np.ndarray:
    """World-from-laser rotation of a laser facing east, tilted nose-down by the angle."""
    p = math.radians(angle_deg)
    return np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])


def test_flat_plane_ranges_are_h_over_sin_depression() -> None:
    terrain = Terrain.from_spec(FLAT)
    bearings = np.radians(np.arange(-80.0, 80.5, 0.5))
    ranges = laser_scan(terrain, [0, 0, 1.5], pitch_down(10), bearings, max_range=20.0)
    # a beam at bearing b in a plane tilted down 10 deg descends at sin(10) cos(b)
    expected = 1.5 / (math.sin(math.radians(10)) * np.cos(bearings))
    hit = expected <= 20.0
    assert hit.sum() > 200 and (~hit).sum() > 20
    np.testing.assert_allclose(ranges[hit], expected[hit], rtol=0, atol=1e-6)
    assert np.isnan(ranges[~hit]).all()
    assert ranges[160] == pytest.approx(1.5 / math.sin(math.radians(10)), abs=1e-6)  # b = 0


def test_sloped_plane() -> None:
    terrain = Terrain.from_spec(TerrainSpec(width=80, depth=80, resolution=0.1, slope_east=0.05))
    bearings = np.radians(np.arange(-30.0, 31.0, 5.0))
    ranges = laser_scan(terrain, [-20, 3, 2.0], pitch_down(5), bearings, max_range=30.0)
    # ground z = 0.05 e; ray (-20 + t dx, 3 + t dy, 2 + t dz) meets it at
    # 2 + t dz = 0.05 (-20 + t dx)  =>  t = (2 + 1) / (0.05 dx - dz)
    p = math.radians(5)
    dx = math.cos(p) * np.cos(bearings)
    dz = -math.sin(p) * np.cos(bearings)
    np.testing.assert_allclose(ranges, 3.0 / (0.05 * dx - dz), atol=1e-5)


def test_scan_hits_box_face_at_known_distance() -> None:
    # heading 90: the 1 m length runs east, so the west face is at east = 9.5
    box = Obstacle("box", east=10, north=0, length=1, width=4, height=2, heading=90)
    terrain = Terrain.from_spec(FLAT, [box])
    bearings = np.radians([0.0, 5.0, -5.0, 30.0])
    ranges = laser_scan(terrain, [0, 0, 1.0], np.eye(3), bearings, max_range=15.0)
    res = terrain.resolution
    assert ranges[0] == pytest.approx(9.5, abs=res)
    for k in (1, 2):  # still on the 4 m wide face: 9.5 / cos(5 deg)
        assert ranges[k] == pytest.approx(9.5 / math.cos(math.radians(5)), abs=res)
    assert math.isnan(ranges[3])  # passes south of the box, never meets level ground
    # above the box: nothing within range
    assert np.isnan(laser_scan(terrain, [0, 0, 2.5], np.eye(3), bearings, 15.0)).all()


def test_cylinder_distance() -> None:
    post = Obstacle("cylinder", east=0, north=12, radius=0.5, height=3)
    terrain = Terrain.from_spec(FLAT, [post])
    # laser facing north: rotate laser x (forward) onto world y
    facing_north = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]])
    r = laser_scan(terrain, [0, 0, 1.0], facing_north, [0.0], 30.0)
    assert r[0] == pytest.approx(11.5, abs=terrain.resolution)


def test_depth_image_of_plane_seen_from_above() -> None:
    terrain = Terrain.from_spec(FLAT)
    # optical frame z (forward) = world down, x = east, y = south
    down = np.array([[1, 0, 0], [0, -1, 0], [0, 0, -1]], dtype=float)
    depth = depth_image(terrain, [0, 0, 5.0], down, width=32, height=24, fov=60, max_range=20)
    assert depth.shape == (24, 32)
    np.testing.assert_allclose(depth, 5.0, atol=1e-6)


def test_depth_image_of_wall() -> None:
    wall = Obstacle("box", east=8, north=0, length=1, width=30, height=5, heading=90)
    terrain = Terrain.from_spec(FLAT, [wall])
    # camera 1.5 m up looking east: optical z = east, x = south, y = down
    east = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]], dtype=float)
    depth = depth_image(terrain, [0, 0, 1.5], east, width=40, height=30, fov=40, max_range=30)
    # upper half sees the wall face at east 7.5 (Z is the distance along the axis)
    np.testing.assert_allclose(depth[:15], 7.5, atol=terrain.resolution)
    # the lowest row looks down at 1.5 m height: ground hit before the wall
    f = 20 / math.tan(math.radians(20))
    v = (29.5 - 15) / f  # image y of the bottom row's centre, optical units
    assert depth[29, 20] == pytest.approx(1.5 / v, rel=1e-6)


def _rough_world() -> Terrain:
    spec = TerrainSpec(width=40, depth=40, resolution=0.1, roughness=0.15, seed=4,
                       slope_east=0.03)
    obstacles = [Obstacle("box", east=6, north=2, length=2, width=1, height=1.0, heading=20),
                 Obstacle("cylinder", east=-5, north=-4, radius=0.6, height=1.5),
                 Obstacle("ditch", east=3, north=-6, length=8, width=2, depth=1.0, heading=60)]
    return Terrain.from_spec(spec, obstacles)


def _brute_force(terrain: Terrain, origins: np.ndarray, directions: np.ndarray,
                 max_range: float) -> np.ndarray:
    """The oracle: a plain 5 mm march per ray against Terrain.height."""
    t = np.arange(0.0, max_range, 0.005)
    out = np.full(len(directions), np.nan)
    for k in range(len(directions)):
        points = origins[k] + t[:, None] * directions[k]
        inside = terrain.contains(points[:, 0], points[:, 1])
        below = (points[:, 2] <= terrain.height(points[:, 0], points[:, 1])) & inside
        if below.any():
            out[k] = t[np.argmax(below)]
    return out


def _random_directions(rng: np.random.Generator, n: int) -> np.ndarray:
    az = rng.uniform(0, 2 * math.pi, n)
    el = rng.uniform(-math.radians(40), math.radians(3), n)
    return np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def test_brute_force_agreement_on_rough_terrain_with_obstacles() -> None:
    terrain = _rough_world()
    rng = np.random.default_rng(9)
    n = 60
    origins = np.column_stack([rng.uniform(-10, 10, n), rng.uniform(-10, 10, n),
                               rng.uniform(1.0, 3.0, n)])
    directions = _random_directions(rng, n)
    ranges = cast_rays(terrain, origins, directions, 25.0)
    expected = _brute_force(terrain, origins, directions, 25.0)
    np.testing.assert_array_equal(np.isnan(ranges), np.isnan(expected))
    np.testing.assert_allclose(ranges, expected, atol=0.01)
    assert np.isfinite(ranges).sum() > n // 2


@pytest.mark.parametrize("origin", [(-8.0, 10.0, 1.8),  # well inside: no clamping needed
                                    (18.5, 17.0, 1.2)])  # rays leave the grid
def test_brute_force_agreement_from_one_origin(origin: tuple[float, float, float]) -> None:
    terrain = _rough_world()
    directions = _random_directions(np.random.default_rng(3), 80)
    ranges = cast_rays(terrain, origin, directions, 8.183)
    expected = _brute_force(terrain, np.tile(origin, (80, 1)), directions, 8.183)
    np.testing.assert_array_equal(np.isnan(ranges), np.isnan(expected))
    np.testing.assert_allclose(ranges, expected, atol=0.01)
    assert np.isfinite(ranges).sum() > 20


def test_rays_leaving_the_grid_and_starting_underground() -> None:
    terrain = Terrain.from_spec(FLAT)
    r = cast_rays(terrain, [[35, 0, 0.5], [0, 0, -1.0]], [[1, 0, -0.01], [1, 0, 0]], 50.0)
    assert math.isnan(r[0])  # would reach the ground at 50 m, but leaves the grid at 40
    assert r[1] == 0.0


def test_bad_arguments() -> None:
    terrain = Terrain.from_spec(FLAT)
    with pytest.raises(ValueError):
        cast_rays(terrain, [0, 0, 1], [[1, 0]], 10.0)
    with pytest.raises(ValueError):
        cast_rays(terrain, [0, 0, 1], [[0, 0, 0]], 10.0)
    with pytest.raises(ValueError):
        cast_rays(terrain, [0, 0, 1], [[1, 0, 0]], 0.0)
    with pytest.raises(ValueError):
        laser_scan(terrain, [0, 0, 1], np.eye(2), [0.0], 10.0)
    assert cast_rays(terrain, [0, 0, 1], np.zeros((0, 3)), 10.0).shape == (0,)


# -- the compiled caster (decision 0014) against the numpy passes ------------------------------

compiled = pytest.mark.skipif(raycast.KERNEL is None,
                              reason="no compiled caster (numba missing, or AFA_KERNELS=numpy)")


def _both(monkeypatch: pytest.MonkeyPatch, cast: Callable[..., np.ndarray], *args: object
          ) -> tuple[np.ndarray, np.ndarray]:
    fast = cast(*args)
    monkeypatch.setattr(raycast, "KERNEL", None)
    slow = cast(*args)
    monkeypatch.undo()
    return fast, slow


@compiled
@pytest.mark.parametrize("world", ["rock-field", "forest", "long-wall", "slalom"])
def test_compiled_caster_is_bit_for_bit_the_numpy_one(world: str,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    spec = load_world(WORLDS / f"{world}.xml")
    terrain = Terrain.from_spec(spec.terrain, spec.obstacles)
    rng = np.random.default_rng(7)
    half_w, half_d = terrain.spec.width / 2, terrain.spec.depth / 2
    hits = 0
    for trial in range(60):
        origin = np.array([rng.uniform(-half_w - 3, half_w + 3),
                           rng.uniform(-half_d - 3, half_d + 3), rng.uniform(-0.3, 2.5)])
        directions = _random_directions(rng, 361)
        if trial % 3 == 0:  # one origin per ray
            origin = origin + rng.normal(scale=0.5, size=(361, 3))
        max_range = (8.183, 25.0, 2.0)[trial % 3]
        fast, slow = _both(monkeypatch, cast_rays, terrain, origin, directions, max_range)
        np.testing.assert_array_equal(fast, slow)
        hits += int(np.isfinite(fast).sum())
    camera = pitch_down(15)[:, [1, 2, 0]] * [-1, -1, 1]
    fast, slow = _both(monkeypatch, depth_image, terrain, [0, 0, 1.5], camera, 80, 60)
    np.testing.assert_array_equal(fast, slow)
    assert hits > 500


@compiled
def test_compiled_caster_agrees_with_brute_force(monkeypatch: pytest.MonkeyPatch) -> None:
    terrain = _rough_world()
    directions = _random_directions(np.random.default_rng(5), 80)
    origin = (18.5, 17.0, 1.2)
    fast, slow = _both(monkeypatch, cast_rays, terrain, origin, directions, 8.183)
    expected = _brute_force(terrain, np.tile(origin, (80, 1)), directions, 8.183)
    np.testing.assert_array_equal(fast, slow)
    np.testing.assert_array_equal(np.isnan(fast), np.isnan(expected))
    np.testing.assert_allclose(fast, expected, atol=0.01)


@compiled
def test_compiled_caster_normalises_as_the_numpy_one(monkeypatch: pytest.MonkeyPatch) -> None:
    # the kernel normalises the directions itself (decision 0030): lengths from 1e-3 to
    # 1e3, and directions whose three squares round differently by the order of the sum
    spec = load_world(WORLDS / "rock-field.xml")
    terrain = Terrain.from_spec(spec.terrain, spec.obstacles)
    rng = np.random.default_rng(11)
    for _ in range(40):
        directions = _random_directions(rng, 361) * rng.choice([1e-3, 0.7, 1.0, 3.0, 1e3],
                                                               size=(361, 1))
        directions *= rng.uniform(0.999, 1.001, size=(361, 3))  # not exactly unit
        origin = np.array([rng.uniform(-20, 20), rng.uniform(-20, 20), rng.uniform(0.5, 2.0)])
        fast, slow = _both(monkeypatch, cast_rays, terrain, origin, directions, 8.183)
        np.testing.assert_array_equal(fast, slow)
    for bad in ([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]], [[np.nan, 0.0, 1.0]]):
        with pytest.raises(ValueError, match="non-zero"):
            cast_rays(terrain, [0, 0, 1], bad, 8.0)
        monkeypatch.setattr(raycast, "KERNEL", None)
        with pytest.raises(ValueError, match="non-zero"):
            cast_rays(terrain, [0, 0, 1], bad, 8.0)
        monkeypatch.undo()

