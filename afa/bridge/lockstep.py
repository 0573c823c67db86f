"""Lock-step virtual time across processes (decision 0011).

In one process, a :class:`~afa.clock.VirtualClock` advances only when every task waits:
then it jumps to the earliest timer. Split over several processes, each with its own
clock, that rule is kept *globally*: virtual time moves only when every process is idle
and no message between them is in flight, and then every process moves to the earliest
timer of any of them. Nothing can run at a different virtual time than it would in one
process, so a split run keeps the outcome of a single-process run (the Pose stream, the
distance driven, the collisions), and clocks cannot silently jump apart.

Roles: one process is the **time master** (``Bridge/TimeMaster``, default the group of
the first Launcher entry, the vehicle); the others **follow**. Every member runs a
:class:`SteppedClock`, a virtual clock that moves only when granted.

1. *Join*: the master waits (``Bridge/JoinTimeout`` real seconds) until every process
   group of the configuration has a bridge up, then welcomes each; a follower answers
   ``ready``. Only then do the systems start their components (at virtual time 0).
2. *Rounds*: when the master's loop is idle it *probes* the followers; each answers, once
   its own loop is idle, with its next timer and its message counters: events exported
   and, per peer, the last event seen, the polls sent and received, the replies sent and
   received. Counters are read before idleness is checked, and counted on arrival (on
   Zenoh's thread), so an idle report is never stale by a message: the run is quiescent
   when every report is idle and, for every pair of members, what one sent the other has
   received (served names appearing and going, liveliness tokens, count too: a component
   waiting for a name must see it at the instant it would in one process). Otherwise
   the master probes again.
3. *Grant*: the master moves every clock to the earliest next timer of any member
   (``advance``), each member runs its timers due then, and the cycle repeats. When
   nothing the master sent or received changed since the last grant and no follower had
   a timer at it, the master grants the next instant without a round.
4. *End*: a member that stops cleanly says ``bye``; the master then ends the run for all
   (``System.request_stop``). A member that dies (its liveliness token disappears) fails
   the run everywhere: virtual time cannot go on without it.

A remote poll in flight does not hold time: it is a message counted like an event, so a
``getWait…`` across processes waits for the next sample in virtual time, as in one
process. Pacing (``--realtime-factor``) is applied by the master between grants.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import threading
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import partial
from typing import TYPE_CHECKING, Any

from afa.bridge import keys
from afa.clock import DEFAULT_EPOCH, VirtualClock
from afa.errors import ComponentError, EOutOfBounds

if TYPE_CHECKING:
    from afa.bridge.bridge import Bridge

__all__ = ["SteppedClock", "LockStep", "TimeMaster", "TimeFollower", "lockstep_for",
           "Traffic"]

log = logging.getLogger("afa.bridge.time")

#: Real seconds between welcome messages while a follower has not answered.
_WELCOME_EVERY = 0.25
_END_ACK_TIMEOUT = 5.0  # s of wall clock the master waits for followers to take the end
#: Real seconds without quiescence after which the master logs its counters.
_STALL_WARNING = 10.0


def _number(value: Any) -> bool:
    """A finite number: JSON's int or float, never a bool, NaN, ±Infinity or an int no
    float holds."""
    try:
        return type(value) in (int, float) and math.isfinite(value)
    except OverflowError:
        return False


def _count(value: Any) -> bool:
    return type(value) is int and value >= 0


def _counts(value: Any) -> bool:
    return isinstance(value, dict) and all(_count(v) for v in value.values())


def _text(value: Any) -> bool:
    return isinstance(value, str)


def _next(value: Any) -> bool:
    return value is None or _number(value)


#: Every field of every message (``op``: its fields and their checks). A message that
#: is not one of these, whole, is counted (``bridge.rejected["time-message"]``) and
#: dropped: a peer's typo cannot end a run.
MESSAGES: dict[str, dict[str, Callable[[Any], bool]]] = {
    # master -> follower
    "welcome": {"start": _number, "t": _number},
    "probe": {"round": _count, "t": _number},
    "advance": {"t": _number},
    "end": {},
    # follower -> master
    "ready": {"from": _text},
    "report": {"from": _text, "round": _count, "t": _number, "next": _next,
               "exported": _count, "seen": _counts, "qsent": _counts, "qrecv": _counts,
               "rsent": _counts, "rrecv": _counts, "tsent": _count, "tseen": _counts},
    "ended": {"from": _text},
    "bye": {"from": _text},
}


class SteppedClock(VirtualClock):
    """Virtual time that moves only by :meth:`grant` (lock-step across processes).

    It is a paused :class:`~afa.clock.VirtualClock`: ``settle()`` works as usual (it
    returns once the loop is idle), and time moves when the lock-step protocol grants
    the next instant. ``pace`` (a real-time factor) is honoured by the time master.
    """

    def __init__(self, start: float = DEFAULT_EPOCH, *, pace: float | None = None) -> None:
        super().__init__(start, auto_advance=False, pace=pace)

    def resume(self) -> None:
        raise ComponentError("a SteppedClock moves only when the lock-step protocol "
                             "grants time; it cannot be resumed")

    @contextmanager
    def running(self) -> Iterator[None]:
        """Nothing: a System starting, running or stopping on this clock waits for the
        time master's grants, as everything else on it does."""
        yield

    def next_deadline(self) -> float | None:
        """The earliest pending timer (monotonic seconds), or None."""
        return self._next_deadline()

    def grant(self, deadline: float) -> None:
        """Move to ``deadline``: timers due before it run at once, in order; those due at
        it run one at a time with the loop idle in between, as on any virtual clock
        (decision 0027), before :meth:`settle` returns."""
        if deadline < self._t:
            raise ComponentError(f"lock-step: time cannot go back from {self._t} to "
                                 f"{deadline}")
        while (due := self._next_deadline()) is not None and due < deadline:
            self._fire_next()
        self._t = deadline
        if (due := self._next_deadline()) is not None and due <= deadline:
            try:
                self._ensure_driver()
            except RuntimeError:  # no running loop: the next settle() starts the driver
                return
            self._poke()

    def set_start(self, start: float) -> None:
        """Take the stamp origin of the time master (before anything ran)."""
        self._start = float(start)


