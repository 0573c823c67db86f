"""Replaying a recording into a System (the seed's LogPlayer, which could not be polled).

:class:`Player` builds a System from a configuration and decides, from the recorded
catalog and its own components' ports:

- which components **re-run**: those that subscribe to something and whose every
  subscription is recorded (maps, planners, the arbiter, ModelServer on raw sensors).
  Components that subscribe to nothing recorded are **sources** (device drivers): they
  do not run, their recorded events are published in their place;
- which recorded topics are **replayed**: every recorded event topic that no re-run
  component publishes (a re-run component's outputs come from the re-run);
- which **servers** it answers for: every recorded server whose component does not
  re-run gets a servant under the recorded name, serving ``get…`` from the latest
  recorded event of the method's type (or the latest recorded result of that call),
  ``getWait…`` with the next one in replay time, and any other method with its
  recorded result.

``only`` and ``skip`` (names or patterns of components and topics) narrow both choices.

Time: the replay clock starts at the recording's clock origin, so an event recorded at
stamp *s* is published when ``clock.now() == s`` exactly, and re-run components start
on the recorded schedule: in virtual time a re-run stamps its outputs as the recording
did (what :meth:`Player.check` relies on). Controls: :meth:`pause`, :meth:`resume`,
:meth:`step` (one message), :meth:`step_time`, :meth:`seek` (republishing the latest
value of every topic before the target), :attr:`speed`.
"""

from __future__ import annotations

import asyncio
import functools
import json
import logging
import math
import types
from collections import deque
from collections.abc import Collection, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from fnmatch import fnmatchcase
from pathlib import Path
from typing import Any, Union, get_args, get_origin

from afa.clock import TIME_TOLERANCE, VirtualClock
from afa.component import Component, State
from afa.errors import AfaError, ConfigError, EDevIO, InterfaceError
from afa.events import Overflow, peek_envelope
from afa.log import format as fmt
from afa.log.check import CheckReport, Divergence, first_difference
from afa.log.reader import LogChannel, LogMessage, LogReader
from afa.naming import join_name
from afa.polling import (
    LatestSlot,
    LocalInvoker,
    PollError,
    PollRecord,
    decode_arguments,
    decode_error,
    proxy_for,
)
from afa.polling import decode_result as decode_poll_result
from afa.system import System
from idl import wire
from idl._base import IDLModel, Interface, type_name

__all__ = ["Player", "ReplayServant", "known_interfaces", "recorded_servants",
           "check"]

log = logging.getLogger("afa.log")

#: How far ahead (s) the player schedules a recorded instant. The clock runs the
#: callbacks of one instant in the order they were scheduled, so scheduling early puts
#: the recorded inputs before the timers the re-run components set for that instant
#: (their periods are shorter than this), as the recorded sources' were.
LOOKAHEAD = 2.0


def known_interfaces() -> dict[str, type[Interface]]:
    """Every Interface class this program has imported, by qualified name. A log names
    an interface; it never makes the player import anything."""
    found: dict[str, type[Interface]] = {}
    pending = list(Interface.__subclasses__())
    while pending:
        cls = pending.pop()
        found[f"{cls.__module__}.{cls.__qualname__}"] = cls
        pending.extend(cls.__subclasses__())
    return found


def _result_type(interface: type[Interface], method: str) -> Any:
    hint = interface.methods[method].hints().get("return")
    if get_origin(hint) in (Union, types.UnionType):
        args = [a for a in get_args(hint) if a is not type(None)]
        hint = args[0] if len(args) == 1 else None
    return hint if isinstance(hint, type) and issubclass(hint, IDLModel) else None


def _matches(name: str, patterns: Sequence[str]) -> bool:
    return any(fnmatchcase(name, p) for p in patterns)


@dataclass
class _Call:
    """The recorded answers of one method, by encoded arguments."""

    latest: dict[bytes, tuple[bytes, str, str]] = field(default_factory=dict)
    last: tuple[bytes, str, str] | None = None


