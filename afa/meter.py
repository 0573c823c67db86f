"""Loop-time accounting: how much of the event loop's time each owner's tasks take.

The seed's Launcher showed %CPU per *process* (``ps``); with every component in one
event loop, the useful figure is the share of the loop's time each component's code
runs. A :class:`LoopMeter` wraps the coroutines of the tasks it is given (a component's
supervisor and scope tasks, an observer, a bridge) in a thin coroutine whose every step
(``send``/``throw``, i.e. one run of the task between two awaits that suspend) is timed
with :func:`time.perf_counter` and added to the owner's account. Callbacks the loop runs
outside tasks (timer callbacks, future callbacks, Zenoh hand-offs) are not attributed.

This is the one place in the framework besides the clocks and the CLI that reads
``time``: it measures the cost of running code for diagnostics (``afa top``), never a
time that components see. It costs two counter reads and one Python call per task step
(~0.3 µs, ``benchmarks/bridge.py``), so systems meter only when asked
(``System(meter=True)``; a bridge turns it on so ``afa top`` can show it).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Coroutine, Generator
from typing import Any, TypeVar

__all__ = ["LoopMeter"]

T = TypeVar("T")


class _Account:
    __slots__ = ("busy", "steps", "longest")

    def __init__(self) -> None:
        self.busy = 0.0
        self.steps = 0
        self.longest = 0.0

    def add(self, seconds: float) -> None:
        self.busy += seconds
        self.steps += 1
        if seconds > self.longest:
            self.longest = seconds


class LoopMeter:
    """Per-owner busy time of the loop (seconds of ``timer``, :func:`time.perf_counter`
    unless given) since creation."""

    def __init__(self, timer: Callable[[], float] = time.perf_counter) -> None:
        self._accounts: dict[str, _Account] = {}
        self._timer = timer
        self._started = timer()

    def wrap(self, coroutine: Coroutine[Any, Any, T], account: str) -> Coroutine[Any, Any, T]:
        """``coroutine``, with the time of each of its steps added to ``account``."""
        entry = self._accounts.get(account)
        if entry is None:
            entry = self._accounts[account] = _Account()
        return _Metered(coroutine, entry, self._timer)

    def snapshot(self) -> dict[str, Any]:
        """``{"wall_s": seconds since creation, "accounts": {owner: {"busy_s", "steps",
        "share", "longest_s"}}}`` where ``share`` is busy time over wall time and
        ``longest_s`` the longest single step: the longest the owner held the loop, during
        which no other component (Obstacle Detection included) could run."""
        wall = max(1e-9, self._timer() - self._started)
        return {"wall_s": wall, "accounts": {
            name: {"busy_s": a.busy, "steps": a.steps, "share": a.busy / wall,
                   "longest_s": a.longest}
            for name, a in sorted(self._accounts.items())}}


class _Metered(Coroutine[Any, Any, T]):
    """A coroutine that times each step of the one it wraps."""

    __slots__ = ("_inner", "_account", "_timer")

    def __init__(self, inner: Coroutine[Any, Any, T], account: _Account,
                 timer: Callable[[], float]) -> None:
        self._inner = inner
        self._account = account
        self._timer = timer

    def send(self, value: Any) -> Any:
        account, timer = self._account, self._timer
        start = timer()
        try:
            return self._inner.send(value)
        finally:
            account.add(timer() - start)

    def throw(self, kind: Any, value: Any = None, traceback: Any = None) -> Any:
        account, timer = self._account, self._timer
        start = timer()
        try:
            if value is None and traceback is None:
                return self._inner.throw(kind)
            return self._inner.throw(kind, value, traceback)  # pragma: no cover - legacy form
        finally:
            account.add(timer() - start)

    def close(self) -> None:
        self._inner.close()

    def __await__(self) -> Generator[Any, None, T]:
        return self  # type: ignore[return-value]

    def __iter__(self) -> _Metered[T]:
        return self

    def __next__(self) -> Any:
        return self.send(None)

    def __repr__(self) -> str:
        return f"<metered {self._inner!r}>"
