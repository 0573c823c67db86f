"""Running statistics for long simulations: constant memory, however long the run.

A simulation may run for hours of virtual time; keeping every sample to summarise it at
the end grows without bound (every pose error, ~0.5 MB per simulated minute with the
other per-event lists). :class:`RunningError` keeps sums instead.
"""

from __future__ import annotations

import math
from typing import Any

__all__ = ["RunningError", "SETTLE_TIME"]

#: Seconds of a run whose errors the summary leaves out: the pose filter converging from
#: its first fix. (The summary used to skip the first tenth of the samples, which needs
#: them all; 10 s is that tenth of the default two-minute run.)
SETTLE_TIME = 10.0


class RunningError:
    """RMS and maximum of a stream of (position, heading) errors in O(1) memory.

    Samples earlier than ``settle_time`` seconds (sample time, from the run's start) are
    counted but left out of the statistics, unless no later sample arrives: a run
    shorter than ``settle_time`` is summarised over all its samples.
    """

    __slots__ = ("settle_time", "samples", "_all", "_settled")

    def __init__(self, settle_time: float = SETTLE_TIME) -> None:
        self.settle_time = settle_time
        self.samples = 0
        self._all = _Sums()
        self._settled = _Sums()

    def add(self, time: float, position_m: float, heading_deg: float) -> None:
        """One sample: the position error (m, >= 0) and heading error (deg) at ``time``."""
        self.samples += 1
        self._all.add(position_m, heading_deg)
        if time >= self.settle_time:
            self._settled.add(position_m, heading_deg)

    def summary(self) -> dict[str, Any] | None:
        """``samples`` (all), ``settled_samples`` (those summarised), ``rms_position_m``,
        ``max_position_m``, ``rms_heading_deg``; None before the first sample."""
        if not self.samples:
            return None
        sums = self._settled if self._settled.count else self._all
        return {
            "samples": self.samples,
            "settled_samples": sums.count,
            "rms_position_m": round(math.sqrt(sums.position_sq / sums.count), 4),
            "max_position_m": round(sums.position_max, 4),
            "rms_heading_deg": round(math.sqrt(sums.heading_sq / sums.count), 4),
        }


class _Sums:
    __slots__ = ("count", "position_sq", "position_max", "heading_sq")

    def __init__(self) -> None:
        self.count = 0
        self.position_sq = 0.0
        self.position_max = 0.0
        self.heading_sq = 0.0

    def add(self, position: float, heading: float) -> None:
        self.count += 1
        self.position_sq += position * position
        self.position_max = max(self.position_max, position)
        self.heading_sq += heading * heading
