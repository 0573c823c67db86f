"""Sans-I/O byte codecs: the pure half of every device driver.

A device driver is two layers (see ``docs/architecture.md``): a codec that turns bytes
into messages and messages into bytes, with no asyncio and no I/O, tested with byte
literals; and an async driver (:mod:`afa.reactor`) that moves bytes between a
:class:`~afa.transport.ByteStream` and the codec.

:class:`StreamDecoder` owns the buffering, resynchronisation and statistics; a concrete
decoder implements one hook, :meth:`StreamDecoder.scan`, which looks at the front of the
buffer and says what is there.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass
from enum import StrEnum
from typing import Generic, TypeVar

M = TypeVar("M")


class Fault(StrEnum):
    """Why bytes at the front of the buffer were skipped."""

    GARBAGE = "garbage"  # bytes that cannot start a frame (before a sync pattern)
    CHECKSUM = "checksum"  # a complete frame whose checksum does not match
    MALFORMED = "malformed"  # checksum fine (or none) but the content is not decodable
    OVERFLOW = "overflow"  # a frame claimed to be longer than the decoder accepts


@dataclass(frozen=True, slots=True)
class Scan(Generic[M]):
    """The result of looking at the front of the buffer.

    - ``Scan.need_more()``: the front may be the start of a frame; wait for more bytes.
    - ``Scan.frame(n, message)``: the first ``n`` bytes are one valid frame.
    - ``Scan.skip(n, fault)``: drop the first ``n`` bytes (n >= 1) and count the fault.
      To resynchronise after a bad frame, skip only up to the next possible sync byte
      (often 1 byte), so a valid frame hidden inside garbage is never lost.
    """

    consumed: int
    message: M | None = None
    fault: Fault | None = None

    @staticmethod
    def need_more() -> Scan[M]:
        return Scan(0)

    @staticmethod
    def frame(consumed: int, message: M) -> Scan[M]:
        return Scan(consumed, message)

    @staticmethod
    def skip(consumed: int, fault: Fault) -> Scan[M]:
        return Scan(max(1, consumed), None, fault)


@dataclass(slots=True)
class DecoderStatistics:
    """Counters every decoder keeps; they surface in component health."""

    frames: int = 0
    checksum_failures: int = 0
    malformed: int = 0
    resyncs: int = 0  # times the decoder had to skip bytes to find a frame again
    bytes_skipped: int = 0
    bytes_in: int = 0

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


class StreamDecoder(ABC, Generic[M]):
    """Accumulates bytes and yields decoded messages; never raises on bad input.

    Subclasses implement :meth:`scan`. ``max_buffer`` bounds memory: if the buffer grows
    beyond it without a frame, the oldest bytes are dropped and counted as skipped.
    """

    def __init__(self, *, max_buffer: int = 1 << 16) -> None:
        self._buffer = bytearray()
        self._max_buffer = max_buffer
        self._skipping = False
        self.stats = DecoderStatistics()

    @abstractmethod
    def scan(self, buffer: bytearray) -> Scan[M]:
        """Look at the front of ``buffer`` (never mutate it) and say what is there."""

    def feed(self, data: bytes) -> list[M]:
        """Add ``data`` and return every message completed by it, in order."""
        self.stats.bytes_in += len(data)
        self._buffer += data
        messages: list[M] = []
        buffer = self._buffer
        while buffer:
            result = self.scan(buffer)
            if result.consumed == 0:
                break
            del buffer[: result.consumed]
            if result.fault is None:
                self._skipping = False
                self.stats.frames += 1
                messages.append(result.message)  # type: ignore[arg-type]
                continue
            self._count_fault(result.fault, result.consumed)
        if len(buffer) > self._max_buffer:
            excess = len(buffer) - self._max_buffer
            del buffer[:excess]
            self._count_fault(Fault.OVERFLOW, excess)
        return messages

    def _count_fault(self, fault: Fault, n: int) -> None:
        self.stats.bytes_skipped += n
        if fault is Fault.CHECKSUM:
            self.stats.checksum_failures += 1
        elif fault is Fault.MALFORMED:
            self.stats.malformed += 1
        if not self._skipping or fault is not Fault.GARBAGE:
            self.stats.resyncs += 1
        self._skipping = fault is Fault.GARBAGE

    @property
    def buffered(self) -> int:
        """Bytes held waiting for the rest of a frame."""
        return len(self._buffer)

    def reset(self) -> None:
        """Forget buffered bytes (after a reconnect); statistics are kept."""
        self._buffer.clear()
        self._skipping = False
