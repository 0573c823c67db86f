"""Test support: the virtual clock, in-memory byte streams, and waiting helpers.

Runtime code never imports this module. Tests use it to drive components through their
real codecs with fake devices, in virtual time, without sleeps::

    clock = VirtualClock()
    host, device = memory_pipe("gps")
    system = System([GpsSokkia("Gps")], clock=clock, devices={"Gps": serve(host)})
    async with system:
        await clock.advance(1.0)        # or: await until(lambda: ..., clock)
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

from afa.clock import Clock, VirtualClock
from afa.errors import ETimeOut
from afa.fake import FakeDevice
from afa.tasks import TaskGroup
from afa.transport import ByteStream, DeviceSpec, MemoryByteStream, memory_pipe

__all__ = ["VirtualClock", "memory_pipe", "MemoryByteStream", "FakeDevice", "TaskGroup", "settle",
           "until", "serve", "configured_parameters"]


async def settle(clock: Clock | None = None) -> None:
    """Wait until no task or callback is ready to run (virtual time does not move)."""
    if isinstance(clock, VirtualClock):
        await clock.settle()
        return
    await VirtualClock().settle()  # idleness does not depend on which clock is used


async def until(predicate: Callable[[], bool], clock: Clock, *, timeout: float = 60.0,
                step: float = 0.01, what: str = "condition") -> None:
    """Advance (virtual) time in ``step`` increments until ``predicate()`` holds.

    Raises :class:`~afa.errors.ETimeOut` after ``timeout`` clock seconds.
    """
    deadline = clock.monotonic() + timeout
    while not predicate():
        if clock.monotonic() >= deadline:
            raise ETimeOut(f"{what} not reached within {timeout:g} s")
        await clock.sleep(step)


def serve(stream: ByteStream) -> Callable[[DeviceSpec], Awaitable[ByteStream]]:
    """A device factory that hands out ``stream`` once (for ``System(devices=...)``)."""

    async def factory(spec: DeviceSpec) -> ByteStream:
        return stream

    return factory


def configured_parameters(config: str | Path, component: str) -> Any:
    """The parameters configuration file ``config`` gives the component named
    ``component`` (its Launcher name, e.g. ``"GpsSokkiaService"``), validated: the model
    its class declares, as the running system would build it. Raises ConfigError for a
    bad file or a name the Launcher does not list."""
    from afa.errors import ConfigError
    from afa.system import System

    system = System.from_xml(config, only=[component], real_devices=False)
    if component not in system.components:
        raise ConfigError(f"{config}: no component {component!r} in its Launcher")
    return system.components[component].parameters
