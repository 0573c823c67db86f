"""The console's data side: the observer intake, one session per browser, and the
messages the console makes itself (component table, geometry, waypoints, truth, replay).

Nothing here imports the web server, so it is tested without one; :mod:`afa.console.server`
hands each WebSocket's ``send`` to a :class:`Session`.

Flow: the system's channel → the console's observer (its own bounded drop-oldest buffer,
:meth:`afa.system.System.observe`) → :meth:`ConsoleHub._on_event` classifies the event
(:func:`~afa.console.streams.classify`) and offers it to every session that shows its kind
→ each session's :class:`~afa.console.streams.Outbox` for that stream (drop-oldest, rate
limited) → the session's sender task encodes (once per event, shared between sessions)
and sends. Publishers never wait for any of it.
"""

from __future__ import annotations

import asyncio
import contextvars
import logging
import math
from collections import Counter, OrderedDict
from collections.abc import Awaitable, Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from afa.clock import Clock, VirtualClock, WallClock
from afa.console.frames import encode_frame, event_names_length
from afa.console.launcher import (
    CONSOLE_TASK,
    LoopProfiler,
    LoopShares,
    component_rows,
    process_memory,
    retained_bytes,
)
from afa.console.replay import ReplayControl, perform, status_of
from afa.console.streams import JSON_KINDS, POLICIES, Outbox, clamp_rate, classify
from afa.errors import AfaError, ComponentError
from afa.events import Event
from afa.ports import Direction, interface_name
from afa.tasks import TaskGroup
from idl import (
    ArcVoteIDL,
    GlobalMap,
    Platform,
    Range3dLaserIDL,
    Range3dStereoEventIDL,
    VehicleControl,
    VehiclePlan,
    WaypointGroupIDL,
)

__all__ = ["ConsoleHub", "Session", "GroundTruth", "HubOptions", "COMPONENT_ACTIONS",
           "VEHICLE_ACTIONS"]

log = logging.getLogger("afa.console")

COMPONENT_ACTIONS = ("start", "stop", "restart")
#: Vehicle actions; ``stop`` is always allowed, the others need control.
VEHICLE_ACTIONS = ("stop", "start", "arbiter-on", "arbiter-off")


class GroundTruth(Protocol):
    """A simulation's ground truth for displays (``RaptorSimulation.truth()``): a mapping
    with ``utm`` [easting, northing], ``heading_deg``, ``pose_error_m``,
    ``heading_error_deg``, ``waypoints_utm`` [[e, n], ...] and other JSON values."""

    def truth(self) -> Mapping[str, Any]: ...


@dataclass
class HubOptions:
    """``reference_frame``: the frame the 3-D view and range points are drawn in (the
    Raptor frame, the pose's reference). ``status_period``: seconds between component
    tables (each also refreshes one component's memory estimate). ``stale_vote_time``:
    seconds after which a behaviour's vote counts as stale on the health view (default:
    the configured arbiter's StaleVoteTime, else 1.5)."""

    reference_frame: str = "Raptor:RearAxleCenter"
    status_period: float = 1.0
    stale_vote_time: float | None = None
    observer_buffer: int = 8192
    rates: dict[str, float] = field(default_factory=dict)


class _EncodedCache:
    """Encoded events by sequence number, shared by the sessions (bounded)."""

    def __init__(self, size: int = 256) -> None:
        self._size = size
        self._items: OrderedDict[tuple[int, str], tuple[bytes, int]] = OrderedDict()

    def get(self, event: Event) -> tuple[bytes, int]:
        key = (event.seq, event.type)
        found = self._items.get(key)
        if found is None:
            found = (event.encode(), event_names_length(event))
            self._items[key] = found
            if len(self._items) > self._size:
                self._items.popitem(last=False)
        return found


