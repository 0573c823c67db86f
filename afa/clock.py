"""Clocks: where components get time from.

Components never read ``time.*`` or use ``asyncio.sleep`` for timing; they ask the clock
the runtime injects. Two clocks share one interface:

- :class:`WallClock`: real time, for the vehicle and for real-time simulation.
- :class:`VirtualClock`: simulated time for tests, ``--fast`` simulation and replay.
  Time stands still while anything can run; when every task is waiting, time jumps to
  the earliest pending timer. Timers fire in (deadline, creation order), so two runs
  with the same inputs produce the same event sequence, and an hour takes seconds.

Times are float seconds since the Unix epoch (UTC); a virtual clock starts at ``start``.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import time
import weakref
from abc import ABC, abstractmethod
from collections.abc import AsyncIterator, Callable, Sized
from contextlib import asynccontextmanager

from afa.errors import ETimeOut

__all__ = ["Clock", "WallClock", "VirtualClock", "TimerHandle", "Watchdog", "DEFAULT_EPOCH"]

#: 2005-09-17 12:00:00 UTC, the date in the Raptor's geometry file name (050917...).
DEFAULT_EPOCH = 1126958400.0


class TimerHandle:
    """A scheduled callback; :meth:`cancel` prevents it from running."""

    __slots__ = ("deadline", "callback", "cancelled", "_inner")

    def __init__(self, deadline: float, callback: Callable[[], object]) -> None:
        self.deadline = deadline
        self.callback = callback
        self.cancelled = False
        self._inner: asyncio.TimerHandle | None = None

    def cancel(self) -> None:
        self.cancelled = True
        if self._inner is not None:
            self._inner.cancel()


class Clock(ABC):
    """The time source the runtime injects into every component."""

    @abstractmethod
    def now(self) -> float:
        """Current time, seconds since the Unix epoch."""

    @abstractmethod
    def call_at(self, deadline: float, callback: Callable[[], object]) -> TimerHandle:
        """Run ``callback()`` (a plain function) once ``now() >= deadline``."""

    async def sleep_until(self, deadline: float) -> None:
        """Suspend until ``now() >= deadline``."""
        if deadline <= self.now():
            await asyncio.sleep(0)
            return
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()

        def wake() -> None:
            if not future.done():
                future.set_result(None)

        handle = self.call_at(deadline, wake)
        try:
            await future
        finally:
            handle.cancel()

    async def sleep(self, seconds: float) -> None:
        """Suspend for ``seconds`` (zero or negative yields once)."""
        await self.sleep_until(self.now() + max(0.0, seconds))

    async def periodic(self, period: float, *, first: float | None = None) -> AsyncIterator[int]:
        """Yield tick numbers every ``period`` seconds without drift.

        Tick ``k`` is due at ``start + k * period``. A consumer that falls behind skips
        the missed ticks (the number jumps) instead of receiving a burst.
        """
        if period <= 0:
            raise ValueError(f"period must be positive, got {period}")
        start = self.now() if first is None else first
        tick = 0
        while True:
            await self.sleep_until(start + tick * period)
            yield tick
            tick = max(tick + 1, int((self.now() - start) / period) + 1)

    @asynccontextmanager
    async def timeout(self, seconds: float | None, what: str = "operation") -> AsyncIterator[None]:
        """Cancel the body after ``seconds`` of this clock's time and raise
        :class:`~afa.errors.ETimeOut` (also a ``TimeoutError``). ``None``: no deadline."""
        if seconds is None:
            yield
            return
        async with self._deadline(seconds, f"{what} timed out after {seconds:g} s"):
            yield

    @asynccontextmanager
    async def watchdog(self, seconds: float, what: str = "operation") -> AsyncIterator[Watchdog]:
        """Cancel the body once :meth:`Watchdog.feed` has not been called for ``seconds``
        of this clock's time, and raise :class:`~afa.errors.ETimeOut`.

        Unlike a :meth:`timeout` around each wait, feeding costs one store: the single
        timer is moved only when it fires early (input that went stale, such as a device
        that stopped talking, is noticed within ``seconds`` of the last feed).
        """
        if not seconds > 0:
            raise ValueError(f"seconds must be positive, got {seconds}")
        async with self._deadline(seconds, f"{what}: nothing for {seconds:g} s") as dog:
            yield dog

    @asynccontextmanager
    async def _deadline(self, seconds: float, message: str) -> AsyncIterator[Watchdog]:
        """The body runs under a :class:`Watchdog`; when it fires, the cancellation it
        causes becomes ``ETimeOut(message)`` (a cancellation from outside stays one). A
        :meth:`timeout` is a watchdog nobody feeds."""
        task = asyncio.current_task()
        assert task is not None, "timeouts and watchdogs need a running task"
        dog = Watchdog(self, seconds, task)
        try:
            yield dog
        except asyncio.CancelledError:
            if dog.fired and task.uncancel() == 0:
                raise ETimeOut(message) from None
            raise
        finally:
            dog.stop()


class Watchdog:
    """The handle :meth:`Clock.watchdog` yields: call :meth:`feed` on every sign of life."""

    __slots__ = ("clock", "seconds", "last", "fired", "_task", "_handle")

    def __init__(self, clock: Clock, seconds: float, task: asyncio.Task[object]) -> None:
        self.clock = clock
        self.seconds = seconds
        self.last = clock.now()
        self.fired = False
        self._task = task
        self._handle: TimerHandle | None = clock.call_at(self.last + seconds, self._check)

    def feed(self) -> None:
        """A sign of life: the deadline is ``seconds`` from now."""
        self.last = self.clock.now()

    def stop(self) -> None:
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None

    def _check(self) -> None:
        due = self.last + self.seconds
        if self.clock.now() < due:  # fed since the timer was set: wait for the rest
            self._handle = self.clock.call_at(due, self._check)
            return
        self._handle = None
        self.fired = True
        self._task.cancel()


class WallClock(Clock):
    """Real time: ``time.time()`` for stamps, the loop's monotonic timers for waiting."""

    def now(self) -> float:
        return time.time()

    def call_at(self, deadline: float, callback: Callable[[], object]) -> TimerHandle:
        loop = asyncio.get_running_loop()
        handle = TimerHandle(deadline, callback)
        handle._inner = loop.call_later(max(0.0, deadline - time.time()), callback)
        return handle


