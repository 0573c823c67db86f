"""Terrain heightfield: slope, obstacles, lookups, roughness, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from afa.sim import Obstacle, Terrain, TerrainSpec
from afa.sim.terrain import BLOCK_PAD

SLOPE = TerrainSpec(width=60, depth=40, resolution=0.1, slope_east=0.02, slope_north=-0.03)


def plane(e: float, n: float) -> float:
    return 0.02 * e - 0.03 * n


def test_slope_plane_heights() -> None:
    terrain = Terrain.from_spec(SLOPE)
    rng = np.random.default_rng(1)
    e = rng.uniform(-29, 29, 200)
    n = rng.uniform(-19, 19, 200)
    np.testing.assert_allclose(terrain.height(e, n), 0.02 * e - 0.03 * n, atol=2e-6)
    assert terrain.height(10.0, -5.0) == pytest.approx(0.35, abs=1e-6)
    assert isinstance(terrain.height(10.0, -5.0), float)
    assert terrain.obstacle_at(10.0, -5.0) == -1
    assert terrain.extent == pytest.approx((-30, 30, -20, 20))
    assert terrain.surface.shape == (401, 601) and terrain.surface.dtype == np.float32


def test_normal_of_slope() -> None:
    terrain = Terrain.from_spec(SLOPE)
    expected = np.array([-0.02, 0.03, 1.0]) / math.sqrt(0.02**2 + 0.03**2 + 1)
    np.testing.assert_allclose(terrain.normal(3.0, 4.0), expected, atol=1e-6)
    assert terrain.normal(np.zeros(5), np.zeros(5)).shape == (5, 3)


def test_box_with_heading_raises_the_surface() -> None:
    # 4 m long along heading 30 deg (clockwise from north), 2 m wide, 1.2 m tall
    box = Obstacle("box", east=10, north=5, length=4, width=2, height=1.2, heading=30)
    terrain = Terrain.from_spec(SLOPE, [box])
    s, c = math.sin(math.radians(30)), math.cos(math.radians(30))
    # 1.5 m along the heading and 0.6 m to its right: inside
    e, n = 10 + 1.5 * s + 0.6 * c, 5 + 1.5 * c - 0.6 * s
    assert terrain.height(e, n) == pytest.approx(plane(e, n) + 1.2, abs=2e-6)
    assert terrain.ground_height(e, n) == pytest.approx(plane(e, n), abs=2e-6)
    assert terrain.obstacle_at(e, n) == 0
    assert terrain.relief(e, n) == pytest.approx(1.2, abs=1e-6)
    # 2.3 m along the heading: beyond the 2 m half-length
    e, n = 10 + 2.3 * s, 5 + 2.3 * c
    assert terrain.height(e, n) == pytest.approx(plane(e, n), abs=2e-6)
    assert terrain.obstacle_at(e, n) == -1
    # 1.2 m to the right: beyond the 1 m half-width
    e, n = 10 + 1.2 * c, 5 - 1.2 * s
    assert terrain.obstacle_at(e, n) == -1


def test_cylinder_and_ditch() -> None:
    cylinder = Obstacle("cylinder", east=-10, north=0, radius=0.5, height=0.8)
    ditch = Obstacle("ditch", east=5, north=-10, length=6, width=1.5, depth=0.8, heading=90)
    terrain = Terrain.from_spec(SLOPE, [cylinder, ditch])
    assert terrain.height(-10.2, 0.2) == pytest.approx(plane(-10.2, 0.2) + 0.8, abs=2e-6)
    assert terrain.obstacle_at(-10.3, -0.3) == 0
    assert terrain.height(-10.6, 0.0) == pytest.approx(plane(-10.6, 0.0), abs=2e-6)
    assert terrain.obstacle_at(-10.0, 0.65) == -1
    # heading 90: the 6 m length runs east-west, the 1.5 m width north-south
    assert terrain.height(7.5, -10.5) == pytest.approx(plane(7.5, -10.5) - 0.8, abs=2e-6)
    assert terrain.obstacle_at(7.5, -10.5) == 1
    assert terrain.relief(7.5, -10.5) == pytest.approx(-0.8, abs=1e-6)
    assert terrain.obstacle_at(5.0, -11.0) == -1
    assert terrain.obstacle_at(8.2, -10.0) == -1
    ids = terrain.obstacle_at(np.array([-10.0, 5.0, 0.0]), np.array([0.0, -10.0, 0.0]))
    assert ids.tolist() == [0, 1, -1]


def test_overlapping_obstacles() -> None:
    low = Obstacle("box", east=0, north=0, length=4, width=4, height=0.5)
    high = Obstacle("cylinder", east=0, north=0, radius=1, height=2.0)
    lower = Obstacle("box", east=0, north=0, length=1, width=1, height=0.2)
    terrain = Terrain.from_spec(SLOPE, [low, high, lower])
    assert terrain.height(0.0, 0.0) == pytest.approx(2.0, abs=1e-6)  # max wins
    assert terrain.height(1.5, 1.5) == pytest.approx(plane(1.5, 1.5) + 0.5, abs=2e-6)
    assert terrain.obstacle_at(0.0, 0.0) == 2  # the last one in file order


def test_off_grid_is_clamped_and_reported() -> None:
    terrain = Terrain.from_spec(SLOPE)
    assert terrain.height(100.0, 0.0) == pytest.approx(plane(30.0, 0.0), abs=2e-6)
    assert terrain.contains(np.array([0.0, 31.0]), np.array([0.0, 0.0])).tolist() == [True, False]
    assert terrain.obstacle_at(100.0, 0.0) == -1


def test_roughness_is_seeded_smooth_and_of_the_stated_rms() -> None:
    spec = TerrainSpec(width=120, depth=120, resolution=0.2, roughness=0.05, seed=7)
    a = Terrain.from_spec(spec)
    b = Terrain.from_spec(spec)
    assert np.array_equal(a.surface, b.surface)
    c = Terrain.from_spec(TerrainSpec(width=120, depth=120, resolution=0.2, roughness=0.05, seed=8))
    assert not np.array_equal(a.surface, c.surface)
    rms = float(np.sqrt(np.mean(a.ground.astype(np.float64) ** 2)))
    assert 0.8 * 0.05 < rms < 1.2 * 0.05
    # smooth: neighbouring samples differ by far less than the amplitude
    assert np.abs(np.diff(a.ground, axis=1)).max() < 0.05


def test_roughness_does_not_depend_on_resolution() -> None:
    def build(resolution: float) -> Terrain:
        return Terrain.from_spec(TerrainSpec(width=20, depth=20, resolution=resolution,
                                             roughness=0.03, seed=3))

    fine, coarse = build(0.1), build(0.5)
    np.testing.assert_allclose(fine.ground[::5, ::5], coarse.ground, atol=1e-6)


def test_block_max_bounds_every_bilinear_height() -> None:
    spec = TerrainSpec(width=30, depth=30, resolution=0.1, roughness=0.1, seed=2)
    terrain = Terrain.from_spec(spec, [Obstacle("cylinder", east=3, north=3, radius=0.4, height=1)])
    bmax = terrain.block_max(8)
    rng = np.random.default_rng(0)
    e = rng.uniform(-15, 15, 5000)
    n = rng.uniform(-15, 15, 5000)
    block = 8 * terrain.resolution
    bi = np.floor((e + 15) / block).astype(int) + BLOCK_PAD
    bj = np.floor((n + 15) / block).astype(int) + BLOCK_PAD
    assert np.all(terrain.height(e, n) <= bmax[bj, bi] + 1e-6)
    # and for points up to a block east and north of them (a segment's reach from its
    # south-west corner)
    for de, dn in [(0.8, 0.0), (0.0, 0.8), (0.8, 0.8), (0.3, 0.7)]:
        assert np.all(terrain.height(e + de, n + dn) <= bmax[bj, bi] + 1e-6)
    # ... which is not a 3 x 3 neighbourhood: the bound is tighter than the maximum
    assert np.mean(bmax[bj, bi] < terrain.surface.max()) > 0.5
    assert bmax.max() == pytest.approx(terrain.surface.max())
    assert np.isneginf(bmax[0]).all() and np.isneginf(bmax[:, -1]).all()


def test_height_at_one_point_agrees_with_the_vectorised_lookup() -> None:
    spec = TerrainSpec(width=30, depth=20, resolution=0.1, roughness=0.1, seed=5,
                       slope_east=0.02)
    terrain = Terrain.from_spec(spec, [Obstacle("box", east=2, north=1, length=2, width=1,
                                                height=0.5, heading=30)])
    rng = np.random.default_rng(1)
    east = rng.uniform(-18, 18, 300)  # some off the grid: both clamp to its edge
    north = rng.uniform(-12, 12, 300)
    expected = terrain.height(east, north)
    got = [terrain.height_at(e, n) for e, n in zip(east, north, strict=True)]
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)


def test_grids_are_read_only() -> None:
    terrain = Terrain.from_spec(SLOPE)
    with pytest.raises(ValueError):
        terrain.surface[0, 0] = 1.0


def test_near_obstacle_along_a_path_answers_as_the_circle_test() -> None:
    """The cached gap (decision 0021) only skips work: along a winding path that passes
    close to, between and away from obstacles, in small and large steps, every answer is
    the plain test "within margin of some bounding circle"."""
    obstacles = [Obstacle("cylinder", east=-10, north=0, radius=0.5, height=0.8),
                 Obstacle("cylinder", east=3, north=4, radius=1.0, height=1.0),
                 Obstacle("box", east=8, north=-6, length=2, width=1, height=0.6)]
    terrain = Terrain.from_spec(SLOPE, obstacles)
    circles = [(o.east, o.north, o.bounding_radius()) for o in obstacles]
    t = np.linspace(0.0, 6 * math.pi, 700)
    path = np.stack([14 * np.cos(t / 3), 9 * np.sin(t)], axis=1)
    path = np.concatenate([path, path[::37]])  # then jumps across the field
    answers = []
    for (east, north), margin in zip(path, np.resize([0.5, 2.3, 4.0], len(path)), strict=True):
        expected = any(math.hypot(ce - east, cn - north) <= r + margin for ce, cn, r in circles)
        answers.append(expected)
        assert terrain.near_obstacle(float(east), float(north), float(margin)) is expected
    assert any(answers) and not all(answers)
