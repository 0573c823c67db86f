"""Byte-stream transports: the seam between device drivers and the outside world.

Drivers are written against :class:`ByteStream` only, so a test or the simulator swaps
the transport and never the driver (pyserial-asyncio and httpx's ``MockTransport`` work
the same way). Three implementations:

- :func:`memory_pipe`: two connected in-memory ends, for fake devices and emulators;
- :func:`open_serial`: a serial port through pyserial-asyncio (the only module that
  imports pyserial);
- :func:`open_tcp`: a TCP connection.

A device is named by a :class:`DeviceSpec` (a serial port or a TCP endpoint);
:class:`DeviceOpener` opens specs, and lets the simulator or a test install a factory
per component name instead of the real device (and refuses real devices where they are
forbidden). Reads from real transports are marked as real I/O on the clock, so a
virtual clock does not mistake waiting on a device for idleness.
"""

from __future__ import annotations

import asyncio
import os
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Awaitable, Callable, Coroutine
from dataclasses import dataclass
from typing import Any

from afa.clock import Clock, WallClock
from afa.errors import EDevIO, RealDeviceForbidden, TransportClosed
from afa.tasks import spawn

__all__ = [
    "ByteStream", "MemoryByteStream", "memory_pipe", "AsyncioByteStream", "PtyDeviceStream",
    "open_serial",
    "open_tcp", "DeviceSpec", "SerialSpec", "TcpSpec", "DeviceOpener", "DeviceFactory",
]


class ByteStream(ABC):
    """A bidirectional byte stream.

    ``read`` returns at least one byte, or raises :class:`~afa.errors.TransportClosed`
    at end of stream; ``write`` raises :class:`~afa.errors.EDevIO` on failure.
    """

    @abstractmethod
    async def read(self, max_bytes: int = 4096) -> bytes: ...

    @abstractmethod
    async def write(self, data: bytes) -> None: ...

    @abstractmethod
    async def close(self) -> None: ...

    @property
    @abstractmethod
    def closed(self) -> bool: ...

    async def __aenter__(self) -> ByteStream:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()


class _Pipe:
    """One direction of a memory pipe."""

    def __init__(self) -> None:
        self.chunks: deque[bytes] = deque()
        self.waiter: asyncio.Future[None] | None = None
        self.eof = False

    def wake(self) -> None:
        waiter, self.waiter = self.waiter, None
        if waiter is not None and not waiter.done():
            waiter.set_result(None)


