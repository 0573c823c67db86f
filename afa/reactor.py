"""The reactor half of the Publish Server and Reactor pattern.

A :class:`Reactor` owns one device connection: it opens the byte stream, feeds what it
reads to a sans-I/O decoder (:mod:`afa.codec`), hands each decoded message to the
server, and writes commands back through the same stream. When the device disappears
(open fails, end of stream, I/O error, or no message for ``stale_after`` seconds) it
reports the component unhealthy, closes the stream and reopens it with exponential
backoff; the rest of the system keeps running. Corrupt frames never reach the server:
the decoder counts and skips them.
"""

from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from afa.clock import Clock, Watchdog
from afa.codec import StreamDecoder
from afa.errors import EDevIO, ETimeOut
from afa.transport import ByteStream

__all__ = ["Reactor", "Backoff"]

M = TypeVar("M")


@dataclass(frozen=True)
class Backoff:
    """Reconnect delays: ``initial * factor**n`` capped at ``maximum`` seconds."""

    initial: float = 0.2
    factor: float = 2.0
    maximum: float = 5.0

    def delay(self, attempt: int) -> float:
        return min(self.maximum, self.initial * self.factor**attempt)


class Reactor(Generic[M]):
    """Reads a byte stream through a decoder; reconnects with backoff."""

    def __init__(
        self,
        name: str,
        open_stream: Callable[[], Awaitable[ByteStream]],
        decoder: StreamDecoder[M],
        on_message: Callable[[M], Any],
        clock: Clock,
        *,
        backoff: Backoff = Backoff(),
        stale_after: float | None = None,
        on_connect: Callable[[ByteStream], Awaitable[None]] | None = None,
        on_health: Callable[[bool, str], None] | None = None,
        logger: logging.Logger | None = None,
        read_size: int = 4096,
    ) -> None:
        self.name = name
        self.decoder = decoder
        self._open = open_stream
        self._on_message = on_message
        self._clock = clock
        self._backoff = backoff
        self._stale_after = stale_after
        self._on_connect = on_connect
        self._on_health = on_health or (lambda healthy, detail: None)
        self._log = logger or logging.getLogger(f"afa.reactor.{name}")
        self._read_size = read_size
        self._stream: ByteStream | None = None
        self.connects = 0
        self.disconnects = 0
        self.last_message_time: float | None = None

    @property
    def connected(self) -> bool:
        return self._stream is not None and not self._stream.closed

    async def send(self, data: bytes) -> None:
        """Write ``data`` to the device; raises EDevIO while disconnected."""
        stream = self._stream
        if stream is None or stream.closed:
            raise EDevIO(f"{self.name}: device not connected")
        await stream.write(data)

    async def run(self) -> None:
        """Connect, read and decode forever, reconnecting with backoff."""
        attempt = 0
        while True:
            try:
                stream = await self._open()
            except EDevIO as exc:
                self._on_health(False, f"cannot open device: {exc}")
            else:
                self._stream = stream
                self.connects += 1
                self.decoder.reset()
                try:
                    if self._on_connect is not None:
                        await self._on_connect(stream)
                    # connected is not alive: healthy only once the device has spoken
                    self._on_health(False, "connected, no message from the device yet")
                    await self._read_loop(stream)
                except EDevIO as exc:  # includes TransportClosed and stale-stream ETimeOut
                    self._on_health(False, f"device lost: {exc}")
                finally:
                    self._stream = None
                    self.disconnects += 1
                    await stream.close()
                if self._messages_since_connect:
                    attempt = 0
            delay = self._backoff.delay(attempt)
            attempt += 1
            self._log.info("reconnecting in %.2f s", delay)
            await self._clock.sleep(delay)

    async def _read_loop(self, stream: ByteStream) -> None:
        self._messages_since_connect = 0
        if self._stale_after is None:
            await self._pump(stream, None)
            return
        try:
            async with self._clock.watchdog(self._stale_after, f"{self.name} read") as dog:
                await self._pump(stream, dog)
        except ETimeOut as exc:
            raise EDevIO(f"no message for {self._stale_after:g} s") from exc

    async def _pump(self, stream: ByteStream, dog: Watchdog | None) -> None:
        decoder, deliver, clock, size = self.decoder, self._on_message, self._clock, self._read_size
        while True:
            messages = decoder.feed(await stream.read(size))
            if messages:
                if dog is not None:  # bytes that decode to nothing (noise) are no sign of life
                    dog.feed()
                if not self._messages_since_connect:
                    self._on_health(True, "receiving")
                self.last_message_time = clock.now()
                self._messages_since_connect += len(messages)
                for message in messages:
                    deliver(message)

    _messages_since_connect = 0

    def statistics(self) -> dict[str, Any]:
        return {
            **self.decoder.stats.as_dict(),
            "connects": self.connects,
            "reconnects": max(0, self.connects - 1),
            "disconnects": self.disconnects,
            "connected": self.connected,
        }