class Session:
    """One browser: its subscriptions (kind → rate), an outbox per stream and the
    sender task (:meth:`run`) that drains them through ``send``.

    ``send`` is awaited for each message; a slow socket slows only this loop, whose
    outboxes then drop their oldest entries.
    """

    def __init__(self, hub: ConsoleHub, send: Callable[[bytes], Awaitable[None]],
                 name: str = "browser") -> None:
        self.hub = hub
        self.name = name
        self._send = send
        self.kinds: dict[str, float] = {}
        self.outboxes: dict[str, Outbox] = {}
        self.sent_messages = 0
        self.sent_bytes = 0
        self.failed = 0
        self._wake: asyncio.Future[None] | None = None
        self._next_wake: float | None = None
        self._closed = False

    # -- from the browser ----------------------------------------------------------------
    def subscribe(self, kinds: Mapping[str, Any]) -> None:
        """Show exactly ``kinds`` (kind → wanted rate, None for the default). Unknown
        kinds are ignored. Newly shown kinds get the latest entry of each of their
        streams at once."""
        wanted = {kind: clamp_rate(kind, rate) for kind, rate in kinds.items()
                  if kind in POLICIES}
        added = set(wanted) - set(self.kinds)
        self.kinds = wanted
        for stream, outbox in list(self.outboxes.items()):
            if outbox.kind not in wanted:
                del self.outboxes[stream]
            else:
                outbox.interval = 1.0 / wanted[outbox.kind]
        for kind, stream, entry in self.hub.latest(added):
            self.offer(kind, stream, entry)
        self._poke()

    # -- from the hub --------------------------------------------------------------------
    def offer(self, kind: str, stream: str, entry: Any) -> None:
        rate = self.kinds.get(kind)
        if rate is None:
            return
        outbox = self.outboxes.get(stream)
        if outbox is None:
            outbox = self.outboxes[stream] = Outbox(stream, kind, 1.0 / rate,
                                                    POLICIES[kind].depth)
        now = self.hub.wall.monotonic()
        outbox.push(entry, now)
        if self._wake is not None:
            # wake the sender only if this outbox may go before it would wake anyway
            due = outbox.due(now)
            if due is not None and (self._next_wake is None or due < self._next_wake):
                self._poke()

    def _poke(self) -> None:
        wake = self._wake
        if wake is not None and not wake.done():
            wake.set_result(None)

    def close(self) -> None:
        self._closed = True
        self._poke()

    # -- the sender ----------------------------------------------------------------------
    async def run(self) -> None:
        """Send what is due, sleep until the next outbox is due or something arrives;
        until :meth:`close` or a failing ``send``."""
        clock = self.hub.wall
        loop = asyncio.get_running_loop()
        while not self._closed:
            now = clock.monotonic()
            next_due: float | None = None
            for outbox in list(self.outboxes.values()):
                due = outbox.due(now)
                if due is None:
                    continue
                if due <= now:
                    await self._deliver(outbox, outbox.take(now), now)
                    now = clock.monotonic()
                    due = outbox.due(now)
                    if due is None:
                        continue
                if next_due is None or due < next_due:
                    next_due = due
            if self._closed:
                break
            self._wake = loop.create_future()
            self._next_wake = next_due
            timer = None if next_due is None else clock.call_at(next_due, self._poke)
            try:
                await self._wake
            finally:
                self._wake = None
                if timer is not None:
                    timer.cancel()

    async def _deliver(self, outbox: Outbox, entries: list[tuple[float, Any]],
                       now: float) -> None:
        """Send what ``outbox`` released: its events in one message, or each of the
        console's own JSON entries."""
        messages: list[bytes] = []
        try:
            events = [(arrival, e) for arrival, e in entries if isinstance(e, Event)]
            if events:
                data = self.hub.frame_for(outbox.kind, outbox.stream, events, now)
                if data is not None:
                    messages.append(data)
            messages.extend(encode_frame({"kind": outbox.kind, "stream": outbox.stream, **e})
                            for _, e in entries if not isinstance(e, Event))
        except Exception as exc:  # one bad entry must not end the browser's stream
            self.failed += 1
            if self.failed <= 3:
                log.exception("console: cannot encode %s for the browser (skipped): %s",
                              outbox.stream, exc)
            return
        for data in messages:
            await self._send(data)
            self.sent_messages += 1
            self.sent_bytes += len(data)

    def statistics(self) -> dict[str, Any]:
        return {"messages": self.sent_messages, "bytes": self.sent_bytes, "failed": self.failed,
                "streams": {s: {"sent": o.stats.sent, "dropped": o.stats.dropped,
                                "rate": round(1.0 / o.interval, 3)}
                            for s, o in sorted(self.outboxes.items())}}


