"""Vectorised ray casting against a :class:`~afa.sim.terrain.Terrain` heightfield.

All rays are cast at once, in two passes:

1. **Coarse**: each ray is cut into segments of ``block * resolution`` metres. A segment
   can only meet the surface if its lowest point is at or below the highest surface
   sample near it; :meth:`Terrain.block_max` gives a conservative bound (the maximum over
   the 3 x 3 blocks around the segment's midpoint), so no hit is ever skipped.
2. **Fine**: the first candidate segment of each ray is sampled every
   ``resolution / 2`` against the bilinear surface; the first sample below the surface
   and the one before it bracket the hit, refined by linear interpolation of the height
   difference (exact on planar ground). Rays whose candidate was a false alarm go round
   again with their next 2, 4, 8, ... candidates; a hit beyond ``max_range`` ends the
   ray with NaN.

Points off the grid are treated as empty space (a ray leaving the world finds nothing).
The terrain's vertical obstacle faces are bilinear ramps one grid cell wide, so a face
is located to within ``resolution``.

Frames: the world is ENU (x east, y north, z up). ``rotation`` arguments are 3x3
world-from-sensor matrices. A laser's scan plane is its x-y plane, bearings in radians
counter-clockwise from its x axis (forward, y left, z up). A camera uses the optical
frame (z along the optical axis, x right, y down), as ``Digiclops:ImagePlane`` does in
docs/geometry.md.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from afa.sim.terrain import BLOCK_PAD, Terrain

__all__ = ["cast_rays", "laser_scan", "laser_directions", "camera_directions", "depth_image"]

FloatArray = NDArray[np.float64]


def cast_rays(terrain: Terrain, origins: ArrayLike, directions: ArrayLike, max_range: float,
              *, block: int = 8) -> FloatArray:
    """Distance (m) along each ray to the first surface hit, NaN when nothing is hit
    within ``max_range``.

    ``origins``: (3,) for one shared origin or (N, 3); ``directions``: (N, 3), normalised
    here. A ray starting below the surface has range 0. Raises ValueError for bad shapes,
    a non-positive ``max_range`` or a zero direction.
    """
    d = np.atleast_2d(np.asarray(directions, dtype=np.float64))
    if d.ndim != 2 or d.shape[1] != 3:
        raise ValueError(f"directions must have shape (N, 3), got {d.shape}")
    o = np.asarray(origins, dtype=np.float64)
    if o.shape == (3,):
        o = np.broadcast_to(o, d.shape)
    if o.shape != d.shape:
        raise ValueError(f"origins must have shape (3,) or {d.shape}, got {o.shape}")
    if not (math.isfinite(max_range) and max_range > 0):
        raise ValueError("max_range must be finite and > 0")
    norm = np.linalg.norm(d, axis=1)
    if not np.all(norm > 0):
        raise ValueError("directions must be non-zero")
    d = d / norm[:, None]
    n_rays = d.shape[0]
    ranges = np.full(n_rays, np.nan)
    if n_rays == 0:
        return ranges

    res = terrain.resolution
    seg = block * res
    n_seg = int(math.ceil(max_range / seg))
    bmax = terrain.block_max(block)
    by, bx = bmax.shape

    # ---- coarse pass: which segments could touch the surface
    # z is linear along a segment: its lowest point is the start, or the end if falling
    starts = seg * np.arange(n_seg)
    dz = d[:, 2:3]
    z_low = (o[:, 2:3] + np.minimum(dz, 0.0) * seg) + dz * starts
    # block coordinates of segment midpoints, offset into the padded block array
    mid = starts + 0.5 * seg
    ax = (o[:, 0:1] - terrain.east0) / seg + BLOCK_PAD
    ay = (o[:, 1:2] - terrain.north0) / seg + BLOCK_PAD
    bi = np.clip(ax + (d[:, 0:1] / seg) * mid, 0, bx - 1).astype(np.intp)
    bj = np.clip(ay + (d[:, 1:2] / seg) * mid, 0, by - 1).astype(np.intp)
    candidate = z_low <= bmax[bj, bi]
    rank = np.cumsum(candidate, axis=1, dtype=np.int32)
    total = rank[:, -1]

    found = np.zeros(n_rays, dtype=bool)
    done = 0
    fine = block  # one sample per grid cell; the hit is refined by interpolation
    step = seg / fine
    offsets = step * np.arange(fine + 1)
    take = 1
    while True:
        todo = ~found & (total > done)
        if not todo.any():
            break
        # the next `take` candidate segments of every unfinished ray; most rays hit in
        # their first, so start with one and double for the stragglers
        sel = candidate & (rank > done) & (rank <= done + take) & todo[:, None]
        done += take
        take *= 2
        ray, segment = np.nonzero(sel)
        t = segment[:, None] * seg + offsets[None, :]
        ox, oy, oz = o[ray, 0:1], o[ray, 1:2], o[ray, 2:3]
        dx, dy, dz = d[ray, 0:1], d[ray, 1:2], d[ray, 2:3]
        dist = (oz + dz * t) - _surface(terrain, ox + dx * t, oy + dy * t)
        below = dist <= 0
        has = below.any(axis=1)
        if not has.any():
            continue
        rows = np.nonzero(has)[0]
        first = np.argmax(below[rows], axis=1)
        t_hit = t[rows, first]
        prev = np.maximum(first - 1, 0)
        d0 = dist[rows, prev]
        d1 = dist[rows, first]
        with np.errstate(invalid="ignore", divide="ignore"):
            frac = d0 / (d0 - d1)
        refine = (first > 0) & np.isfinite(frac)
        t_hit = np.where(refine, t[rows, prev] + np.clip(frac, 0.0, 1.0) * step, t_hit)
        # rows are ordered by ray then segment: the first row of each ray is its nearest hit
        hit_rays, first_row = np.unique(ray[rows], return_index=True)
        t_hit = t_hit[first_row]
        ranges[hit_rays] = np.where(t_hit <= max_range, t_hit, np.nan)
        found[hit_rays] = True
    return ranges


def _surface(terrain: Terrain, east: FloatArray, north: FloatArray) -> FloatArray:
    """Bilinear surface height; -inf off the grid (nothing to hit there)."""
    fx = (east - terrain.east0) / terrain.resolution
    fy = (north - terrain.north0) / terrain.resolution
    inside = (fx >= 0) & (fx <= terrain.nx - 1) & (fy >= 0) & (fy <= terrain.ny - 1)
    fx = np.clip(fx, 0.0, terrain.nx - 1.0)
    fy = np.clip(fy, 0.0, terrain.ny - 1.0)
    i = np.minimum(fx.astype(np.intp), terrain.nx - 2)
    j = np.minimum(fy.astype(np.intp), terrain.ny - 2)
    tx = fx - i
    ty = fy - j
    grid = terrain.surface
    z = ((grid[j, i] * (1 - tx) + grid[j, i + 1] * tx) * (1 - ty)
         + (grid[j + 1, i] * (1 - tx) + grid[j + 1, i + 1] * tx) * ty)
    return np.where(inside, z, -np.inf)


def laser_directions(rotation: ArrayLike, bearings: ArrayLike) -> FloatArray:
    """World directions (N, 3) of beams at ``bearings`` (rad, counter-clockwise from the
    laser's x axis in its x-y plane) for a laser with world-from-laser ``rotation``."""
    b = np.asarray(bearings, dtype=np.float64).ravel()
    local = np.stack([np.cos(b), np.sin(b), np.zeros_like(b)], axis=1)
    r = _rotation(rotation)
    result: FloatArray = local @ r.T
    return result


def laser_scan(terrain: Terrain, origin: ArrayLike, rotation: ArrayLike, bearings: ArrayLike,
               max_range: float, *, block: int = 8) -> FloatArray:
    """One scan line: range (m) of each beam, NaN for no return within ``max_range``.

    ``origin``: the laser's centre in the world (3,); ``rotation``: world-from-laser.
    Raises ValueError as :func:`cast_rays` does.
    """
    return cast_rays(terrain, np.asarray(origin, dtype=np.float64).reshape(3),
                     laser_directions(rotation, bearings), max_range, block=block)


def camera_directions(width: int, height: int, fov: float) -> FloatArray:
    """(height, width, 3) unit ray directions of a pinhole camera in its optical frame
    (z forward, x right, y down) through pixel centres; ``fov`` is the horizontal field
    of view in degrees, square pixels, principal point at the image centre."""
    if width < 1 or height < 1 or not 0 < fov < 180:
        raise ValueError("width and height must be >= 1 and 0 < fov < 180 degrees")
    f = 0.5 * width / math.tan(math.radians(fov) / 2)
    u = (np.arange(width) + 0.5 - 0.5 * width) / f
    v = (np.arange(height) + 0.5 - 0.5 * height) / f
    gu, gv = np.meshgrid(u, v)
    rays = np.stack([gu, gv, np.ones_like(gu)], axis=-1)
    result: FloatArray = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
    return result


def depth_image(terrain: Terrain, origin: ArrayLike, rotation: ArrayLike, width: int = 320,
                height: int = 240, fov: float = 66.0, max_range: float = 20.0, *,
                block: int = 8) -> FloatArray:
    """A (height, width) depth image: the optical-axis distance Z (m) of the first
    surface point seen through each pixel, NaN where nothing lies within ``max_range``
    (measured along the ray). ``rotation``: world-from-optical-frame. Raises ValueError
    for bad arguments."""
    local = camera_directions(width, height, fov)
    r = _rotation(rotation)
    world = local.reshape(-1, 3) @ r.T
    ranges = cast_rays(terrain, np.asarray(origin, dtype=np.float64).reshape(3), world,
                       max_range, block=block)
    depth: FloatArray = (ranges * local[..., 2].ravel()).reshape(height, width)
    return depth


def _rotation(rotation: ArrayLike) -> FloatArray:
    r = np.asarray(rotation, dtype=np.float64)
    if r.shape != (3, 3):
        raise ValueError(f"rotation must be 3x3, got {r.shape}")
    return r
