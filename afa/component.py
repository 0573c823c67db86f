"""Components: Miro's three design patterns as small async base classes.

A component declares its **ports** in its constructor, from its parameters, so the data
flow of a configuration is known before anything runs (:mod:`afa.ports`)::

    class Counter(SubscribePublishServer[CounterParameters]):
        def __init__(self, name, parameters=None):
            super().__init__(name, parameters)
            self.counts = self.publishes("Count", Count)             # Output[Count]
            self.subscribes("Tick", Tick, self.on_tick)               # handler per event
            self.serves(CounterInterface, "Counter")                  # bound while running
            self.platform = self.uses(Platform, "ModelService")       # a proxy by name

and fills a few hooks; the base owns lifecycle, logging, error routing, names and the
ports:

- :meth:`Component.setup` (each (re)start, before any event or poll arrives): make
  slots, open files, reset state. Keep it quick; do not wait for other components.
- :meth:`Component.run` (after setup, with subscriptions flowing and names bound): the
  main body. It may return at once: the component stays up until it is stopped.
- :meth:`Component.teardown` (every stop or failure): release what setup acquired.

Any exception in setup, run, a subscription handler (a body of the wrong type
included) or a spawned task fails the component as a unit: it is logged with the
component's name, its names are unbound, its subscriptions closed, and the supervisor
(:mod:`afa.system`) restarts it with backoff per its :class:`RestartPolicy`. A handler
that ends any other way than returning (even with a ``CancelledError`` of its own) fails
it too, and so does a ``CancelledError`` that setup, run or a spawned task raises without
having been cancelled (cancelling a task the component spawned is no failure). The other
components keep running.

Components are generic in their parameter model: ``class Gps(PublishServerReactor[
GpsParameters, GpsMessage])`` makes ``self.parameters`` a ``GpsParameters``.

The three patterns (seed §2.2.1):

- :class:`SubscribePublishServer` (SPS): receives events, processes, publishes, serves.
- :class:`PublishServerReactor` (PSR): a device driver; the reactor (a byte stream and
  a codec, :mod:`afa.reactor`) stays apart from the server part that publishes events
  and answers polls. The base starts the reactor after setup.
- :class:`Client`: resolves a name and polls a server through its typed interface.
"""

from __future__ import annotations

import asyncio
import logging
import typing
from collections.abc import Callable, Coroutine
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any, ClassVar, Generic, TypeVar

from afa.clock import Clock
from afa.codec import StreamDecoder
from afa.config.parameters import Parameters
from afa.errors import ComponentError, ConfigError, EDevIO
from afa.events import EventChannel, Overflow
from afa.meter import LoopMeter
from afa.naming import NameRegistry, join_name
from afa.polling import (
    LatestSlot,
    LocalInvoker,
    PollLayer,
    Proxy,
    Servant,
    check_servant,
    proxy_for,
    proxy_name,
)
from afa.ports import Handler, Input, Output, PortInfo, Served, Used
from afa.reactor import Backoff, Reactor
from afa.tasks import Scope, cancel_requested, first_error
from afa.transport import ByteStream, DeviceOpener, DeviceSpec
from idl._base import IDLModel, Interface

__all__ = [
    "State", "Context", "Component", "SubscribePublishServer", "PublishServerReactor",
    "Client", "RestartPolicy", "Health",
]

InterfaceT = TypeVar("InterfaceT", bound=Interface)
M = TypeVar("M")
P = TypeVar("P", bound=Parameters)
T = TypeVar("T", bound=IDLModel)


class State(StrEnum):
    CREATED = "created"
    STARTING = "starting"
    RUNNING = "running"
    STOPPING = "stopping"
    STOPPED = "stopped"
    FAILED = "failed"


@dataclass(frozen=True)
class RestartPolicy:
    """How the supervisor restarts a failed component.

    Delays grow ``initial * factor**n`` up to ``maximum`` (clock seconds). After
    ``max_restarts`` consecutive failures (None: never give up) the component stays
    failed. A run longer than ``reset_after`` seconds resets the count.
    """

    restart: bool = True
    initial: float = 0.5
    factor: float = 2.0
    maximum: float = 30.0
    max_restarts: int | None = None
    reset_after: float = 60.0

    def delay(self, attempt: int) -> float:
        return min(self.maximum, self.initial * self.factor**attempt)


def _no_sections(name: str) -> Parameters | None:
    return None


