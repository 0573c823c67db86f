"""Components: Miro's three design patterns as small async base classes.

A component fills a few hooks; the base owns lifecycle, logging, error routing, names
and the get/getWait machinery:

- :meth:`Component.setup` (each (re)start): make publishers, subscribe, serve
  interfaces. Keep it local and quick: do not wait for other components here.
- :meth:`Component.run` (after setup): the main body. It may return at once; the
  component then lives as long as the tasks it spawned (subscription handlers, reactor,
  timers). Resolve other components' names here (``await self.resolve(...)``).
- :meth:`Component.teardown` (every stop or failure): release what setup acquired.

Any exception in setup, run, a subscription handler or a spawned task fails the
component as a unit: it is logged with the component's name, its names are unbound,
its subscriptions closed, and the supervisor (:mod:`afa.system`) restarts it with
backoff per its :class:`RestartPolicy`. The other components keep running.

The three patterns (seed §2.2.1):

- :class:`SubscribePublishServer` (SPS): receives events, processes, publishes, serves.
- :class:`PublishServerReactor` (PSR): a device driver; the reactor (a byte stream and
  a codec, :mod:`afa.reactor`) stays apart from the server part that publishes events
  and answers polls.
- :class:`Client`: resolves a name and polls a server through its typed interface.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable, Coroutine
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any, ClassVar, Generic, TypeVar

from afa.clock import Clock
from afa.codec import StreamDecoder
from afa.config.parameters import Parameters
from afa.errors import ComponentError, EDevIO
from afa.events import Event, EventChannel, Overflow, Publisher, Subscription
from afa.naming import NameRegistry, join_name
from afa.polling import LatestSlot, Servant, proxy_for
from afa.reactor import Backoff, Reactor
from afa.transport import ByteStream, DeviceOpener, DeviceSpec
from idl._base import Interface

__all__ = [
    "State", "Context", "Component", "SubscribePublishServer", "PublishServerReactor",
    "Client", "RestartPolicy", "Health",
]

InterfaceT = TypeVar("InterfaceT", bound=Interface)
M = TypeVar("M")
P = TypeVar("P", bound=Parameters)


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


@dataclass
class Context:
    """What the runtime gives every component."""

    robot: str
    channel: EventChannel
    registry: NameRegistry
    clock: Clock
    devices: DeviceOpener = field(default_factory=DeviceOpener)
    base_dir: Path = field(default_factory=Path.cwd)


@dataclass(frozen=True)
class Health:
    name: str
    state: State
    healthy: bool
    detail: str
    restarts: int
    failures: int
    last_error: str | None


class Component:
    """Base of every component (see the module docstring for the hooks)."""

    #: The component's parameter model; ``parameters`` is an instance of it.
    Parameters: ClassVar[type[Parameters] | None] = None
    #: Per-class restart policy; None uses the system's.
    restart_policy: ClassVar[RestartPolicy | None] = None

    def __init__(self, name: str, parameters: Parameters | None = None) -> None:
        if parameters is None and self.Parameters is not None:
            parameters = self.Parameters()
        if self.Parameters is not None and not isinstance(parameters, self.Parameters):
            raise ComponentError(
                f"{name}: expected {self.Parameters.__name__}, got {type(parameters).__name__}")
        self.name = name
        self.parameters = parameters
        self.state = State.CREATED
        self.log = logging.getLogger(f"afa.component.{name}")
        self.restarts = 0
        self.failures = 0
        self.last_error: BaseException | None = None
        self._context: Context | None = None
        self._tasks: asyncio.TaskGroup | None = None
        self._subscriptions: list[Subscription] = []
        self._healthy = True
        self._health_detail = ""
        self._state_changed = asyncio.Event()

    # -- hooks -----------------------------------------------------------------------
    async def setup(self) -> None:
        """Create publishers, subscriptions and servants. Called at every (re)start."""

    async def run(self) -> None:
        """The main body; may return at once (spawned tasks keep the component alive)."""

    async def teardown(self) -> None:
        """Release resources acquired in setup. Called at every stop or failure."""

    def statistics(self) -> dict[str, Any]:
        """Counters for health displays and run summaries; extend in subclasses."""
        stats: dict[str, Any] = {}
        for subscription in self._subscriptions:
            counters = subscription.statistics()
            stats[f"{subscription.domain}/{subscription.type}"] = {
                "delivered": counters.delivered, "dropped": counters.dropped,
                "high_water": counters.high_water}
        return stats

    # -- context ---------------------------------------------------------------------
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

    # -- helpers for setup/run ---------------------------------------------------------
    def publisher(self, event_name: str) -> Publisher:
        """A publisher of ``<Robot>/<event_name>`` events."""
        return self.context.channel.offer(self.robot, event_name)

    def subscribe(self, event_name: str, handler: Callable[[Event], Awaitable[None] | None],
                  *, domain: str | None = None, maxsize: int = 16,
                  policy: Overflow = Overflow.DROP_OLDEST) -> Subscription:
        """Deliver matching events to ``handler`` (sync or async) in a task of this
        component; an exception in the handler fails the component."""
        subscription = self.context.channel.subscribe(
            self.robot if domain is None else domain, event_name, maxsize=maxsize, policy=policy)
        self._subscriptions.append(subscription)

        async def deliver() -> None:
            async for event in subscription:
                result = handler(event)
                if result is not None:
                    await result

        self.spawn(deliver(), f"{self.name}:{event_name}")
        return subscription

    def serve(self, interface: type[Interface], name: str | None = None,
              impl: object | None = None) -> str:
        """Bind ``<Robot>/<name>`` to this component (or ``impl``) serving ``interface``.

        The name is unbound when the component stops. Returns the full name.
        """
        full = join_name(self.robot, name or self.name)
        servant = Servant(interface, self if impl is None else impl, name=full, logger=self.log)
        self.context.registry.rebind(full, servant, owner=self)
        return full

    async def resolve(self, interface: type[InterfaceT], name: str, *,
                      timeout: float | None = None,
                      call_timeout: float | None = None) -> InterfaceT:
        """Wait until ``name`` is bound (``timeout`` None: forever) and return a proxy."""
        full = join_name(self.robot, name)
        servant = await self.context.registry.wait_resolve(full, timeout)
        return proxy_for(interface, servant, self.clock, timeout=call_timeout, name=full)

    def slot(self, what: str) -> LatestSlot[Any]:
        """A latest-value slot on this component's clock (for get/getWait polls)."""
        return LatestSlot(self.clock, f"{what} from {self.name}")

    def spawn(self, coroutine: Coroutine[Any, Any, Any],
              name: str | None = None) -> asyncio.Task[Any]:
        """Run ``coroutine`` as part of this component (failing with it)."""
        if self._tasks is None:
            coroutine.close()
            raise ComponentError(f"{self.name}: spawn() is only possible while starting or running")
        return self._tasks.create_task(coroutine, name=name or self.name)

    def set_health(self, healthy: bool, detail: str = "") -> None:
        """Report the component (un)healthy, e.g. while its device is lost."""
        if healthy != self._healthy or detail != self._health_detail:
            self._healthy, self._health_detail = healthy, detail
            log = self.log.info if healthy else self.log.warning
            log("%s", f"healthy {detail}".strip() if healthy else f"unhealthy: {detail}")

    def health(self) -> Health:
        healthy = self._healthy and self.state is State.RUNNING
        return Health(self.name, self.state, healthy, self._health_detail, self.restarts,
                      self.failures, None if self.last_error is None else repr(self.last_error))

    # -- lifecycle (driven by the supervisor) ------------------------------------------
    def _attach(self, context: Context) -> None:
        self._context = context

    def _set_state(self, state: State) -> None:
        self.state = state
        self._state_changed.set()
        self._state_changed = asyncio.Event()

    async def _wait_state_change(self) -> None:
        await self._state_changed.wait()

    async def _run_once(self) -> None:
        """One life: setup, run, until the tasks end; raises what failed it."""
        self._set_state(State.STARTING)
        self._healthy, self._health_detail = True, ""
        try:
            async with asyncio.TaskGroup() as tasks:
                self._tasks = tasks
                await self.setup()
                self._set_state(State.RUNNING)
                await self.run()
        except BaseExceptionGroup as group:
            raise _first_error(group) from None
        finally:
            self._tasks = None
            if self.state is not State.FAILED:
                self._set_state(State.STOPPING)
            await self._release()

    async def _release(self) -> None:
        for subscription in self._subscriptions:
            subscription.close()
        self._subscriptions.clear()
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
        self.log.error("component %s failed: %s: %s", self.name, type(error).__name__, error,
                       exc_info=error)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name} {self.state.value}>"


