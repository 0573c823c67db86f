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

import asyncio
from collections.abc import Awaitable, Callable

from afa.clock import Clock, VirtualClock
from afa.errors import ETimeOut
from afa.transport import ByteStream, DeviceSpec, MemoryByteStream, memory_pipe

__all__ = ["VirtualClock", "memory_pipe", "MemoryByteStream", "settle", "until", "serve",
           "DeviceSwitch"]


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
    deadline = clock.now() + timeout
    while not predicate():
        if clock.now() >= deadline:
            raise ETimeOut(f"{what} not reached within {timeout:g} s")
        await clock.sleep(step)


def serve(stream: ByteStream) -> Callable[[DeviceSpec], Awaitable[ByteStream]]:
    """A device factory that hands out ``stream`` once (for ``System(devices=...)``)."""

    async def factory(spec: DeviceSpec) -> ByteStream:
        return stream

    return factory


class DeviceSwitch:
    """A device factory whose device can be unplugged and plugged back in.

    Each open creates a fresh memory pipe and passes its device end to ``attach``
    (the fake device's coroutine, run in a task owned by this switch). While
    unplugged, opening fails with EDevIO, as a missing serial port does.
    """

    def __init__(self, attach: Callable[[MemoryByteStream], Awaitable[None]], name: str = "device") -> None:
        self._attach = attach
        self._name = name
        self.plugged = True
        self.opens = 0
        self._device: MemoryByteStream | None = None
        self._tasks: set[asyncio.Task[None]] = set()

    async def __call__(self, spec: DeviceSpec) -> ByteStream:
        from afa.errors import EDevIO

        if not self.plugged:
            raise EDevIO(f"{self._name}: no such device")
        host, device = memory_pipe(self._name)
        self._device = device
        self.opens += 1
        task = asyncio.get_running_loop().create_task(self._attach(device))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return host

    def unplug(self) -> None:
        """Close the current connection and refuse new ones."""
        self.plugged = False
        if self._device is not None:
            self._device.close_nowait()
        for task in list(self._tasks):
            task.cancel()

    def plug(self) -> None:
        self.plugged = True

    async def aclose(self) -> None:
        self.unplug()
        for task in list(self._tasks):
            try:
                await task
            except (asyncio.CancelledError, Exception):
                pass
