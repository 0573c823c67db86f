"""Reading recordings: finished files through their index, cut-off files by a scan.

:class:`LogReader` opens an MCAP file and says what it found:

- a finished file (footer and summary present): channels, schemas, counts and the chunk
  index come from the summary; reading seeks straight to the chunks it needs;
- a file cut off by a killed process (no summary): one linear scan of the records builds
  the same chunk index, up to the last complete chunk (the last flush); every chunk after
  that point is lost, and :attr:`LogReader.problems` says where the file ends;
- a damaged chunk (bad CRC or frame checksum, undecompressible): its messages are
  skipped with a problem naming the chunk's byte offset and time range; the others are
  read;
- a file that is not MCAP: :class:`LogError` naming the file.

Messages come in time order (log time, then file position) from a merge over the chunks
(:meth:`LogReader.messages`); :meth:`LogReader.latest_before` finds the last message of
each channel before a time by walking the index backwards (what a seek republishes).
Decoding goes through :mod:`idl.wire` only: a message can name a type, never code, and a
type this program does not know, or a newer version of one, is reported once per topic
and skipped.

:func:`recover` rewrites a readable part of any file as a finished one.
"""

from __future__ import annotations

import heapq
import io
import json
import struct
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from afa.errors import AfaError
from afa.events import Event
from afa.log import format as fmt
from afa.log.recorder import load_mcap
from idl import wire

__all__ = ["LogError", "LogReader", "LogChannel", "LogMessage", "ChunkRef", "recover"]

MAGIC = b"\x89MCAP0\r\n"
_RECORD_HEAD = struct.Struct("<BQ")
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 1, 2, 3, 4, 5, 6
_OP_METADATA, _OP_DATA_END = 0x0C, 0x0F
#: A record longer than this is taken as damage, not data.
MAX_RECORD = 1 << 32


# a message record's content: channel id, sequence, log time (then publish time, data)
_MESSAGE_HEAD = struct.Struct("<HIQ")
_MESSAGE_HEAD_SIZE = _MESSAGE_HEAD.size + 8
_CHUNK_HEAD = struct.Struct("<QQQII")  # start, end, uncompressed size and CRC, len(compression)


def _chunk_content(content: bytes, validate_crc: bool) -> bytes:
    """The uncompressed records of a chunk record's content (MCAP: start and end time,
    uncompressed size, CRC, compression, records). Raises ValueError (or the
    decompressor's error) for a damaged chunk."""
    _, _, size, crc, n = _CHUNK_HEAD.unpack_from(content)
    at = _CHUNK_HEAD.size
    compression = content[at:at + n].decode()
    at += n
    (length,) = struct.unpack_from("<Q", content, at)
    at += 8
    if at + length > len(content):
        raise ValueError(f"its records claim {length} bytes, {len(content) - at} present")
    data = content[at:at + length]
    if compression == "zstd":
        import zstandard

        records = zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    elif compression == "lz4":
        import lz4.frame

        records = lz4.frame.decompress(data)
    elif compression == "":
        records = data
    else:
        raise ValueError(f"unknown compression {compression!r}")
    if len(records) != size:
        raise ValueError(f"{len(records)} bytes uncompressed, {size} expected")
    if validate_crc and crc != 0 and zlib.crc32(records) != crc:
        raise ValueError("the uncompressed records fail their CRC")
    return records


class LogError(AfaError, ValueError):
    """A file that cannot be read as a recording at all (the message names the file)."""


@dataclass(frozen=True)
class LogChannel:
    """One channel of a recording."""

    id: int
    topic: str
    encoding: str  #: message encoding: afa-event, afa-wire, json, protobuf
    schema: str  #: schema name: a versioned IDL type name, or a Foxglove schema
    metadata: dict[str, str] = field(default_factory=dict, compare=False)

    @property
    def kind(self) -> str:
        """event, poll, dropped or viewer (afa.log.format)."""
        return self.metadata.get(fmt.KIND, fmt.VIEWER if self.encoding == "json" else "")

    @property
    def event(self) -> str:
        """The event name of an event channel."""
        return self.metadata.get("afa.event", self.topic.rpartition("/")[2])


@dataclass(frozen=True, slots=True)
class LogMessage:
    channel: LogChannel
    log_time: int  #: nanoseconds since the epoch
    data: bytes
    sequence: int = 0

    @property
    def time(self) -> float:
        return fmt.from_ns(self.log_time)