def _first_error(group: BaseExceptionGroup) -> BaseException:
    """The exception that failed a component, unwrapped from TaskGroup's group."""
    for exc in group.exceptions:
        if isinstance(exc, BaseExceptionGroup):
            return _first_error(exc)
        if not isinstance(exc, asyncio.CancelledError):
            return exc
    return group


class SubscribePublishServer(Component):
    """SPS: receives events, processes them, publishes events and answers polls."""


class Client(Component):
    """Client: resolves names and polls servers (``await self.resolve(Interface, name)``)."""


class PublishServerReactor(Component, Generic[M]):
    """PSR: a device component. The reactor owns the byte stream and the decoder and
    reconnects with backoff; the server part (this class) publishes and answers polls.

    Subclasses implement :meth:`device` (what to open), :meth:`decoder` (a fresh
    decoder), and :meth:`handle` (one decoded message); optionally :meth:`on_connect`
    (e.g. send configuration commands). ``stale_after`` seconds without a message
    count as a lost device.
    """

    backoff: ClassVar[Backoff] = Backoff()
    stale_after: ClassVar[float | None] = None

    def __init__(self, name: str, parameters: Parameters | None = None) -> None:
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

    async def setup(self) -> None:
        spec = self.device()

        async def open_stream() -> ByteStream:
            return await self.context.devices.open(self.name, spec)

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