@dataclass
class Context:
    """What the runtime gives every component. ``section(name)`` returns the default
    parameter set of a configuration section shared by several components (the candidate
    arc set), or None when the system has no such section."""

    robot: str
    channel: EventChannel
    registry: NameRegistry
    clock: Clock
    devices: DeviceOpener = field(default_factory=DeviceOpener)
    base_dir: Path = field(default_factory=Path.cwd)
    polls: PollLayer | None = None
    section: Callable[[str], Parameters | None] = _no_sections
    meter: LoopMeter | None = None  # loop-time accounting (afa top), when the system meters


@dataclass(frozen=True)
class Health:
    name: str
    state: State
    healthy: bool
    detail: str
    restarts: int
    failures: int
    last_error: str | None
    ever_healthy: bool = False  #: healthy at some moment of this run
    #: required inputs not received yet, while the component itself is fine (a map
    #: still filling upstream is not a fault of the component waiting for it)
    waiting: tuple[str, ...] = ()


class _Forever:
    """Awaited after ``run`` returns: a component lives until it is stopped."""

    def __await__(self) -> typing.Generator[Any, None, None]:
        return asyncio.get_running_loop().create_future().__await__()


class Component(Generic[P]):
    """Base of every component (see the module docstring for ports and hooks)."""

    #: The component's parameter model (derived from ``Component[Model]``).
    parameters_type: ClassVar[type[Parameters] | None] = None
    #: Per-class restart policy; None uses the system's.
    restart_policy: ClassVar[RestartPolicy | None] = None

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "parameters_type" in cls.__dict__:
            return
        for base in getattr(cls, "__orig_bases__", ()):
            origin = typing.get_origin(base)
            if isinstance(origin, type) and issubclass(origin, Component):
                args = typing.get_args(base)
                if args and isinstance(args[0], type) and issubclass(args[0], Parameters):
                    cls.parameters_type = args[0]
                    return

    def __init__(self, name: str, parameters: P | None = None) -> None:
        expected = self.parameters_type
        if parameters is None and expected is not None:
            parameters = expected()  # type: ignore[assignment]
        if expected is not None and not isinstance(parameters, expected):
            raise ComponentError(
                f"{name}: expected {expected.__name__}, got {type(parameters).__name__}")
        self.name = name
        self.parameters: P = parameters  # type: ignore[assignment]
        self.type_name = type(self).__name__
        self.state = State.CREATED
        self.log = _component_logger(name)
        self.restarts = 0
        self.failures = 0
        self.last_error: BaseException | None = None
        self._context: Context | None = None
        self._scope: Scope | None = None
        self._outputs: list[Output[Any]] = []
        self._inputs: list[Input] = []
        self._served: list[Served] = []
        self._used: list[Used] = []
        self._healthy = True
        self._health_detail = ""
        self._ever_healthy = False
        self._state_changed = asyncio.Event()

    # -- ports (declare in __init__) ---------------------------------------------------
    def publishes(self, event_name: str, body_type: type[T], *,
                  enabled: bool = True) -> Output[T]:
        """Declare a publication of ``<Robot>/<event_name>`` with ``body_type`` bodies.
        ``enabled=False`` keeps it in the catalog but publishes nothing (``Notify``)."""
        port = Output(self.name, event_name, body_type, enabled)
        self._outputs.append(port)
        return port

    def subscribes(self, event_name: str, body_types: type[IDLModel] | tuple[type[IDLModel], ...],
                   handler: Handler, *, domain: str | None = None, maxsize: int = 16,
                   policy: Overflow = Overflow.DROP_OLDEST, required: bool = False) -> Input:
        """Declare a subscription: ``handler(event)`` (sync or async) runs in a task of
        this component for every event whose body is one of ``body_types``. ``*``,
        ``?`` and ``[...]`` are wildcards in ``event_name``. A ``required`` input keeps
        the component unhealthy ("waiting for ...") until its first event arrives."""
        types = body_types if isinstance(body_types, tuple) else (body_types,)
        port = Input(self.name, event_name, types, handler, domain, maxsize, policy, required)
        self._inputs.append(port)
        return port

    def serves(self, interface: type[Interface], name: str | None = None,
               impl: object | None = None) -> str:
        """Declare that ``<Robot>/<name>`` (default: the component's name) serves
        ``interface`` with this component (or ``impl``) while the component runs.
        Signatures are checked now. Returns the short name."""
        target = self if impl is None else impl
        check_servant(interface, target)
        served = Served(self.name, interface, name or self.name, target)
        self._served.append(served)
        return served.name

    def uses(self, interface: type[InterfaceT], name: str) -> InterfaceT:
        """Declare that this component polls ``interface`` at ``<Robot>/<name>``; returns
        the proxy. It reaches whatever serves the name at each call (NameNotFound while
        nothing does); :meth:`bound` waits for it."""
        proxy = _unattached_proxy(interface, name)
        self._used.append(Used(self.name, interface, name, proxy))  # type: ignore[arg-type]
        return proxy

    def ports(self) -> list[PortInfo]:
        """This component's catalog entries."""
        return ([p.info() for p in self._outputs] + [p.info() for p in self._inputs]
                + [p.info() for p in self._served] + [p.info() for p in self._used])

    async def bound(self, proxy: object, timeout: float | None = None) -> None:
        """Wait until the name a used proxy calls is bound (ETimeOut after ``timeout``)."""
        await self.context.registry.wait_resolve(join_name(self.robot, proxy_name(proxy)),
                                                 timeout)

    # -- hooks -------------------------------------------------------------------------
    async def setup(self) -> None:
        """Prepare state for a (re)start; no event or poll arrives before it returns."""

    async def run(self) -> None:
        """The main body; may return at once (the component stays up until stopped)."""

    async def teardown(self) -> None:
        """Release resources acquired in setup. Called at every stop or failure."""

    def check_files(self, base_dir: Path) -> None:
        """Read the files ``setup`` would read (relative names resolved against
        ``base_dir``, the configuration's folder) and raise what is wrong with them,
        without starting anything: ``afa config check`` calls it. The default reads none."""

    def statistics(self) -> dict[str, Any]:
        """Counters for health displays and run summaries; extend in subclasses."""
        return {port.name: port.statistics() for port in self._inputs}

    def traffic(self) -> dict[str, int]:
        """Events this component received (delivered to its handlers) and published, over
        every life (the Launcher table's events in and out)."""
        return {"in": sum(port.received for port in self._inputs),
                "out": sum(port.published for port in self._outputs)}

    # -- context -----------------------------------------------------------------------
    @property
    def context(self) -> Context:
        if self._context is None:
            raise ComponentError(f"{self.name} is not attached to a System")
        return self._context

    @property
    def clock(self) -> Clock:
        return self.context.clock

    @property
    def robot(self) -> str:
        return self.context.robot

    def slot(self, what: str) -> LatestSlot[Any]:
        """A latest-value slot on this component's clock (for get/getWait polls)."""
        return LatestSlot(self.clock, f"{what} from {self.name}")

    def spawn(self, coroutine: Coroutine[Any, Any, Any],
              name: str | None = None) -> asyncio.Task[Any]:
        """Run ``coroutine`` as part of this component (failing with it). Cancelling the
        task is no failure; a CancelledError it raises without being cancelled is."""
        if self._scope is None:
            coroutine.close()
            raise ComponentError(f"{self.name}: spawn() is only possible while starting or running")
        name = name or self.name
        return self._scope.spawn(self._own_task(coroutine, name), name)

    async def _own_task(self, coroutine: Coroutine[Any, Any, Any], name: str) -> Any:
        """A spawned task's body: a CancelledError that no ``cancel()`` asked for (one
        raised, or leaked from a helper's cancelled future) fails the component instead
        of ending the task silently while the component looks RUNNING and healthy."""
        try:
            return await coroutine
        except asyncio.CancelledError:
            if cancel_requested() or self._stopping():
                raise
            raise ComponentError(f"{self.name}: task {name!r} raised CancelledError "
                                 "without being cancelled") from None

    def set_health(self, healthy: bool, detail: str = "") -> None:
        """Report the component (un)healthy, e.g. while its device is lost."""
        if healthy != self._healthy or detail != self._health_detail:
            self._healthy, self._health_detail = healthy, detail
            # coming up (opening, waiting for the first message) is routine; a loss after
            # the component was healthy is what an operator must see
            log = self.log.warning if not healthy and self._ever_healthy else self.log.info
            log("%s", f"{self.name}: healthy {detail}".strip() if healthy
                else f"{self.name}: unhealthy: {detail}")
        self._note_health()

    def _waiting_for(self) -> list[str]:
        return [port.name for port in self._inputs if port.required and not port.received]

    def _note_health(self) -> None:
        if (not self._ever_healthy and self._healthy and self.state is State.RUNNING
                and not self._waiting_for()):
            self._ever_healthy = True

    def health(self) -> Health:
        waiting = self._waiting_for() if self.state is State.RUNNING else []
        healthy = self._healthy and self.state is State.RUNNING and not waiting
        detail = self._health_detail
        if waiting and self._healthy:
            detail = f"waiting for {', '.join(waiting)}"
        return Health(self.name, self.state, healthy, detail, self.restarts, self.failures,
                      None if self.last_error is None else repr(self.last_error),
                      self._ever_healthy, tuple(waiting) if self._healthy else ())

    # -- lifecycle (driven by the supervisor) ------------------------------------------
    def _attach(self, context: Context) -> None:
        self._context = context
        for used in self._used:
            _attach_proxy(used.proxy, context)

    def _set_state(self, state: State) -> None:
        self.state = state
        self._state_changed.set()
        self._state_changed = asyncio.Event()
        self._note_health()

    async def _wait_state_change(self) -> None:
        await self._state_changed.wait()

    async def _run_once(self) -> None:
        """One life: setup, ports open, run, then up until stopped; raises what failed
        it."""
        self._set_state(State.STARTING)
        self._healthy, self._health_detail = True, ""
        context = self.context
        try:
            async with Scope(context.meter, self.name) as scope:
                self._scope = scope
                for output in self._outputs:
                    output._publisher = context.channel.offer(self.robot, output.name)
                await self.setup()
                for port in self._inputs:
                    port.subscription = context.channel.subscribe(
                        self.robot if port.domain is None else port.domain, port.name,
                        maxsize=port.maxsize, policy=port.policy)
                    scope.spawn(self._deliver(port), f"{self.name}:{port.name}")
                for served in self._served:
                    context.registry.rebind(
                        join_name(self.robot, served.name),
                        Servant(served.interface, served.impl, name=join_name(
                            self.robot, served.name), logger=self.log), owner=self)
                self._on_ports_open()
                self._set_state(State.RUNNING)
                await self.run()
                await _Forever()
        except BaseExceptionGroup as group:
            raise first_error(group) from None
        except asyncio.CancelledError:
            if cancel_requested():
                raise  # stopped by the supervisor (or the system)
            # setup() or run() raised it of its own: a failure, not a silent stop
            raise ComponentError(f"{self.name}: setup() or run() raised CancelledError "
                                 "without being cancelled") from None
        finally:
            self._scope = None
            for output in self._outputs:
                output._publisher = None
            if self.state is not State.FAILED:
                self._set_state(State.STOPPING)
            await self._release()

    def _on_ports_open(self) -> None:
        """Called after setup with the ports open (the PSR base starts its reactor)."""

    async def _deliver(self, port: Input) -> None:
        """Deliver ``port``'s events to its handler until the component's life ends.

        However else delivery ends (a handler that raises CancelledError, cancels its own
        task or raises a BaseException that is not an Exception, a subscription that
        closes under it), the component fails: a subscription never dies silently while
        its component looks RUNNING and healthy."""
        subscription = port.subscription
        assert subscription is not None
        handler = port.handler
        async for event in subscription:
            port.check(event)
            if not port.received:
                port.received = 1
                self._note_health()
            else:
                port.received += 1
            try:
                result = handler(event)
                if result is not None:
                    await result
            except asyncio.CancelledError:
                if self._stopping():
                    raise  # the component is stopping (or a sibling task failed)
                raise ComponentError(f"{self.name}: the handler of {port.name!r} raised "
                                     "CancelledError without being cancelled") from None
            except BaseException as exc:
                if isinstance(exc, (Exception, KeyboardInterrupt, SystemExit)):
                    raise  # an Exception fails the component as it is; an exit exits
                raise ComponentError(f"{self.name}: the handler of {port.name!r} raised "
                                     f"{type(exc).__name__}: {exc}") from exc
        if not self._stopping():
            raise ComponentError(f"{self.name}: the subscription to {port.name!r} ended")

    def _stopping(self) -> bool:
        """Whether this component's current life is ending (its scope is closing)."""
        return self._scope is None or self._scope.closing

    async def _release(self) -> None:
        for port in self._inputs:
            if port.subscription is not None:
                port.subscription.close()
        if self._context is not None:
            self._context.registry.unbind_owner(self)
        try:
            await self.teardown()
        except Exception:
            self.log.exception("teardown of %s failed", self.name)

    def _record_failure(self, error: BaseException) -> None:
        self.failures += 1
        self.last_error = error
        self._set_state(State.FAILED)
        # an input file's error (ConfigError: ``file:line: message``) is the user's to
        # fix and says where; a traceback is for faults in the code
        self.log.error("component %s failed: %s: %s", self.name, type(error).__name__, error,
                       exc_info=None if isinstance(error, ConfigError) else error)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name} {self.state.value}>"