class MemoryByteStream(ByteStream):
    """One end of an in-memory pipe (see :func:`memory_pipe`). Writes never block."""

    def __init__(self, incoming: _Pipe, outgoing: _Pipe, name: str) -> None:
        self._in = incoming
        self._out = outgoing
        self._closed = False
        self.name = name
        self.bytes_written = 0

    async def read(self, max_bytes: int = 4096) -> bytes:
        pipe = self._in
        while not pipe.chunks:
            if pipe.eof or self._closed:
                raise TransportClosed(f"{self.name}: end of stream")
            pipe.waiter = asyncio.get_running_loop().create_future()
            await pipe.waiter
        chunk = pipe.chunks.popleft()
        if len(chunk) > max_bytes:
            pipe.chunks.appendleft(chunk[max_bytes:])
            chunk = chunk[:max_bytes]
        return chunk

    async def write(self, data: bytes) -> None:
        self.write_nowait(data)

    def write_nowait(self, data: bytes) -> None:
        """Synchronous write, for emulators driven from plain callbacks."""
        if self._closed or self._out.eof:
            raise TransportClosed(f"{self.name}: write on a closed stream")
        if data:
            self._out.chunks.append(bytes(data))
            self.bytes_written += len(data)
            self._out.wake()

    async def close(self) -> None:
        self.close_nowait()

    def close_nowait(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._out.eof = True  # the peer reads what was written, then end of stream
        self._in.eof = True  # the peer's writes fail from now on
        self._in.chunks.clear()
        self._out.wake()
        self._in.wake()

    @property
    def closed(self) -> bool:
        return self._closed


def memory_pipe(name: str = "memory") -> tuple[MemoryByteStream, MemoryByteStream]:
    """Two connected ends: what one writes, the other reads. Closing one end makes the
    other read end-of-stream after it has read what was already written."""
    a_to_b, b_to_a = _Pipe(), _Pipe()
    return (MemoryByteStream(b_to_a, a_to_b, f"{name}[host]"),
            MemoryByteStream(a_to_b, b_to_a, f"{name}[device]"))


class AsyncioByteStream(ByteStream):
    """A :class:`ByteStream` over an asyncio ``StreamReader``/``StreamWriter`` pair."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter,
                 name: str, clock: Clock | None = None) -> None:
        self._reader = reader
        self._writer = writer
        self._closed = False
        self._clock = clock or _REAL_TIME
        self.name = name

    async def read(self, max_bytes: int = 4096) -> bytes:
        try:
            with self._clock.real_io():
                data = await self._reader.read(max_bytes)
        except (OSError, asyncio.IncompleteReadError) as exc:
            raise EDevIO(f"{self.name}: read failed: {exc}") from exc
        if not data:
            raise TransportClosed(f"{self.name}: end of stream")
        return data

    async def write(self, data: bytes) -> None:
        try:
            self._writer.write(data)
            await self._writer.drain()
        except (OSError, RuntimeError) as exc:
            raise EDevIO(f"{self.name}: write failed: {exc}") from exc

    async def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._writer.close()
        try:
            await self._writer.wait_closed()
        except (OSError, RuntimeError):
            pass  # already broken; closing is best effort

    @property
    def closed(self) -> bool:
        return self._closed


_REAL_TIME = WallClock()


async def open_serial(device: str, baudrate: int, *, clock: Clock | None = None,
                      **serial_options: object) -> ByteStream:
    """Open a serial port through pyserial-asyncio; raises EDevIO if it cannot."""
    try:
        import serial  # noqa: F401  (pyserial's exceptions)
        import serial_asyncio
    except ImportError as exc:  # pragma: no cover - a dependency of the package
        raise EDevIO("pyserial-asyncio is not installed") from exc
    try:
        reader, writer = await serial_asyncio.open_serial_connection(
            url=device, baudrate=baudrate, **serial_options)
    except (OSError, ValueError, serial.SerialException) as exc:
        raise EDevIO(f"cannot open serial port {device} at {baudrate} baud: {exc}") from exc
    return AsyncioByteStream(reader, writer, device, clock)


async def open_tcp(host: str, port: int, *, clock: Clock | None = None) -> ByteStream:
    """Connect to ``host:port``; raises EDevIO if it cannot."""
    try:
        with (clock or _REAL_TIME).real_io():
            reader, writer = await asyncio.open_connection(host, port)
    except OSError as exc:
        raise EDevIO(f"cannot connect to {host}:{port}: {exc}") from exc
    return AsyncioByteStream(reader, writer, f"{host}:{port}", clock)


@dataclass(frozen=True, slots=True)
class SerialSpec:
    device: str
    baudrate: int = 9600


@dataclass(frozen=True, slots=True)
class TcpSpec:
    host: str
    port: int


DeviceSpec = SerialSpec | TcpSpec
DeviceFactory = Callable[[DeviceSpec], Awaitable[ByteStream]]


class PtyDeviceStream(ByteStream):
    """The device end of a pseudo-terminal, as a :class:`ByteStream`.

    Fake devices and simulator emulators serve it while the driver opens the terminal's
    path (:attr:`path`) as a real serial port through pyserial-asyncio.
    """

    def __init__(self, clock: Clock | None = None) -> None:
        import tty

        self._clock = clock or _REAL_TIME
        self._fd, self._worker = os.openpty()
        tty.setraw(self._fd)
        os.set_blocking(self._fd, False)
        self.path = os.ttyname(self._worker)
        self._closed = False

    async def read(self, max_bytes: int = 4096) -> bytes:
        while True:
            if self._closed:
                raise TransportClosed(f"{self.path}: closed")
            try:
                data = os.read(self._fd, max_bytes)
            except BlockingIOError:
                with self._clock.real_io():
                    await self._ready(reading=True)
                continue
            except OSError as exc:
                raise TransportClosed(f"{self.path}: {exc}") from exc
            if not data:
                raise TransportClosed(f"{self.path}: end of stream")
            return data

    async def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            if self._closed:
                raise TransportClosed(f"{self.path}: closed")
            try:
                view = view[os.write(self._fd, view):]
            except BlockingIOError:  # the driver has not read yet
                await self._ready(reading=False)
            except OSError as exc:
                raise TransportClosed(f"{self.path}: {exc}") from exc

    async def _ready(self, *, reading: bool) -> None:
        loop = asyncio.get_running_loop()
        ready: asyncio.Future[None] = loop.create_future()

        def wake() -> None:
            if not ready.done():
                ready.set_result(None)

        (loop.add_reader if reading else loop.add_writer)(self._fd, wake)
        try:
            await ready
        finally:
            (loop.remove_reader if reading else loop.remove_writer)(self._fd)

    async def close(self) -> None:
        if not self._closed:
            self._closed = True
            os.close(self._fd)
            os.close(self._worker)

    @property
    def closed(self) -> bool:
        return self._closed


class _SharedPort:
    """One real connection shared by several components (the Raptor's Wheel Odometry
    and Vehicle Control both talk to the MPC555 on one serial port).

    Every tap reads everything the device sends (each component's decoder ignores the
    messages that are not its own); writes from any tap go to the device. When the
    device fails, every tap sees end of stream; the next open reopens the device.
    """

    def __init__(self, open_real: Callable[[], Awaitable[ByteStream]], name: str) -> None:
        self._open_real = open_real
        self._name = name
        self._real: ByteStream | None = None
        self._taps: list[tuple[MemoryByteStream, MemoryByteStream]] = []
        self._tasks: set[asyncio.Task[None]] = set()
        self._lock = asyncio.Lock()

    async def open(self) -> ByteStream:
        async with self._lock:
            if self._real is None or self._real.closed:
                self._real = await self._open_real()
                self._own(self._fan_out(self._real))
            host, inner = memory_pipe(self._name)
            self._taps.append((host, inner))
            self._own(self._forward_writes(host, inner, self._real))
            return host

    def _own(self, coroutine: Coroutine[Any, Any, None]) -> None:
        task = spawn(coroutine, owner=f"shared port {self._name}")
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def _fan_out(self, real: ByteStream) -> None:
        try:
            while True:
                data = await real.read()
                for host, inner in list(self._taps):
                    if inner.closed or host.closed:
                        self._taps.remove((host, inner))
                        continue
                    inner.write_nowait(data)
                if not self._taps:
                    break
        except EDevIO:
            pass
        finally:
            for _host, inner in self._taps:
                inner.close_nowait()
            self._taps.clear()
            await real.close()

    async def _forward_writes(self, host: MemoryByteStream, inner: MemoryByteStream,
                              real: ByteStream) -> None:
        try:
            while True:
                await real.write(await inner.read())
        except EDevIO:
            inner.close_nowait()
        if (host, inner) in self._taps:
            self._taps.remove((host, inner))
        if not self._taps:  # the last user closed its end: release the device
            await real.close()


class DeviceOpener:
    """Opens the device a component names, or what a test or simulator put in its place.

    ``overrides`` maps a component name to an async factory receiving the spec and
    returning the device (a :class:`ByteStream`, or for devices that are not byte
    streams, such as a camera, whatever the driver expects). Two components naming the
    same serial device share one connection. With ``allow_real=False`` a component
    without an override gets :class:`~afa.errors.RealDeviceForbidden` instead of its
    real port (tests must never drive a vehicle's serial line).
    """

    def __init__(self, overrides: dict[str, DeviceFactory] | None = None, *,
                 allow_real: bool = True, clock: Clock | None = None) -> None:
        self.overrides: dict[str, DeviceFactory] = dict(overrides or {})
        self.allow_real = allow_real
        self.clock = clock
        self._shared: dict[str, _SharedPort] = {}
        self._rates: dict[str, int] = {}  # the baud rate each shared port was opened at

    async def open(self, component: str, spec: Any) -> Any:
        """Open ``component``'s device: its override if one is installed, else the real
        serial port or TCP endpoint. Other device kinds (a camera) have no real opener
        here: their driver supplies one, or a simulator installs an override; without
        one, EDevIO."""
        factory = self.overrides.get(component)
        if factory is not None:
            return await factory(spec)
        if not isinstance(spec, (SerialSpec, TcpSpec)):
            raise EDevIO(f"{component}: no device available for {spec!r}")
        if not self.allow_real:
            raise RealDeviceForbidden(
                f"{component} would open its real device {spec}, and real devices are "
                "forbidden here; give it a fake device")
        if isinstance(spec, SerialSpec):
            return await self.open_serial(spec)
        return await open_tcp(spec.host, spec.port, clock=self.clock)

    async def open_serial(self, spec: SerialSpec) -> ByteStream:
        """Open a serial port (real, or a pseudo-terminal an emulator serves), shared
        with any other component naming it."""
        port = self._shared.get(spec.device)
        if port is None:
            port = self._shared[spec.device] = _SharedPort(
                lambda: open_serial(spec.device, spec.baudrate, clock=self.clock), spec.device)
            self._rates[spec.device] = spec.baudrate
        elif self._rates.get(spec.device, spec.baudrate) != spec.baudrate:
            raise EDevIO(f"serial port {spec.device} is shared with another component at "
                         f"{self._rates[spec.device]} baud; this one asks for {spec.baudrate} "
                         "(give each device its own port)")
        return await port.open()