class Traffic:
    """Message counters of one member, safe to update from Zenoh's threads."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.exported = 0
        self.seen: dict[str, int] = {}
        self.queries_sent: Counter[str] = Counter()
        self.queries_received: Counter[str] = Counter()
        self.replies_sent: Counter[str] = Counter()
        self.replies_received: Counter[str] = Counter()
        self.replies_unprocessed = 0
        self.tokens_declared = 0  # name tokens declared and withdrawn by this process
        self.tokens_seen: Counter[str] = Counter()  # per process, its name tokens' changes

    def saw(self, sender: str, seq: int) -> None:
        with self._lock:
            if seq > self.seen.get(sender, 0):
                self.seen[sender] = seq

    def count(self, which: Counter[str], process: str, delta: int = 1) -> None:
        with self._lock:
            which[process] += delta

    def reply_pending(self, delta: int) -> None:
        with self._lock:
            self.replies_unprocessed += delta

    def snapshot(self) -> dict[str, Any]:
        with self._lock:
            return {"exported": self.exported, "seen": dict(self.seen),
                    "qsent": dict(self.queries_sent), "qrecv": dict(self.queries_received),
                    "rsent": dict(self.replies_sent), "rrecv": dict(self.replies_received),
                    "tsent": self.tokens_declared, "tseen": dict(self.tokens_seen)}


def lockstep_for(bridge: Bridge, system: Any, configuration: Any,
                 members: list[str] | None = None) -> LockStep:
    """The lock-step role of ``system``'s process among ``members`` (default: the
    process groups of ``configuration``'s enabled Launcher entries)."""
    groups: list[str] = list(members or [])
    if not groups and configuration is not None:
        groups = list(dict.fromkeys(
            e.group for e in configuration.launcher.Components if e.Enabled))
    if system.process not in groups:
        groups.append(system.process)
    master = bridge.parameters.TimeMaster or groups[0]
    if master not in groups:
        raise ComponentError(f"Bridge/TimeMaster names {master!r}, which is not a process "
                             f"group here ({', '.join(groups)})")
    if system.process == master:
        return TimeMaster(bridge, system, [g for g in groups if g != master])
    return TimeFollower(bridge, system, master)