class ReplayServant:
    """Answers a recorded server's polls from the recording (see the module docstring).
    Bound in the replay system's registry under the recorded name."""

    def __init__(self, interface: type[Interface], name: str, clock: Any,
                 topics: dict[str, str], decode: Any = None) -> None:
        self.interface = interface
        self.name = name
        self._decode = decode or (lambda value: value)  # slots hold recorded messages
        self.calls: dict[str, _Call] = {}
        self._slots: dict[str, LatestSlot[Any]] = {}  # by topic
        self._by_type = topics  # qualified versioned type -> the topic carrying it
        self._clock = clock

    @property
    def topics(self) -> set[str]:
        """The event names its ``get…`` answers come from (what its component published)."""
        return set(self._by_type.values())

    def slot(self, topic: str) -> LatestSlot[Any]:
        slot = self._slots.get(topic)
        if slot is None:
            slot = self._slots[topic] = LatestSlot(self._clock, f"{topic} (recorded)")
        return slot

    def reset(self) -> None:
        """Forget what was replayed (a seek)."""
        self._slots.clear()
        self.calls.clear()

    def record(self, method: str, arguments: bytes, result: bytes, kind: str,
               message: str) -> None:
        call = self.calls.setdefault(method, _Call())
        call.latest[arguments] = call.last = (result, kind, message)

    async def invoke(self, method: str, arguments: dict[str, Any]) -> Any:
        interface = self.interface
        if method not in interface.methods:
            raise InterfaceError(f"{interface.__name__} has no method {method!r}")
        result_type = _result_type(interface, method)
        topic = None if result_type is None else self._by_type.get(type_name(result_type))
        waits = method.startswith("get") and "Wait" in method
        if topic is not None and not interface.methods[method].parameters:
            slot = self.slot(topic)
            if waits:
                return self._decode(await slot.wait_next(interface.wait_timeout))
            return self._decode(slot.get())
        if waits:
            plain = method.replace("Wait", "", 1)
            return await self._wait_call(method, plain)
        return self._answer(method, arguments)

    def _answer(self, method: str, arguments: dict[str, Any]) -> Any:
        from afa.polling import encode_arguments

        call = self.calls.get(method)
        key = encode_arguments(self.interface, method, arguments)
        found = None if call is None else call.latest.get(key)
        if found is None and call is not None and not self.interface.methods[method].parameters:
            found = call.last
        if found is None:
            if self.interface.methods[method].hints().get("return") in (None, type(None)):
                return None  # a command (setVelocity): accepted, as the server did
            raise EDevIO(f"{self.name}.{method}({', '.join(map(repr, arguments.values()))}): "
                         "not in the recording (yet)")
        result, kind, message = found
        if kind:
            raise decode_error(wire.encode(PollError(kind=kind, message=message)))
        return decode_poll_result(self.interface, method, result)

    async def _wait_call(self, method: str, plain: str) -> Any:
        slot = self.slot(f"poll:{method}")
        try:
            return await slot.wait_next(self.interface.wait_timeout)
        except AfaError:
            if plain in self.interface.methods and plain != method:
                return self._answer(plain, {})
            raise

    def heard(self, method: str, result: Any) -> None:
        """A recorded result of ``method`` has been replayed (wakes getWait callers)."""
        self.slot(f"poll:{method}").set(result)

    def replay(self, record: fmt.PollCallIDL) -> None:
        """A recorded call to this server: its answer is kept and getWait callers woken."""
        result, arguments = bytes(record.result), bytes(record.arguments)
        self.record(record.method, arguments, result, record.error_kind,
                    record.error_message)
        if not record.error_kind and result:
            try:
                self.heard(record.method, decode_poll_result(self.interface, record.method,
                                                             result))
            except AfaError:
                pass


def recorded_servants(reader: LogReader, robot: str, clock: Any, decode: Any,
                      rerun: Collection[str] = ()) -> dict[str, ReplayServant]:
    """A :class:`ReplayServant` for every recorded server whose component is not in
    ``rerun``, by full name: what a replay binds, and what ``afa poll --log`` asks.
    ``decode`` turns a recorded event message into the body a ``get…`` answers with.
    A server of an interface this program does not know is named in ``reader.problems``."""
    interfaces = known_interfaces()
    ports = reader.catalog()
    servants: dict[str, ReplayServant] = {}
    for port in ports:
        if port.get("direction") != "serves" or port.get("component") in rerun:
            continue
        types = port.get("types") or []
        interface = interfaces.get(types[0]) if types else None
        if interface is None:
            reader.problems.append(
                f"{reader.path}: server {port.get('name')} serves {types}, which this "
                "afa does not know: its polls are not answered")
            continue
        topics: dict[str, str] = {}
        for other in ports:
            if other.get("component") == port.get("component") and \
                    other.get("direction") == "publishes":
                for published in other.get("types") or []:
                    topics.setdefault(published, other.get("name", ""))
        name = join_name(robot, str(port.get("name")))
        servants[name] = ReplayServant(interface, name, clock, topics, decode)
    return servants


