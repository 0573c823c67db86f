"""Diagnostics: how much real processing time something took.

Components take *time* only from the injected clock (a layering test enforces it). What
they spend in real CPU/wall time to do their work (a planner's replan, a map's fusion) is
not time in that sense: under a virtual clock it is exactly what the clock does not show.
This module is the one place outside the clocks that reads the process's
performance counter, for statistics and run summaries only; never for behaviour.
"""

from __future__ import annotations

import time

__all__ = ["Stopwatch"]


class Stopwatch:
    """``with Stopwatch() as watch: ...`` then ``watch.seconds`` (wall seconds spent)."""

    __slots__ = ("_start", "seconds")

    def __init__(self) -> None:
        self._start = 0.0
        self.seconds = 0.0

    def __enter__(self) -> Stopwatch:
        self._start = time.perf_counter()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.seconds = time.perf_counter() - self._start