class LockStep:
    """What the two roles share: messages, idleness, counters."""

    role = ""
    receives: frozenset[str] = frozenset()  # the ops of the messages sent to this role

    def __init__(self, bridge: Bridge, system: Any) -> None:
        self.bridge = bridge
        self.system = system
        self.clock: SteppedClock = system.clock
        self.rounds = 0
        self.grants = 0
        self.skipped_rounds = 0
        self._task: asyncio.Task[Any] | None = None
        self._failure: asyncio.Future[None] | None = None
        self._ended = False

    # -- hooks from the bridge -----------------------------------------------------------
    async def start(self) -> None:
        self._failure = asyncio.get_running_loop().create_future()

    async def join(self) -> None:
        raise NotImplementedError

    async def stop(self) -> None:
        raise NotImplementedError

    def on_message(self, rest: list[str], payload: bytes) -> None:
        if rest != [self.bridge.process]:
            return
        try:
            message = json.loads(payload)
        except (ValueError, RecursionError):
            message = None
        op = message.get("op") if isinstance(message, dict) else None
        fields = MESSAGES.get(op) if isinstance(op, str) and op in self.receives else None
        if fields is None or not all(name in message and valid(message[name])
                                     for name, valid in fields.items()):
            self.refuse(f"{payload[:100]!r} is not a lock-step message for a {self.role}")
            return
        self.handle(message)

    def handle(self, message: dict[str, Any]) -> None:
        """A message of :attr:`receives` whose every field is valid (:data:`MESSAGES`)."""
        raise NotImplementedError

    def refuse(self, why: str) -> None:
        """Count and drop a time message (bad input from a peer never ends a run)."""
        self.bridge._reject("time-message", f"lock-step: {why}")

    def on_process(self, process: str, present: bool) -> None:
        """A process's liveliness token appeared or disappeared."""

    async def reach(self, moment: float) -> None:
        """Wait until this process's clock reaches ``moment``, the virtual time another
        member made a call at (the grant of that time may still be on its way here).
        Raises EOutOfBounds for a time that is not finite or that no grant reaches."""
        raise NotImplementedError

    def _beyond(self, moment: float) -> EOutOfBounds:
        return EOutOfBounds(f"lock-step: a call made at t={moment!r} s, and no process "
                            f"has been granted more than t={self.clock.monotonic()!r} s")

    # -- helpers ---------------------------------------------------------------------------
    def send(self, process: str, message: dict[str, Any]) -> None:
        session = self.bridge.session
        if session is None:
            return
        zenoh = self.bridge.zenoh
        session.put(keys.time_to(self.bridge.robot, process), json.dumps(message).encode(),
                    congestion_control=zenoh.CongestionControl.BLOCK, express=True)

    def fail(self, message: str) -> None:
        if self._failure is not None and not self._failure.done() and not self._ended:
            self._failure.set_exception(ComponentError(f"lock-step: {message}"))

    async def quiet(self) -> dict[str, Any]:
        """Wait until this process is idle (loop and bridge); its counters then."""
        bridge = self.bridge
        while True:
            bridge.changed.clear()
            await self.clock.settle()
            snapshot = bridge.traffic.snapshot()  # counters first, then idleness
            if bridge.idle():
                return snapshot
            await bridge.changed.wait()

    async def finish_instant(self) -> None:
        """The end of a run: let every process finish the current instant, then hold."""

    def statistics(self) -> dict[str, Any]:
        return {"role": self.role, "rounds": self.rounds, "grants": self.grants,
                "rounds_skipped": self.skipped_rounds, "time": self.clock.monotonic()}


