"""Vectorised ray casting against a :class:`~afa.sim.terrain.Terrain` heightfield.

All rays are cast at once, in two passes:

1. **Coarse**: each ray is cut into segments of ``block * resolution`` metres. A segment
   can only meet the surface if its lowest point is at or below the highest surface
   sample under it; :meth:`Terrain.block_max` gives a conservative bound (the maximum
   over the 2 x 2 blocks from the segment's south-west corner, which a segment one
   block long cannot leave), so no hit is ever skipped.
2. **Fine**: the first two candidate segments of each ray are sampled every
   ``resolution`` against the bilinear surface; the first sample below the surface and
   the one before it bracket the hit, refined by linear interpolation of the height
   difference (exact on planar ground). Rays whose candidates were false alarms go round
   again with their next 4, 8, ... candidates; a hit beyond ``max_range`` ends the ray
   with NaN. (A descending ray's segment before the hit is usually a candidate too, so
   two at once finish most scan lines in one round; batches of over 1024 rays, such as
   depth images, start with one.)

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

import functools
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from afa.kernels import compiled
from afa.sim.terrain import BLOCK_PAD, Terrain

__all__ = ["cast_rays", "laser_scan", "laser_directions", "camera_directions", "depth_image"]

FloatArray = NDArray[np.float64]


def _load_kernel() -> Callable[..., bool] | None:
    """The compiled caster (decision 0014), or None for the numpy passes
    (:func:`afa.kernels.compiled`)."""
    return compiled("afa.sim._raycast_jit", "cast_kernel")  # type: ignore[no-any-return]


#: The compiled caster in use, None when the numpy passes cast (see :func:`_load_kernel`).
KERNEL: Any = _load_kernel()


def cast_rays(terrain: Terrain, origins: ArrayLike, directions: ArrayLike, max_range: float,
              *, block: int = 8) -> FloatArray:
    """Distance (m) along each ray to the first surface hit, NaN when nothing is hit
    within ``max_range``.

    ``origins``: (3,) for one shared origin or (N, 3); ``directions``: (N, 3), normalised
    here. A ray starting below the surface has range 0. Raises ValueError for bad shapes,
    a non-positive ``max_range`` or a zero direction.
    """
    d = np.asarray(directions, dtype=np.float64)
    if d.ndim == 1:
        d = d[None, :]
    if d.ndim != 2 or d.shape[1] != 3:
        raise ValueError(f"directions must have shape (N, 3), got {d.shape}")
    o = np.asarray(origins, dtype=np.float64)
    shared = o.shape == (3,)
    if not shared and o.shape != d.shape:
        raise ValueError(f"origins must have shape (3,) or {d.shape}, got {o.shape}")
    if not (math.isfinite(max_range) and max_range > 0):
        raise ValueError("max_range must be finite and > 0")
    n_rays = d.shape[0]
    if n_rays == 0:
        return np.full(0, np.nan)
    if KERNEL is not None:  # it normalises the directions itself, as below
        ranges = np.empty(n_rays)
        if not _cast_compiled(terrain, o, shared, d, max_range, block, ranges):
            raise ValueError("directions must be non-zero")
        return ranges
    ranges = np.full(n_rays, np.nan)
    # each length as (x^2 + z^2) + y^2, in that order: the order numpy's einsum
    # ("ij,ij->i") sums three products in, and the compiled kernel's
    x2, y2, z2 = (d * d).T
    length = np.sqrt((x2 + z2) + y2)
    if not length.min() > 0:  # also False for NaN
        raise ValueError("directions must be non-zero")
    unit = d / length[:, None]
    dx, dy, dz = unit.T
    # a shared origin as scalars, per-ray origins as (N,) vectors (broadcast either way)
    ox, oy, oz = o.tolist() if shared else o.T

    res = terrain.resolution
    seg = block * res
    n_seg = int(math.ceil(max_range / seg))

    # Rays from one origin that cannot leave the grid need no clamping (the usual case)
    gx = (ox - terrain.east0) / res + 1.0  # padded-surface grid units (see below)
    gy = (oy - terrain.north0) / res + 1.0
    x_max, y_max = terrain.nx + 1.0 - 1e-9, terrain.ny + 1.0 - 1e-9
    reach = n_seg * block + 1.0  # grid steps to the last sample of the last segment
    clamp = not (shared and reach <= gx <= x_max - reach and reach <= gy <= y_max - reach)

    # ---- coarse pass: which segments could touch the surface
    blocks = terrain.block_max(block)
    by, bx = blocks.shape
    bmax = blocks.ravel()
    starts, offsets = _steps(n_seg, seg, block, res)
    # z is linear along a segment: its lowest point is the start, or the end if falling
    # (lowered by a micrometre, against rounding differences with the fine pass)
    z_low = (oz - 1e-6 + np.minimum(dz, 0.0) * seg)[:, None] + dz[:, None] * starts
    # a segment spans at most one block in each axis (dx blocks east, dy north): the
    # block of its south-west corner indexes the bound, offset into the padded array
    bi = ((ox - terrain.east0) / seg + BLOCK_PAD + np.minimum(dx, 0.0))[:, None] \
        + (dx / seg)[:, None] * starts
    bj = ((oy - terrain.north0) / seg + BLOCK_PAD + np.minimum(dy, 0.0))[:, None] \
        + (dy / seg)[:, None] * starts
    if clamp:  # (ufuncs rather than np.clip: its Python wrapper costs more than the work)
        np.minimum(np.maximum(bi, 0, out=bi), bx - 1, out=bi)
        np.minimum(np.maximum(bj, 0, out=bj), by - 1, out=bj)
    cell = bj.astype(np.intp)
    cell *= bx
    cell += bi.astype(np.intp)
    candidate = z_low <= bmax.take(cell)
    rank = candidate.cumsum(axis=1, dtype=np.int32)
    total = rank[:, -1]

    # ---- fine passes, in grid units of the padded surface (off-grid points need no mask)
    padded = terrain.padded_surface()
    surface, width = padded.ravel(), padded.shape[1]
    gdx, gdy = dx / res, dy / res
    found = np.zeros(n_rays, dtype=bool)
    done = 0
    step = res  # one sample per grid cell; the hit is refined by interpolation
    width_t = block + 1  # samples per segment: row r, sample p is r * width_t + p flat
    # two at once saves a round of ~60 small array operations; a big batch (a depth
    # image) is bound by memory instead, where the extra samples cost more than a round
    take = 2 if n_rays <= 1024 else 1
    while True:
        # the next `take` candidate segments of every unfinished ray; most rays hit in
        # their first two, so start with two and double for the stragglers
        if done == 0:
            sel = candidate & (rank <= take)
        else:
            todo = ~found & (total > done)
            if not np.count_nonzero(todo):
                break
            sel = (rank > done) & (rank <= done + take) & candidate & todo[:, None]
        done += take
        take *= 2
        ray, segment = np.divmod(np.flatnonzero(sel), n_seg)  # faster than 2-D nonzero
        if not len(ray):
            break
        t = (segment * seg)[:, None] + offsets
        if shared:
            x0, y0, z0 = gx, gy, oz
        else:
            x0, y0, z0 = gx.take(ray)[:, None], gy.take(ray)[:, None], oz.take(ray)[:, None]
        fx = x0 + gdx.take(ray)[:, None] * t
        fy = y0 + gdy.take(ray)[:, None] * t
        dist = (z0 + dz.take(ray)[:, None] * t) - _bilinear(surface, width, fx, fy, x_max, y_max,
                                                            clamp)
        below = dist <= 0
        first = below.argmax(axis=1)
        first += np.arange(0, len(ray) * width_t, width_t)  # flat index of each row's first
        has = below.take(first)
        if not np.count_nonzero(has):
            continue
        first = first[has]
        # rows are ordered by ray then segment: the first row of each ray is its nearest hit
        hit_rays = ray.take(first // width_t)
        nearest = np.ones(len(first), dtype=bool)
        np.not_equal(hit_rays[1:], hit_rays[:-1], out=nearest[1:])
        first, hit_rays = first[nearest], hit_rays[nearest]
        t_hit = t.take(first)
        # the sample before the first one below is above (dist > 0): interpolate between
        refine = first % width_t > 0
        if np.count_nonzero(refine):
            p = first[refine] - 1
            above = dist.take(p)
            t_hit[refine] = t.take(p) + above / (above - dist.take(p + 1)) * step
        ranges[hit_rays] = np.where(t_hit <= max_range, t_hit, np.nan)
        found[hit_rays] = True
    return ranges


def _cast_compiled(terrain: Terrain, o: FloatArray, shared: bool, d: FloatArray,
                   max_range: float, block: int, ranges: FloatArray) -> bool:
    """The passes below, compiled (decision 0014): the same normalisation, bounds,
    clamping and arithmetic, one loop per ray. False for a direction of length zero or
    NaN."""
    res = terrain.resolution
    n_seg = int(math.ceil(max_range / (block * res)))
    east0, north0 = float(terrain.east0), float(terrain.north0)
    x_max, y_max = terrain.nx + 1.0 - 1e-9, terrain.ny + 1.0 - 1e-9
    clamp = True
    if shared:
        ox, oy, _ = o.tolist()
        gx = (ox - east0) / res + 1.0
        gy = (oy - north0) / res + 1.0
        reach = n_seg * block + 1.0
        clamp = not (reach <= gx <= x_max - reach and reach <= gy <= y_max - reach)
    bmax, bx, by, surface, width = terrain.ray_tables(block)
    return bool(KERNEL(np.ascontiguousarray(o.reshape(-1, 3)), np.ascontiguousarray(d), bmax,
                       bx, by, surface, width, east0, north0, float(res), block, n_seg,
                       float(max_range), clamp, float(BLOCK_PAD), x_max, y_max, ranges))


@functools.lru_cache(maxsize=8)
def _steps(n_seg: int, seg: float, block: int, res: float) -> tuple[FloatArray, FloatArray]:
    """Where each segment starts along a ray and where its samples lie within it (m),
    read-only: the same for every cast with one terrain, block and range."""
    starts: FloatArray = seg * np.arange(n_seg, dtype=np.float64)
    offsets: FloatArray = res * np.arange(block + 1, dtype=np.float64)
    starts.flags.writeable = offsets.flags.writeable = False
    return starts, offsets


def _bilinear(flat: NDArray[np.float32], width: int, fx: FloatArray, fy: FloatArray,
              x_max: float, y_max: float, clamp: bool) -> FloatArray:
    """Bilinear height at padded-grid coordinates ``fx``, ``fy`` (overwritten), clamped
    onto the grid and its border unless the caller knows they are well inside."""
    if clamp:
        np.minimum(np.maximum(fx, 0.0, out=fx), x_max, out=fx)
        np.minimum(np.maximum(fy, 0.0, out=fy), y_max, out=fy)
    i = fx.astype(np.intp)
    j = fy.astype(np.intp)
    tx = fx - i
    ty = fy - j
    k = j * width + i
    z00 = flat.take(k)
    z01 = flat.take(k + 1)
    k += width
    z10 = flat.take(k)
    z11 = flat.take(k + 1)
    near = z00 + (z01 - z00) * tx
    far = z10 + (z11 - z10) * tx
    return near + (far - near) * ty


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


@functools.lru_cache(maxsize=16)
def camera_directions(width: int, height: int, fov: float) -> FloatArray:
    """(height, width, 3) unit ray directions of a pinhole camera in its optical frame
    (z forward, x right, y down) through pixel centres; ``fov`` is the horizontal field
    of view in degrees, square pixels, principal point at the image centre. Read-only
    and cached: a camera renders every frame through the same rays."""
    if width < 1 or height < 1 or not 0 < fov < 180:
        raise ValueError("width and height must be >= 1 and 0 < fov < 180 degrees")
    f = 0.5 * width / math.tan(math.radians(fov) / 2)
    u = (np.arange(width) + 0.5 - 0.5 * width) / f
    v = (np.arange(height) + 0.5 - 0.5 * height) / f
    gu, gv = np.meshgrid(u, v)
    rays = np.stack([gu, gv, np.ones_like(gu)], axis=-1)
    result: FloatArray = rays / np.linalg.norm(rays, axis=-1, keepdims=True)
    result.flags.writeable = False
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
