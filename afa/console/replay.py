"""Replay controls: what the console needs of a log player, and an adapter for players
that spell it differently.

The console's replay pane (play, pause, step, seek, speed) drives any object with the
:class:`ReplayControl` protocol. Methods may be plain or ``async``. :func:`replay_control`
wraps a player whose verbs differ (``resume`` for ``play``, a ``speed`` attribute instead
of ``set_speed``, ``position``/``time`` for the status), so ``afa.log``'s ``Player`` can be
passed as it is once it exists.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Mapping
from typing import Any, Protocol, runtime_checkable

__all__ = ["ReplayControl", "replay_control", "ReplayAdapter", "ACTIONS"]

#: The replay actions the console's server accepts (``POST /api/replay/<action>``).
ACTIONS = ("play", "pause", "step", "seek", "speed")


@runtime_checkable
class ReplayControl(Protocol):
    """A replay source the console can drive.

    ``status()`` returns a mapping with at least ``position`` (seconds from the start of
    the recording), ``duration`` (seconds, or None if unknown), ``speed`` (the pace as a
    multiple of real time; None: as fast as possible) and ``paused`` (bool); optionally
    ``label`` (the file). ``set_speed(None)`` means as fast as possible (``speed max``).
    """

    def play(self) -> Any: ...
    def pause(self) -> Any: ...
    def step(self) -> Any: ...
    def seek(self, position: float) -> Any: ...
    def set_speed(self, speed: float | None) -> Any: ...
    def status(self) -> Mapping[str, Any]: ...


class ReplayAdapter:
    """:class:`ReplayControl` over a player with other verbs (see :func:`replay_control`)."""

    def __init__(self, player: Any) -> None:
        self.player = player

    def _call(self, *names: str, args: tuple[Any, ...] = ()) -> Any:
        for name in names:
            method = getattr(self.player, name, None)
            if callable(method):
                return method(*args)
        raise AttributeError(f"{type(self.player).__name__} has none of {', '.join(names)}")

    def play(self) -> Any:
        return self._call("play", "resume")

    def pause(self) -> Any:
        return self._call("pause")

    def step(self) -> Any:
        return self._call("step")

    def seek(self, position: float) -> Any:
        return self._call("seek", args=(position,))

    def set_speed(self, speed: float | None) -> Any:
        method = getattr(self.player, "set_speed", None)
        if callable(method):
            return method(speed)
        self.player.speed = speed
        return None

    def status(self) -> Mapping[str, Any]:
        status = getattr(self.player, "status", None)
        if callable(status):
            value = status()
            if isinstance(value, Mapping):
                return value
        player = self.player
        reader = getattr(player, "reader", None)  # afa.log's Player: its LogReader
        position = _first(player, "elapsed", "position", "offset")
        duration = _first(player, "duration", "length")
        if duration is None and reader is not None:
            duration = _first(reader, "duration")
        label = _first(player, "path", "file", "label") or _first(reader, "path") or ""
        return {"position": position, "duration": duration, "speed": _first(player, "speed"),
                "paused": bool(_first(player, "paused")), "label": str(label)}


def _first(obj: Any, *names: str) -> Any:
    if obj is None:
        return None
    for name in names:
        value = getattr(obj, name, None)
        if value is not None and not callable(value):
            return value
    return None


def replay_control(player: Any) -> ReplayControl:
    """``player`` itself if it has the protocol, else an adapter over it."""
    if isinstance(player, ReplayControl):
        return player
    return ReplayAdapter(player)


async def perform(control: ReplayControl, action: str, value: Any = None) -> None:
    """Run one replay action. Raises ValueError for an unknown action or a bad value."""
    if action not in ACTIONS:
        raise ValueError(f"unknown replay action {action!r}; known: {', '.join(ACTIONS)}")
    if action == "speed" and value == "max":
        result = control.set_speed(None)   # as fast as possible
    elif action in ("seek", "speed"):
        try:
            number = float(value)
        except (TypeError, ValueError, OverflowError):
            raise ValueError(f"{action} needs a number, got {value!r}") from None
        if not math.isfinite(number) or (action == "speed" and number <= 0) or number < 0:
            kind = "positive" if action == "speed" else "non-negative"
            raise ValueError(f"{action} needs a {kind} finite number, got {value!r}")
        result = control.seek(number) if action == "seek" else control.set_speed(number)
    else:
        result = getattr(control, action)()
    if inspect.isawaitable(result):
        await result


def status_of(control: ReplayControl) -> dict[str, Any]:
    """The status as JSON-ready values (non-finite numbers become None)."""
    out: dict[str, Any] = {}
    for key, value in dict(control.status()).items():
        if isinstance(value, float) and not math.isfinite(value):
            value = None
        if isinstance(value, (str, int, float, bool)) or value is None:
            out[str(key)] = value
    return out
