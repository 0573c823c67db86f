"""The compiled form of :func:`components.nodding_laser.codec.sick_crc16` (decision 0014's
pattern, decision 0021): the LMS telegram listing's byte-by-byte register update in one
loop, the same integers as :func:`~components.nodding_laser.codec.sick_crc16_reference`.
Importing this module compiles the kernel, or loads it from numba's on-disk cache; it
raises ImportError where numba is missing.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["crc_kernel"]

#: The one signature, compiled (or loaded from the cache) on import: read-only bytes in.
SIGNATURE = numba.int64(numba.types.Array(numba.uint8, 1, "C", readonly=True))


@numba.njit(SIGNATURE, cache=True, nogil=True, boundscheck=False)
def crc_kernel(data: np.ndarray) -> int:
    """SICK's CRC-16 (generator 0x8005) of ``data``: per byte, shift the register left by
    one (XOR the generator when bit 15 falls out), then XOR the word of this byte (low)
    and the previous one (high)."""
    crc = 0
    previous = 0
    for k in range(data.shape[0]):
        byte = int(data[k])
        crc = (((crc << 1) & 0xFFFF) ^ 0x8005) if crc & 0x8000 else (crc << 1) & 0xFFFF
        crc ^= byte | (previous << 8)
        previous = byte
    return crc
