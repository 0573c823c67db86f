"""Recording a running system into an MCAP file (the seed's LogNotify).

:class:`Recorder` is an *observer* (``system.observe``) with its own bounded buffer: a
publisher never waits for it and nothing it does can fail a publisher. What its buffer
drops is counted and written into the file (``/afa/dropped``, and the ``afa.end``
metadata). It also hears every poll through the poll layer's recording hook; those
records wait in a second bounded buffer and are written by the recorder's own task,
never by the caller.

Events wait in the observer's buffer for up to ``batch_period`` of clock time and are
recorded together (one step of the recorder's task per batch, not per event).

The file is flushed (the open chunk finished and handed to the operating system) every
``flush_period`` seconds of clock time, so a process that is killed leaves a file that
is readable up to its last flush (:class:`afa.log.reader.LogReader` reads such a file
without its index; ``afa log recover`` rewrites it whole).

At each flush it also writes the Launcher's table (``/afa/statistics``: each
component's state, health, restarts, events in and out and loop time), so that ``afa top
--log`` shows a recording as ``afa top`` shows a running system; attached before the
system starts, it turns the loop meter on (:mod:`afa.meter`, about 0.3 µs per task step)
for the loop-time column.

Layout and encodings: :mod:`afa.log.format`; viewer channels: :mod:`afa.log.viewer`.
"""

from __future__ import annotations

import asyncio
import datetime
import json
import logging
import os
import socket
from collections import Counter, deque
from collections.abc import Callable, Iterable, Mapping
from fnmatch import fnmatchcase
from pathlib import Path
from typing import IO, Any

import numpy as np

from afa.bridge.info import components as component_rows
from afa.bridge.info import memory
from afa.errors import AfaError, ComponentError
from afa.events import Event, Overflow
from afa.log import format as fmt
from afa.log.viewer import (
    ENCODINGS,
    TF_TOPIC,
    VEHICLE_FRAME,
    ViewerConverter,
    dumps,
    schema_of,
)
from afa.log.writer import CHUNK_SIZE, COMPRESSIONS, ZSTD_LEVEL, McapWriter
from afa.polling import LocalInvoker, PollRecord, encode_arguments, encode_result, proxy_for
from afa.ports import Direction, interface_name
from afa.tasks import spawn
from idl import Platform, wire
from idl._base import IDLModel, type_name

__all__ = ["Recorder", "COMPRESSIONS", "load_mcap"]

log = logging.getLogger("afa.log")

#: The chunk group of the viewer channels (:class:`afa.log.writer.McapWriter`): their
#: messages are half a recording's bytes and a replay never reads them, so they get
#: chunks of their own that a replay or a seek skips without decompressing.
VIEWER_GROUP = 1
#: How long (s of clock time) the recorder lets events queue before recording them in
#: one step (decision 0034): a step of the observer's task per event cost about as much
#: as recording a small event, and a batch keeps the recorder's code and data in the
#: processor's caches. About 50 events; in a real-time run a pause of a few milliseconds
#: four times a second.
BATCH_PERIOD = 0.25
#: How often the geometry model's transforms are written again (s of clock time), so a
#: viewer that opens the file in the middle finds them.
STATIC_TF_PERIOD = 10.0


def load_mcap() -> Any:
    """The ``mcap`` package, or an AfaError saying how to install it."""
    try:
        import mcap.writer
    except ImportError as exc:  # pragma: no cover - the extra is installed in tests
        raise AfaError("recording and replay need the 'mcap' package: "
                       "pip install 'afa[log]'") from exc
    return mcap