class _NamesItsComponent(logging.Filter):
    """Puts the component's name at the front of a message that does not name it, so a
    warning printed without a formatter (Python's last-resort handler in a notebook shows
    only the message) still says which component it is about."""

    def __init__(self, component: str) -> None:
        super().__init__()
        self.component = component

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage()
        if self.component not in message:
            record.msg, record.args = f"{self.component}: {message}", None
        return True


def _component_logger(name: str) -> logging.Logger:
    """``afa.component.NAME``, whose messages name the component."""
    logger = logging.getLogger(f"afa.component.{name}")
    if not any(isinstance(f, _NamesItsComponent) for f in logger.filters):
        logger.addFilter(_NamesItsComponent(name))
    return logger


def _unattached_proxy(interface: type[InterfaceT], name: str) -> InterfaceT:
    """A proxy whose calls fail until its component is attached to a system."""

    class _Detached:
        def __init__(self) -> None:
            self.interface: type[Interface] = interface
            self.name = name

        async def invoke(self, method: str, arguments: dict[str, Any]) -> Any:
            raise ComponentError(f"{name}.{method}: the calling component is not attached "
                                 "to a System")

    return proxy_for(interface, _Detached())


def _attach_proxy(proxy: Proxy, context: Context) -> None:
    """Point a used port's proxy at the system's registry and middleware."""
    interface = type(proxy).interface  # type: ignore[attr-defined]
    fresh = proxy_for(interface, LocalInvoker(context.registry, join_name(
        context.robot, proxy._invoker.name), interface),
        middleware=context.polls.middleware if context.polls is not None else ())
    proxy._invoker, proxy._chain = fresh._invoker, fresh._chain  # type: ignore[attr-defined]