@dataclass
class ChunkRef:
    """Where one chunk lies and what it holds."""

    offset: int
    length: int
    start: int
    end: int
    channels: frozenset[int] | None = None  #: None: unknown (read it to see)


class LogReader:
    """An open recording (see the module docstring). Use as a context manager.

    Raises :class:`LogError` for a file that is missing, empty or not MCAP.
    """

    def __init__(self, path: str | Path, *, validate_crcs: bool = True) -> None:
        load_mcap()
        self.path = Path(path)
        self.validate_crcs = validate_crcs
        self.problems: list[str] = []
        self.channels: dict[int, LogChannel] = {}
        self.schemas: dict[int, tuple[str, str, bytes]] = {}  # id -> (name, encoding, data)
        self.metadata: dict[str, dict[str, str]] = {}
        self.counts: dict[int, int] = {}
        self.chunks: list[ChunkRef] = []
        self.indexed = False
        self.library = ""
        self.profile = ""
        self._undecodable: dict[int, str] = {}
        try:
            self._file: IO[bytes] = open(self.path, "rb")  # noqa: SIM115 - closed in close()
        except OSError as exc:
            raise LogError(f"{self.path}: cannot open: {exc.strerror or exc}") from None
        try:
            self._open()
        except BaseException:
            self._file.close()
            raise

    # -- opening -----------------------------------------------------------------------------
    def _open(self) -> None:
        f = self._file
        head = f.read(len(MAGIC))
        if not head:
            raise LogError(f"{self.path}: the file is empty (not an MCAP recording)")
        if head != MAGIC:
            raise LogError(f"{self.path}: not an MCAP file (it starts with {head[:8]!r}; an "
                           f"MCAP file starts with {MAGIC!r})")
        size = f.seek(0, io.SEEK_END)
        f.seek(max(0, size - len(MAGIC)))
        if f.read(len(MAGIC)) == MAGIC and size > 2 * len(MAGIC):
            try:
                self._open_indexed()
                return
            except Exception as exc:  # a damaged summary: fall back to the scan
                self.problems.append(f"{self.path}: the index is unreadable "
                                     f"({type(exc).__name__}: {exc}); "
                                     "reading the file linearly")
                self.channels.clear()
                self.chunks.clear()
        else:
            self.problems.append(
                f"{self.path}: the file has no index (the recording was cut off, e.g. a killed "
                "process): reading it linearly up to its last complete chunk; "
                "`afa log recover` rewrites it whole")
        self._scan()

    def _open_indexed(self) -> None:
        from mcap.reader import SeekingReader

        self._file.seek(0)
        reader = SeekingReader(self._file, validate_crcs=False)
        header = reader.get_header()
        self.library, self.profile = header.library, header.profile
        summary = reader.get_summary()
        if summary is None:
            raise ValueError("the footer points to no summary")
        for schema in summary.schemas.values():
            self.schemas[schema.id] = (schema.name, schema.encoding, bytes(schema.data))
        for channel in summary.channels.values():
            self._add_channel(channel)
        if summary.statistics is not None:
            self.counts = dict(summary.statistics.channel_message_counts)
        for index in summary.chunk_indexes:
            ref = ChunkRef(index.chunk_start_offset, index.chunk_length,
                           index.message_start_time, index.message_end_time,
                           frozenset(index.message_index_offsets))
            problem = self._check_index_entry(ref)
            if problem is None:
                self.chunks.append(ref)
            else:
                self.problems.append(f"{self.path}: {problem}; that chunk is not read")
        for record in reader.iter_metadata():
            self.metadata[record.name] = dict(record.metadata)
        self.chunks.sort(key=lambda c: (c.start, c.offset))
        self.indexed = True

    def _check_index_entry(self, ref: ChunkRef) -> str | None:
        """What is wrong with a chunk index entry (None: a chunk record of its length and
        times begins at its offset). A damaged entry would place data wrongly, hide it,
        or have a read trust a length the file never held."""
        f = self._file
        f.seek(ref.offset)
        head = f.read(_RECORD_HEAD.size + 16)
        if len(head) < _RECORD_HEAD.size + 16:
            return f"a chunk index entry points past the end (byte {ref.offset})"
        opcode, length = _RECORD_HEAD.unpack_from(head)
        start, end = struct.unpack_from("<QQ", head, _RECORD_HEAD.size)
        if (opcode, _RECORD_HEAD.size + length, start, end) != (_OP_CHUNK, ref.length,
                                                                 ref.start, ref.end):
            return (f"the chunk index entry for byte {ref.offset} does not match the record "
                    f"there (opcode {opcode}, {length} bytes)")
        return None

    def _scan(self) -> None:
        """One pass over the records: the chunk index, channels, counts, metadata."""
        from mcap.data_stream import ReadDataStream
        from mcap.records import Header, Metadata

        f = self._file
        f.seek(len(MAGIC))
        offset = len(MAGIC)
        while True:
            head = f.read(_RECORD_HEAD.size)
            if not head:
                break
            if len(head) < _RECORD_HEAD.size:
                self._cut(offset, "in a record header")
                break
            opcode, length = _RECORD_HEAD.unpack(head)
            if length > MAX_RECORD:
                self._cut(offset, f"a record claims {length} bytes")
                break
            content = f.read(length)
            if len(content) < length:
                self._cut(offset, f"in a record of {length} bytes")
                break
            stream = ReadDataStream(io.BytesIO(content))
            try:
                if opcode == _OP_CHUNK:
                    self._scan_chunk(offset, _RECORD_HEAD.size + length, content)
                elif opcode == _OP_METADATA:
                    record = Metadata.read(stream)
                    self.metadata[record.name] = dict(record.metadata)
                elif opcode == _OP_HEADER:
                    header = Header.read(stream)
                    self.library, self.profile = header.library, header.profile
                elif opcode in (_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE):
                    self.problems.append(f"{self.path}: byte {offset}: a record outside a "
                                         "chunk is skipped (afa writes chunked files)")
                elif opcode in (_OP_DATA_END, _OP_FOOTER):
                    break
            except Exception as exc:
                self.problems.append(f"{self.path}: byte {offset}: a damaged record "
                                     f"(opcode {opcode:#x}) is skipped: {exc}")
            offset += _RECORD_HEAD.size + length
        self.chunks.sort(key=lambda c: (c.start, c.offset))

    def _cut(self, offset: int, where: str) -> None:
        self.problems.append(f"{self.path}: the file ends at byte {offset} {where} (cut off "
                             "while writing); everything before it is read")

    def _scan_chunk(self, offset: int, length: int, content: bytes) -> None:
        records = self._chunk_records(offset, content)
        if records is None:
            return
        seen: set[int] = set()
        start, end = None, None
        for record in records:
            if isinstance(record, tuple):
                channel_id, log_time = record[0], record[1]
                seen.add(channel_id)
                self.counts[channel_id] = self.counts.get(channel_id, 0) + 1
                start = log_time if start is None else min(start, log_time)
                end = log_time if end is None else max(end, log_time)
        if start is not None and end is not None:
            self.chunks.append(ChunkRef(offset, length, start, end, frozenset(seen)))

    def _chunk_records(self, offset: int, content: bytes,
                       wanted: frozenset[int] | None = None) -> list[Any] | None:
        """The messages of a chunk record's content as (channel, log_time, data, seq),
        only those of ``wanted`` channels (None: all), registering its schemas and
        channels; None (and a problem) if it is damaged.

        Messages, nearly every record, are parsed here with one ``struct`` call each
        and the data of an unwanted channel is never copied (a replay reads a few of a
        recording's channels; the viewer channels are half its bytes); schemas and
        channels go through the ``mcap`` package's record parser."""
        try:
            records = _chunk_content(content, self.validate_crcs)
        except Exception as exc:
            times = ""
            if len(content) >= 16:
                start, end = struct.unpack_from("<QQ", content)
                times = f" ({fmt.from_ns(start):.3f}-{fmt.from_ns(end):.3f} s)"
            self.problems.append(f"{self.path}: the chunk at byte {offset}{times} is damaged "
                                 f"({type(exc).__name__}: {exc}); its messages are skipped")
            return None
        out: list[Any] = []
        position, size = 0, len(records)
        unpack_head, unpack_message = _RECORD_HEAD.unpack_from, _MESSAGE_HEAD.unpack_from
        try:
            while position < size:
                opcode, length = unpack_head(records, position)
                body = position + _RECORD_HEAD.size
                position = body + length
                if position > size:
                    raise ValueError(f"a record of {length} bytes runs past the chunk's end")
                if opcode == _OP_MESSAGE:
                    channel_id, sequence, log_time = unpack_message(records, body)
                    if wanted is None or channel_id in wanted:
                        out.append((channel_id, log_time,
                                    records[body + _MESSAGE_HEAD_SIZE:position], sequence))
                elif opcode in (_OP_SCHEMA, _OP_CHANNEL):
                    self._chunk_definition(opcode, records[body:position])
        except Exception as exc:
            self.problems.append(f"{self.path}: the chunk at byte {offset} is damaged after "
                                 f"{len(out)} message(s) ({type(exc).__name__}: {exc}); "
                                 "the rest of it is skipped")
        return out

    def _chunk_definition(self, opcode: int, content: bytes) -> None:
        from mcap.data_stream import ReadDataStream
        from mcap.records import Channel, Schema

        stream = ReadDataStream(io.BytesIO(content))
        if opcode == _OP_SCHEMA:
            schema = Schema.read(stream)
            self.schemas.setdefault(schema.id, (schema.name, schema.encoding,
                                                bytes(schema.data)))
        else:
            channel = Channel.read(stream)
            if channel.id not in self.channels:
                self._add_channel(channel)

    def _add_channel(self, channel: Any) -> None:
        schema = self.schemas.get(channel.schema_id, ("", "", b""))
        self.channels[channel.id] = LogChannel(channel.id, channel.topic,
                                               channel.message_encoding, schema[0],
                                               dict(channel.metadata))

    # -- reading -----------------------------------------------------------------------------
    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> LogReader:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    @property
    def start(self) -> int:
        """Log time of the first message (ns; 0 for an empty recording)."""
        return min((c.start for c in self.chunks), default=0)

    @property
    def end(self) -> int:
        return max((c.end for c in self.chunks), default=0)

    @property
    def duration(self) -> float:
        return fmt.from_ns(self.end - self.start)

    def topics(self, kind: str | None = None) -> list[LogChannel]:
        return sorted((c for c in self.channels.values() if kind is None or c.kind == kind),
                      key=lambda c: (c.topic, c.id))

    def _load(self, ref: ChunkRef, wanted: frozenset[int] | None = None) -> list[Any]:
        f = self._file
        # a ref's record was checked when the file was opened (_check_index_entry, or
        # _scan, which made the ref from it): a chunk record of ref.length bytes
        f.seek(ref.offset + _RECORD_HEAD.size)
        content = f.read(ref.length - _RECORD_HEAD.size)
        if len(content) < ref.length - _RECORD_HEAD.size:
            self.problems.append(f"{self.path}: the chunk at byte {ref.offset} is missing")
            return []
        records = self._chunk_records(ref.offset, content, wanted)
        return [] if records is None else records

    def messages(self, start: int | None = None, end: int | None = None,
                 channels: Iterable[int] | None = None) -> Iterator[LogMessage]:
        """Messages with ``start <= log_time < end`` (ns) on ``channels`` (ids; None:
        all), in time order."""
        wanted = None if channels is None else frozenset(channels)
        refs = [c for c in self.chunks
                if (start is None or c.end >= start) and (end is None or c.start < end)
                and (wanted is None or c.channels is None or c.channels & wanted)]
        heap: list[tuple[int, int, int, Any]] = []
        position = 0
        while position < len(refs) or heap:
            while position < len(refs) and (not heap or refs[position].start <= heap[0][0]):
                ref = refs[position]
                position += 1
                for index, record in enumerate(self._load(ref, wanted)):
                    log_time = record[1]
                    if (start is not None and log_time < start) or (
                            end is not None and log_time >= end):
                        continue
                    heapq.heappush(heap, (log_time, ref.offset, index, record))
            if heap:
                log_time, _, _, record = heapq.heappop(heap)
                channel = self.channels.get(record[0])
                if channel is not None:
                    yield LogMessage(channel, log_time, record[2], record[3])

    def latest_before(self, time: int, channels: Iterable[int]) -> dict[int, LogMessage]:
        """The last message of each of ``channels`` with ``log_time < time`` (ns)."""
        missing = set(channels)
        found: dict[int, LogMessage] = {}
        for ref in sorted((c for c in self.chunks if c.start < time),
                          key=lambda c: (c.end, c.offset), reverse=True):
            if not missing:
                break
            if ref.channels is not None and not (ref.channels & missing):
                continue
            best: dict[int, tuple[int, Any]] = {}
            for record in self._load(ref, frozenset(missing)):
                channel_id, log_time = record[0], record[1]
                if channel_id in missing and log_time < time:
                    if channel_id not in best or log_time >= best[channel_id][0]:
                        best[channel_id] = (log_time, record)
            for channel_id, (log_time, record) in best.items():
                found[channel_id] = LogMessage(self.channels[channel_id], log_time,
                                               record[2], record[3])
                missing.discard(channel_id)
        return found

    # -- decoding ----------------------------------------------------------------------------
    def decode_event(self, message: LogMessage) -> Event | None:
        """The event a message holds, or None (reported once per topic) if it cannot be
        decoded."""
        channel = message.channel
        if channel.id in self._undecodable:
            return None
        if channel.encoding != fmt.EVENT_ENCODING:
            self._refuse(channel, f"message encoding {channel.encoding!r} is not "
                                  f"{fmt.EVENT_ENCODING!r}")
            return None
        try:
            return Event.decode(message.data)
        except wire.WireError as exc:
            self._refuse(channel, str(exc))
            return None

    def decode_wire(self, message: LogMessage) -> Any:
        """The IDL model of an ``afa-wire`` message (a poll record, a drop count), or
        None (reported once per topic)."""
        channel = message.channel
        if channel.id in self._undecodable:
            return None
        try:
            return wire.decode(message.data)
        except wire.WireError as exc:
            self._refuse(channel, str(exc))
            return None

    def _refuse(self, channel: LogChannel, why: str) -> None:
        count = self.counts.get(channel.id)
        self._undecodable[channel.id] = why
        what = channel.schema or "no schema"
        skipped = f"its {count} messages are" if count is not None else "its messages are"
        self.problems.append(f"{self.path}: topic {channel.topic} ({what}) cannot be read: "
                             f"{why}; {skipped} skipped")

    def catalog(self) -> list[dict[str, Any]]:
        """The recorded system's ports (component, direction, name, types), if recorded."""
        text = self.metadata.get(fmt.META_CATALOG, {}).get("ports")
        try:
            ports = json.loads(text) if text else []
        except ValueError:
            self.problems.append(f"{self.path}: the recorded catalog is not JSON; ignored")
            return []
        return ports if isinstance(ports, list) else []


