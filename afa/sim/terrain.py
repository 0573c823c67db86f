"""The 2.5-D heightfield of a simulated world: ground, obstacles and an obstacle-id grid.

Grid layout: samples at ``east[i] = -width/2 + i*resolution`` and
``north[j] = -depth/2 + j*resolution``; arrays are indexed ``[j, i]`` (north row, east
column), float32 heights in metres above the origin's elevation (up in the local ENU
tangent plane).

- ``ground``: planar slope + seeded roughness (a sum of random Fourier modes, so the
  same seed gives the same ground at any resolution; RMS = ``roughness``).
- ``surface``: ground with obstacles: boxes and cylinders raise it to ground + height
  (flat against the ground's own shape), ditches lower it to ground - depth. Where
  obstacles overlap, positive ones take the maximum, ditches the minimum.
- ``ids``: int16, the index (in the world file's order) of the obstacle that last
  shaped each sample, ``-1`` for bare ground.

Lookups are vectorised over numpy arrays; points outside the grid are clamped to its edge
(the world continues as its border), and :meth:`Terrain.contains` tells them apart.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from afa.sim.world import (
    MAX_RASTER_CELLS,
    MAX_TERRAIN_CELLS,
    Obstacle,
    TerrainSpec,
    raster_cells,
    raster_window,
    terrain_cells,
)

__all__ = ["Terrain", "ROUGHNESS_MODES", "ROUGHNESS_WAVELENGTHS", "BLOCK_PAD", "OFF_GRID_HEIGHT"]

#: Padding (in blocks) around :meth:`Terrain.block_max`'s array.
BLOCK_PAD = 2

#: Height of the border around :meth:`Terrain.padded_surface`: far below anything a
#: ray can reach, finite so that interpolating towards it stays a number.
OFF_GRID_HEIGHT = -1e30

#: Number of Fourier modes in the roughness field.
ROUGHNESS_MODES = 48
#: Shortest and longest roughness wavelength (m); log-uniformly distributed.
ROUGHNESS_WAVELENGTHS = (1.5, 30.0)

FloatArray = NDArray[np.float64]


class Terrain:
    """A heightfield built from a :class:`TerrainSpec` and obstacles (see module doc)."""

    def __init__(self, spec: TerrainSpec, ground: NDArray[np.float32],
                 surface: NDArray[np.float32], ids: NDArray[np.int16],
                 obstacles: Sequence[Obstacle] = ()) -> None:
        if ground.shape != surface.shape or ground.shape != ids.shape or ground.ndim != 2:
            raise ValueError("ground, surface and ids must be 2-D arrays of one shape")
        self.spec = spec
        self.obstacles: tuple[Obstacle, ...] = tuple(obstacles)
        self.resolution = float(spec.resolution)
        self.ny, self.nx = ground.shape
        self.east0 = -spec.width / 2.0
        self.north0 = -spec.depth / 2.0
        self.ground = ground
        self.surface = surface
        self.ids = ids
        for array in (self.ground, self.surface, self.ids):
            array.flags.writeable = False
        self._block_cache: dict[int, NDArray[np.float32]] = {}
        self._ray_tables: dict[int, tuple[NDArray[np.float32], int, int,
                                          NDArray[np.float32], int]] = {}
        self._padded: NDArray[np.float32] | None = None
        self._circles: NDArray[np.float64] | None = None  # east, north, bounding radius
        self._last_gap = (0.0, 0.0, -math.inf)  # near_obstacle's last point, its gap

    # ------------------------------------------------------------------ building
    @classmethod
    def from_spec(cls, spec: TerrainSpec, obstacles: Sequence[Obstacle] = ()) -> Terrain:
        """Build the heightfield: slope + roughness, then each obstacle in order.

        Raises ValueError beyond the limits a world file is held to (``afa.sim.world``:
        grid samples, obstacles, rasterised samples), which bound the time and memory of
        a build to seconds and about half a gigabyte.
        """
        if not terrain_cells(spec) <= MAX_TERRAIN_CELLS:
            raise ValueError(f"a terrain grid of more than {MAX_TERRAIN_CELLS} samples")
        if len(obstacles) > np.iinfo(np.int16).max:
            raise ValueError(f"at most {np.iinfo(np.int16).max} obstacles")
        if sum(raster_cells(o, spec) for o in obstacles) > MAX_RASTER_CELLS:
            raise ValueError(f"obstacles covering more than {MAX_RASTER_CELLS} grid samples")
        res = spec.resolution
        nx = int(round(spec.width / res)) + 1
        ny = int(round(spec.depth / res)) + 1
        east: FloatArray = -spec.width / 2.0 + res * np.arange(nx, dtype=np.float64)
        north: FloatArray = -spec.depth / 2.0 + res * np.arange(ny, dtype=np.float64)
        ground = (spec.slope_north * north[:, None] + spec.slope_east * east[None, :])
        if spec.roughness > 0:
            ground = ground + _roughness(spec.roughness, spec.seed, east, north)
        ground32 = np.ascontiguousarray(ground, dtype=np.float32)
        surface = ground32.copy()
        ids = np.full(ground32.shape, -1, dtype=np.int16)
        for index, obstacle in enumerate(obstacles):
            _rasterise(obstacle, index, spec, east, north, ground32, surface, ids)
        return cls(spec, ground32, surface, ids, obstacles)

    # ------------------------------------------------------------------ geometry
    @property
    def east(self) -> FloatArray:
        """East coordinates of the grid columns (m)."""
        result: FloatArray = self.east0 + self.resolution * np.arange(self.nx, dtype=np.float64)
        return result

    @property
    def north(self) -> FloatArray:
        """North coordinates of the grid rows (m)."""
        result: FloatArray = self.north0 + self.resolution * np.arange(self.ny, dtype=np.float64)
        return result

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(east_min, east_max, north_min, north_max) of the grid (m)."""
        return (self.east0, self.east0 + (self.nx - 1) * self.resolution,
                self.north0, self.north0 + (self.ny - 1) * self.resolution)

    def contains(self, east: ArrayLike, north: ArrayLike) -> Any:
        """Whether points lie on the grid (bool or bool array)."""
        e0, e1, n0, n1 = self.extent
        e, n = np.asarray(east), np.asarray(north)
        return (e >= e0) & (e <= e1) & (n >= n0) & (n <= n1)

    # ------------------------------------------------------------------ lookups
    def height(self, east: ArrayLike, north: ArrayLike) -> Any:
        """Surface height (m, with obstacles) by bilinear interpolation; float or array."""
        return _scalar_or_array(self._bilinear(self.surface, east, north), east, north)

    def height_at(self, east: float, north: float) -> float:
        """:meth:`height` of one point, in plain Python (a few microseconds instead of a
        numpy round trip; the vehicle model asks for four per step)."""
        fx = min(max((east - self.east0) / self.resolution, 0.0), self.nx - 1.0)
        fy = min(max((north - self.north0) / self.resolution, 0.0), self.ny - 1.0)
        i = min(int(fx), self.nx - 2)
        j = min(int(fy), self.ny - 2)
        tx, ty = fx - i, fy - j
        z = self.surface.item
        near = z(j, i) * (1 - tx) + z(j, i + 1) * tx
        far = z(j + 1, i) * (1 - tx) + z(j + 1, i + 1) * tx
        return near * (1 - ty) + far * ty

    def ground_height(self, east: ArrayLike, north: ArrayLike) -> Any:
        """Ground height (m, without obstacles) by bilinear interpolation."""
        return _scalar_or_array(self._bilinear(self.ground, east, north), east, north)

    def normal(self, east: ArrayLike, north: ArrayLike) -> NDArray[np.float64]:
        """Unit upward surface normal(s) (..., 3) in ENU, from central differences of
        :meth:`height` one grid step either side."""
        e = np.asarray(east, dtype=np.float64)
        n = np.asarray(north, dtype=np.float64)
        h = self.resolution
        z = self.surface
        dzde = (self._bilinear(z, e + h, n) - self._bilinear(z, e - h, n)) / (2 * h)
        dzdn = (self._bilinear(z, e, n + h) - self._bilinear(z, e, n - h)) / (2 * h)
        v = np.stack([-dzde, -dzdn, np.ones_like(dzde)], axis=-1)
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    def obstacle_at(self, east: ArrayLike, north: ArrayLike) -> Any:
        """Index of the obstacle occupying the nearest grid sample, -1 for bare ground or
        off the grid; int or int array."""
        j, i, inside = self._nearest(east, north)
        out = np.where(inside, self.ids[j, i], -1).astype(np.int64)
        return int(out) if out.ndim == 0 else out

    def relief(self, east: ArrayLike, north: ArrayLike) -> Any:
        """Surface minus ground at the nearest sample (m): an obstacle's height above the
        ground (> 0) or a ditch's depth (< 0); 0 off the grid."""
        j, i, inside = self._nearest(east, north)
        out = np.where(inside, self.surface[j, i].astype(np.float64) - self.ground[j, i], 0.0)
        return float(out) if out.ndim == 0 else out

    # ------------------------------------------------------------------ internals
    def grid_coordinates(self, east: ArrayLike, north: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Fractional (column, row) grid coordinates of points."""
        e = np.asarray(east, dtype=np.float64)
        n = np.asarray(north, dtype=np.float64)
        return (e - self.east0) / self.resolution, (n - self.north0) / self.resolution

    def _nearest(self, east: ArrayLike, north: ArrayLike
                 ) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
        fx, fy = self.grid_coordinates(east, north)
        i = np.rint(fx)
        j = np.rint(fy)
        inside = (i >= 0) & (i <= self.nx - 1) & (j >= 0) & (j <= self.ny - 1)
        i = np.clip(i, 0, self.nx - 1).astype(np.intp)
        j = np.clip(j, 0, self.ny - 1).astype(np.intp)
        return j, i, inside

    def _bilinear(self, grid: NDArray[np.float32], east: ArrayLike,
                  north: ArrayLike) -> FloatArray:
        fx, fy = self.grid_coordinates(east, north)
        fx = np.clip(fx, 0.0, self.nx - 1.0)
        fy = np.clip(fy, 0.0, self.ny - 1.0)
        i = np.minimum(fx.astype(np.intp), self.nx - 2)
        j = np.minimum(fy.astype(np.intp), self.ny - 2)
        tx = fx - i
        ty = fy - j
        z00 = grid[j, i].astype(np.float64)
        z01 = grid[j, i + 1]
        z10 = grid[j + 1, i]
        z11 = grid[j + 1, i + 1]
        return (z00 * (1 - tx) + z01 * tx) * (1 - ty) + (z10 * (1 - tx) + z11 * tx) * ty

    def near_obstacle(self, east: float, north: float, margin: float) -> bool:
        """Whether (east, north) lies within ``margin`` metres of any obstacle's bounding
        circle (a cheap test before looking at the grid)."""
        if self._circles is None:
            self._circles = np.array([(o.east, o.north, o.bounding_radius())
                                      for o in self.obstacles], dtype=np.float64).reshape(-1, 3)
        c = self._circles
        if not len(c):
            return False
        # The gap (distance less radius) to the nearest circle changes by no more than
        # the point moves: while the last gap, less the move, exceeds the margin (with
        # a nanometre for rounding), the answer is False without looking at every circle.
        e0, n0, gap0 = self._last_gap
        if gap0 - math.hypot(east - e0, north - n0) - 1e-9 > margin:
            return False
        distance = np.hypot(c[:, 0] - east, c[:, 1] - north)
        self._last_gap = (east, north, float((distance - c[:, 2]).min()))
        return bool((distance <= c[:, 2] + margin).any())

    def padded_surface(self) -> NDArray[np.float32]:
        """The surface inside a one-sample border at :data:`OFF_GRID_HEIGHT` (cached):
        bilinear lookups clamped onto the border fall towards "nothing here", so ray
        casting needs no off-grid mask. Element ``[j + 1, i + 1]`` is ``surface[j, i]``."""
        if self._padded is None:
            padded = np.full((self.ny + 2, self.nx + 2), OFF_GRID_HEIGHT, dtype=np.float32)
            padded[1:-1, 1:-1] = self.surface
            padded.flags.writeable = False
            self._padded = padded
        return self._padded

    def ray_tables(self, block: int) -> tuple[NDArray[np.float32], int, int,
                                              NDArray[np.float32], int]:
        """What the compiled ray caster reads, cached per block size: the flat
        :meth:`block_max` array, its row length and row count, the flat
        :meth:`padded_surface` and its row length."""
        cached = self._ray_tables.get(block)
        if cached is None:
            blocks, padded = self.block_max(block), self.padded_surface()
            cached = self._ray_tables[block] = (blocks.ravel(), blocks.shape[1], blocks.shape[0],
                                                padded.ravel(), padded.shape[1])
        return cached

    def block_max(self, block: int) -> NDArray[np.float32]:
        """Conservative maxima for ray casting, cached per block size.

        Block (bj, bi) spans samples ``[b*block, (b+1)*block]`` in each axis (one sample
        of overlap, so bilinear interpolation anywhere in the block is bounded by it).
        Element ``[bj + BLOCK_PAD, bi + BLOCK_PAD]`` of the result is the highest sample in
        blocks bj..bj+1 x bi..bi+1: it bounds any segment no longer than a block in either
        axis whose lowest corner lies in block (bj, bi). The array is padded by
        ``BLOCK_PAD`` blocks of -inf on every side, so clipped indices of far-off points
        find nothing.
        """
        cached = self._block_cache.get(block)
        if cached is not None:
            return cached
        if block < 1:
            raise ValueError("block must be >= 1")
        bx = -(-(self.nx - 1) // block) or 1
        by = -(-(self.ny - 1) // block) or 1
        padded = np.full((by * block + 1, bx * block + 1), -np.inf, dtype=np.float32)
        padded[: self.ny, : self.nx] = self.surface
        core = padded[:-1, :-1].reshape(by, block, bx, block).max(axis=(1, 3))
        # the overlap sample: the first row/column of the next block
        edge_r = padded[block::block, :-1].reshape(by, bx, block).max(axis=2)
        edge_c = padded[:-1, block::block].reshape(by, block, bx).max(axis=1)
        corner = padded[block::block, block::block]
        blocks = np.full((by + 2 * BLOCK_PAD, bx + 2 * BLOCK_PAD), -np.inf, dtype=np.float32)
        blocks[BLOCK_PAD:-BLOCK_PAD, BLOCK_PAD:-BLOCK_PAD] = np.maximum(
            np.maximum(core, edge_r), np.maximum(edge_c, corner))
        out = blocks.copy()
        np.maximum(out[:, :-1], blocks[:, 1:], out=out[:, :-1])  # and the block east
        rows = out.copy()
        np.maximum(out[:-1], rows[1:], out=out[:-1])  # and the two north of those
        out.flags.writeable = False
        self._block_cache[block] = out
        return out


def _scalar_or_array(values: FloatArray, east: ArrayLike, north: ArrayLike) -> Any:
    if np.ndim(east) == 0 and np.ndim(north) == 0:
        return float(values)
    return values


def _roughness(rms: float, seed: int, east: FloatArray, north: FloatArray) -> FloatArray:
    """Sum of random plane waves with RMS ``rms``, evaluated on the grid by two matrix
    products (cos(a+b) = cos a cos b - sin a sin b), so it costs O(K (nx + ny) + nx ny K)
    in BLAS rather than K full-grid trig evaluations."""
    rng = np.random.default_rng(seed)
    lo, hi = ROUGHNESS_WAVELENGTHS
    wavelength = np.exp(rng.uniform(math.log(lo), math.log(hi), ROUGHNESS_MODES))
    direction = rng.uniform(0.0, 2 * math.pi, ROUGHNESS_MODES)
    phase = rng.uniform(0.0, 2 * math.pi, ROUGHNESS_MODES)
    weight = wavelength  # longer waves carry more amplitude: a 1/k spectrum
    # RMS of sum A_k cos(...) over a large area is sqrt(sum A_k^2 / 2)
    amplitude = weight * (rms / math.sqrt(float(np.sum(weight ** 2)) / 2.0))
    k = 2 * math.pi / wavelength
    kx, ky = k * np.cos(direction), k * np.sin(direction)
    ax = east[:, None] * kx[None, :] + phase[None, :]
    ay = north[:, None] * ky[None, :]
    cos_y, sin_y = np.cos(ay) * amplitude, np.sin(ay) * amplitude
    result: FloatArray = cos_y @ np.cos(ax).T - sin_y @ np.sin(ax).T
    return result


def _rasterise(obstacle: Obstacle, index: int, spec: TerrainSpec, east: FloatArray,
               north: FloatArray, ground: NDArray[np.float32], surface: NDArray[np.float32],
               ids: NDArray[np.int16]) -> None:
    # the footprint's bounding box (the work the world reader bounds), not its circle
    i0, i1, j0, j1 = raster_window(obstacle, spec)
    if i0 >= i1 or j0 >= j1:
        return
    de = east[None, i0:i1] - obstacle.east
    dn = north[j0:j1, None] - obstacle.north
    eps = 1e-9  # a face exactly on a sample line includes that sample
    if obstacle.type == "cylinder":
        mask = de * de + dn * dn <= obstacle.radius ** 2 + eps
    else:
        h = math.radians(obstacle.heading)
        along = de * math.sin(h) + dn * math.cos(h)
        across = de * math.cos(h) - dn * math.sin(h)
        mask = ((np.abs(along) <= obstacle.length / 2 + eps)
                & (np.abs(across) <= obstacle.width / 2 + eps))
    window = (slice(j0, j1), slice(i0, i1))
    base = ground[window]
    if obstacle.positive:
        level = (base + np.float32(obstacle.height)).astype(np.float32)
        surface[window] = np.where(mask, np.maximum(surface[window], level), surface[window])
    else:
        level = (base - np.float32(obstacle.depth)).astype(np.float32)
        surface[window] = np.where(mask, np.minimum(surface[window], level), surface[window])
    ids[window] = np.where(mask, np.int16(index), ids[window])
