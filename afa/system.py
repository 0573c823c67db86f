"""The System: one event channel, one name registry, one clock, supervised components.

``async with system:`` starts every component inside the *caller's* running event loop
(a notebook's, a test's, or the CLI's) and stops them all on exit; afa never calls
``asyncio.run`` outside the CLI and never takes a ``loop=`` argument.

- **Supervision**: each component runs in its own supervisor task. An exception fails
  only that component: it is logged with its name, marked failed, and restarted with
  backoff per its :class:`~afa.component.RestartPolicy`; the others keep running.
  Start-up starts components in order, waiting each one's start delay (the seed
  Launcher's dT), and raises one :class:`~afa.errors.StartupError` naming every
  component whose first start failed.
- **Owned tasks**: the system owns a :class:`~afa.tasks.TaskGroup`; every task of the
  framework, the fake devices, the simulation and bridges runs in it. A task that
  fails outside a component (a fake device, the simulation's physics) fails the system:
  :meth:`run` raises :class:`~afa.errors.TaskFailed`, and so does leaving the
  ``async with`` block if nobody has seen it yet.
- **The catalog** (:meth:`catalog`): every port of every component, from construction.
- **Services** (:meth:`add_service`): something with ``start(system)`` and ``stop()``
  that lives as long as the running system, around its components: a bridge to other
  processes. Started before the components, stopped after them.
- **Loop-time accounting** (``meter=True``, :mod:`afa.meter`): each component's share of
  the loop's time, for ``afa top``.
- **Devices**: ``devices`` maps component names to factories that open a fake device
  or an emulator in place of the real one (a name that is no component is an error);
  ``real_devices=False`` (or the environment variable ``AFA_FORBID_REAL_DEVICES=1``,
  which afa's test suite sets) makes opening a real serial port or socket an error.
"""

from __future__ import annotations

import asyncio
import logging
import os
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, Protocol, TypeVar

from afa.clock import Clock, VirtualClock, WallClock
from afa.component import Component, Context, Health, PublishServerReactor, RestartPolicy, State
from afa.errors import AfaError, ComponentError, StartupError, TaskFailed
from afa.events import Event, EventChannel, Overflow, Subscription
from afa.meter import LoopMeter
from afa.naming import NameRegistry, join_name
from afa.polling import LocalInvoker, PollLayer, current_caller, proxy_for
from afa.ports import Catalog, PortInfo
from afa.tasks import Scope, TaskGroup, cancel_requested
from afa.transport import DeviceFactory, DeviceOpener, SerialSpec
from idl._base import Interface

__all__ = ["System", "Observer", "Service", "FORBID_REAL_DEVICES"]

InterfaceT = TypeVar("InterfaceT", bound=Interface)
log = logging.getLogger("afa.system")

#: Environment variable: when "1", no System opens a real device (tests set it).
FORBID_REAL_DEVICES = "AFA_FORBID_REAL_DEVICES"

#: ``provider(component)``: a device factory to use in place of ``component``'s real
#: device, or None (a simulation provides emulators this way).
DeviceProvider = Callable[[Component[Any]], DeviceFactory | None]


class Service(Protocol):
    """Something that runs as long as a system runs (:meth:`System.add_service`)."""

    name: str

    async def start(self, system: System) -> None:
        """Called when the system starts, before its components (the task group exists).
        An exception fails the start (StartupError naming the service)."""
        ...

    async def stop(self) -> None:
        """Called when the system stops, after its components; must not raise."""
        ...


class Observer:
    """A callback that sees every event, in its own task with its own buffer: it never
    slows or fails a publisher. ``statistics()``: delivered, dropped, errors."""

    def __init__(self, name: str, subscription: Subscription,
                 callback: Callable[[Event], Any]) -> None:
        self.name = name
        self.subscription = subscription
        self.callback = callback
        self.errors = 0

    async def run(self) -> None:
        async for event in self.subscription:
            try:
                result = self.callback(event)
                if result is not None:
                    await result
            except asyncio.CancelledError:
                if cancel_requested():
                    raise  # the system is stopping
                self.failed(event, "raised CancelledError without being cancelled")
            except Exception as exc:
                self.failed(event, exc)

    def failed(self, event: Event, error: BaseException | str) -> None:
        """One event the callback failed on: counted; the first three logged (also for a
        callback that records events queued behind its own, as the recorder does)."""
        self.errors += 1
        if self.errors <= 3:
            log.error("observer %s failed on %s (event dropped): %s", self.name, event.type,
                      error, exc_info=error if isinstance(error, BaseException) else None)

    async def drain(self) -> None:
        """Process everything already queued (before a summary or a digest is read)."""
        while (event := self.subscription.get_nowait()) is not None:
            try:
                result = self.callback(event)
                if result is not None:
                    await result
            except Exception:
                self.errors += 1

    def statistics(self) -> dict[str, int]:
        stats = self.subscription.statistics()
        return {"delivered": stats.delivered, "dropped": stats.dropped, "errors": self.errors}

    def close(self) -> None:
        self.subscription.close()


