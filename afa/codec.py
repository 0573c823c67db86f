"""Sans-I/O byte codecs: the pure half of every device driver.

A device driver is two layers (see ``docs/architecture.md``): a codec that turns bytes
into messages and messages into bytes, with no asyncio and no I/O, tested with byte
literals; and an async driver (:mod:`afa.reactor`) that moves bytes between a
:class:`~afa.transport.ByteStream` and the codec.

:class:`StreamDecoder` owns the buffering, resynchronisation and statistics; a concrete
decoder implements one hook, :meth:`StreamDecoder.scan`, which looks at the front of the
buffer and says what is there.

Cost. Decoding must stay linear in the bytes fed, whatever they are (line noise, a
hostile or broken device), because every read runs on the event loop. The contract that
keeps it so:

- ``feed`` calls ``scan`` at most once per byte consumed plus once per read;
- a scan that waits (``Scan.need_more``) for the end of a delimited frame says how far it
  searched (``searched=``) and resumes there on the next read (:attr:`StreamDecoder.
  searched`), so a frame arriving byte by byte is searched once, not once per read;
- a skip after a bad frame goes only to the next possible frame start, and finding that
  start costs no more than the bytes it skips;
- a frame may not contain the start of another frame of its own kind where the protocol
  can tell (each decoder documents how), so false frame starts cannot nest and each byte
  is checked against a bounded number of candidate frames.

Consuming a frame deletes it from the front of a ``bytearray``; CPython does that in
amortised O(1) time (it moves the array's start, bpo-19087), so ``feed`` is not
quadratic in a large buffer even when it skips byte by byte. ``tests/components/
test_decoder_hardening.py`` counts the work of every decoder on hostile streams.
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

    - ``Scan.need_more(searched=k)``: the front may be the start of a frame; wait for more
      bytes. ``k`` (optional) is how far the scan searched for the frame's end without
      finding it: the next scan of the same front may resume there (see
      :attr:`StreamDecoder.searched`).
    - ``Scan.frame(n, message)``: the first ``n`` bytes are one valid frame.
    - ``Scan.skip(n, fault)``: drop the first ``n`` bytes (n >= 1) and count the fault.
      To resynchronise after a bad frame, skip only up to the next possible sync byte
      (often 1 byte), so a valid frame hidden inside garbage is never lost.
    """

    consumed: int
    message: M | None = None
    fault: Fault | None = None
    searched: int = 0

    @staticmethod
    def need_more(searched: int = 0) -> Scan[M]:
        return Scan(0, searched=searched)

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
        self._searched = 0
        self._front = 0  # stream offset of the first buffered byte
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
                self._searched = min(result.searched, len(buffer))
                break
            del buffer[: result.consumed]  # amortised O(1): see the module docstring
            self._front += result.consumed
            self._searched = 0
            if result.fault is None:
                self._skipping = False
                self.stats.frames += 1
                messages.append(result.message)  # type: ignore[arg-type]
                continue
            self._count_fault(result.fault, result.consumed)
        if len(buffer) > self._max_buffer:
            excess = len(buffer) - self._max_buffer
            del buffer[:excess]
            self._front += excess
            self._searched = 0
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

    @property
    def searched(self) -> int:
        """Where the last scan of the current front stopped searching for the frame's end
        (the ``searched`` of its ``Scan.need_more``), an index into the buffer; 0 when
        the front is new (bytes were consumed since) or the scan gave no resume point.

        A scan that searches for a delimiter starts at ``max(its own start, searched)``,
        so bytes already searched are not searched again on every read.
        """
        return self._searched

    @property
    def front_position(self) -> int:
        """Stream offset of the first buffered byte: every byte fed before it has been
        consumed, skipped or dropped. Lets a decoder recognise a front it has seen."""
        return self._front

    def reset(self) -> None:
        """Forget buffered bytes (after a reconnect); statistics are kept. A decoder that
        keeps state about the stream overrides this and calls ``super().reset()``."""
        self._front += len(self._buffer)
        self._buffer.clear()
        self._skipping = False
        self._searched = 0
