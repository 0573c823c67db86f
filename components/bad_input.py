"""Bad input in a map component's health: what the Terrain, Traversability and Global
Maps share.

A map component refuses input it cannot use (a scan in a frame ModelServer does not know,
non-finite points, a pose marked invalid, a map stamped in the future, a map on another
grid) and counts it in its ``statistics()``. So that an operator sees it without reading
counters, it is also *reflected in the component's health*: the component is unhealthy
while it has refused some input within the last :data:`BAD_INPUT_WINDOW` seconds, and its
health detail names each kind of input refused (the counts are in the statistics, so the
detail, and with it the log line a health change writes, changes only when the kinds do).
"""

from __future__ import annotations

__all__ = ["BadInputLog", "BAD_INPUT_WINDOW", "FUTURE_TOLERANCE"]

#: A component stays unhealthy for this long (s) after it last refused an input.
BAD_INPUT_WINDOW = 2.0
#: An input stamped this far (s) ahead of the clock is refused as from the future.
FUTURE_TOLERANCE = 1.0


class BadInputLog:
    """The kinds of bad input a component refused, each with the (monotonic) time it
    last did."""

    def __init__(self, window: float = BAD_INPUT_WINDOW) -> None:
        self.window = window
        self._last: dict[str, float] = {}

    def note(self, what: str, now: float) -> None:
        """Record that input of kind ``what`` (a short phrase) was refused at ``now``."""
        self._last[what] = now

    def recent(self, now: float) -> list[str]:
        """The kinds refused within the window before ``now``, in the order first seen."""
        return [what for what, at in self._last.items() if now - at < self.window]

    def clear(self) -> None:
        self._last.clear()