class ReplayClock(VirtualClock):
    """The replay's clock: a :class:`VirtualClock` (paced when ``pace`` is set) that can
    say when it first shows a recorded stamp.

    A recorded stamp is a float near 1e9 s (an ulp is 2.4e-7 s), the rounded sum of the
    recorded clock's start and monotonic time: ``stamp - start`` is not the monotonic
    instant the recorded run had but one of the few floats whose stamp rounds to it. The
    player delivers a recorded instant at the *earliest* of them (:meth:`earliest`), so
    that its inputs come before the re-run timers due at that stamp, as the recorded
    sources' did, and what is made from them carries the recorded stamp.
    """

    def __init__(self, start: float, *, auto_advance: bool, pace: float | None) -> None:
        super().__init__(start, auto_advance=auto_advance, pace=pace)

    def stamp_at(self, monotonic: float) -> float:
        """The stamp :meth:`now` gives at ``monotonic`` (the same float sum)."""
        return self._start + monotonic + self._wall_offset

    def span(self, stamp: float, guess: float) -> tuple[float, float]:
        """The least and the greatest monotonic time (near ``guess``) whose stamp is
        ``stamp``; ``(guess, guess)`` if no time shows exactly ``stamp``."""
        if self.stamp_at(guess) != stamp:
            return guess, guess
        reach = 4 * (math.ulp(stamp) + math.ulp(guess))
        return self._edge(stamp, guess, guess - reach), self._edge(stamp, guess, guess + reach)

    def _edge(self, stamp: float, inside: float, outside: float) -> float:
        """Bisect between a time showing ``stamp`` and one that does not."""
        if self.stamp_at(outside) == stamp:
            return inside
        start, offset = self._start, self._wall_offset  # stamp_at inlined: ~50 steps
        while True:
            middle = (inside + outside) / 2
            if middle == inside or middle == outside:
                return inside
            if start + middle + offset == stamp:  # the same float sum as stamp_at
                inside = middle
            else:
                outside = middle


