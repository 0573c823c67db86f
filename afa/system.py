"""The System: one event channel, one name registry, one clock, supervised components.

``async with system:`` starts every component inside the *caller's* running event loop
(a notebook's, a test's, or the CLI's) and stops them all on exit; afa never calls
``asyncio.run`` outside the CLI and never takes a ``loop=`` argument.

Supervision: each component runs in its own supervisor task. An exception fails only
that component: it is logged with its name, marked failed, and restarted with backoff
per its :class:`~afa.component.RestartPolicy`; the others keep running. Start-up
starts components in order, waiting each one's start delay (the seed Launcher's dT), and
raises one :class:`~afa.errors.StartupError` naming every component whose first start
failed.
"""

from __future__ import annotations

import asyncio
import logging
from collections import Counter
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from afa.clock import Clock, WallClock
from afa.component import Component, Context, Health, RestartPolicy, State
from afa.errors import ComponentError, StartupError
from afa.events import Event, EventChannel
from afa.naming import NameRegistry, join_name
from afa.polling import proxy_for
from afa.transport import DeviceFactory, DeviceOpener
from idl._base import Interface

__all__ = ["System"]

InterfaceT = TypeVar("InterfaceT", bound=Interface)
log = logging.getLogger("afa.system")


class System:
    """A set of components sharing one channel, registry and clock.

    ``components`` are started in the given order; ``start_delays`` maps a component
    name to the seconds to wait after starting it (dT). ``devices`` maps a component
    name to a factory opening a byte stream in place of its real device. ``base_dir``
    is where components resolve relative file names (the configuration's folder).
    """

    def __init__(
        self,
        components: Iterable[Component] = (),
        *,
        robot: str = "Raptor",
        clock: Clock | None = None,
        devices: Mapping[str, DeviceFactory] | None = None,
        restart_policy: RestartPolicy = RestartPolicy(),
        start_delays: Mapping[str, float] | None = None,
        base_dir: str | Path | None = None,
    ) -> None:
        self.robot = robot
        self.clock: Clock = clock or WallClock()
        self.channel = EventChannel(self.clock)
        self.registry = NameRegistry(self.clock)
        self.devices = DeviceOpener(dict(devices or {}))
        self.restart_policy = restart_policy
        self.start_delays = dict(start_delays or {})
        self.base_dir = Path(base_dir) if base_dir is not None else Path.cwd()
        self.configuration: Any = None  # the validated Configuration, when built from XML
        self.components: dict[str, Component] = {}
        self.notes: list[str] = []  # start-up remarks (e.g. components not implemented yet)
        self._supervisors: dict[str, asyncio.Task[None]] = {}
        self._event_counts: Counter[str] = Counter()
        self._running = False
        self._stopped = asyncio.Event()
        for component in components:
            self.add(component)

    @classmethod
    def from_xml(cls, path: str | Path, **options: Any) -> System:
        """Build the system a Miro XML configuration file describes.

        Options are passed to the constructor (``clock``, ``devices``, ...) except
        ``strict`` (default False): when True a configured component whose
        implementation is not written yet is an error instead of a start-up note.
        Raises :class:`~afa.errors.ConfigError` for an invalid file.
        """
        from afa.assembly import build_system  # config + registry; kept out of import time

        return build_system(cls, Path(path), **options)

    def add(self, component: Component) -> Component:
        """Add a component (before start, or while running: it starts at once)."""
        if component.name in self.components:
            raise ComponentError(f"two components are named {component.name!r}")
        self.components[component.name] = component
        component._attach(Context(self.robot, self.channel, self.registry, self.clock,
                                  self.devices, self.base_dir))
        if self._running:
            self._launch(component)
        return component

    # -- running -------------------------------------------------------------------------
    async def __aenter__(self) -> System:
        await self.start()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.stop()

    async def start(self) -> None:
        """Start every component in order; raises StartupError if any first start fails
        (after stopping the ones that started)."""
        if self._running:
            return
        self._running = True
        self._stopped = asyncio.Event()
        self.registry.rebind(join_name(self.robot, "EventChannel"), self.channel, owner=self)
        self._remove_tap = self.channel.add_tap(self._count)
        failures: dict[str, BaseException] = {}
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
            await self.stop()
            raise StartupError(failures)

    async def stop(self) -> None:
        """Stop every component (reverse start order) and unbind the channel."""
        if not self._running:
            return
        for name in reversed(list(self._supervisors)):
            await self.stop_component(name)
        self._remove_tap()
        self.registry.unbind_owner(self)
        self._running = False
        self._stopped.set()

    async def run(self, duration: float | None = None) -> None:
        """Run until ``duration`` clock seconds have passed (None: until stopped)."""
        if duration is None:
            await self._stopped.wait()
        else:
            await self.clock.sleep(duration)

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
    async def resolve(self, interface: type[InterfaceT], name: str, *,
                      timeout: float | None = None,
                      call_timeout: float | None = None) -> InterfaceT:
        """A client proxy for ``<Robot>/<name>`` (waits up to ``timeout`` for the bind)."""
        full = join_name(self.robot, name)
        servant = await self.registry.wait_resolve(full, timeout)
        return proxy_for(interface, servant, self.clock, timeout=call_timeout, name=full)

    # -- observation -------------------------------------------------------------------
    def health(self) -> dict[str, Health]:
        return {name: c.health() for name, c in self.components.items()}

    def statistics(self) -> dict[str, Any]:
        dropped = sum(s.statistics().dropped for s in self.channel.subscriptions())
        return {
            "events": dict(sorted(self._event_counts.items())),
            "events_published": self.channel.published,
            "events_dropped": dropped,
            "components": {name: c.statistics() for name, c in self.components.items()},
        }

    def _count(self, event: Event) -> None:
        self._event_counts[event.type] += 1

    def _launch(self, component: Component) -> None:
        component._set_state(State.CREATED)
        self._supervisors[component.name] = asyncio.get_running_loop().create_task(
            self._supervise(component), name=f"afa-supervisor:{component.name}")

    async def _supervise(self, component: Component) -> None:
        policy = component.restart_policy or self.restart_policy
        attempt = 0
        while True:
            started = self.clock.now()
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
            if self.clock.now() - started >= policy.reset_after:
                attempt = 0
            if policy.max_restarts is not None and attempt >= policy.max_restarts:
                log.error("%s failed %d times in a row; giving up", component.name, attempt + 1)
                return
            delay = policy.delay(attempt)
            attempt += 1
            log.warning("restarting %s in %.2f s", component.name, delay)
            await self.clock.sleep(delay)
            component.restarts += 1