class TimeMaster(LockStep):
    """Probes the followers, checks quiescence, grants time (module docstring)."""

    role = "master"
    receives = frozenset({"ready", "report", "ended", "bye"})

    def __init__(self, bridge: Bridge, system: Any, followers: list[str]) -> None:
        super().__init__(bridge, system)
        self.followers = followers
        self.present: set[str] = set()
        self.ready: set[str] = set()
        self.departed: set[str] = set()
        self._ready_all: asyncio.Event = asyncio.Event()
        self._reports: dict[str, dict[str, Any]] = {}
        self._reports_in: asyncio.Event = asyncio.Event()
        self._anchor: tuple[float, float, float] | None = None
        self._holding = False  # the run is ending: no more grants
        self._stall_since: float | None = None
        self._stall_reported = False
        self._quiescent: asyncio.Event = asyncio.Event()
        self._acknowledged: asyncio.Event = asyncio.Event()

    async def join(self) -> None:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.bridge.parameters.JoinTimeout
        while not self._ready_all.is_set():
            for follower in self.followers:
                if follower in self.present and follower not in self.ready:
                    self.send(follower, {"op": "welcome", "start": self.clock.now(),
                                         "t": self.clock.monotonic()})
            if loop.time() >= deadline:
                missing = [f for f in self.followers if f not in self.ready]
                raise ComponentError(
                    f"lock-step: process group(s) {', '.join(missing)} did not join within "
                    f"{self.bridge.parameters.JoinTimeout:g} s; start each with `afa run "
                    f"CONFIG --process NAME` (same configuration, --fast)")
            try:
                await asyncio.wait_for(self._ready_all.wait(), _WELCOME_EVERY)
            except TimeoutError:
                pass
        log.info("lock-step: %s master of %s", self.bridge.process,
                 ", ".join(self.followers) or "nobody")
        self._task = self.system.tasks.spawn(self._coordinate(), owner="bridge lock-step",
                                             name="bridge:time-master")

    def _check_ready(self) -> None:
        if all(f in self.ready for f in self.followers):
            self._ready_all.set()

    def on_process(self, process: str, present: bool) -> None:
        if process not in self.followers:
            return
        if present:
            self.present.add(process)
            self.send(process, {"op": "welcome", "start": self.clock.now(),
                                "t": self.clock.monotonic()})
        else:
            self.present.discard(process)
            self._acknowledged.set()
            if process in self.ready and process not in self.departed:
                self.fail(f"process {process} went away at t={self.clock.monotonic():.3f} s; "
                          "virtual time cannot go on without it")
            self._reports_in.set()

    async def reach(self, moment: float) -> None:
        """At once: the master grants itself each instant before anybody else hears of
        it, so a call from a member is never ahead of it."""
        if not (math.isfinite(moment) and moment <= self.clock.monotonic()):
            raise self._beyond(moment)

    def handle(self, message: dict[str, Any]) -> None:
        op = message.get("op")
        sender = message.get("from")
        if sender not in self.followers:
            return
        if op == "ready":
            self.ready.add(sender)
            self._check_ready()
        elif op == "report":
            if message["next"] is not None and message["next"] < message["t"]:
                self.refuse(f"{sender}'s report has its next timer before its time")
                return
            self._reports[sender] = message
            self._reports_in.set()
        elif op == "ended":  # a follower acknowledges "end": it may now see us go
            self.departed.add(sender)
            self._acknowledged.set()
        elif op == "bye":
            self.departed.add(sender)
            log.warning("lock-step: process %s stopped at t=%.3f s, which ends the run "
                        "for every process", sender, self.clock.monotonic())
            self._ended = True
            self.system.request_stop()
            self._reports_in.set()

    async def stop(self) -> None:
        self._ended = True
        ending = [f for f in self.followers if f in self.present and f not in self.departed]
        for follower in ending:
            self.send(follower, {"op": "end"})
        if self._task is not None:
            self._task.cancel()
        # Wait (a bounded wall-clock time) for each follower to acknowledge the end:
        # closing the session first lets a follower see this process's liveliness go
        # before the "end" message, and it would stop with "the time master went away".
        loop = asyncio.get_running_loop()
        deadline = loop.time() + _END_ACK_TIMEOUT
        while any(f in self.present and f not in self.departed for f in ending):
            self._acknowledged.clear()
            remaining = deadline - loop.time()
            if remaining <= 0:
                log.warning("lock-step: %s did not acknowledge the end of the run",
                            ", ".join(f for f in ending if f not in self.departed))
                break
            try:
                await asyncio.wait_for(self._acknowledged.wait(), remaining)
            except TimeoutError:
                pass

    async def _coordinate(self) -> None:
        assert self._failure is not None
        failure = self._failure
        clock = self.clock
        last: dict[str, Any] | None = None   # master's counters at the last grant
        nexts: dict[str, float | None] = {}  # followers' next timers, last reported
        granted: float | None = None
        while True:
            mine = await self.quiet()
            if failure.done():
                failure.result()
            if self._ended:
                return
            skip = (last is not None and mine == last and self.followers
                    and all(n is None or (granted is not None and n > granted)
                            for n in nexts.values()))
            if skip:
                self.skipped_rounds += 1
            elif self.followers:
                self.rounds += 1
                reports = await self._probe(self.rounds, failure)
                if reports is None:
                    continue
                mine = await self.quiet()
                if not self._consistent(mine, reports):
                    self._stalled(mine, reports)
                    continue
                self._stall_since = None
                nexts = {f: r.get("next") for f, r in reports.items()}
            if self._holding:  # everyone has finished this instant: hold time here
                self._quiescent.set()
                await failure
            candidates = [d for d in [clock.next_deadline(), *nexts.values()] if d is not None]
            if not candidates:
                await self._activity(failure)
                continue
            instant = min(candidates)
            log.debug("grant %r (mine %r, followers %r, skip %s)", instant,
                      clock.next_deadline(), nexts, skip)
            await self._pace(instant)
            for follower in self.followers:
                self.send(follower, {"op": "advance", "t": instant})
            clock.grant(instant)
            self.grants += 1
            granted = instant
            last = mine

    async def _probe(self, number: int, failure: asyncio.Future[None]
                     ) -> dict[str, dict[str, Any]] | None:
        self._reports.clear()
        now = self.clock.monotonic()
        for follower in self.followers:
            self.send(follower, {"op": "probe", "round": number, "t": now})
        while True:
            self._reports_in.clear()
            if failure.done():
                failure.result()
            if self._ended:
                return None
            if all(f in self._reports for f in self.followers):
                break
            await self._reports_in.wait()
        reports = dict(self._reports)
        if any(r.get("round") != number or r.get("t") != now for r in reports.values()):
            return None
        return reports

    async def finish_instant(self) -> None:
        """Stop granting; return once every member is idle at the current instant with
        nothing in flight (at once if the run was ended by a member or failed)."""
        self._holding = True
        task = self._task
        while not (task is None or task.done() or self._ended or self._quiescent.is_set()
                   or (self._failure is not None and self._failure.done())):
            try:
                await asyncio.wait_for(self._quiescent.wait(), 0.5)
            except TimeoutError:
                pass

    def _stalled(self, mine: dict[str, Any], reports: dict[str, dict[str, Any]]) -> None:
        """Say so (once) when quiescence has not come for a while: a message counted as
        sent that never arrives would otherwise stop time without a word."""
        now = asyncio.get_running_loop().time()
        if self._stall_since is None:
            self._stall_since = now
        elif now - self._stall_since > _STALL_WARNING and not self._stall_reported:
            self._stall_reported = True
            log.warning("lock-step: no quiescence at t=%.6f for %.0f s; counters: %s",
                        self.clock.monotonic(), now - self._stall_since,
                        json.dumps({self.bridge.process: mine, **reports}))

    def _consistent(self, mine: dict[str, Any], reports: dict[str, dict[str, Any]]) -> bool:
        members = {self.bridge.process: mine, **reports}
        for sender, s in members.items():
            for receiver, r in members.items():
                if sender == receiver:
                    continue
                if r["seen"].get(sender, 0) != s["exported"]:
                    return False
                if r["qrecv"].get(sender, 0) != s["qsent"].get(receiver, 0):
                    return False
                if r["rrecv"].get(sender, 0) != s["rsent"].get(receiver, 0):
                    return False
                if r.get("tseen", {}).get(sender, 0) != s.get("tsent", 0):
                    return False  # a served name appearing or going is still on its way
        return True

    async def _activity(self, failure: asyncio.Future[None]) -> None:
        """Nothing is scheduled anywhere: wait (in real time) until something happens (a
        call from a tool, a message) or a local timer appears."""
        while not failure.done() and self.clock.next_deadline() is None:
            self.bridge.changed.clear()
            try:
                await asyncio.wait_for(self.bridge.changed.wait(), 0.5)
            except TimeoutError:
                continue
            return

    async def _pace(self, instant: float) -> None:
        pace = self.clock.pace
        if pace is None:
            self._anchor = None
            return
        loop = asyncio.get_running_loop()
        real = loop.time()
        if self._anchor is None or self._anchor[2] != pace:
            self._anchor = (self.clock.monotonic(), real, pace)
        wait = self._anchor[1] + (instant - self._anchor[0]) / pace - real
        if wait > 0:
            done = loop.create_future()
            handle = loop.call_later(wait, _resolve, done)
            try:
                await done
            finally:
                handle.cancel()

    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        stats["followers"] = list(self.followers)
        return stats