def recover(source: str | Path, target: str | Path, *, compression: str = "zstd") -> int:
    """Rewrite what can be read of ``source`` (cut off, damaged or whole) as a finished
    file ``target`` with its index. Returns the number of messages written. Raises
    LogError if ``source`` is not MCAP at all."""
    mcap = load_mcap()
    kinds = {"zstd": mcap.writer.CompressionType.ZSTD, "lz4": mcap.writer.CompressionType.LZ4,
             "none": mcap.writer.CompressionType.NONE}
    with LogReader(source) as reader, open(target, "wb") as out:
        writer = mcap.writer.Writer(out, compression=kinds[compression])
        writer.start(profile=reader.profile or fmt.PROFILE, library=reader.library or "afa")
        schema_ids: dict[int, int] = {}
        channel_ids: dict[int, int] = {}
        written = 0
        for message in reader.messages():
            channel = message.channel
            target_channel = channel_ids.get(channel.id)
            if target_channel is None:
                schema_id = 0
                for key, (name, encoding, data) in reader.schemas.items():
                    if name == channel.schema:
                        if key not in schema_ids:
                            schema_ids[key] = writer.register_schema(name, encoding, data)
                        schema_id = schema_ids[key]
                        break
                target_channel = channel_ids[channel.id] = writer.register_channel(
                    channel.topic, channel.encoding, schema_id, channel.metadata)
            writer.add_message(target_channel, message.log_time, message.data,
                               message.log_time, message.sequence)
            written += 1
        for name, values in reader.metadata.items():
            writer.add_metadata(name, values)
        writer.add_metadata("afa.recovered", {"from": str(Path(source).resolve()),
                                              "messages": str(written),
                                              "problems": json.dumps(reader.problems)})
        writer.finish()
    return written