class ConsoleHub:
    """Everything the console knows about one system (see the module docstring).

    Construct it before the system starts, so its observer sees every event; call
    :meth:`start` inside the running loop (it starts the console's owned tasks) and
    :meth:`aclose` at the end.
    """

    def __init__(self, system: Any, options: HubOptions | None = None, *,
                 truth: GroundTruth | None = None,
                 replay: ReplayControl | None = None, wall: Clock | None = None) -> None:
        self.system = system
        self.options = options or HubOptions()
        self.truth = truth
        self.replay = replay
        #: the console's pace (rates, periods): real time whatever the system's clock;
        #: tests give a virtual one
        self.wall: Clock = wall or WallClock()
        self.sessions: set[Session] = set()
        self.events_out: dict[str, int] = {}
        self.observed = 0
        #: requests and messages the console refused, ignored or failed on, by kind
        self.rejected: Counter[str] = Counter()
        self.halts: Counter[str] = Counter()
        self.last_halt: dict[str, float] = {}
        self.votes: dict[str, dict[str, Any]] = {}
        self.actions: list[dict[str, Any]] = []
        self.frames: dict[str, list[float] | None] = {}
        self.geometry: dict[str, Any] | None = None
        self.profiler = LoopProfiler(lambda: self.system.components)
        self._latest: dict[str, tuple[str, Event]] = {}
        self._seq_sensors: set[tuple[str, int]] = set()
        self._encoded = _EncodedCache()
        self._memory: dict[str, int] = {}
        self._shares: LoopShares | None = None
        self._tasks: TaskGroup | None = None
        self._frame_fetches: set[str] = set()
        self._rates = self._rate_window()
        self.observer = system.observe(self._on_event, name="console",
                                       maxsize=self.options.observer_buffer)

    # -- lifecycle -------------------------------------------------------------------------
    async def start(self) -> None:
        """Start timing task steps and the console's own producers."""
        self.profiler.install()
        self._shares = LoopShares(self.profiler, self.wall)
        # The console's tasks (and the web server's connection tasks, which inherit the
        # context of the task that starts the server) carry CONSOLE_TASK, so the loop
        # profiler charges them to the console; the caller's context is left alone.
        context = contextvars.copy_context()
        context.run(CONSOLE_TASK.set, True)
        self._tasks = context.run(TaskGroup, "console", on_failure=self._task_failed)
        self._tasks.spawn(self._produce_status(), owner="console status")
        self._tasks.spawn(self._produce_geometry(), owner="console geometry")
        self._tasks.spawn(self._produce_waypoints(), owner="console waypoints")
        if self.truth is not None:
            self._tasks.spawn(self._produce_truth(), owner="console truth")
        if self.replay is not None:
            self._tasks.spawn(self._produce_replay(), owner="console replay")

    async def aclose(self) -> None:
        for session in list(self.sessions):
            session.close()
        if self._tasks is not None:
            await self._tasks.aclose()
            self._tasks = None
        self.profiler.uninstall()

    def spawn(self, coroutine: Any, owner: str) -> asyncio.Task[Any]:
        """Run ``coroutine`` in the console's task group (its failure is logged; it
        never fails the system)."""
        if self._tasks is None:
            coroutine.close()
            raise ComponentError("the console is not running")
        return self._tasks.spawn(coroutine, owner=owner)

    @staticmethod
    def _task_failed(owner: str, error: BaseException) -> None:
        log.error("console task %s failed: %s: %s (the vehicle is not affected)", owner,
                  type(error).__name__, error)

    # -- sessions ----------------------------------------------------------------------------
    def open_session(self, send: Callable[[bytes], Awaitable[None]],
                     name: str = "browser") -> Session:
        session = Session(self, send, name)
        self.sessions.add(session)
        return session

    def close_session(self, session: Session) -> None:
        session.close()
        self.sessions.discard(session)

    def latest(self, kinds: Iterable[str]) -> list[tuple[str, str, Any]]:
        """The latest entry of every stream of ``kinds`` (for a view just shown)."""
        wanted = set(kinds)
        return [(kind, stream, entry) for stream, (kind, entry) in self._latest.items()
                if kind in wanted]

    def _broadcast(self, kind: str, stream: str, entry: Any) -> None:
        self._latest[stream] = (kind, entry)
        for session in self.sessions:
            if kind in session.kinds:
                session.offer(kind, stream, entry)

    # -- intake ----------------------------------------------------------------------------
    def _on_event(self, event: Event) -> None:
        self.observed += 1
        origin = event.origin
        if origin:
            counts = self.events_out
            counts[origin] = counts.get(origin, 0) + 1
        found = classify(event)
        if found is None:
            return
        kind, stream = found
        body = event.body
        if kind in ("range.laser", "range.stereo"):
            # the static-array form repeats the sequence form's points: keep one
            sensor = (kind, int(body.sensorId))  # type: ignore[attr-defined]
            if isinstance(body, (Range3dLaserIDL, Range3dStereoEventIDL)):
                if sensor in self._seq_sensors:
                    return
            else:
                self._seq_sensors.add(sensor)
        elif kind == "arcs.vote":
            self._on_vote(event, body)  # type: ignore[arg-type]
        self._broadcast(kind, stream, event)

    def _on_vote(self, event: Event, vote: ArcVoteIDL) -> None:
        behaviour = vote.behaviour
        halted = vote.all_vetoed
        self.votes[behaviour] = {"time": event.time, "received": self.system.clock.monotonic(),
                                 "halt": halted, "vetoes": int(np.count_nonzero(vote.veto)),
                                 "arcs": int(vote.curvatures.shape[0]), "origin": event.origin}
        if halted:
            self.halts[behaviour] += 1
            self.last_halt[behaviour] = event.time

    def frame_for(self, kind: str, stream: str, events: list[tuple[float, Event]],
                  now: float) -> bytes | None:
        """The console message for ``events`` (arrival time, event) of one stream (None
        to skip them: range events whose sensor frame is not known yet). The header
        carries the wall time it is sent at and how long each event waited in its outbox
        (for the page's latency figures)."""
        header: dict[str, Any] = {"kind": kind, "stream": stream, "wall": self.wall.now(),
                                  "waited": [round(now - arrival, 6) for arrival, _ in events],
                                  "origin": events[-1][1].origin}
        if kind in ("range.laser", "range.stereo", "ego.terrain", "ego.traverse"):
            frame = str(events[-1][1].body.frame)  # type: ignore[attr-defined]
            transform = self.transform(frame)
            if transform is None:
                return None
            header["transform"] = transform
            header["reference"] = self.options.reference_frame
        return encode_frame(header, [self._encoded.get(event) for _, event in events])

    # -- geometry ----------------------------------------------------------------------------
    def served_name(self, interface: type[Any]) -> str | None:
        """The name the first component serving ``interface`` binds (from the catalog)."""
        wanted = interface_name(interface)
        for port in self.system.catalog().by(Direction.SERVES):
            if port.types == (wanted,):
                return str(port.name)
        return None

    def serving_component(self, interface: type[Any]) -> str | None:
        """The component that serves ``interface`` (from the catalog)."""
        wanted = interface_name(interface)
        for port in self.system.catalog().by(Direction.SERVES):
            if port.types == (wanted,):
                return str(port.component)
        return None

    def transform(self, frame: str) -> list[float] | None:
        """^Ref T_frame (row-major 16 numbers) if known; otherwise fetch it (once) and
        return None for now."""
        key = frame.replace(" ", "")
        if key in self.frames:
            return self.frames[key]
        if key not in self._frame_fetches and self._tasks is not None:
            self._frame_fetches.add(key)
            self.spawn(self._fetch_transform(key), owner="console geometry")
        return None

    async def _fetch_transform(self, frame: str) -> None:
        name = self.served_name(Platform)
        try:
            while name is None or not self._bound(name):
                await self.wall.sleep(1.0)
                name = self.served_name(Platform)
            platform = self.system.proxy(Platform, name)
            result = await platform.getTransformation(self.options.reference_frame, frame)
            self.frames[frame] = [float(v) for v in np.asarray(result.HTransform).ravel()]
        except AfaError as exc:
            log.warning("console: no transform from %s to %s: %s",
                        self.options.reference_frame, frame, exc)
            self.frames[frame] = None
        finally:
            self._frame_fetches.discard(frame)

    def _bound(self, name: str) -> bool:
        return self.system.registry.try_resolve(f"{self.system.robot}/{name}") is not None

    async def _produce_geometry(self) -> None:
        """Read the geometry model once ModelServer serves it (QtBodyViewer's frames)."""
        while True:
            name = self.served_name(Platform)
            if name is not None and self._bound(name):
                try:
                    self.geometry = await self._read_geometry(name)
                except AfaError as exc:
                    log.info("console: geometry not available yet: %s", exc)
                else:
                    self._broadcast("geometry", "geometry/model", dict(self.geometry))
                    return
            await self.wall.sleep(1.0)

    async def _read_geometry(self, name: str) -> dict[str, Any]:
        platform = self.system.proxy(Platform, name)
        reference = self.options.reference_frame
        frames = []
        for body in (await platform.getBodyList()).values:
            for frame in (await platform.getBodyFrameList(body)).values:
                full = f"{body}:{frame}"
                transform = await platform.getTransformation(reference, full)
                matrix = [float(v) for v in np.asarray(transform.HTransform).ravel()]
                self.frames[full] = matrix
                frames.append({"body": body, "frame": frame, "name": full,
                               "transform": matrix})
        return {"reference": reference, "server": name, "frames": frames}

    # -- waypoints ---------------------------------------------------------------------------
    async def _produce_waypoints(self) -> None:
        """Poll the waypoint lists of whoever serves VehiclePlan and GlobalMap."""
        while True:
            if self._wanted("waypoints"):
                lists = {}
                for interface in (VehiclePlan, GlobalMap):
                    name = self.served_name(interface)
                    if name is None or not self._bound(name):
                        continue
                    try:
                        group = await self.system.proxy(interface, name).getWaypointList()
                        current = await self.system.proxy(interface, name).getCurrentWaypoint()
                    except AfaError as exc:
                        log.debug("console: %s.getWaypointList: %s", name, exc)
                        continue
                    lists[name] = _waypoints_json(group, current)
                if lists:
                    self._broadcast("waypoints", "waypoints/planners", {"lists": lists})
            await self.wall.sleep(2.0)

    # -- truth, replay ---------------------------------------------------------------------
    async def _produce_truth(self) -> None:
        assert self.truth is not None
        while True:
            if self._wanted("truth"):
                self._broadcast("truth", "truth/simulation", {"truth": _jsonable(
                    dict(self.truth.truth()))})
            await self.wall.sleep(1.0 / POLICIES["truth"].rate)

    async def _produce_replay(self) -> None:
        assert self.replay is not None
        while True:
            if self._wanted("replay"):
                self._broadcast("replay", "replay/player", {"replay": status_of(self.replay)})
            await self.wall.sleep(1.0 / POLICIES["replay"].rate)

    def _wanted(self, kind: str) -> bool:
        return any(kind in session.kinds for session in self.sessions)

    # -- status ------------------------------------------------------------------------------
    async def _produce_status(self) -> None:
        turn = 0
        while True:
            if self._shares is not None:
                self._shares.update()
            if self._wanted("status"):
                # one component's memory per table: the walk's cost is spread out
                names = list(self.system.components)
                if names:
                    self._measure_memory(names[turn % len(names)])
                    turn += 1
                self._broadcast("status", "status/system", self.status())
            await self.wall.sleep(self.options.status_period)

    def _measure_memory(self, name: str) -> None:
        try:
            self._memory[name] = retained_bytes(self.system.components[name])
        except Exception as exc:  # an exotic attribute must not break the table
            log.debug("console: memory of %s: %s", name, exc)

    def _rate_window(self) -> dict[str, float]:
        return {"clock": self.system.clock.monotonic(), "wall": self.wall.monotonic()}

    def status(self) -> dict[str, Any]:
        """The Launcher table and everything the health views show, JSON-ready."""
        system = self.system
        shares = self._shares.shares if self._shares is not None else {}
        clock_now, wall_now = system.clock.monotonic(), self.wall.monotonic()
        elapsed_wall = wall_now - self._rates["wall"]
        factor = ((clock_now - self._rates["clock"]) / elapsed_wall) if elapsed_wall > 0 else None
        if elapsed_wall >= 5.0:
            self._rates = {"clock": clock_now, "wall": wall_now}
        rows = component_rows(system, self.events_out, shares, self._memory)
        known = {row["name"] for row in rows}
        configured = []
        configuration = getattr(system, "configuration", None)
        launcher = getattr(configuration, "launcher", None)
        notes = " ".join(getattr(system, "notes", ()))
        for entry in getattr(launcher, "Components", ()):
            if entry.Name not in known:
                state = ("not implemented" if f"{entry.Name} ({entry.Type}) is configured but "
                         "not implemented" in notes else
                         "not started" if entry.Enabled else "disabled")
                configured.append({"name": entry.Name, "type": entry.Type, "state": state,
                                   "enabled": bool(entry.Enabled),
                                   "start_delay": float(entry.Period)})
        others = {key: round(value, 6) for key, value in shares.items() if key not in known}
        statistics = system.statistics()
        stale_after = self._stale_vote_time()
        votes = {}
        for behaviour, info in sorted(self.votes.items()):
            age = clock_now - info["received"]
            votes[behaviour] = {**info, "age": age, "stale": age > stale_after,
                                "halts": self.halts.get(behaviour, 0)}
        return {
            "robot": system.robot,
            "clock": "virtual" if isinstance(system.clock, VirtualClock) else "wall",
            "paused": bool(getattr(system.clock, "paused", False)),
            "now": system.clock.now(),
            "wall": self.wall.now(),
            "realtime_factor": None if factor is None else round(factor, 3),
            "running": self._running(),
            "components": rows,
            "not_started": configured,
            "loop": {"busy": round(sum(shares.values()), 6), "others": others},
            "rss": process_memory(),
            "events": statistics["events"],
            "events_dropped": statistics["events_dropped"],
            "votes": votes,
            "stale_vote_time": stale_after,
            "actions": self.actions[-20:],
            "console": {"observer": self.observer.statistics(), "observed": self.observed,
                        "rejected": dict(self.rejected),
                        "sessions": [s.statistics() for s in self.sessions]},
            "vehicle_control": self.served_name(VehicleControl),
            "vehicle_control_component": self.serving_component(VehicleControl),
        }

    def _running(self) -> bool:
        try:
            self.system.tasks  # noqa: B018 - raises while the system is not running
        except ComponentError:
            return False
        return True

    def _stale_vote_time(self) -> float:
        if self.options.stale_vote_time is not None:
            return self.options.stale_vote_time
        for component in self.system.components.values():
            value = getattr(component.parameters, "stale_vote_time", None)
            if isinstance(value, (int, float)):
                return float(value)
        return 1.5

    # -- actions -----------------------------------------------------------------------------
    def _record(self, action: str, target: str, ok: bool, message: str = "") -> None:
        self.actions.append({"time": self.wall.now(), "action": action, "target": target,
                             "ok": ok, "message": message})
        del self.actions[:-100]
        (log.info if ok else log.warning)("console: %s %s: %s", action, target,
                                          message or ("done" if ok else "failed"))

    async def component_action(self, name: str, action: str) -> str:
        """Start, stop or restart a component (the Launcher's buttons). Raises KeyError
        for an unknown component, ValueError for an unknown action."""
        if action not in COMPONENT_ACTIONS:
            raise ValueError(f"unknown action {action!r}; known: {', '.join(COMPONENT_ACTIONS)}")
        if name not in self.system.components:
            raise KeyError(name)
        run = {"start": self.system.start_component, "stop": self.system.stop_component,
               "restart": self.system.restart_component}[action]
        await run(name)
        state = self.system.components[name].state.value
        self._record(action, name, True, f"now {state}")
        return str(state)

    async def vehicle_action(self, action: str) -> str:
        """Stop the vehicle (VehicleControl.stopVehicle), start it, or switch the
        arbiter, through the poll seam. Raises ValueError for an unknown action and
        :class:`~afa.errors.AfaError` when the call fails or nobody serves
        VehicleControl."""
        if action not in VEHICLE_ACTIONS:
            raise ValueError(f"unknown action {action!r}; known: {', '.join(VEHICLE_ACTIONS)}")
        name = self.served_name(VehicleControl)
        if name is None:
            raise ComponentError("no component serves VehicleControl here")
        control = self.system.proxy(VehicleControl, name)
        try:
            if action == "stop":
                await control.stopVehicle()
            elif action == "start":
                await control.startVehicle()
            else:
                await control.setArbiter(action == "arbiter-on")
        except AfaError as exc:
            self._record(f"vehicle {action}", name, False, str(exc))
            raise
        self._record(f"vehicle {action}", name, True)
        return name

    async def replay_action(self, action: str, value: Any = None) -> dict[str, Any]:
        """Play, pause, step, seek or change the speed of the replay. Raises
        ComponentError when the console has no replay source, ValueError for a bad
        action or value."""
        if self.replay is None:
            raise ComponentError("this console shows a live system, not a recording")
        await perform(self.replay, action, value)
        self._record(f"replay {action}", "player", True, "" if value is None else str(value))
        status = status_of(self.replay)
        self._broadcast("replay", "replay/player", {"replay": status})
        return status


def _waypoints_json(group: WaypointGroupIDL, current: Any) -> dict[str, Any]:
    points = []
    for waypoint in group.waypoints:
        points.append({"latitude": waypoint.latitude, "longitude": waypoint.longitude,
                       "easting": waypoint.easting, "northing": waypoint.northing,
                       "tolerance": waypoint.tolerance})
    current_json = None if current is None else {
        "latitude": current.latitude, "longitude": current.longitude,
        "easting": current.easting, "northing": current.northing}
    return {"waypoints": points, "patrol": group.patrolMode, "current": current_json}


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (np.floating, float)):
        number = float(value)
        return number if math.isfinite(number) else None
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (str, int, bool)) or value is None:
        return value
    return str(value)


__all__ += ["JSON_KINDS"]
