"""Compiled scan-line loops (decision 0014's pattern, decision 0030), each bit for bit
its numpy form: the emulator's value words (:func:`words_kernel`) and the driver's points.

:func:`points_kernel` is :meth:`components.nodding_laser.codec.ScanLineGeometry.scan_line`:
one loop over the beams does what the driver's
numpy form does in about fifteen array operations (the range field and the validity of
each value word, its range in metres as float32, the beam's point as float32, NaN for
no return), with the same floating-point operations in the same order, so the points are
bit for bit the numpy form's. The nod angles' cosines and sines come in from numpy (a
compiled ``cos`` need not round as numpy's does). Importing this module compiles the
kernel, or loads it from numba's on-disk cache; it raises ImportError where numba is
missing.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["points_kernel", "words_kernel"]

_F64 = numba.float64[::1]
#: The one signature, compiled (or loaded from the cache) on import.
SIGNATURE = numba.void(numba.uint32[::1], numba.int64, numba.int64, numba.float64, _F64, _F64,
                       _F64, _F64, numba.float32[:, ::1], numba.boolean[::1])


@numba.njit(SIGNATURE, cache=True, nogil=True, fastmath=False, error_model="numpy",
            boundscheck=False)
def points_kernel(words: np.ndarray, mask: int, threshold: int, metres: float,
                  sin_b: np.ndarray, minus_cos_b: np.ndarray, cos_n: np.ndarray,
                  sin_n: np.ndarray, points: np.ndarray, valid: np.ndarray) -> None:
    """Fill ``points`` (N, 3) and ``valid`` (N,) from N value ``words``: a value is valid
    when its range field (``words & mask``) is above 0 and below ``threshold``; its range
    is the field times ``metres``, rounded to float32 (as the driver's ranges are), and
    its point ``(r sin_b cos_n, r minus_cos_b, r sin_b sin_n)`` in float64, each
    coordinate rounded to float32; an invalid value's point is NaN."""
    nan = np.float32(math.nan)
    for i in range(words.shape[0]):
        count = np.int64(words[i]) & mask
        if 0 < count < threshold:
            valid[i] = True
            r = np.float64(np.float32(np.float64(count) * metres))
            forward = r * sin_b[i]
            points[i, 0] = np.float32(forward * cos_n[i])
            points[i, 1] = np.float32(r * minus_cos_b[i])
            points[i, 2] = np.float32(forward * sin_n[i])
        else:
            valid[i] = False
            points[i, 0] = nan
            points[i, 1] = nan
            points[i, 2] = nan


#: The emulator's kernel: ranges (and noise) in, value words out.
WORDS_SIGNATURE = numba.void(_F64, _F64, numba.boolean, numba.int64, numba.int64,
                             numba.uint16[::1])


@numba.njit(WORDS_SIGNATURE, cache=True, nogil=True, fastmath=False, error_model="numpy",
            boundscheck=False)
def words_kernel(ranges: np.ndarray, noise: np.ndarray, noisy: bool, max_count: int,
                 no_return: int, words: np.ndarray) -> None:
    """The fake LMS's value words (:meth:`FakeNodLaser._measure`'s numpy form): each range
    (m; NaN or inf for no return) plus its ``noise`` if ``noisy``, in millimetres
    rounded half to even; a count from 1 to below ``max_count`` is sent as it is, any
    other as the ``no_return`` word."""
    for i in range(ranges.shape[0]):
        r = ranges[i]
        if noisy:
            r = r + noise[i]
        count = np.rint(r * 1000.0)
        if count >= 1 and count < max_count:
            words[i] = np.uint16(count)
        else:
            words[i] = np.uint16(no_return)
