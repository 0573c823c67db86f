"""Clocks: where components get time from.

Components never read ``time.*`` or use ``asyncio.sleep`` for timing; they ask the clock
the runtime injects. A clock keeps two kinds of time apart (decision 0008):

- **stamps**, :meth:`Clock.now`: seconds since the Unix epoch (UTC), for the time
  fields of events. On a vehicle the wall clock can step (GPS or NTP corrects it);
- **intervals**, :meth:`Clock.monotonic`: a base that never steps, for every deadline,
  timeout, watchdog and periodic timer (:meth:`call_at`, :meth:`sleep_until` and
  :meth:`periodic`'s ``first`` take monotonic times). A wall-clock step fires nothing.

Implementations:

- :class:`WallClock`: real time, for the vehicle and real-time simulation.
- :class:`VirtualClock`: simulated time for tests, ``--fast`` simulation and replay.
  Time stands still while anything can run; when every task is waiting, time jumps to
  the earliest pending timer. Timers fire in (deadline, creation order), **one at a
  time**: after each the loop runs until nothing is ready before the next fires, even
  at the same instant, so what happens within one instant is ordered by its timers and
  not by how many awaits each chain of tasks takes (decision 0027). Two runs with the
  same inputs produce the same events, and an hour takes seconds. Optional *pacing*
  caps it at a multiple of real time (``pace``; ``--realtime-factor``); it can be paused,
  resumed, stepped and run for a given time (notebooks, a console, a replay). While real
  I/O is pending (a socket, a serial port) waiting is not idleness: virtual time then runs
  no faster than real time, so a device that answers in 50 ms is not timed out by a
  5 s timeout that virtual time would otherwise reach at once.
- :class:`ScaledClock`: a :class:`VirtualClock` paced at a speed factor (1.0 by
  default) from the start: the replay clock.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import time
import weakref
from abc import ABC, abstractmethod
from collections.abc import AsyncIterator, Callable, Iterator, Sized
from contextlib import contextmanager

from afa.errors import ETimeOut
from afa.tasks import loop_service

__all__ = ["Clock", "WallClock", "VirtualClock", "ScaledClock", "TimerHandle", "Watchdog",
           "Deadline", "DEFAULT_EPOCH", "TIME_TOLERANCE"]

#: The slack a component allows when it compares a duration with a threshold ("at
#: least every 0.2 s", "older than 1 s"). Event times are stamps (epoch seconds as
#: float64, exact to ~0.25 µs), so a replay rebuilds monotonic times that differ from
#: the recorded run's by that much; a comparison on the knife edge (a timer at 4.8 s
#: against an event at 4.6 s) must not flip with it.
TIME_TOLERANCE = 1e-6

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
        """Time stamp: seconds since the Unix epoch (may step on a real vehicle)."""

    @abstractmethod
    def monotonic(self) -> float:
        """Interval base: seconds from an arbitrary origin; never steps backwards or
        jumps with the wall clock. Every deadline is on this base."""

    @abstractmethod
    def call_at(self, deadline: float, callback: Callable[[], object]) -> TimerHandle:
        """Run ``callback()`` (a plain function) once ``monotonic() >= deadline``."""

    def call_later(self, delay: float, callback: Callable[[], object]) -> TimerHandle:
        """Run ``callback()`` after ``delay`` seconds."""
        return self.call_at(self.monotonic() + max(0.0, delay), callback)

    @contextmanager
    def real_io(self) -> Iterator[None]:
        """Mark a wait on real I/O (a socket, a serial port); see :class:`VirtualClock`.
        Transports wrap their reads in it; on a real-time clock it does nothing."""
        yield

    @contextmanager
    def running(self) -> Iterator[None]:
        """Let time pass inside the block even if the clock is paused (see
        :meth:`VirtualClock.running`); real time always passes, so here it does nothing.
        :meth:`System.start <afa.system.System.start>`, ``run`` and ``stop`` run in it."""
        yield

    async def sleep_until(self, deadline: float) -> None:
        """Suspend until ``monotonic() >= deadline``."""
        if deadline <= self.monotonic():
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
        await self.sleep_until(self.monotonic() + max(0.0, seconds))

    async def periodic(self, period: float, *, first: float | None = None) -> AsyncIterator[int]:
        """Yield tick numbers every ``period`` seconds without drift.

        Tick ``k`` is due at ``first + k * period`` (``first``: a monotonic time, default
        now). A consumer that falls behind skips the missed ticks (the number jumps)
        instead of receiving a burst.
        """
        if period <= 0:
            raise ValueError(f"period must be positive, got {period}")
        start = self.monotonic() if first is None else first
        tick = 0
        while True:
            await self.sleep_until(start + tick * period)
            yield tick
            tick = max(tick + 1, int((self.monotonic() - start) / period) + 1)

    def timeout(self, seconds: float | None, what: str = "operation") -> Deadline:
        """``async with clock.timeout(s):`` cancels the body after ``seconds`` of this
        clock's time and raises :class:`~afa.errors.ETimeOut` (also a ``TimeoutError``).
        ``None``: no deadline."""
        return Deadline(self, seconds, what, f"{what} timed out after {seconds:g} s"
                        if seconds is not None else "")

    def watchdog(self, seconds: float, what: str = "operation") -> Deadline:
        """``async with clock.watchdog(s) as dog:`` cancels the body once
        :meth:`Watchdog.feed` has not been called for ``seconds`` of this clock's time,
        and raises :class:`~afa.errors.ETimeOut`.

        Unlike a :meth:`timeout` around each wait, feeding costs one store: the single
        timer is moved only when it fires early (input that went stale, such as a device
        that stopped talking, is noticed within ``seconds`` of the last feed).
        """
        if not seconds > 0:
            raise ValueError(f"seconds must be positive, got {seconds}")
        return Deadline(self, seconds, what, f"{what}: nothing for {seconds:g} s")


class Deadline:
    """The context manager of :meth:`Clock.timeout` and :meth:`Clock.watchdog`: the body
    runs under a :class:`Watchdog`; when it fires, the cancellation it causes becomes
    ``ETimeOut`` (a cancellation from outside stays one). A timeout is a watchdog nobody
    feeds. (A class rather than a generator: polls enter one per call.)"""

    __slots__ = ("_clock", "_seconds", "_message", "_dog")

    def __init__(self, clock: Clock, seconds: float | None, what: str, message: str) -> None:
        self._clock = clock
        self._seconds = seconds
        self._message = message
        self._dog: Watchdog | None = None

    async def __aenter__(self) -> Watchdog | None:
        if self._seconds is None:
            return None
        task = asyncio.current_task()
        assert task is not None, "timeouts and watchdogs need a running task"
        self._dog = Watchdog(self._clock, self._seconds, task)
        return self._dog

    async def __aexit__(self, kind: type[BaseException] | None, error: BaseException | None,
                        traceback: object) -> None:
        dog = self._dog
        if dog is None:
            return
        dog.stop()
        if kind is asyncio.CancelledError and dog.fired and dog._task.uncancel() == 0:
            raise ETimeOut(self._message) from None


class Watchdog:
    """The handle :meth:`Clock.watchdog` yields: call :meth:`feed` on every sign of life."""

    __slots__ = ("clock", "seconds", "last", "fired", "_task", "_handle")

    def __init__(self, clock: Clock, seconds: float, task: asyncio.Task[object]) -> None:
        self.clock = clock
        self.seconds = seconds
        self.last = clock.monotonic()
        self.fired = False
        self._task = task
        self._handle: TimerHandle | None = clock.call_at(self.last + seconds, self._check)

    def feed(self) -> None:
        """A sign of life: the deadline is ``seconds`` from now."""
        self.last = self.clock.monotonic()

    def stop(self) -> None:
        if self._handle is not None:
            self._handle.cancel()
            self._handle = None

    def _check(self) -> None:
        due = self.last + self.seconds
        if self.clock.monotonic() < due:  # fed since the timer was set: wait for the rest
            self._handle = self.clock.call_at(due, self._check)
            return
        self._handle = None
        self.fired = True
        self._task.cancel()


class WallClock(Clock):
    """Real time: stamps from ``time_source`` (``time.time``), intervals and timers from
    the monotonic clock the event loop uses."""

    def __init__(self, time_source: Callable[[], float] = time.time) -> None:
        self._stamp = time_source

    def now(self) -> float:
        return self._stamp()

    def monotonic(self) -> float:
        return time.monotonic()

    def call_at(self, deadline: float, callback: Callable[[], object]) -> TimerHandle:
        loop = asyncio.get_running_loop()
        handle = TimerHandle(deadline, callback)
        handle._inner = loop.call_later(max(0.0, deadline - time.monotonic()), callback)
        return handle


class VirtualClock(Clock):
    """Simulated time that advances only when every task is waiting.

    While timers are pending a driver task (one per event loop) yields until nothing
    else is ready, then moves time to the earliest deadline and runs the first callback
    due then; the next one (due at the same instant or later) runs only once the loop is
    idle again. So timers due at one instant fire in the order they were scheduled, each
    with everything it wakes run to completion before the next (a source's input and
    what is computed from it come before a periodic task's tick scheduled after it,
    whatever the number of awaits in between). :meth:`call_when_idle` runs a callback at
    the next such idle point, before the next timer (a log player places recorded
    inputs between re-run timers of one instant with it). It needs the standard asyncio
    event loop (it looks at the loop's ready queue to detect idleness).

    - ``start``: the stamp (:meth:`now`) at creation; :meth:`monotonic` starts at 0.
    - ``pace``: None runs as fast as possible; a number caps virtual time at that
      multiple of real time (a time stamp never runs ahead of the paced line; a run
      that falls behind catches up without waiting).
    - ``auto_advance=False`` starts paused: time moves only through :meth:`advance`,
      :meth:`run_for`, :meth:`resume`, or inside :meth:`running` (a System starts,
      runs and stops in it, so a paused clock does not deadlock ``system.start()``).
      A notebook keeps its clock paused so that time does not run on, at full CPU,
      between cells.
    - ``real_time``: the real-time source pacing reads (``time.monotonic``; a test
      injects its own to check pacing without waiting).
    - While real I/O is pending (:meth:`real_io`), virtual time runs at most at real
      time, so waiting on the outside world is not mistaken for idleness.
    """

    def __init__(self, start: float = DEFAULT_EPOCH, *, auto_advance: bool = True,
                 pace: float | None = None,
                 real_time: Callable[[], float] = time.monotonic) -> None:
        if pace is not None and not pace > 0:
            raise ValueError(f"pace must be positive or None, got {pace}")
        self._real_time = real_time
        self._holds = 0  # running() blocks in progress
        self._held_paused = False  # the outermost running() found the clock paused
        self._start = float(start)
        self._t = 0.0
        self._wall_offset = 0.0
        self._timers: list[tuple[float, int, TimerHandle]] = []
        self._order = itertools.count()
        self._settlers: list[asyncio.Future[None]] = []
        self._idle: list[Callable[[], object]] = []  # call_when_idle callbacks
        self._driver: _LoopDriver | None = None  # of the loop last used
        self._pace = pace
        self._io_pending = 0
        self._anchor: tuple[float, float, float] | None = None  # (virtual, real, pace)
        self._served = False  # a live driver has this clock in its list
        self.auto_advance = auto_advance

    # -- time ---------------------------------------------------------------------------
    def now(self) -> float:
        return self._start + self._t + self._wall_offset

    def monotonic(self) -> float:
        return self._t

    def step_wall(self, seconds: float) -> None:
        """Step the stamps by ``seconds`` (as GPS or NTP correcting a wall clock would);
        intervals, timers and watchdogs are unaffected."""
        self._wall_offset += seconds

    @property
    def pace(self) -> float | None:
        """The real-time factor (None: as fast as possible)."""
        return self._pace

    @pace.setter
    def pace(self, value: float | None) -> None:
        if value is not None and not value > 0:
            raise ValueError(f"pace must be positive or None, got {value}")
        self._pace = value
        self._anchor_now()
        self._poke()

    @property
    def paused(self) -> bool:
        return not self.auto_advance

    def pause(self) -> None:
        """Freeze time: timers stay pending until :meth:`resume`, :meth:`advance` or
        :meth:`run_for` (a pause inside :meth:`running` holds the block too: an
        operator's pause button stops a run in progress)."""
        self._held_paused = False
        self.auto_advance = False

    def resume(self) -> None:
        """Let time advance by itself again (paced from this moment)."""
        self._held_paused = False  # stays running after any running() block
        self._resume()

    @contextmanager
    def running(self) -> Iterator[None]:
        """Let time advance by itself (paced, if :attr:`pace` is set) inside the block,
        and leave the clock as it was: a clock that was paused is paused again at the
        end, so nothing runs on at full CPU once the block is left (between notebook
        cells). Blocks nest and may overlap in several tasks; the last one out pauses."""
        if self._holds == 0 and self.paused:
            self._held_paused = True
            self._resume()
        self._holds += 1
        try:
            yield
        finally:
            self._holds -= 1
            if self._holds == 0 and self._held_paused:
                self._held_paused = False
                self.auto_advance = False

    def _resume(self) -> None:
        self.auto_advance = True
        self._anchor_now()
        if self._driver is not None or self._timers:
            try:
                self._ensure_driver()
            except RuntimeError:  # no running loop: the next call_at starts the driver
                return
        self._poke()

    @property
    def pending(self) -> int:
        """Timers scheduled and not yet run or cancelled."""
        return sum(1 for _, _, h in self._timers if not h.cancelled)

    def call_at(self, deadline: float, callback: Callable[[], object]) -> TimerHandle:
        """As :meth:`Clock.call_at`; ValueError for a NaN deadline (it would be due
        never and always: the order of every timer after it is lost)."""
        if deadline != deadline:
            raise ValueError("a timer's deadline cannot be NaN")
        handle = TimerHandle(max(deadline, self._t), callback)
        earliest = self._timers[0][0] if self._timers else None
        heapq.heappush(self._timers, (handle.deadline, next(self._order), handle))
        if self.auto_advance:
            if not self._served:  # time starts moving (again): pace from now
                self._ensure_driver()
                self._anchor_now()
            if earliest is None or handle.deadline < earliest:
                self._poke()
        return handle

    def call_when_idle(self, callback: Callable[[], object]) -> None:
        """Run ``callback()`` once, the next time the loop is idle (nothing ready to run)
        before time moves or the next timer fires, even one due at this instant; before
        :meth:`settle` callers are woken. Work it makes ready runs before that timer.

        It does not keep time moving by itself: it runs at the next idle point the clock
        reaches because a timer is pending, :meth:`settle` is awaited or time advances.
        A callback may register itself again to run at the following idle point (after
        the next timer has fired and what it woke has run)."""
        self._idle.append(callback)
        if self._driver is not None:
            self._poke()

    def next_deadline(self) -> float | None:
        """The monotonic time of the earliest pending timer, or None."""
        return self._next_deadline()

    @contextmanager
    def real_io(self) -> Iterator[None]:
        self._io_pending += 1
        try:
            yield
        finally:
            self._io_pending -= 1
            self._poke()

    # -- driving by hand ------------------------------------------------------------------
    async def settle(self) -> None:
        """Return once no other task or callback is ready to run (time does not move)."""
        future: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._settlers.append(future)
        self._ensure_driver()
        self._poke()
        await future

    async def advance(self, seconds: float) -> None:
        """Move time forward by ``seconds``, running due timers in order and settling
        between instants; returns settled at ``monotonic() + seconds``. Works paused or
        running (when running, pacing applies)."""
        target = self._t + seconds
        if self.auto_advance:
            await self.sleep_until(target)
        else:
            await self.settle()
            while (deadline := self._next_deadline()) is not None and deadline <= target:
                self._fire_next()  # one timer, then settle: the driver's order
                await self.settle()
            self._t = max(self._t, target)
        await self.settle()

    async def run_for(self, seconds: float) -> None:
        """Run for ``seconds`` of virtual time, paced if :attr:`pace` is set, and leave
        the clock as it was (paused clocks stay paused between calls: a notebook cell
        can run a simulation for ten seconds and the next cell finds it where it
        stopped). Returns settled at ``monotonic() + seconds``."""
        target = self._t + max(0.0, seconds)
        with self.running():
            await self.sleep_until(target)
        await self.settle()

    # -- internals ----------------------------------------------------------------------
    def _next_deadline(self) -> float | None:
        while self._timers and self._timers[0][2].cancelled:
            heapq.heappop(self._timers)
        return self._timers[0][0] if self._timers else None

    def _fire_next(self) -> None:
        """Move to the earliest pending timer and run it (only it: the caller lets the
        loop go idle before the next, even one due at the same instant)."""
        deadline = self._next_deadline()
        if deadline is None:
            return
        self._t = max(self._t, deadline)
        _, _, handle = heapq.heappop(self._timers)  # not cancelled: _next_deadline saw to it
        handle.cancelled = True  # a handle runs at most once
        handle.callback()

    def _run_idle(self) -> None:
        """Run the :meth:`call_when_idle` callbacks registered so far (those they
        register run at the next idle point)."""
        callbacks, self._idle = self._idle, []
        for callback in callbacks:
            callback()

    def _effective_pace(self) -> float | None:
        if self._io_pending:
            return 1.0 if self._pace is None else min(self._pace, 1.0)
        return self._pace

    def _anchor_now(self) -> None:
        """Start the paced line here: virtual time now at real time now."""
        pace = self._effective_pace()
        self._anchor = None if pace is None else (self._t, self._real_time(), pace)

    def _real_wait(self, deadline: float) -> float:
        """Real seconds to wait before virtual time may reach ``deadline`` (0: now)."""
        pace = self._effective_pace()
        if pace is None:
            self._anchor = None
            return 0.0
        real = self._real_time()
        anchor = self._anchor
        if anchor is None or anchor[2] != pace:
            anchor = self._anchor = (self._t, real, pace)
        return anchor[1] + (deadline - anchor[0]) / pace - real

    def _ensure_driver(self) -> None:
        loop = asyncio.get_running_loop()
        driver = self._driver
        if driver is None or driver.loop is not loop:
            driver = self._driver = _LoopDriver.of(loop)
        driver.serve(self)

    def _poke(self) -> None:
        if self._driver is not None:
            self._driver.poke()

    def _due(self) -> float | None:
        """The deadline of the next timer the driver may fire: any, while time advances
        by itself; paused, only one due at the current instant (a pause stops time, not
        the rest of an instant whose first timers have fired)."""
        deadline = self._next_deadline()
        if deadline is None or self.auto_advance:
            return deadline
        return deadline if deadline <= self._t else None

    def _has_work(self) -> bool:
        return bool(self._settlers) or self._due() is not None

    def _wake_settlers(self) -> bool:
        settlers, self._settlers = self._settlers, []
        for future in settlers:
            if not future.done():
                future.set_result(None)
        return bool(settlers)


class ScaledClock(VirtualClock):
    """Virtual time paced at ``speed`` times real time (1.0: real time): the replay
    clock. ``speed`` can change while running (``clock.pace = 4.0``; ``None`` = as fast
    as possible); :meth:`pause`, :meth:`resume`, :meth:`advance` (a step) as for any
    :class:`VirtualClock`."""

    def __init__(self, start: float = DEFAULT_EPOCH, *, speed: float | None = 1.0,
                 paused: bool = False) -> None:
        super().__init__(start, auto_advance=not paused, pace=speed)


class _LoopDriver:
    """The one task per event loop that moves virtual time.

    It yields until the loop is idle, then wakes ``settle()`` callers, or else moves one
    clock (round robin, if several virtual clocks share the loop) to its next timer, or,
    when every clock is paced, waits in real time until the earliest may move (a new
    timer, a resume or finished I/O wakes it early). A single driver per loop matters: two
    spinning drivers would each keep the other's loop busy and time would never move.
    """

    _instances: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, _LoopDriver] = (
        weakref.WeakKeyDictionary())

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = weakref.ref(loop)
        self.clocks: list[VirtualClock] = []
        self.task: asyncio.Task[None] | None = None
        self._wake: asyncio.Future[None] | None = None

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
        clock._served = True
        if self.task is None or self.task.done():
            # the clock's own task, outside any System: it must outlive them all
            self.task = loop_service(self._run(), "afa-virtual-clock")

    def poke(self) -> None:
        wake = self._wake
        if wake is not None and not wake.done():
            wake.set_result(None)

    async def _run(self) -> None:
        ready = _ready_queue()
        loop = asyncio.get_running_loop()
        while True:
            working = []
            for clock in self.clocks:
                if clock._has_work():
                    working.append(clock)
                else:
                    clock._served = False
            self.clocks = working
            if not working:
                return
            await asyncio.sleep(0)
            if ready:
                continue
            for clock in self.clocks:
                if clock._idle:
                    clock._run_idle()
            if ready:
                continue
            # the rest of the current instant, one timer at a time, before settle() returns
            for clock in self.clocks:
                deadline = clock._due()
                if deadline is not None and deadline <= clock._t:
                    clock._fire_next()
                    break
            else:
                deadline = None
            if deadline is not None:
                continue
            if any([c._wake_settlers() for c in self.clocks]):
                continue
            wait: float | None = None
            for index, clock in enumerate(self.clocks):
                deadline = clock._due()
                if deadline is None:
                    continue
                real = 0.0 if deadline <= clock._t else clock._real_wait(deadline)
                if real <= 0.0:
                    clock._fire_next()
                    self.clocks.append(self.clocks.pop(index))
                    wait = None
                    break
                wait = real if wait is None else min(wait, real)
            else:
                if wait is not None:
                    await self._sleep_real(loop, wait)

    async def _sleep_real(self, loop: asyncio.AbstractEventLoop, seconds: float) -> None:
        self._wake = wake = loop.create_future()
        timer = loop.call_later(seconds, self.poke)
        try:
            await wake
        finally:
            timer.cancel()
            self._wake = None


def _ready_queue() -> Sized:
    loop = asyncio.get_running_loop()
    ready = getattr(loop, "_ready", None)
    if ready is None:
        raise RuntimeError(
            "VirtualClock needs the standard asyncio event loop (it inspects the ready queue "
            "to detect idleness); use WallClock with this loop."
        )
    return ready  # type: ignore[no-any-return]
