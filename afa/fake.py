"""Fake devices: the device side of a byte protocol, for tests and the simulator.

A :class:`FakeDevice` plays a real device over a :class:`~afa.transport.ByteStream`: it
decodes the host's commands with the device-side decoder of the component's codec and
produces the device's output (periodic reports, replies) with its encoders. Tests put
it on an in-memory pipe in place of the serial port or socket; the simulator feeds it
ground truth from the simulated world. The driver cannot tell.

``device.factory()`` is what ``System(devices={name: ...})`` takes: each open makes a
fresh pipe, serves the device end in a task the fake owns, and returns the host end.
``unplug()`` / ``plug()`` simulate a lost and returning device.

A fake may run for hours in the simulator, so what it keeps is bounded: the commands it
received are a :class:`RecentLog` (the latest :attr:`FakeDevice.command_history`, and a
count of all), and a connection is forgotten when it ends.
"""

from __future__ import annotations

import asyncio
import logging
from collections import deque
from collections.abc import Awaitable, Callable, Iterator, Sequence
from typing import Generic, TypeVar, overload

from afa.clock import Clock
from afa.codec import StreamDecoder
from afa.errors import EDevIO
from afa.tasks import Scope, first_error, spawn
from afa.transport import ByteStream, DeviceSpec, MemoryByteStream, memory_pipe

__all__ = ["FakeDevice", "RecentLog"]

C = TypeVar("C")
T = TypeVar("T")
log = logging.getLogger("afa.fake")


class RecentLog(Sequence[T]):
    """The latest ``maxlen`` items of an endless stream, oldest first; :attr:`total`
    counts every item ever appended. Indexes and slices like a list (a slice is a new
    list), so a test reads ``fake.commands[:4]`` or ``fake.commands[-1]`` as before,
    while a long run holds at most ``maxlen`` items.
    """

    def __init__(self, maxlen: int) -> None:
        if maxlen < 1:
            raise ValueError("maxlen must be >= 1")
        self._items: deque[T] = deque(maxlen=maxlen)
        self.total = 0

    @property
    def maxlen(self) -> int:
        return self._items.maxlen or 0

    def append(self, item: T) -> None:
        self._items.append(item)
        self.total += 1

    def clear(self) -> None:
        """Forget the items; :attr:`total` is kept."""
        self._items.clear()

    @overload
    def __getitem__(self, index: int) -> T: ...

    @overload
    def __getitem__(self, index: slice) -> list[T]: ...

    def __getitem__(self, index: int | slice) -> T | list[T]:
        if isinstance(index, slice):
            return list(self._items)[index]
        return self._items[index]

    def __len__(self) -> int:
        return len(self._items)

    def __iter__(self) -> Iterator[T]:
        return iter(self._items)

    def __repr__(self) -> str:
        return f"RecentLog({list(self._items)!r}, total={self.total})"


class FakeDevice(Generic[C]):
    """Base of fake devices. Override :meth:`command_decoder`, :meth:`on_command` and
    :meth:`produce` (any of them may stay empty)."""

    name = "device"
    #: How many of the latest decoded commands :attr:`commands` keeps.
    command_history = 1024

    def __init__(self, clock: Clock) -> None:
        self.clock = clock
        #: The latest decoded host commands (``commands.total``: all of them).
        self.commands: RecentLog[C] = RecentLog(self.command_history)
        self.plugged = True
        self.opens = 0
        self._streams: list[MemoryByteStream] = []
        self._tasks: set[asyncio.Task[None]] = set()

    # -- hooks ---------------------------------------------------------------------------
    def command_decoder(self) -> StreamDecoder[C] | None:
        """A fresh device-side decoder of host commands (None: the device ignores input)."""
        return None

    async def on_command(self, command: C, stream: ByteStream) -> None:
        """React to one host command (reply, change mode)."""

    async def produce(self, stream: ByteStream) -> None:
        """Write the device's unsolicited output (periodic reports) until cancelled."""
        await asyncio.Event().wait()

    # -- serving -------------------------------------------------------------------------
    async def serve(self, stream: ByteStream) -> None:
        """Play the device on ``stream`` until it closes. Raises what a hook raised
        (a bug in the fake), never the end of the connection."""
        decoder = self.command_decoder()
        try:
            async with Scope() as scope:
                producer = scope.spawn(self.produce(stream), f"{self.name}:produce")
                if decoder is not None:
                    while True:
                        data = await stream.read()
                        for command in decoder.feed(data):
                            self.commands.append(command)
                            await self.on_command(command, stream)
                else:
                    await producer
        except EDevIO:
            pass  # the host went away: this connection is over
        except BaseExceptionGroup as group:
            error = first_error(group)
            if not isinstance(error, EDevIO):
                raise error from None
        finally:
            if stream in self._streams:
                self._streams.remove(stream)  # a long run reconnects many times
            await stream.close()

    def factory(self) -> Callable[[DeviceSpec], Awaitable[ByteStream]]:
        """A device factory for ``System(devices=...)``."""

        async def open_device(spec: DeviceSpec) -> ByteStream:
            if not self.plugged:
                raise EDevIO(f"{self.name}: no such device")
            host, device = memory_pipe(self.name)
            self.opens += 1
            self._streams.append(device)
            task = spawn(self.serve(device), owner=f"fake {self.name}")
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)
            return host

        return open_device

    def unplug(self) -> None:
        """Drop every connection and refuse new ones until :meth:`plug`."""
        self.plugged = False
        for stream in self._streams:
            stream.close_nowait()
        self._streams.clear()

    def plug(self) -> None:
        self.plugged = True

    async def aclose(self) -> None:
        """Stop serving (end of a test or simulation)."""
        self.unplug()
        for task in list(self._tasks):
            task.cancel()
        for task in list(self._tasks):
            try:
                await task
            except (asyncio.CancelledError, Exception):  # already reported by serve()
                pass