class TimeFollower(LockStep):
    """Answers probes once idle, moves its clock when granted (module docstring)."""

    role = "follower"
    receives = frozenset({"welcome", "probe", "advance", "end"})

    def __init__(self, bridge: Bridge, system: Any, master: str) -> None:
        super().__init__(bridge, system)
        self.master = master
        self._welcomed: asyncio.Event = asyncio.Event()
        self._reporting: asyncio.Task[Any] | None = None
        self._awaited: list[tuple[float, asyncio.Future[None]]] = []  # reach()

    async def join(self) -> None:
        timeout = self.bridge.parameters.JoinTimeout
        try:
            await asyncio.wait_for(self._welcomed.wait(), timeout)
        except TimeoutError:
            raise ComponentError(
                f"lock-step: the time master {self.master} did not welcome this process "
                f"within {timeout:g} s; start it with `afa run CONFIG --process "
                f"{self.master}` (same configuration, --fast)") from None
        log.info("lock-step: %s follows %s", self.bridge.process, self.master)
        self._task = self.system.tasks.spawn(self._watch(), owner="bridge lock-step",
                                             name="bridge:time-follower")

    async def _watch(self) -> None:
        assert self._failure is not None
        await self._failure

    async def reach(self, moment: float) -> None:
        """A follower may be behind the caller by grants still on their way: the call
        waits for them without asking for that time (a timer would, the next grant being
        the earliest timer of any member). The next probe tells the master's time; a
        call still waiting for a later one is refused then."""
        if not math.isfinite(moment):
            raise self._beyond(moment)
        if moment > self.clock.monotonic():
            future = asyncio.get_running_loop().create_future()
            self._awaited.append((moment, future))
            await future

    def _release(self, instant: float) -> None:
        """Time is granted up to ``instant``: the calls waiting for it or an earlier
        time become timers of the clock, which fire them in order."""
        waiting, self._awaited = self._awaited, []
        for moment, future in waiting:
            if moment > instant:
                self._awaited.append((moment, future))
            elif not future.done():
                self.clock.call_at(moment, partial(_resolve, future))

    def on_process(self, process: str, present: bool) -> None:
        if process == self.master and not present and self._welcomed.is_set() \
                and not self._ended:
            self.fail(f"the time master {process} went away at "
                      f"t={self.clock.monotonic():.3f} s; virtual time cannot go on")

    def handle(self, message: dict[str, Any]) -> None:
        op = message.get("op")
        if op == "welcome":
            if not self._welcomed.is_set():
                self.clock.set_start(float(message["start"]))
                self._welcomed.set()
            self.send(self.master, {"op": "ready", "from": self.bridge.process})
        elif op == "probe":
            self.rounds += 1
            if self._reporting is not None:
                self._reporting.cancel()
            self._reporting = self.system.tasks.spawn(
                self._report(message["round"], float(message["t"])),
                owner="bridge lock-step", name="bridge:time-report")
        elif op == "advance":
            if message["t"] < self.clock.monotonic():
                self.refuse(f"a grant of t={message['t']} would take time back from "
                            f"t={self.clock.monotonic()}")
                return
            self._release(float(message["t"]))
            self.clock.grant(float(message["t"]))
            self.grants += 1
        elif op == "end":
            if not self._ended:
                self.send(self.master, {"op": "ended", "from": self.bridge.process})
            self._ended = True
            log.info("lock-step: the time master ended the run at t=%.3f s",
                     self.clock.monotonic())
            self.system.request_stop()

    async def _report(self, number: int, now: float) -> None:
        if now != self.clock.monotonic():
            self.fail(f"probe for t={now} arrived at t={self.clock.monotonic()}")
            return
        waiting, self._awaited = self._awaited, []  # later than the master's time
        for moment, future in waiting:
            if not future.done():
                future.set_exception(self._beyond(moment))
        snapshot = await self.quiet()
        self.send(self.master, {"op": "report", "from": self.bridge.process,
                                "round": number, "t": self.clock.monotonic(),
                                "next": self.clock.next_deadline(), **snapshot})

    async def stop(self) -> None:
        if not self._ended:
            self.send(self.master, {"op": "bye", "from": self.bridge.process})
        self._ended = True
        for task in (self._reporting, self._task):
            if task is not None:
                task.cancel()


def _resolve(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)