class SubscribePublishServer(Component[P]):
    """SPS: receives events, processes them, publishes events and answers polls."""


class Client(Component[P]):
    """Client: polls servers through typed proxies (``self.uses(Interface, name)``)."""


class PublishServerReactor(Component[P], Generic[P, M]):
    """PSR: a device component. The reactor owns the byte stream and the decoder and
    reconnects with backoff; the server part (this class) publishes and answers polls.

    Subclasses implement :meth:`device` (what to open), :meth:`decoder` (a fresh
    decoder), and :meth:`handle` (one decoded message); optionally :meth:`on_connect`
    (e.g. send configuration commands). ``stale_after`` seconds without a message
    count as a lost device. The base starts the reactor once setup has returned.
    """

    backoff: ClassVar[Backoff] = Backoff()
    stale_after: float | None = None

    def __init__(self, name: str, parameters: P | None = None) -> None:
        super().__init__(name, parameters)
        self.reactor: Reactor[M] | None = None

    def device(self) -> DeviceSpec:
        raise NotImplementedError(f"{type(self).__name__} must say which device to open")

    def decoder(self) -> StreamDecoder[M]:
        raise NotImplementedError(f"{type(self).__name__} must provide a decoder")

    def handle(self, message: M) -> None:
        """Integrate one decoded message (Miro's integrateData)."""
        raise NotImplementedError

    async def on_connect(self, stream: ByteStream) -> None:
        """Called after each (re)connection, before reading."""

    async def send(self, data: bytes) -> None:
        """Write to the device; raises EDevIO while it is not connected."""
        if self.reactor is None:
            raise EDevIO(f"{self.name}: not started")
        await self.reactor.send(data)

    def _on_ports_open(self) -> None:
        spec = self.device()
        devices = self.context.devices
        self.set_health(False, "opening the device")  # healthy once the device has spoken

        async def open_stream() -> ByteStream:
            return await devices.open(self.name, spec)  # type: ignore[no-any-return]

        self.reactor = Reactor(self.name, open_stream, self.decoder(), self.handle, self.clock,
                               backoff=self.backoff, stale_after=self.stale_after,
                               on_connect=self.on_connect, on_health=self.set_health,
                               logger=self.log)
        self.spawn(self.reactor.run(), f"{self.name}:reactor")

    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        if self.reactor is not None:
            stats.update(self.reactor.statistics())
        return stats