class VirtualClock(Clock):
    """Simulated time that advances only when every task is waiting.

    While timers are pending the clock runs a small driver task: it yields to the loop
    until nothing else is ready, then moves ``now`` to the earliest deadline and runs
    every callback due at that instant, in the order they were scheduled. It needs the
    standard asyncio event loop (it looks at the loop's ready queue to detect idleness).

    ``auto_advance=False`` freezes time; tests then move it with :meth:`advance`.
    """

    def __init__(self, start: float = DEFAULT_EPOCH, *, auto_advance: bool = True) -> None:
        self._now = float(start)
        self._timers: list[tuple[float, int, TimerHandle]] = []
        self._order = itertools.count()
        self._settlers: list[asyncio.Future[None]] = []
        self._driver: _LoopDriver | None = None  # of the loop last used
        self.auto_advance = auto_advance

    def now(self) -> float:
        return self._now

    @property
    def pending(self) -> int:
        """Timers scheduled and not yet run or cancelled."""
        return sum(1 for _, _, h in self._timers if not h.cancelled)

    def call_at(self, deadline: float, callback: Callable[[], object]) -> TimerHandle:
        handle = TimerHandle(max(deadline, self._now), callback)
        heapq.heappush(self._timers, (handle.deadline, next(self._order), handle))
        if self.auto_advance:
            self._ensure_driver()
        return handle

    async def settle(self) -> None:
        """Return once no other task or callback is ready to run (time does not move)."""
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._settlers.append(future)
        self._ensure_driver()
        await future

    async def advance(self, seconds: float) -> None:
        """Move time forward by ``seconds``, running due timers in order and settling
        between instants; returns settled at ``now + seconds``."""
        target = self._now + seconds
        if self.auto_advance:
            await self.sleep_until(target)
        else:
            await self.settle()
            while (deadline := self._next_deadline()) is not None and deadline <= target:
                self._fire_next()
                await self.settle()
            self._now = max(self._now, target)
        await self.settle()

    def _next_deadline(self) -> float | None:
        while self._timers and self._timers[0][2].cancelled:
            heapq.heappop(self._timers)
        return self._timers[0][0] if self._timers else None

    def _fire_next(self) -> None:
        deadline = self._next_deadline()
        if deadline is None:
            return
        self._now = max(self._now, deadline)
        while self._timers and self._timers[0][0] == deadline:
            _, _, handle = heapq.heappop(self._timers)
            if not handle.cancelled:
                handle.cancelled = True  # a handle runs at most once
                handle.callback()

    def _ensure_driver(self) -> None:
        loop = asyncio.get_running_loop()
        driver = self._driver
        if driver is None or driver.loop is not loop:
            driver = self._driver = _LoopDriver.of(loop)
        driver.serve(self)

    def _has_work(self) -> bool:
        return bool(self._settlers) or (self.auto_advance and self._next_deadline() is not None)

    def _wake_settlers(self) -> bool:
        settlers, self._settlers = self._settlers, []
        for future in settlers:
            if not future.done():
                future.set_result(None)
        return bool(settlers)


class _LoopDriver:
    """The one task per event loop that moves virtual time.

    It yields until the loop is idle, then wakes ``settle()`` callers, or else moves one
    clock (round robin, if several virtual clocks share the loop) to its next timer. A
    single driver per loop matters: two spinning drivers would each keep the other's
    loop busy and time would never move.
    """

    _instances: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, _LoopDriver] = (
        weakref.WeakKeyDictionary())

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = weakref.ref(loop)
        self.clocks: list[VirtualClock] = []
        self.task: asyncio.Task[None] | None = None

    @property
    def loop(self) -> asyncio.AbstractEventLoop | None:
        return self._loop()

    @classmethod
    def of(cls, loop: asyncio.AbstractEventLoop) -> _LoopDriver:
        driver = cls._instances.get(loop)
        if driver is None:
            driver = cls._instances[loop] = cls(loop)
        return driver

    def serve(self, clock: VirtualClock) -> None:
        if clock not in self.clocks:
            self.clocks.append(clock)
        if self.task is None or self.task.done():
            loop = asyncio.get_running_loop()
            self.task = loop.create_task(self._run(), name="afa-virtual-clock")

    async def _run(self) -> None:
        ready = _ready_queue()
        while True:
            self.clocks = [c for c in self.clocks if c._has_work()]
            if not self.clocks:
                return
            await asyncio.sleep(0)
            if ready:
                continue
            if any([c._wake_settlers() for c in self.clocks]):
                continue
            for index, clock in enumerate(self.clocks):
                if clock.auto_advance and clock._next_deadline() is not None:
                    clock._fire_next()
                    self.clocks.append(self.clocks.pop(index))
                    break


def _ready_queue() -> Sized:
    loop = asyncio.get_running_loop()
    ready = getattr(loop, "_ready", None)
    if ready is None:
        raise RuntimeError(
            "VirtualClock needs the standard asyncio event loop (it inspects the ready queue "
            "to detect idleness); use WallClock with this loop."
        )
    return ready  # type: ignore[no-any-return]
