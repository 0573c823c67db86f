"""The compiled form of the refinement's search (:func:`components.find_path.kinematic.
search`, decision 0014's pattern): the same Hybrid A* loop over the same arrays with the
same floating-point operations in the same order (no fast-math), so it expands the same
states in the same order and returns the same path, bit for bit
(tests/components/test_kinematic_refinement.py compares the two). Where the Python form
keeps a dict of best costs and a set of closed states, this one keeps flat arrays over
the window's (cell, heading bin) states, and its own binary heap of (priority, index)
pairs, which pops in the order :mod:`heapq` does (the pairs are distinct, so the least
one is unique). Importing it compiles the kernel or loads it from numba's cache; it
raises ImportError where numba is missing.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["search_kernel"]

_F1 = numba.float64[::1]
_F2 = numba.float64[:, ::1]
SIGNATURE = numba.types.UniTuple(numba.int64, 3)(
    _F2, numba.float64, _F2, _F2, numba.float64, numba.float64, numba.float64, _F1, _F1, _F1,
    numba.float64[:, :, ::1], numba.boolean[:, ::1], _F1, _F1, numba.float64, numba.float64,
    numba.float64, numba.float64, numba.float64, numba.float64, numba.float64, numba.int64,
    numba.int64, _F2, numba.int64[::1], _F1, _F1)


@numba.njit(inline="always")
def _less(pa: float, ia: int, pb: float, ib: int) -> bool:
    return pa < pb or (pa == pb and ia < ib)


@numba.njit(inline="always")
def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@numba.njit(inline="always")
def _clearance(distance: np.ndarray, inv: float, ox: float, oy: float, offsets: np.ndarray,
               x: float, y: float, c: float, s: float) -> float:
    least = math.inf
    mi, mj = distance.shape
    for k in range(offsets.shape[0]):
        o = offsets[k]
        fi = (x + o * c - ox) * inv
        fj = (y + o * s - oy) * inv
        if not (0.0 <= fi < mi and 0.0 <= fj < mj):
            return -math.inf
        d = distance[int(fi), int(fj)]
        if d < least:
            least = d
    return least


@numba.njit(SIGNATURE, cache=True, nogil=True, fastmath=False, error_model="numpy",
            boundscheck=False)
def search_kernel(distance: np.ndarray, inv: float, window_cost: np.ndarray,
                  togo: np.ndarray, ox: float, oy: float, g: float, offsets: np.ndarray,
                  kappas_of_motions: np.ndarray, signs_of_motions: np.ndarray,
                  samples: np.ndarray, reversible: np.ndarray, start: np.ndarray,
                  target: np.ndarray, kappa_scale: float, tol2: float,
                  heading_tolerance: float, curvature_change_cost: float,
                  reverse_cost: float, switch_cost: float, step: float,
                  bins: int, max_expansions: int, poses: np.ndarray, parents: np.ndarray,
                  kappas: np.ndarray, signs: np.ndarray) -> tuple[int, int, int]:
    """Run the search; ``start`` is (x, y, h, curvature or NaN, need, escape_from,
    escape_rate), ``target`` (x, y, h, has heading, then the arrival region: x, y,
    radius squared (negative for none), ahead, left), ``kappa_scale`` the largest
    curvature magnitude (the change cost's scale); a motion of sign −1 runs in reverse,
    costs ``reverse_cost`` times as much, may end only on a ``reversible`` cell, and a
    change of sign costs ``switch_cost``. ``poses`` (n, 3), ``parents``, ``kappas`` and
    ``signs`` (n) receive the states, n at least ``max_expansions`` × motions + 1.
    Returns (the goal state's index or -1, expansions, states used)."""
    ni, nj = window_cost.shape
    n_states = ni * nj * bins
    best = np.full(n_states, math.inf)
    closed = np.zeros(n_states, dtype=np.bool_)
    costs = np.empty(poses.shape[0])
    travel = np.empty(poses.shape[0])
    heap_p = np.empty(poses.shape[0])
    heap_i = np.empty(poses.shape[0], dtype=np.int64)
    bin_width = 2.0 * math.pi / bins
    need, escape_from, escape_rate = start[4], start[5], start[6]
    tx, ty, th, has_heading = target[0], target[1], target[2], target[3] != 0.0
    wx, wy, r2, ahead, left = target[4], target[5], target[6], target[7], target[8]
    scale = max(abs(kappa_scale), 1e-9)

    poses[0, 0], poses[0, 1], poses[0, 2] = start[0], start[1], start[2]
    parents[0] = -1
    kappas[0] = start[3]
    signs[0] = 1.0
    costs[0] = 0.0
    travel[0] = 0.0
    i = int(math.floor((start[0] - ox) / g))
    j = int(math.floor((start[1] - oy) / g))
    b = int(round(start[2] / bin_width)) % bins
    best[(i * nj + j) * bins + b] = 0.0
    count = 1
    heap_p[0] = togo[i, j]
    heap_i[0] = 0
    size = 1
    expansions = 0
    n_motions = kappas_of_motions.shape[0]
    n_samples = samples.shape[1]
    while size > 0 and expansions < max_expansions:
        # pop the least (priority, index)
        n = heap_i[0]
        size -= 1
        if size > 0:
            lp, li = heap_p[size], heap_i[size]
            k = 0
            while True:
                child = 2 * k + 1
                if child >= size:
                    break
                if child + 1 < size and _less(heap_p[child + 1], heap_i[child + 1],
                                              heap_p[child], heap_i[child]):
                    child += 1
                if _less(heap_p[child], heap_i[child], lp, li):
                    heap_p[k], heap_i[k] = heap_p[child], heap_i[child]
                    k = child
                else:
                    break
            heap_p[k], heap_i[k] = lp, li
        x, y, h = poses[n, 0], poses[n, 1], poses[n, 2]
        i = int(math.floor((x - ox) / g))
        j = int(math.floor((y - oy) / g))
        b = int(round(h / bin_width)) % bins
        state = (i * nj + j) * bins + b
        if closed[state]:
            continue
        closed[state] = True
        expansions += 1
        c, s = math.cos(h), math.sin(h)
        if (x - tx) ** 2 + (y - ty) ** 2 <= tol2 and (
                not has_heading or abs(_wrap(h - th)) <= heading_tolerance) or (
                n > 0 and r2 >= 0.0 and (
                    (x - wx) ** 2 + (y - wy) ** 2 <= r2
                    or (x + ahead * c - left * s - wx) ** 2
                    + (y + ahead * s + left * c - wy) ** 2 <= r2)):
            return n, expansions, count
        required = min(need, escape_from - 0.05 + escape_rate * travel[n])
        for m in range(n_motions):
            kappa = kappas_of_motions[m]
            ok = True
            for q in range(n_samples):
                ax, ay, turn = samples[m, q, 0], samples[m, q, 1], samples[m, q, 2]
                if _clearance(distance, inv, ox, oy, offsets, x + ax * c - ay * s,
                              y + ax * s + ay * c, math.cos(h + turn),
                              math.sin(h + turn)) <= required:
                    ok = False
                    break
            if not ok:
                continue
            ex, ey, turn = (samples[m, n_samples - 1, 0], samples[m, n_samples - 1, 1],
                            samples[m, n_samples - 1, 2])
            nx, ny, nh = x + ex * c - ey * s, y + ex * s + ey * c, _wrap(h + turn)
            ci = int(math.floor((nx - ox) / g))
            cj = int(math.floor((ny - oy) / g))
            if not (0 <= ci < ni and 0 <= cj < nj):
                continue
            sign = signs_of_motions[m]
            remaining = togo[ci, cj]
            if not math.isfinite(remaining) or (sign < 0.0 and not reversible[ci, cj]):
                continue
            step_cost = step * window_cost[ci, cj]
            if not math.isfinite(step_cost):
                continue
            if sign < 0.0:
                step_cost *= reverse_cost
            if sign != signs[n]:
                step_cost += switch_cost
            previous = kappas[n]
            if not math.isnan(previous):
                step_cost += curvature_change_cost * abs(kappa - previous) / scale
            total = costs[n] + step_cost
            b = int(round(nh / bin_width)) % bins
            new_state = (ci * nj + cj) * bins + b
            if closed[new_state] or total >= best[new_state]:
                continue
            best[new_state] = total
            poses[count, 0], poses[count, 1], poses[count, 2] = nx, ny, nh
            parents[count] = n
            kappas[count] = kappa
            signs[count] = sign
            costs[count] = total
            travel[count] = travel[n] + step
            # push (total + remaining, count)
            pp, pi = total + remaining, count
            k = size
            size += 1
            while k > 0:
                parent = (k - 1) // 2
                if _less(pp, pi, heap_p[parent], heap_i[parent]):
                    heap_p[k], heap_i[k] = heap_p[parent], heap_i[parent]
                    k = parent
                else:
                    break
            heap_p[k], heap_i[k] = pp, pi
            count += 1
    return -1, expansions, count