class Recorder:
    """Writes a system's events, polls, statistics and viewer channels to ``path`` (MCAP).

    ``events``: event-name patterns to record (``*``, ``?``, ``[...]``; None: all).
    ``compression``: ``zstd`` (default), ``lz4`` or ``none``; ``level``: the zstd level
    (:data:`afa.log.writer.ZSTD_LEVEL`, 2: decision 0031); ``threaded``: compress chunks
    in a worker thread, off the event loop (decision 0031). ``viewer``: also write the
    Foxglove channels. ``maxsize``: the observer's buffer (events); ``poll_buffer``: the
    poll records' buffer. ``batch_period``: the clock time events wait in that buffer to
    be recorded together (:data:`BATCH_PERIOD`; a flush records them first; 0: each as it
    comes). ``on_flush(count)`` is told the number of events on disk after each flush.

    Raises :class:`~afa.errors.AfaError` for an unknown compression or a file that cannot
    be created.
    """

    def __init__(self, path: str | Path, *, events: Iterable[str] | None = None,
                 compression: str = "zstd", level: int = ZSTD_LEVEL,
                 chunk_size: int = CHUNK_SIZE, threaded: bool = True, viewer: bool = True,
                 flush_period: float = 1.0, maxsize: int = 1 << 16, poll_buffer: int = 4096,
                 batch_period: float = BATCH_PERIOD,
                 on_flush: Callable[[int], None] | None = None) -> None:
        if compression not in COMPRESSIONS:
            raise AfaError(f"unknown compression {compression!r}; use one of "
                           f"{', '.join(COMPRESSIONS)}")
        if not flush_period > 0:
            raise AfaError(f"flush_period must be positive, got {flush_period}")
        self.path = Path(path)
        self.patterns = None if events is None else [p for p in events if p]
        self.compression = compression
        self.level = level
        self.threaded = threaded
        self.chunk_size = chunk_size
        self.viewer = viewer
        self.flush_period = flush_period
        self.batch_period = batch_period
        self.maxsize = maxsize
        self.on_flush = on_flush
        self.events_written = 0
        self.events_flushed = 0  #: events on disk as of the last flush
        self.polls_written = 0
        self.polls_dropped = 0
        self.viewer_written = 0
        self.written: Counter[str] = Counter()
        self.closed = False
        self._polls: deque[PollRecord] = deque()
        self._poll_buffer = poll_buffer
        self._wanted: dict[str, bool] = {}
        self._schemas: dict[str, int] = {}
        self._channels: dict[Any, int] = {}
        self._viewer = ViewerConverter()
        self._file: IO[bytes] | None = None
        self._writer: Any = None  # McapWriter once attached
        self._system: Any = None
        self._observer: Any = None
        self._remove_hook: Callable[[], None] | None = None
        self._flusher: asyncio.Task[None] | None = None
        self._geometry: asyncio.Task[None] | None = None
        self._static_tf: list[dict[str, Any]] = []
        self._static_written_at: float | None = None
        self._frames: set[str] = set()
        self._tf_stale = True  # frames seen that the static transforms may not cover
        self._tf_attempt: float | None = None
        self._dropped_reported = (0, 0)
        self._baseline: Counter[str] = Counter()
        self._start_stamp = 0.0

    # -- lifecycle -----------------------------------------------------------------------
    def attach(self, system: Any, *, metadata: Mapping[str, Any] | None = None) -> Recorder:
        """Open the file and observe ``system`` (before it starts, to see every event
        from the first). ``metadata`` adds entries to the file's ``afa`` record (the
        CLI adds the world and seed of a simulation). Raises AfaError if the file cannot
        be written."""
        load_mcap()  # the replay's reader; recording needs zstandard / lz4 with it
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        except OSError as exc:
            raise AfaError(f"cannot record to {self.path}: {exc.strerror or exc}") from exc
        self._writer = McapWriter(self._file, compression=self.compression,
                                  level=self.level, chunk_size=self.chunk_size,
                                  threaded=self.threaded)
        from afa import __version__

        self._writer.start(profile=fmt.PROFILE, library=f"afa {__version__}")
        self._system = system
        clock = system.clock
        self._start_stamp = clock.now()
        monotonic = clock.monotonic()
        self._baseline = Counter(system.channel.counts())
        info = {
            "version": __version__,
            "start_time": datetime.datetime.fromtimestamp(
                self._start_stamp, datetime.UTC).isoformat(),
            "start_stamp": repr(self._start_stamp),
            "start_monotonic": repr(monotonic),
            "clock": type(clock).__name__,
            # the stamp at monotonic 0: a replay clock starting there stamps as this did
            "clock_origin": repr(getattr(clock, "_start", self._start_stamp - monotonic)),
            "robot": system.robot,
            "events": ",".join(self.patterns) if self.patterns is not None else "*",
            "compression": self.compression,
        }
        info.update({k: str(v) for k, v in (metadata or {}).items()})
        self._writer.add_metadata(fmt.META_AFA, info)
        configuration = getattr(system, "configuration", None)
        if configuration is not None:
            path = Path(configuration.path)
            try:
                text = path.read_text()
            except OSError:
                text = ""
            self._writer.add_metadata(fmt.META_CONFIG, {"path": str(path.resolve()),
                                                        "text": text})
        order = [[name, system.start_delays.get(name, 0.0)] for name in system.components]
        self._writer.add_metadata(fmt.META_CATALOG, {
            "ports": json.dumps(system.catalog().as_dicts()),
            "start_order": json.dumps(order)})
        if getattr(system, "meter", 0) is None:  # loop share per component (afa top --log)
            try:
                system.enable_meter()
            except ComponentError:  # started already (LogNotify): no loop times
                pass
        self._observer = system.observe(self._on_batch, name="recorder", maxsize=self.maxsize,
                                        policy=Overflow.DROP_NEWEST)
        self._remove_hook = system.polls.add_hook(self._on_poll)
        if getattr(system, "_tasks", None) is not None:
            self._start_flusher()
        return self

    async def drain(self) -> None:
        """Write everything queued so far (events and polls)."""
        if self._observer is not None and not self.closed:
            self._drain_queue()
            self._write_polls()

    def _drain_queue(self) -> None:
        """Record every event queued in the observer's buffer."""
        if self._observer is None:
            return
        get = self._observer.subscription.get_nowait
        on_event = self._on_event
        while (event := get()) is not None:
            try:
                on_event(event)
            except Exception as exc:
                self._observer.failed(event, exc)

    async def _on_batch(self, event: Event) -> None:
        """The observer's callback: records ``event`` and everything queued behind it,
        then lets ``batch_period`` of clock time pass, so that one step of the observer's
        task records a batch of events (decision 0034: a task step per event cost more
        than most events' recording)."""
        self._on_event(event)
        self._drain_queue()
        if self.batch_period > 0 and not self.closed:
            await self._system.clock.sleep(self.batch_period)

    async def close(self) -> None:
        """Drain, stop observing, and finish the file (index and summary). Idempotent."""
        if self.closed:
            return
        await self.drain()
        for task in (self._flusher, self._geometry):
            if task is not None and not task.done():
                task.cancel()
        self.finish()

    def finish(self) -> None:
        """Stop observing and finish the file, without awaiting anything: the events
        waiting in the buffer (up to a batch, :data:`BATCH_PERIOD`) and the polls are
        recorded first. Idempotent."""
        if self.closed:
            return
        if self._writer is not None:
            self._drain_queue()
        self.closed = True
        if self._remove_hook is not None:
            self._remove_hook()
        if self._observer is not None:
            self._observer.close()
        try:
            self._write_polls()
            self._report_dropped()
            stats = self.statistics()
            self._writer.add_metadata(fmt.META_END, {k: json.dumps(v) for k, v in stats.items()})
            self._writer.finish()
        finally:
            if self._file is not None:
                self._file.close()

    def statistics(self) -> dict[str, Any]:
        observer = self._observer.statistics() if self._observer is not None else {}
        return {"events": self.events_written, "polls": self.polls_written,
                "viewer_messages": self.viewer_written,
                "events_dropped": observer.get("dropped", 0),
                "polls_dropped": self.polls_dropped,
                "recorder_errors": observer.get("errors", 0),
                "by_type": dict(sorted(self.written.items()))}

    # -- events --------------------------------------------------------------------------
    def _wants(self, event_type: str) -> bool:
        wanted = self._wanted.get(event_type)
        if wanted is None:
            wanted = self._wanted[event_type] = self.patterns is None or any(
                fnmatchcase(event_type, p) for p in self.patterns)
        return wanted

    def _on_event(self, event: Event) -> None:
        if self.closed:
            return
        if self._flusher is None:
            self._start_flusher()
        if self._polls:
            self._write_polls()
        if not self._wants(event.type):
            return
        body = event.body
        key = (event.domain, event.type, type(body))
        channel = self._channels.get(key)
        if channel is None:
            channel = self._channels[key] = self._writer.register_channel(
                fmt.event_topic(event.domain, event.type), fmt.EVENT_ENCODING,
                self._schema(type(body)),
                {fmt.KIND: fmt.EVENT, "afa.domain": event.domain, "afa.event": event.type})
        nanoseconds = fmt.to_ns(event.time)
        self._writer.add_message(channel, nanoseconds, event.encode_parts(), nanoseconds,
                                 event.seq & 0xFFFFFFFF)
        self.events_written += 1
        self.written[event.type] += 1
        if self.viewer:
            self._view(event, nanoseconds)

    def _schema(self, cls: type[IDLModel]) -> int:
        name = type_name(cls)
        schema = self._schemas.get(name)
        if schema is None:
            schema = self._schemas[name] = self._writer.register_schema(
                name, fmt.SCHEMA_ENCODING, json.dumps(wire.schema(cls)).encode())
        return schema

    # -- viewer channels ---------------------------------------------------------------------
    def _view(self, event: Event, nanoseconds: int) -> None:
        try:
            messages = self._viewer.encode(event.type, event.origin, event.body)
        except Exception:  # a viewer channel must never cost the recording
            log.exception("viewer conversion of %s failed (skipped)", event.type)
            return
        frame = getattr(event.body, "frame", None)
        if isinstance(frame, str) and frame not in self._frames:
            self._frames.add(frame)
            self._tf_stale = True
        if self._tf_stale:
            self._static_tf_later()
        for topic, schema, message in messages:
            self._write_json(topic, schema, message, nanoseconds)
        if self._static_tf and self._static_written_at is not None and (
                self._system.clock.monotonic() - self._static_written_at >= STATIC_TF_PERIOD):
            self._write_static_tf(nanoseconds)

    def _write_json(self, topic: str, schema_name: str,
                    message: dict[str, Any] | bytes | list[bytes | memoryview],
                    nanoseconds: int) -> None:
        """A viewer message: a JSON-ready dict, or its encoded bytes (JSON, or protobuf
        as a list of parts, :data:`afa.log.viewer.ENCODINGS`)."""
        key = ("viewer", topic, schema_name)
        channel = self._channels.get(key)
        if channel is None:
            schema = self._schemas.get(schema_name)
            if schema is None:
                schema = self._schemas[schema_name] = self._writer.register_schema(
                    schema_name, *schema_of(schema_name))
            channel = self._channels[key] = self._writer.register_channel(
                topic, ENCODINGS.get(schema_name, fmt.JSON_ENCODING), schema,
                {fmt.KIND: fmt.VIEWER}, group=VIEWER_GROUP)
        self._writer.add_message(channel, nanoseconds,
                                 dumps(message) if isinstance(message, dict) else message,
                                 nanoseconds)
        self.viewer_written += 1

    def _static_tf_later(self) -> None:
        """Ask the geometry model (whoever serves Platform) for every frame's place on
        the vehicle, in a task of the system (a poll must not run in the observer)."""
        if self._geometry is not None and not self._geometry.done():
            return
        now = self._system.clock.monotonic()
        if self._tf_attempt is not None and now - self._tf_attempt < 1.0:
            return  # no Platform server yet: ask again a second later
        self._tf_attempt = now
        try:
            self._geometry = spawn(self._fetch_static_tf(), owner="recorder geometry")
        except RuntimeError:  # not inside a running system
            self._geometry = None

    async def _fetch_static_tf(self) -> None:
        from afa.log.viewer import frame_transform
        from afa.naming import join_name

        system = self._system
        wanted = interface_name(Platform)
        server = next((p.name for p in system.catalog().by(Direction.SERVES)
                       if p.types == (wanted,)), None)
        if server is None:
            return
        # no middleware: the recorder's own polls are not part of the recording
        platform = proxy_for(Platform, LocalInvoker(system.registry,
                                                    join_name(system.robot, server), Platform))
        frames = set(self._frames)
        self._tf_stale = False
        try:
            for body in (await platform.getBodyList()).values:
                for frame in (await platform.getBodyFrameList(body)).values:
                    frames.add(frame if ":" in frame else f"{body}:{frame}")
        except AfaError as exc:
            log.info("recorder: no geometry model for the viewer channels yet: %s", exc)
            self._tf_stale = True
            return
        transforms = []
        for frame in sorted(frames - {VEHICLE_FRAME}):
            try:
                pose = await platform.getTransformation(VEHICLE_FRAME, frame)
            except AfaError:
                continue
            transforms.append(frame_transform(VEHICLE_FRAME, frame, pose.HTransform,
                                              self._start_stamp))
        if transforms and not self.closed:
            self._static_tf = transforms
            self._write_static_tf(fmt.to_ns(system.clock.now()))

    def _write_static_tf(self, nanoseconds: int) -> None:
        for message in self._static_tf:
            self._write_json(TF_TOPIC, "foxglove.FrameTransform", message, nanoseconds)
        self._static_written_at = self._system.clock.monotonic()

    # -- polls ---------------------------------------------------------------------------
    def _on_poll(self, record: PollRecord) -> None:
        if len(self._polls) >= self._poll_buffer:
            self.polls_dropped += 1
            return
        self._polls.append(record)

    def _write_polls(self) -> None:
        while self._polls:
            self._write_poll(self._polls.popleft())

    def _write_poll(self, record: PollRecord) -> None:
        interface = record.interface
        try:
            arguments = encode_arguments(interface, record.method, record.arguments)
            result = b"" if record.error is not None else encode_result(
                interface, record.method, record.result)
        except Exception as exc:  # an unencodable call is noted, never fatal
            arguments, result = b"", b""
            error: tuple[str, str] = ("EncodeError", f"{type(exc).__name__}: {exc}")
        else:
            error = ("", "") if record.error is None else (
                type(record.error).__name__, str(record.error))
        body = fmt.PollCallIDL(
            caller=record.caller, server=record.name, interface=interface_name(interface),
            method=record.method, arguments=np.frombuffer(arguments, np.uint8),
            result=np.frombuffer(result, np.uint8), error_kind=error[0],
            error_message=error[1], duration=record.duration, seq=record.seq)
        key = ("poll", record.name, record.method)
        channel = self._channels.get(key)
        if channel is None:
            channel = self._channels[key] = self._writer.register_channel(
                fmt.poll_topic(record.name, record.method), fmt.WIRE_ENCODING,
                self._schema(fmt.PollCallIDL),
                {fmt.KIND: fmt.POLL, "afa.server": record.name,
                 "afa.interface": interface_name(interface), "afa.method": record.method})
        nanoseconds = fmt.to_ns(record.time)
        # the parts, copied once into the chunk (a getPlanMap result is 4 MB)
        self._writer.add_message(channel, nanoseconds, wire.encode_parts(body), nanoseconds)
        self.polls_written += 1

    # -- flushing and drops --------------------------------------------------------------
    def _start_flusher(self) -> None:
        try:
            self._flusher = spawn(self._flush_periodically(), owner="recorder flush")
        except RuntimeError:
            self._flusher = None

    async def _flush_periodically(self) -> None:
        clock = self._system.clock
        async for _ in clock.periodic(self.flush_period, first=clock.monotonic()
                                      + self.flush_period):
            self.write_statistics()
            self.flush()

    def write_statistics(self) -> None:
        """The Launcher's table as of now, on ``/afa/statistics`` (``afa top --log``):
        per component its state, health, restarts, events in and out and loop time, with
        the process's clock and memory; the fields of the bridge's info document."""
        if self.closed or self._writer is None:
            return
        system = self._system
        clock = system.clock
        meter = system.meter.snapshot() if getattr(system, "meter", None) else None
        document = {
            "robot": system.robot, "process": system.process, "pid": os.getpid(),
            "host": socket.gethostname(),
            "clock": {"kind": type(clock).__name__, "now": clock.now(),
                      "monotonic": clock.monotonic()},
            "components": component_rows(system),
            "loop": None if meter is None else {"wall_s": meter["wall_s"]},
            "memory": memory(),
        }
        key = ("statistics",)
        channel = self._channels.get(key)
        if channel is None:
            channel = self._channels[key] = self._writer.register_channel(
                fmt.STATISTICS_TOPIC, fmt.JSON_ENCODING, 0, {fmt.KIND: fmt.STATISTICS})
        nanoseconds = fmt.to_ns(clock.now())
        self._writer.add_message(channel, nanoseconds, json.dumps(document).encode(),
                                 nanoseconds)

    def flush(self) -> None:
        """Write the queued poll records and the drop counts, finish the open chunk and
        hand everything to the operating system."""
        if self.closed or self._writer is None:
            return
        self._drain_queue()
        self._write_polls()
        self._report_dropped()
        self._writer.flush()
        self.events_flushed = self.events_written
        if self.on_flush is not None:
            self.on_flush(self.events_flushed)

    def _report_dropped(self) -> None:
        if self._observer is None:
            return
        stats = self._observer.subscription.statistics()
        state = (stats.dropped, self.polls_dropped)
        if state == self._dropped_reported:
            return
        self._dropped_reported = state
        by_type: dict[str, int] = {}
        if stats.dropped:
            queued = Counter(e.type for e in self._observer.subscription._queue)
            published = self._system.channel.counts()
            for name, count in published.items():
                if self._wants(name):
                    missing = (count - self._baseline.get(name, 0) - self.written[name]
                               - queued.get(name, 0))
                    if missing > 0:
                        by_type[name] = missing
        body = fmt.DroppedIDL(events=stats.dropped, polls=self.polls_dropped, by_type=by_type)
        key = ("dropped",)
        channel = self._channels.get(key)
        if channel is None:
            channel = self._channels[key] = self._writer.register_channel(
                fmt.DROPPED_TOPIC, fmt.WIRE_ENCODING, self._schema(fmt.DroppedIDL),
                {fmt.KIND: fmt.DROPPED})
        nanoseconds = fmt.to_ns(self._system.clock.now())
        self._writer.add_message(channel, nanoseconds, wire.encode(body), nanoseconds)
        log.warning("recorder %s: %d event(s) and %d poll(s) dropped so far", self.path,
                    stats.dropped, self.polls_dropped)