class Player:
    """A recording replayed into the components of ``config`` (see the module docstring).

    ``speed``: multiple of real time, None for as fast as possible (virtual time).
    ``start``/``end``: seconds from the recording's first message. ``loop``: start
    again at the end. ``paused``: start paused. ``only``/``skip``: names or patterns of
    components and recorded topics (``Pose``, ``modelServer``, ``Laser*``).
    ``config`` defaults to the configuration file the recording names, if it exists.

    Raises :class:`~afa.log.reader.LogError` for an unreadable file,
    :class:`~afa.errors.ConfigError` for a bad or missing configuration or a pattern
    that names nothing.
    """

    def __init__(self, path: str | Path, config: str | Path | None = None, *,
                 speed: float | None = 1.0, start: float | None = None,
                 end: float | None = None, loop: bool = False, paused: bool = False,
                 only: Iterable[str] = (), skip: Iterable[str] = (),
                 check: bool = False, atol: float = 0.0) -> None:
        self.reader = LogReader(path)
        try:
            self._setup(config, speed, start, end, loop, paused, list(only), list(skip),
                        check, atol)
        except BaseException:
            self.reader.close()
            raise

    def _setup(self, config: str | Path | None, speed: float | None, start: float | None,
               end: float | None, loop: bool, paused: bool, only: list[str], skip: list[str],
               check: bool, atol: float) -> None:
        from afa.assembly import build_components
        from afa.config.loader import load_configuration

        reader = self.reader
        info = reader.metadata.get(fmt.META_AFA, {})
        if config is None:
            recorded = reader.metadata.get(fmt.META_CONFIG, {}).get("path")
            if not recorded or not Path(recorded).exists():
                raise ConfigError(f"{reader.path}: give the configuration to replay into "
                                  f"(the recording names {recorded or 'none'}, which is not "
                                  "here)")
            config = recorded
        configuration = load_configuration(config)
        components, delays, _ = build_components(configuration)
        self.configuration = configuration
        self.robot = configuration.robot
        self.check_mode = check
        self.atol = atol
        self.loop = loop
        try:
            self.origin = float(info.get("clock_origin", ""))
        except ValueError:
            self.origin = fmt.from_ns(reader.start)
        try:
            self.start_monotonic = float(info.get("start_monotonic", "0"))
        except ValueError:
            self.start_monotonic = 0.0
        self.clock: ReplayClock = ReplayClock(
            self.origin, auto_advance=not paused,
            pace=None if speed is None or check else speed)
        self._base = self.origin  # the stamp at monotonic 0 (moves with seeks)

        events = {c.event: c for c in reader.topics(fmt.EVENT)}
        by_name = {c.name: c for c in components}
        for pattern in only + skip:
            if not any(fnmatchcase(n, pattern) for n in [*events, *by_name]):
                raise ConfigError(f"{pattern!r} names no recorded topic and no component of "
                                  f"{configuration.path}; recorded topics: "
                                  f"{', '.join(sorted(events))}; components: "
                                  f"{', '.join(by_name)}")
        only_components = [p for p in only if any(fnmatchcase(n, p) for n in by_name)]
        only_topics = [p for p in only if any(fnmatchcase(n, p) for n in events)]

        self.sources: list[str] = []
        self.rerun: list[Component[Any]] = []
        def inputs_of(component: Component[Any]) -> list[Any]:
            return [p for p in component.ports() if p.direction.value == "subscribes"]

        # an input is covered if recorded, or made by a processing component (one that
        # re-runs too): a short recording may end before the first Traverse map
        made = {p.name for c in components if inputs_of(c) for p in c.ports()
                if p.direction.value == "publishes"}
        for component in components:
            inputs = inputs_of(component)
            covered = [any(fnmatchcase(name, p.name) for name in events) for p in inputs]
            if any(covered):
                covered = [c or p.name in made for c, p in zip(covered, inputs, strict=True)]
            if not inputs or not any(covered):
                self.sources.append(component.name)
                continue
            if not all(covered):
                log.warning("%s: not all of its inputs are recorded; it does not re-run",
                            component.name)
                continue
            if (only_components and not _matches(component.name, only_components)) or \
                    _matches(component.name, skip):
                continue
            self.rerun.append(component)
        rerun_names = {c.name for c in self.rerun}
        produced = {p.name for c in self.rerun for p in c.ports()
                    if p.direction.value == "publishes"}
        # a topic is replayed if a component that does not re-run published it (one
        # topic may have several publishers: ArcVote from each behaviour); its events
        # from re-run components are the outputs to compare, not inputs
        publishers: dict[str, set[str]] = {}
        for port in reader.catalog():
            if port.get("direction") == "publishes":
                publishers.setdefault(str(port.get("name")), set()).add(
                    str(port.get("component")))

        def from_outside(event: str) -> bool:
            return event not in produced or bool(publishers.get(event, set()) - rerun_names)

        self.replayed: dict[int, LogChannel] = {
            c.id: c for c in events.values()
            if from_outside(c.event) and not _matches(c.event, skip)
            and (not only_topics or _matches(c.event, only_topics))}
        # every event channel of the same names (one name may carry two types)
        for channel in reader.topics(fmt.EVENT):
            if channel.event in {c.event for c in self.replayed.values()}:
                self.replayed[channel.id] = channel
        # an output can only be checked if the recording would have kept it
        # (``afa run --record-events`` chooses); the others are named, not compared
        kept = [p for p in info.get("events", "*").split(",") if p]
        self.checked = sorted(n for n in produced if _matches(n, kept))
        self.unchecked = sorted(produced - set(self.checked))
        self.outputs = {c.id: c for c in reader.topics(fmt.EVENT)
                        if c.event in self.checked} if check else {}
        # the re-run's outputs the player watches: to compare them (a check), and to
        # know when the re-run has made those recorded before an input (every replay)
        self._watched = sorted((set(self.checked) if check else set()) | {
            c.event for c in self.replayed.values() if c.event in produced})

        self.system = System(robot=self.robot, clock=self.clock,
                             base_dir=configuration.path.parent, real_devices=False)
        self.system.configuration = configuration
        self._order = self._start_order(components, delays)
        self._pending = {c.name: c for c in self.rerun}
        self.servants = self._servants(rerun_names)
        self.polls = {c.id: c for c in reader.topics(fmt.POLL)}
        self.first = reader.start + (0 if start is None else round(start * 1e9))
        self.last = None if end is None else reader.start + round(end * 1e9)
        self.position = fmt.from_ns(self.first)  #: replay time: the stamp reached
        self.published = 0  #: recorded events published (to subscribers)
        self.delivered = 0  #: recorded messages handled (events, polls, expected outputs)
        self.finished = asyncio.Event()
        self.report = CheckReport(str(reader.path), [c.name for c in self.rerun],
                                  sorted({c.event for c in self.replayed.values()}),
                                  unchecked=self.unchecked if check else [])
        self._feeder: asyncio.Task[None] | None = None
        self._upcoming: deque[float] = deque()  # stamps scheduled, not yet reached
        self.failure: Exception | None = None  #: what stopped the replay, if anything
        self._expected: dict[tuple[str, ...], deque[tuple[float, Any]]] = {}
        self._produced: dict[tuple[str, ...], deque[tuple[float, Any]]] = {}
        self._watch: list[Any] = []
        self._rerun_names = rerun_names
        # the instant being delivered (:meth:`_walk`): outputs recorded before the next
        # input and outputs the re-run has made, by (kind, domain, type, origin)
        self._instant = float("nan")
        self._needed: dict[tuple[str, ...], int] = {}
        self._made: dict[tuple[str, ...], int] = {}
        self._epoch = 0  # a seek starts a new one; callbacks of an older one do nothing
        self._final = float("inf")  # the last recorded instant (set when reached)
        self.reissued = 0  #: recorded calls re-issued to re-run servers
        self._calls_queued = self._calls_done = 0  # what :meth:`_walk` waits for
        self._rerun_servers = {
            join_name(self.robot, str(port.get("name"))) for port in reader.catalog()
            if port.get("direction") == "serves" and port.get("component") in rerun_names}
        self._calls: asyncio.Queue[fmt.PollCallIDL] = asyncio.Queue()
        self._listeners: dict[str, list[ReplayServant]] = {}
        for servant in self.servants.values():
            for event_name in set(servant._by_type.values()):
                self._listeners.setdefault(event_name, []).append(servant)

    # -- who runs, who is served ---------------------------------------------------------
    def _start_order(self, components: list[Component[Any]],
                     delays: dict[str, float]) -> list[tuple[str, float]]:
        text = self.reader.metadata.get(fmt.META_CATALOG, {}).get("start_order")
        try:
            order = [(str(n), float(d)) for n, d in json.loads(text)] if text else []
        except (ValueError, TypeError):
            order = []
        return order or [(c.name, delays.get(c.name, 0.0)) for c in components]

    def _servants(self, rerun: set[str]) -> dict[str, ReplayServant]:
        return recorded_servants(self.reader, self.robot, self.clock, self._body, rerun)

    def _body(self, message: LogMessage) -> Any:
        event = self.reader.decode_event(message)
        if event is None:
            raise EDevIO(f"{message.channel.topic}: the recorded event cannot be decoded")
        return event.body

    # -- running -------------------------------------------------------------------------
    async def __aenter__(self) -> Player:
        await self.start()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.stop()

    async def start(self) -> None:
        """Start the replay system, bind the servants, and begin publishing."""
        system = self.system
        self._watch = [system.channel.observe(self.robot, name, maxsize=1 << 20,
                                              policy=Overflow.DROP_NEWEST)
                       for name in self._watched]
        if self.check_mode:
            system.polls.add_hook(self._heard_poll)
        await system.start()
        for name, servant in self.servants.items():
            system.registry.rebind(name, servant, owner=self)
        seeking = self.first > self.reader.start
        if seeking:  # the clock shows the start at once (paused, a step is one second)
            self._seek_state(self.first)
            await self._launch_all()
            self._republish(self.first)
        else:
            system.tasks.spawn(self._start_components(), owner="player schedule")
        self._feeder = system.tasks.spawn(self._feed(self.first), owner="player")
        system.tasks.spawn(self._reissue(), owner="player calls")

    async def stop(self) -> None:
        try:
            await self.system.stop()
        finally:
            self.reader.close()

    async def run(self) -> None:
        """Until the end of the recording (or of ``end``); forever with ``loop``.
        Raises TaskFailed if the player or a system task fails."""
        from afa.tasks import Scope

        async with Scope() as scope:
            runner: asyncio.Task[Any] = scope.spawn(self.system.run(), "player-system")
            waiter: asyncio.Task[Any] = scope.spawn(self.finished.wait(), "player-finished")
            done, _ = await asyncio.wait([runner, waiter], return_when=asyncio.FIRST_COMPLETED)
            for task in (runner, waiter):
                task.cancel()
            for task in done:
                task.result()
        if self.failure is not None:
            raise self.failure

    async def _start_components(self) -> None:
        clock = self.clock
        await clock.sleep_until(self.start_monotonic)
        for name, delay in self._order:
            component = self._pending.pop(name, None)
            if component is not None:
                await self._launch(component)
            if delay > 0:
                await clock.sleep(delay)
        await self._launch_all()

    async def _launch_all(self) -> None:
        for name in list(self._pending):
            await self._launch(self._pending.pop(name))

    async def _launch(self, component: Component[Any]) -> None:
        self.system.add(component)
        while component.state in (State.CREATED, State.STARTING):
            await component._wait_state_change()

    # -- feeding -------------------------------------------------------------------------
    def _channels(self) -> set[int]:
        return set(self.replayed) | set(self.polls) | set(self.outputs)

    async def _feed(self, first: int) -> None:
        """Read ahead and schedule each recorded instant (every message of one stamp) as
        a clock callback ``LOOKAHEAD`` seconds before it is due, then wait for the end."""
        clock = self.clock
        handles: deque[Any] = deque()  # scheduled instants, in time order
        try:
            while True:
                last: float | None = None
                for stamp, group in self._instants(first):
                    await clock.sleep_until(stamp - LOOKAHEAD - self._base)
                    if self.finished.is_set():
                        return
                    self._upcoming.append(stamp)
                    while handles and handles[0].cancelled:  # run (or cancelled) ones
                        handles.popleft()
                    span = clock.span(stamp, stamp - self._base)
                    handles.append(clock.call_at(
                        span[0], functools.partial(self._at, stamp, group, span[1])))
                    last = stamp
                if last is not None:
                    self._final = last
                    await clock.sleep_until(last - self._base)
                if self.finished.is_set():
                    return
                if self.check_mode:
                    if isinstance(clock, VirtualClock):
                        # the last stamp rebuilt as monotonic time may fall a rounding
                        # short of a timer the recorded run fired at the same instant
                        await clock.advance(TIME_TOLERANCE)
                        await clock.settle()
                    self._verify(before=None)
                    self.finished.set()
                    return
                if not self.loop:
                    self.finished.set()
                    return
                first = self.first
                self._seek_state(first)
                await self._start_over()
                self._republish(first)
        finally:
            for handle in handles:
                handle.cancel()
            self._upcoming.clear()

    def _instants(self, first: int) -> Iterator[tuple[float, list[tuple[LogMessage, Any, Any]]]]:
        """The recorded messages from ``first`` grouped by stamp, each group in recorded
        sequence order: at one instant the order of events matters (the arbiter decides
        on every vote), and the file's order of equal times is not the publishing one."""
        stamp: float | None = None
        group: list[tuple[float, int, int, LogMessage, Any, Any]] = []
        for message in self.reader.messages(start=first, end=self.last,
                                            channels=self._channels()):
            header = None
            if message.channel.kind == fmt.EVENT:
                header = self._header(message)
                if header is None:
                    continue
            at = header[2] if header is not None else message.time
            if stamp is not None and at > stamp:
                yield stamp, self._ordered(group)
                group = []
            if stamp is None or at > stamp:
                stamp = at
            if header is not None:
                group.append((header[3], 0, len(group), message, header, None))
                continue
            # a poll comes after the last event published when it was made (its ``seq``;
            # a recording before PollCall@2 has none: it keeps its place in the file)
            record = self.reader.decode_wire(message)
            seq = getattr(record, "seq", -1)
            if seq < 0:
                seq = group[-1][0] if group else -1
            group.append((seq, 1, len(group), message, None, record))
        if stamp is not None:
            yield stamp, self._ordered(group)

    @staticmethod
    def _ordered(group: list[tuple[float, int, int, LogMessage, Any, Any]]
                 ) -> list[tuple[LogMessage, Any, Any]]:
        """(message, event header or None, decoded poll record or None) in order."""
        return [(m, h, r) for *_, m, h, r in sorted(group, key=lambda item: item[:3])]

    def _at(self, stamp: float, group: list[tuple[LogMessage, Any, Any]], latest: float) -> None:
        """One recorded instant, run by the clock as it first shows ``stamp`` (before the
        re-run's timers due at that stamp): compare what came before, then deliver the
        recorded messages in recorded order (:meth:`_walk`)."""
        if self._upcoming and self._upcoming[0] <= stamp:
            self._upcoming.popleft()
        if self.finished.is_set():
            return
        try:
            if self.check_mode and self._verify(before=stamp):
                self.finished.set()
                return
            self._collect()  # outputs of earlier instants (a replay's watches drained)
            self.position = stamp
            self._instant = stamp
            self._made.clear()
            self._needed.clear()
            self._walk(self._epoch, stamp, group, 0, latest, idle=False)
        except Exception as exc:  # never into the clock's driver: fail the replay
            self.failure = exc
            self.finished.set()

    def _walk(self, epoch: int, stamp: float, group: list[tuple[LogMessage, Any, Any]], k: int,
              latest: float, *, idle: bool = True) -> None:
        """Deliver the recorded messages of one instant from the ``k``-th, in recorded
        order, holding each input until the re-run has made every output recorded
        before it at this instant (decision 0027).

        The clock fires one timer at a time and lets the loop go idle in between, so the
        recorded order of an instant is the order of its timers (the sources' and the
        re-run components') with each one's consequences after it. The player's own
        callback comes first (scheduled ``LOOKAHEAD`` ahead, at the earliest time showing
        the stamp); an input recorded after a re-run output (a GPS fix after Pure
        Pursuit's timed vote) waits, at each idle point (:meth:`VirtualClock.call_when_idle`
        ), until that output has been made: then its turn has come among the re-run's
        timers. An output the re-run does not make (a divergence) holds nothing beyond
        the instant: once no timer is due within it, the rest is delivered."""
        if epoch != self._epoch or self.finished.is_set():
            return  # a seek or the end came in between
        try:
            rerun = self._rerun_names
            while k < len(group):
                message, header, record = group[k]
                if header is not None and header[4] in rerun:  # an output, not delivered
                    key = ("event", header[0], header[1], header[4])
                    self._needed[key] = self._needed.get(key, 0) + 1
                elif (self._needed or self._calls_done < self._calls_queued) and \
                        not self._caught_up() and not (idle and self._instant_over(latest)):
                    self.clock.call_when_idle(functools.partial(
                        self._walk, epoch, stamp, group, k, latest))
                    return
                self.delivered += 1
                self._deliver(message, header, record)
                k += 1
        except Exception as exc:  # never into the clock's driver: fail the replay
            self.failure = exc
            self.finished.set()

    def _caught_up(self) -> bool:
        """Whether the re-run has made, at this instant, every output recorded so far in
        it."""
        if self._calls_done < self._calls_queued:  # a re-issued command is under way
            return False
        self._collect()
        made = self._made
        return all(made.get(key, 0) >= n for key, n in self._needed.items())

    def _instant_over(self, latest: float) -> bool:
        """At an idle point: whether no timer is due within the instant any more."""
        deadline = self.clock.next_deadline()
        return deadline is None or deadline > latest

    def _header(self, message: LogMessage) -> tuple[str, str, float, int, str] | None:
        if message.channel.id in self.reader._undecodable:
            return None
        try:
            return peek_envelope(message.data)
        except wire.WireError as exc:
            self.reader._refuse(message.channel, str(exc))
            return None

    def _deliver(self, message: LogMessage, header: tuple[str, str, float, int, str] | None,
                 record: Any = None) -> None:
        """One recorded message: an event (``header``) or a poll (``record``, decoded
        already by the feeder, else here)."""
        channel = message.channel
        if header is None:
            if channel.id in self.polls:
                self._replay_poll(message, record)
            return
        domain, event_type, stamp, _, origin = header
        if channel.id in self.outputs and origin in self._rerun_names:
            self._expected.setdefault(("event", domain, event_type, origin),
                                      deque()).append((stamp, message))
        if channel.id in self.replayed and origin not in self._rerun_names:
            for servant in self._listeners.get(channel.event, ()):
                servant.slot(channel.event).set(message)
            if self.system.channel.subscribed(domain, event_type):
                event = self.reader.decode_event(message)
                if event is not None:
                    self.system.channel.inject(event)
                    self.published += 1

    def _pending_or_rerun(self) -> set[str]:
        return self._rerun_names

    def _replay_poll(self, message: LogMessage, record: Any = None) -> None:
        if record is None:
            record = self.reader.decode_wire(message)
        if not isinstance(record, fmt.PollCallIDL):
            return
        if self.check_mode and record.caller in self._pending_or_rerun():
            self._expected.setdefault(("poll", record.caller, record.server, record.method),
                                      deque()).append((message.time, record))
        if self._reissues(record):
            self._calls_queued += 1
            self._calls.put_nowait(record)
        servant = self.servants.get(record.server)
        if servant is not None:
            servant.replay(record)

    def _reissues(self, record: fmt.PollCallIDL) -> bool:
        """A recorded command (not a ``get…`` query, which changes nothing) from a caller
        that does not re-run (the control station, a source) to a server that does: the
        re-run server must hear it again (waypoints, patrol mode, arbiter on)."""
        return (record.server in self._rerun_servers
                and record.caller not in self._rerun_names
                and not record.method.startswith("get"))

    async def _reissue(self) -> None:
        """Make the queued recorded commands, one after the other in recorded order, at
        the instant the feeder reached them; their outcome is the re-run server's."""
        interfaces = known_interfaces()
        registry = self.system.registry
        while True:
            record = await self._calls.get()
            interface = interfaces.get(record.interface)
            if interface is None:
                self.reader.problems.append(
                    f"{self.reader.path}: {record.server}.{record.method} is on "
                    f"{record.interface}, which this afa does not know: not re-issued")
                self._calls_done += 1
                continue
            try:
                arguments = decode_arguments(interface, record.method, bytes(record.arguments))
                await registry.wait_resolve(record.server, interface.call_timeout)
                proxy = proxy_for(interface, LocalInvoker(registry, record.server, interface),
                                  middleware=self.system.polls.middleware)
                await getattr(proxy, record.method)(**arguments)
            except AfaError as exc:  # as the recorded caller, the player carries on
                log.info("re-issued %s.%s: %s", record.server, record.method, exc)
            self.reissued += 1
            self._calls_done += 1

    # -- controls ------------------------------------------------------------------------
    @property
    def speed(self) -> float | None:
        """Multiple of real time; None: as fast as possible."""
        return self.clock.pace

    @speed.setter
    def speed(self, value: float | None) -> None:
        self.clock.pace = value

    @property
    def paused(self) -> bool:
        return self.clock.paused

    def pause(self) -> None:
        self.clock.pause()

    def resume(self) -> None:
        self.clock.resume()

    @property
    def elapsed(self) -> float:
        """Replay position in seconds from the recording's first message."""
        return self.position - fmt.from_ns(self.reader.start)

    async def step(self) -> None:
        """Publish the next message (works paused: the clock moves just to its time)."""
        if not self._upcoming:  # the feeder has not scheduled anything yet
            await self.clock.settle()
        target = self._upcoming[0] if self._upcoming else None
        if target is None:
            return
        await self.clock.advance(max(0.0, target - (self._base + self.clock.monotonic())))

    async def step_time(self, seconds: float = 1.0) -> None:
        """Run ``seconds`` of replay time (works paused)."""
        await self.clock.advance(seconds)

    async def seek(self, seconds: float) -> None:
        """Continue from ``seconds`` after the recording's first message: the latest
        value of every replayed topic (and every recorded poll result) before it is
        published first, so consumers start from a correct state."""
        target = self.reader.start + max(0, round(seconds * 1e9))
        if self._feeder is not None:
            self._feeder.cancel()
            try:
                await self._feeder
            except asyncio.CancelledError:
                pass
        back = fmt.from_ns(target) < self.position
        self._seek_state(target)
        if back:
            await self._start_over()
        await self._launch_all()
        self._republish(target)
        self._feeder = self.system.tasks.spawn(self._feed(target), owner="player")
        await asyncio.sleep(0)

    async def _start_over(self) -> None:
        """Before going back in the recording: restart every running re-run component,
        so that none keeps what it made of later times (queued events stamped after the
        target, a pose buffer ahead of the scans, a map) into the earlier stretch."""
        for component in self.rerun:
            if component.name in self.system.components and component.name not in self._pending:
                await self.system.restart_component(component.name)

    def _seek_state(self, target: int) -> None:
        stamp = fmt.from_ns(target)
        self.clock.step_wall(stamp - self.clock.now())
        self._base = stamp - self.clock.monotonic()
        self.position = stamp
        self.finished.clear()
        self._epoch += 1
        self._needed.clear()
        for servant in self.servants.values():
            servant.reset()

    def _republish(self, target: int) -> None:
        latest = self.reader.latest_before(target, set(self.replayed) | set(self.polls))
        for message in sorted(latest.values(), key=lambda m: m.log_time):
            header = self._header(message) if message.channel.kind == fmt.EVENT else None
            if message.channel.kind != fmt.EVENT or header is not None:
                self._deliver(message, header)

    # -- the check ------------------------------------------------------------------------
    def _heard_poll(self, record: PollRecord) -> None:
        if record.caller in self._pending_or_rerun():
            self._produced.setdefault(("poll", record.caller, record.name, record.method),
                                      deque()).append((record.time, record))

    def _collect(self) -> None:
        """Take the re-run's outputs from the watches: count those of the current
        instant (:meth:`_walk`), and keep them for comparing in a check."""
        names = self._rerun_names
        for watch in self._watch:
            while (event := watch.get_nowait()) is not None:
                if event.origin in names:
                    key = ("event", event.domain, event.type, event.origin)
                    if event.time == self._instant:
                        self._made[key] = self._made.get(key, 0) + 1
                    if self.check_mode:
                        self._produced.setdefault(key, deque()).append(
                            (event.time, event.body))
            if watch.statistics().dropped:
                self.report.problems.append(
                    f"the check's buffer of {watch.type} overflowed; outputs were lost")

    def _verify(self, before: float | None) -> bool:
        """Compare what both sides have; True (and the report set) at a divergence."""
        self._collect()
        start = fmt.from_ns(self.reader.start)
        found: list[Divergence] = []
        for key in sorted(set(self._expected) | set(self._produced)):
            expected = self._expected.setdefault(key, deque())
            produced = self._produced.setdefault(key, deque())
            topic = (f"/{key[1]}/{key[2]}" if key[0] == "event"
                     else f"{key[2]}.{key[3]}")
            origin = key[3] if key[0] == "event" else key[1]
            while expected and produced:
                (t_rec, rec), (t_rep, rep) = expected.popleft(), produced.popleft()
                difference = self._difference(key[0], t_rec, rec, t_rep, rep)
                if difference is not None:
                    found.append(Divergence(t_rec, t_rec - start, topic, origin, *difference))
                    break
                self.report.compared[topic] = self.report.compared.get(topic, 0) + 1
            horizon = float("inf") if before is None else before
            if expected and expected[0][0] < horizon and not produced:
                t = expected[0][0]
                found.append(Divergence(t, t - start, topic, origin, "(missing)",
                                        _summary(expected[0][1]), "nothing produced"))
            # at the end: an output of the last recorded instant or later is not "extra"
            # (the recording stopped within that instant: its later timers did not fire)
            if produced and produced[0][0] < horizon and not expected and (
                    before is not None or produced[0][0] < self._final):
                t = produced[0][0]
                found.append(Divergence(t, t - start, topic, origin, "(extra)",
                                        "nothing recorded", _summary(produced[0][1])))
        if found:
            self.report.divergence = min(found, key=lambda d: d.time)
            return True
        return False

    def _difference(self, kind: str, t_rec: float, rec: Any, t_rep: float,
                    rep: Any) -> tuple[str, Any, Any] | None:
        if kind == "event":
            if abs(t_rec - t_rep) > self.atol:
                return ("(time)", t_rec, t_rep)
            event = self.reader.decode_event(rec)
            if event is None:
                return ("(undecodable)", rec.channel.topic, rep)
            return first_difference(event.body, rep, atol=self.atol)
        if abs(t_rec - t_rep) > self.atol:
            return ("(time)", t_rec, t_rep)
        try:
            interface = rep.interface
            recorded = decode_arguments(interface, rec.method, bytes(rec.arguments))
        except AfaError as exc:
            return ("(arguments)", f"undecodable: {exc}", rep.arguments)
        return first_difference(recorded, rep.arguments, "arguments", atol=self.atol)


async def check(path: str | Path, config: str | Path | None = None, *,
                only: Iterable[str] = (), skip: Iterable[str] = (),
                atol: float = 0.0) -> CheckReport:
    """Re-run the processing components of ``config`` on the recording ``path`` in
    virtual time and compare every output with the recorded one; the report names the
    first divergence or says the log re-runs identically. Raises as :class:`Player`."""
    player = Player(path, config, speed=None, only=only, skip=skip, check=True, atol=atol)
    async with player:
        await player.run()
    player.report.problems.extend(player.reader.problems)
    return player.report


def _summary(value: Any) -> str:
    if isinstance(value, LogMessage):
        return f"a recorded {value.channel.schema} event"
    if isinstance(value, IDLModel):
        return f"{type(value).__name__} at {getattr(value, 'time', '')}"
    return repr(value)