class System:
    """A set of components sharing one channel, registry and clock.

    ``components`` are started in the given order; ``start_delays`` maps a component
    name to the seconds to wait after starting it (dT). ``devices`` replaces components'
    real devices: a mapping of component name to device factory, or a provider function
    asked for each component. ``base_dir`` is where components resolve relative file
    names (the configuration's folder).

    Raises :class:`~afa.errors.ComponentError` for a device override that names no
    component, or for two components with one name.
    """

    def __init__(
        self,
        components: Iterable[Component[Any]] = (),
        *,
        robot: str = "Raptor",
        clock: Clock | None = None,
        devices: Mapping[str, DeviceFactory] | DeviceProvider | None = None,
        restart_policy: RestartPolicy = RestartPolicy(),
        start_delays: Mapping[str, float] | None = None,
        base_dir: str | Path | None = None,
        real_devices: bool | None = None,
        process: str = "main",
        meter: bool = False,
        start_after: float = 0.0,
    ) -> None:
        self.robot = robot
        self.process = process  # this process's group name (origin prefix across a bridge)
        self.meter: LoopMeter | None = LoopMeter() if meter else None
        self.clock: Clock = clock or WallClock()
        self.channel = EventChannel(self.clock)
        self.registry = NameRegistry(self.clock)
        self.polls = PollLayer(self.clock, lambda: self.channel.published)
        if real_devices is None:
            real_devices = os.environ.get(FORBID_REAL_DEVICES, "") not in ("1", "true", "yes")
        self.real_devices = real_devices
        self._provider: DeviceProvider | None = devices if callable(devices) else None
        overrides = {} if devices is None or callable(devices) else dict(devices)
        self.devices = DeviceOpener(overrides, allow_real=real_devices, clock=self.clock)
        self.restart_policy = restart_policy
        self.start_delays = dict(start_delays or {})
        #: clock seconds to wait before starting the first component (a process group of
        #: a split configuration starts its part of the Launcher when one process would)
        self.start_after = start_after
        self.base_dir = Path(base_dir) if base_dir is not None else Path.cwd()
        self.configuration: Any = None  # the validated Configuration, when built from XML
        self.components: dict[str, Component[Any]] = {}
        self.notes: list[str] = []  # start-up remarks
        self.failures: list[tuple[str, BaseException]] = []
        self._reported = 0
        self._supervisors: dict[str, asyncio.Task[None]] = {}
        self._tasks: TaskGroup | None = None
        self._observers: list[Observer] = []
        self._services: list[Service] = []
        #: the ports of the components other processes run (a split configuration), so
        #: that the catalog describes the whole distributed system
        self.peer_ports: list[PortInfo] = []
        self._started_services: list[Service] = []
        self._running = False
        self._stopped = asyncio.Event()
        self._failed = asyncio.Event()
        self._stop_requested = asyncio.Event()
        for component in components:
            self.add(component)
        unknown = sorted(set(overrides) - set(self.components))
        if unknown:
            raise ComponentError(
                f"devices names {', '.join(map(repr, unknown))}, which "
                f"{'is' if len(unknown) == 1 else 'are'} not a component here; the components "
                f"are {', '.join(self.components) or 'none'}")

    @classmethod
    def from_xml(cls, path: str | Path, **options: Any) -> System:
        """Build the system a Miro XML configuration file describes.

        Options are passed to the constructor (``clock``, ``devices``, ...) except
        ``only`` (component names to keep, e.g. to test one component with its
        configured parameters). Raises :class:`~afa.errors.ConfigError` for an invalid
        file (``file:line:`` messages), including a component type that is not installed.
        """
        from afa.assembly import build_system  # config + registry; kept out of import time

        return build_system(cls, Path(path), **options)

    def add(self, component: Component[Any]) -> Component[Any]:
        """Add a component (before start, or while running: it starts at once)."""
        if component.name in self.components:
            raise ComponentError(f"two components are named {component.name!r}")
        self.components[component.name] = component
        if self._provider is not None:
            factory = self._provider(component)
            if factory is not None:
                self.devices.overrides[component.name] = factory
        component._attach(Context(self.robot, self.channel, self.registry, self.clock,
                                  self.devices, self.base_dir, self.polls, self._section,
                                  self.meter))
        if self._running:
            self._launch(component)
        return component

    def _section(self, name: str) -> Any:
        """The default parameter set of configuration section ``name``, if any."""
        sections = getattr(self.configuration, "sections", None) or {}
        sets = sections.get(name)
        return None if not sets else next(iter(sets.values()))

    def add_service(self, service: Service) -> Service:
        """Run ``service`` while the system runs (before start). Raises ComponentError
        while running."""
        if self._running:
            raise ComponentError(f"add the service {service.name} before the system starts")
        self._services.append(service)
        return service

    @property
    def services(self) -> list[Service]:
        return list(self._services)

    def enable_meter(self, meter: LoopMeter | None = None) -> LoopMeter:
        """Turn loop-time accounting on (before start), with ``meter`` if given (one
        with its own timer, say); returns the meter."""
        if self.meter is None:
            if self._running:
                raise ComponentError("turn the meter on before the system starts")
            self.meter = meter if meter is not None else LoopMeter()
            for component in self.components.values():
                if component._context is not None:
                    component._context.meter = self.meter
        return self.meter

    def catalog(self) -> Catalog:
        """Every declared port of every component (available before start), with those
        of the other processes of a split configuration (``PortInfo.process`` set)."""
        return Catalog([port for c in self.components.values() for port in c.ports()]
                       + self.peer_ports, self.robot)

    def serial_ports(self) -> dict[str, list[tuple[str, int]]]:
        """``{device: [(component, baud rate), ...]}`` for every serial port a device
        driver names (available before start; components that share one port share one
        connection, opened at the rate of the first)."""
        ports: dict[str, list[tuple[str, int]]] = {}
        for component in self.components.values():
            if isinstance(component, PublishServerReactor):
                try:
                    spec = component.device()
                except Exception:  # a driver without a fixed device (a camera's own)
                    continue
                if isinstance(spec, SerialSpec):
                    ports.setdefault(spec.device, []).append((component.name, spec.baudrate))
        return ports

    def file_problems(self) -> dict[str, str]:
        """``{component: what is wrong}`` for the files components would read at setup
        (a geometry model, ...), read now without starting (``afa config check``)."""
        problems: dict[str, str] = {}
        for component in self.components.values():
            try:
                component.check_files(self.base_dir)
            except (AfaError, OSError, ValueError) as exc:
                problems[component.name] = str(exc)
        return problems

    def port_conflicts(self) -> dict[str, list[tuple[str, int]]]:
        """The serial ports that components name at different baud rates: at most one of
        them can talk to its device (``afa config check`` warns)."""
        return {device: users for device, users in self.serial_ports().items()
                if len({baud for _, baud in users}) > 1}

    # -- running -------------------------------------------------------------------------
    async def __aenter__(self) -> System:
        await self.start()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.stop(raise_failures=exc_info[0] is None)

    @property
    def tasks(self) -> TaskGroup:
        """The system's task group (while running)."""
        if self._tasks is None:
            raise ComponentError("the system is not running")
        return self._tasks

    async def start(self) -> None:
        """Start every component in order; raises StartupError if any first start fails
        (after stopping the ones that started). Time passes during start-up even on a
        paused virtual clock (:meth:`Clock.running <afa.clock.Clock.running>`): start
        delays and device handshakes take clock time."""
        if self._running:
            return
        with self.clock.running():
            await self._start()

    async def _start(self) -> None:
        self._check_devices()
        self._running = True
        self._stopped = asyncio.Event()
        self._failed = asyncio.Event()
        self._stop_requested = asyncio.Event()
        self._tasks = TaskGroup(f"system {self.robot}", on_failure=self._task_failed,
                                meter=self.meter)
        for observer in self._observers:
            self._tasks.spawn(observer.run(), owner=f"observer {observer.name}")
        self.registry.rebind(join_name(self.robot, "EventChannel"), self.channel, owner=self)
        failures: dict[str, BaseException] = {}
        for service in self._services:
            try:
                await service.start(self)
            except Exception as exc:
                failures[service.name] = exc
                break
            self._started_services.append(service)
        if failures:
            await self.stop(raise_failures=False)
            raise StartupError(failures)
        if self.start_after > 0:
            await self.clock.sleep(self.start_after)
        for component in list(self.components.values()):
            self._launch(component)
            while component.state in (State.CREATED, State.STARTING):
                await component._wait_state_change()
            if component.state is State.FAILED and component.last_error is not None:
                failures[component.name] = component.last_error
            delay = self.start_delays.get(component.name, 0.0)
            if delay > 0:
                await self.clock.sleep(delay)
        for note in self.notes:
            log.warning("%s", note)
        if failures:
            await self.stop(raise_failures=False)
            raise StartupError(failures)

    async def stop(self, *, raise_failures: bool = True) -> None:
        """Stop every component (reverse start order), the observers and every owned
        task. Raises TaskFailed if an owned task failed and nobody has been told."""
        if not self._running:
            return
        with self.clock.running():  # a component's clean-up may wait on the clock
            await self._stop()
        if raise_failures:
            self._raise_failures()

    async def _stop(self) -> None:
        for name in reversed(list(self._supervisors)):
            await self.stop_component(name)
        while self._started_services:
            service = self._started_services.pop()
            try:
                await service.stop()
            except Exception:
                log.exception("service %s failed to stop", service.name)
        for observer in self._observers:
            observer.close()
        self._observers.clear()
        if self._tasks is not None:
            await self._tasks.aclose()
            self._tasks = None
        self.registry.unbind_owner(self)
        self._running = False
        self._stopped.set()

    async def run(self, duration: float | None = None, *,
                  until: asyncio.Event | None = None) -> None:
        """Run until ``duration`` clock seconds have passed (None: until stopped), or
        ``until`` is set (a simulated mission finished, say). Raises TaskFailed as soon as
        a task of the system (not of a component) fails.

        When the duration or ``until`` ends it, the rest of that instant runs (a virtual
        clock fires the other timers due then, one at a time), then services with a
        ``finish_instant()``
        coroutine are awaited (a lock-step bridge lets every process finish the last
        instant), so that what happens at the end time is the same whether the system is
        one process or several.

        With a ``duration`` or ``until``, time runs for the call even on a paused virtual
        clock, which is paused again when it returns (``await system.run(10)`` in a
        notebook cell: ten simulated seconds, then time stands still until the next
        run). Without either, the clock is left to whoever owns it (a paused replay stays
        paused until its player resumes it)."""
        if duration is None and until is None:
            await self._run(duration, until)
            return
        with self.clock.running():
            await self._run(duration, until)

    async def _run(self, duration: float | None, until: asyncio.Event | None) -> None:
        self._raise_failures()
        waiter = self._stopped.wait() if duration is None else self.clock.sleep(duration)
        waiters = [waiter, self._failed.wait(), self._stop_requested.wait()]
        if until is not None:
            waiters.append(until.wait())
        await _first_of(*waiters)
        self._raise_failures()
        if (duration is not None or until is not None) and not self._stop_requested.is_set():
            if isinstance(self.clock, VirtualClock):
                # the rest of the last instant: its other timers fire one at a time
                # (decision 0027), as they would have had the run gone on
                await _first_of(self.clock.settle(), self._failed.wait())
                self._raise_failures()
            for service in self._started_services:
                finish = getattr(service, "finish_instant", None)
                if finish is not None:
                    await _first_of(finish(), self._failed.wait())
            self._raise_failures()

    def request_stop(self) -> None:
        """Make :meth:`run` return now (a time master ended a split run; an operator's
        stop). The caller then stops the system as usual."""
        self._stop_requested.set()

    def _raise_failures(self) -> None:
        if len(self.failures) > self._reported:
            owner, error = self.failures[self._reported]
            self._reported = len(self.failures)
            raise TaskFailed(owner, error) from error

    def _task_failed(self, owner: str, error: BaseException) -> None:
        self.failures.append((owner, error))
        self._failed.set()

    def observe(self, callback: Callable[[Event], Any], *, name: str, maxsize: int = 4096,
                policy: Overflow = Overflow.DROP_OLDEST) -> Observer:
        """Run ``callback(event)`` (sync or async) for every event, in a task of its own
        with a bounded buffer (see :class:`Observer`). Made before start, it sees every
        event from the first; it ends when the system stops."""
        observer = Observer(name, self.channel.observe(maxsize=maxsize, policy=policy),
                            callback)
        self._observers.append(observer)
        if self._tasks is not None:
            self._tasks.spawn(observer.run(), owner=f"observer {name}")
        return observer

    # -- operator actions (the Launcher's start/stop/restart) -------------------------
    async def stop_component(self, name: str) -> None:
        task = self._supervisors.pop(name, None)
        component = self.components[name]
        if task is None:
            return
        task.cancel()
        try:
            await task
        except asyncio.CancelledError:
            pass
        if component.state is not State.FAILED:
            component._set_state(State.STOPPED)

    async def start_component(self, name: str) -> None:
        component = self.components[name]
        if name in self._supervisors:
            return
        self._launch(component)
        while component.state in (State.CREATED, State.STOPPED, State.STARTING):
            await component._wait_state_change()

    async def restart_component(self, name: str) -> None:
        await self.stop_component(name)
        await self.start_component(name)

    # -- polling from outside (notebooks, tools, tests) --------------------------------
    def proxy(self, interface: type[InterfaceT], name: str, *,
              call_timeout: float | None = None) -> InterfaceT:
        """A client proxy for ``<Robot>/<name>``: it reaches whatever serves the name at
        each call (NameNotFound while nothing does)."""
        full = join_name(self.robot, name)
        return proxy_for(interface, LocalInvoker(self.registry, full, interface),
                         middleware=self.polls.middleware, timeout=call_timeout)

    async def resolve(self, interface: type[InterfaceT], name: str, *,
                      timeout: float | None = None,
                      call_timeout: float | None = None) -> InterfaceT:
        """:meth:`proxy`, once the name is bound (waits up to ``timeout``; ETimeOut)."""
        await self.registry.wait_resolve(join_name(self.robot, name), timeout)
        return self.proxy(interface, name, call_timeout=call_timeout)

    # -- observation -------------------------------------------------------------------
    def health(self) -> dict[str, Health]:
        return {name: c.health() for name, c in self.components.items()}

    def statistics(self) -> dict[str, Any]:
        dropped = sum(s.statistics().dropped for s in self.channel.subscriptions())
        return {
            "events": dict(sorted(self.channel.counts().items())),
            "events_published": self.channel.published,
            "events_dropped": dropped,
            "components": {name: c.statistics() for name, c in self.components.items()},
            "polls": {f"{name}.{method}": stats.as_dict()
                      for (name, method), stats in sorted(self.polls.statistics.items())},
            "observers": {o.name: o.statistics() for o in self._observers},
        }

    # -- internals -----------------------------------------------------------------------
    def _check_devices(self) -> None:
        if self.real_devices:
            return
        missing = [c.name for c in self.components.values()
                   if isinstance(c, PublishServerReactor) and c.name not in self.devices.overrides]
        if missing:
            raise StartupError({name: ComponentError(
                f"{name} would open its real device, and real devices are forbidden here "
                f"(real_devices=False or {FORBID_REAL_DEVICES}=1): give it a fake in "
                "devices={...}") for name in missing})

    def _launch(self, component: Component[Any]) -> None:
        component._set_state(State.CREATED)
        context = self.tasks.context()  # the component's own: its polls name their caller
        context.run(current_caller.set, component.name)
        self._supervisors[component.name] = self.tasks.spawn(
            self._supervise(component), owner=component.name,
            name=f"afa-supervisor:{component.name}", context=context)

    async def _supervise(self, component: Component[Any]) -> None:
        policy = component.restart_policy or self.restart_policy
        attempt = 0
        while True:
            started = self.clock.monotonic()
            try:
                await component._run_once()
                component._set_state(State.STOPPED)
                return
            except asyncio.CancelledError:
                raise
            except Exception as exc:
                component._record_failure(exc)
            if not policy.restart:
                return
            if self.clock.monotonic() - started >= policy.reset_after:
                attempt = 0
            if policy.max_restarts is not None and attempt >= policy.max_restarts:
                log.error("%s failed %d times in a row; giving up", component.name, attempt + 1)
                return
            delay = policy.delay(attempt)
            attempt += 1
            log.warning("restarting %s in %.2f s", component.name, delay)
            await self.clock.sleep(delay)
            component.restarts += 1


async def _first_of(*awaitables: Any) -> None:
    """Wait until the first of ``awaitables`` finishes; cancel the rest."""
    done = asyncio.Event()

    async def watch(awaitable: Any) -> None:
        await awaitable
        done.set()

    async with Scope() as scope:
        tasks = [scope.spawn(watch(a), "afa-wait") for a in awaitables]
        await done.wait()
        for task in tasks:
            task.cancel()

