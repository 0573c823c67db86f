"""The compiled form of :meth:`TerrainGrid._fuse_chunk <components.terrain_map.grid.TerrainGrid>`
(decision 0014): one loop over the points, in order, with the numpy form's arithmetic
(cell coordinates by subtraction, division and floor; the flat index as ``fi * cols + fj``
in floats; ``np.minimum`` and ``np.maximum``'s choice on ties), so the accumulators are
bit for bit those of the numpy form (tests/components/test_terrain_map_grid.py compares
them). Importing it compiles the kernel or loads it from numba's cache; it raises
ImportError where numba is missing.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["fuse_kernel"]

_F64 = numba.float64[::1]
SIGNATURE = numba.types.UniTuple(numba.int64, 2)(
    numba.float64[:, ::1], numba.float64, numba.float64, numba.float64, numba.int64,
    numba.int64, numba.float64, numba.boolean, numba.float64, numba.int64[::1], _F64, _F64,
    _F64, _F64, _F64, _F64, _F64, _F64)


@numba.njit(SIGNATURE, cache=True, nogil=True, fastmath=False, error_model="numpy",
            boundscheck=False)
def fuse_kernel(p: np.ndarray, origin_x: float, origin_y: float, gridsize: float, rows: int,
                cols: int, time: float, assign: bool, window: float, count: np.ndarray,
                sum_z: np.ndarray, sum_z2: np.ndarray, last_seen: np.ndarray,
                prev_min: np.ndarray, prev_max: np.ndarray, gen_min: np.ndarray,
                gen_max: np.ndarray, gen_start: np.ndarray) -> tuple[int, int]:
    """Fuse the points ``p`` (n, 3) seen at ``time``; ``assign``: every stored time is
    older (set ``last_seen``, else keep the newer); ``window``: the generations' length
    (a new one opens at a point ``window`` or more after the current one's start).
    Returns (fused, nonfinite)."""
    fused = 0
    nonfinite = 0
    for k in range(p.shape[0]):
        x, y, z = p[k, 0], p[k, 1], p[k, 2]
        fi = np.floor((x - origin_x) / gridsize)
        fj = np.floor((y - origin_y) / gridsize)
        if fi >= 0 and fj >= 0 and fi < rows and fj < cols and math.isfinite(z):
            cell = int(fi * cols + fj)
            fused += 1
            count[cell] += 1
            sum_z[cell] += z
            sum_z2[cell] += z * z
            if time - gen_start[cell] >= window:  # a new generation: drop the one before
                prev_min[cell] = gen_min[cell]
                prev_max[cell] = gen_max[cell]
                gen_min[cell] = math.inf
                gen_max[cell] = -math.inf
                gen_start[cell] = time
            low = gen_min[cell]  # np.minimum(a, b) is b unless a < b (ties: b)
            gen_min[cell] = low if low < z else z
            high = gen_max[cell]
            gen_max[cell] = high if high > z else z
            if assign:
                last_seen[cell] = time
            else:
                seen = last_seen[cell]
                last_seen[cell] = seen if seen > time else time
        elif not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            nonfinite += 1
    return fused, nonfinite
