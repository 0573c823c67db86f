"""The compiled form of :func:`afa.sim.raycast.cast_rays` (decision 0014).

One loop per ray walks its segments in order, tests each against the block maxima and
samples the first candidate segment that dips below the surface: the same hit as the
numpy passes (which take the first candidate segment of each ray, in order, whose samples
go below), computed with the same floating-point operations in the same order, so the
ranges are bit for bit those of the numpy form (tests/sim/test_raycast.py checks both on
every shipped world). Importing this module compiles the kernel, or loads it from
numba's on-disk cache; it raises ImportError where numba is missing.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["cast_kernel"]


#: The one signature, compiled (or loaded from the cache) when this module is imported.
#: (The terrain's arrays are read-only.)
_FROZEN = numba.types.Array(numba.float32, 1, "C", readonly=True)
SIGNATURE = numba.boolean(numba.float64[:, ::1], numba.float64[:, ::1], _FROZEN,
                       numba.int64, numba.int64, _FROZEN, numba.int64,
                       numba.float64, numba.float64, numba.float64, numba.int64, numba.int64,
                       numba.float64, numba.boolean, numba.float64, numba.float64,
                       numba.float64, numba.float64[::1])


@numba.njit(SIGNATURE, cache=True, nogil=True, fastmath=False, error_model="numpy",
            boundscheck=False)
def cast_kernel(origins: np.ndarray, directions: np.ndarray,
                bmax: np.ndarray, bx: int, by: int,
                surface: np.ndarray, width: int, east0: float, north0: float, res: float,
                block: int, n_seg: int, max_range: float, clamp: bool, block_pad: float,
                x_max: float, y_max: float, ranges: np.ndarray) -> bool:
    """Fill ``ranges`` (NaN where nothing is hit); False if a direction's length is not
    > 0 (zero or NaN: the caller raises; ``ranges`` is then incomplete). ``origins``:
    (1, 3), shared, or one per ray (N, 3); ``directions``: (N, 3), normalised here as
    :func:`cast_rays`'s numpy form does (the same operations in the same order);
    ``bmax`` and ``surface`` flat (rows of ``bx`` and ``width``)."""
    n = directions.shape[0]
    shared = origins.shape[0] == 1
    seg = block * res
    for r in range(n):
        ranges[r] = math.nan
        o = 0 if shared else r
        x, y, z = origins[o, 0], origins[o, 1], origins[o, 2]
        dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
        length = math.sqrt((dx * dx + dz * dz) + dy * dy)
        if not length > 0:
            return False
        ddx, ddy, ddz = dx / length, dy / length, dz / length
        # the coarse pass's bounds, as cast_rays computes them
        z_base = z - 1e-6 + min(ddz, 0.0) * seg
        bi0 = (x - east0) / seg + block_pad + min(ddx, 0.0)
        bj0 = (y - north0) / seg + block_pad + min(ddy, 0.0)
        bdi, bdj = ddx / seg, ddy / seg
        gx = (x - east0) / res + 1.0
        gy = (y - north0) / res + 1.0
        gdx, gdy = ddx / res, ddy / res
        for k in range(n_seg):
            start = seg * float(k)
            z_low = z_base + ddz * start
            bi = bi0 + bdi * start
            bj = bj0 + bdj * start
            if clamp:
                bi = min(max(bi, 0.0), float(bx - 1))
                bj = min(max(bj, 0.0), float(by - 1))
            if not z_low <= bmax[int(bj) * bx + int(bi)]:
                continue
            t0 = float(k) * seg
            above = 0.0
            t_prev = 0.0
            for p in range(block + 1):
                t = t0 + res * float(p)
                fx = gx + gdx * t
                fy = gy + gdy * t
                if clamp:
                    fx = min(max(fx, 0.0), x_max)
                    fy = min(max(fy, 0.0), y_max)
                i = int(fx)
                j = int(fy)
                tx = fx - i
                ty = fy - j
                q = j * width + i
                z00 = surface[q]
                z01 = surface[q + 1]
                z10 = surface[q + width]
                z11 = surface[q + width + 1]
                near = z00 + np.float32(z01 - z00) * tx
                far = z10 + np.float32(z11 - z10) * tx
                dist = (z + ddz * t) - (near + (far - near) * ty)
                if dist <= 0:
                    t_hit = t if p == 0 else t_prev + above / (above - dist) * res
                    ranges[r] = t_hit if t_hit <= max_range else math.nan
                    break
                above = dist
                t_prev = t
            else:
                continue
            break
    return True
