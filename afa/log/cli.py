"""The log commands: ``afa run --record``, ``afa replay``, ``afa log info|echo|recover``.

Parser entries live in :mod:`afa.cli`; the work is here. Command-line code: it may print,
call ``asyncio.run`` and read the wall clock.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import sys
import time
from collections.abc import AsyncIterator, Iterator
from typing import Any

import numpy as np

from afa.errors import AfaError
from afa.log import format as fmt
from afa.log import protobuf
from afa.log.reader import LogChannel, LogError, LogReader
from afa.log.reader import recover as recover_file
from afa.log.recorder import Recorder

__all__ = ["start_recording", "replay", "info", "echo", "recover"]

EXIT_OK, EXIT_FAILURE, EXIT_INVALID, EXIT_DIVERGED = 0, 1, 2, 3


def _names(text: str | None) -> list[str]:
    return [n.strip() for n in (text or "").split(",") if n.strip()]


# -- afa run --record -----------------------------------------------------------------------
def start_recording(args: argparse.Namespace, system: Any, simulation: Any) -> Recorder:
    """The recorder ``afa run --record`` attaches before the system starts."""
    metadata: dict[str, Any] = {"command": " ".join(sys.argv)}
    if simulation is not None:
        metadata.update(world=simulation.world.name, seed=simulation.seed,
                        world_file=str(getattr(simulation.world, "path", "") or ""))
    patterns = _names(args.record_events) or None
    recorder = Recorder(args.record, events=patterns, compression=args.record_compression,
                        viewer=not args.record_no_viewer)
    return recorder.attach(system, metadata=metadata)


# -- afa log info -----------------------------------------------------------------------------
def _summary(reader: LogReader) -> dict[str, Any]:
    duration = reader.duration
    afa = reader.metadata.get(fmt.META_AFA, {})
    end = reader.metadata.get(fmt.META_END, {})
    dropped: dict[str, Any] = {}
    for key in ("events_dropped", "polls_dropped"):
        if key in end:
            dropped[key] = json.loads(end[key])
    drop_channels = [c.id for c in reader.topics(fmt.DROPPED)]
    if drop_channels:
        last = reader.latest_before(reader.end + 1, drop_channels)
        for message in last.values():
            body = reader.decode_wire(message)
            if isinstance(body, fmt.DroppedIDL):
                dropped.update(events_dropped=body.events, polls_dropped=body.polls,
                               dropped_by_type=dict(body.by_type))

    def rows(kind: str) -> list[dict[str, Any]]:
        out = []
        for channel in reader.topics(kind):
            count = reader.counts.get(channel.id, 0)
            out.append({"topic": channel.topic, "type": channel.schema, "count": count,
                        "rate_hz": round(count / duration, 3) if duration > 0 else None})
        return out

    return {
        "file": str(reader.path), "indexed": reader.indexed, "library": reader.library,
        "start": fmt.from_ns(reader.start), "end": fmt.from_ns(reader.end),
        "duration_s": round(duration, 6), "messages": sum(reader.counts.values()),
        "chunks": len(reader.chunks),
        "metadata": {k: v for k, v in afa.items()},
        "config": reader.metadata.get(fmt.META_CONFIG, {}).get("path"),
        "events": rows(fmt.EVENT), "polls": rows(fmt.POLL), "viewer": rows(fmt.VIEWER),
        "statistics": rows(fmt.STATISTICS),
        "dropped": dropped or {"events_dropped": 0, "polls_dropped": 0},
        "problems": list(reader.problems),
    }


def info(args: argparse.Namespace) -> int:
    try:
        with LogReader(args.file) as reader:
            summary = _summary(reader)
    except LogError as exc:
        print(f"afa log info: {exc}", file=sys.stderr)
        return EXIT_INVALID
    if args.json:
        print(json.dumps(summary, indent=2))
        return EXIT_OK
    meta = summary["metadata"]
    print(f"{summary['file']}: {summary['messages']} messages in {summary['chunks']} chunks, "
          f"{summary['duration_s']:.3f} s{'' if summary['indexed'] else ' (no index: cut off)'}")
    print(f"  recorded {meta.get('start_time', '?')} by {summary['library'] or '?'}; clock "
          f"{meta.get('clock', '?')}" + (f"; world {meta['world']} seed {meta.get('seed')}"
                                         if "world" in meta else ""))
    if summary["config"]:
        print(f"  configuration {summary['config']}")
    for title, key in (("events", "events"), ("polls", "polls"), ("viewer channels", "viewer"),
                       ("the Launcher's table (afa top --log)", "statistics")):
        if summary[key]:
            print(f"{title}:")
            for row in summary[key]:
                rate = "" if row["rate_hz"] is None else f"{row['rate_hz']:9.3f} Hz"
                print(f"  {row['topic']:48s} {row['type']:40s} {row['count']:8d} {rate}")
    dropped = summary["dropped"]
    print(f"dropped: {dropped.get('events_dropped', 0)} event(s), "
          f"{dropped.get('polls_dropped', 0)} poll(s)"
          + (f" ({dropped['dropped_by_type']})" if dropped.get("dropped_by_type") else ""))
    for problem in summary["problems"]:
        print(f"warning: {problem}", file=sys.stderr)
    return EXIT_OK


# -- afa log echo -----------------------------------------------------------------------------
def _brief(value: Any) -> Any:
    """A readable form: arrays as dtype and shape (first values if small)."""
    from idl._base import IDLModel

    if isinstance(value, IDLModel):
        return {name: _brief(getattr(value, name)) for name in type(value).model_fields}
    if isinstance(value, np.ndarray):
        if value.size <= 16:
            return value.tolist()
        return f"<{value.dtype} array {'x'.join(map(str, value.shape))}>"
    if isinstance(value, (list, tuple)):
        return [_brief(v) for v in value]
    if isinstance(value, float) and not np.isfinite(value):
        return str(value)
    return value


def _find(reader: LogReader, topic: str) -> list[LogChannel]:
    found = [c for c in reader.channels.values()
             if c.topic == topic or (c.kind == fmt.EVENT and c.event == topic)]
    if not found:
        known = ", ".join(sorted({c.topic for c in reader.channels.values()}))
        raise LogError(f"{reader.path}: no topic {topic!r}; topics: {known}")
    return found


def _echo_lines(reader: LogReader, channels: list[LogChannel], as_json: bool
                ) -> Iterator[str]:
    from afa.log.player import known_interfaces
    from afa.polling import decode_arguments, decode_result

    start = fmt.from_ns(reader.start)
    interfaces = known_interfaces()
    decoders: dict[str, protobuf.Decoder] = {}
    for message in reader.messages(channels=[c.id for c in channels]):
        channel = message.channel
        record: dict[str, Any] = {"t": round(message.time - start, 6), "topic": channel.topic}
        if channel.kind == fmt.EVENT:
            event = reader.decode_event(message)
            if event is None:
                continue
            record.update(time=event.time, seq=event.seq, origin=event.origin,
                          type=channel.schema)
            record["body"] = (json.loads(event.body.to_json()) if as_json
                              else _brief(event.body))
        elif channel.encoding == fmt.JSON_ENCODING:
            record["body"] = json.loads(message.data)
        elif channel.encoding == protobuf.ENCODING:
            try:
                record["body"] = _protobuf_decoder(reader, channel, decoders).decode(
                    channel.schema, message.data)
            except ValueError as exc:
                record["undecodable"] = f"protobuf: {exc}"
        else:
            body = reader.decode_wire(message)
            if body is None:
                continue
            if isinstance(body, fmt.PollCallIDL):
                interface = interfaces.get(body.interface)
                record.update(caller=body.caller, server=body.server, method=body.method)
                try:
                    if interface is None:
                        raise AfaError(f"unknown interface {body.interface}")
                    arguments = decode_arguments(interface, body.method, bytes(body.arguments))
                    record["arguments"] = {k: _jsonable(v, as_json)
                                           for k, v in arguments.items()}
                    if body.error_kind:
                        record["error"] = f"{body.error_kind}: {body.error_message}"
                    else:
                        record["result"] = _jsonable(decode_result(
                            interface, body.method, bytes(body.result)), as_json)
                except AfaError as exc:
                    record["undecodable"] = str(exc)
            else:
                record["body"] = json.loads(body.to_json()) if as_json else _brief(body)
        yield json.dumps(record) if as_json else _text(record)


def _protobuf_decoder(reader: LogReader, channel: LogChannel,
                      decoders: dict[str, protobuf.Decoder]) -> protobuf.Decoder:
    """The decoder of a protobuf channel's schema (its FileDescriptorSet), made once."""
    decoder = decoders.get(channel.schema)
    if decoder is None:
        data = next((data for name, encoding, data in reader.schemas.values()
                     if name == channel.schema and encoding == protobuf.ENCODING), b"")
        decoder = decoders[channel.schema] = protobuf.Decoder(data)
    return decoder


def _jsonable(value: Any, as_json: bool) -> Any:
    from idl._base import IDLModel

    if isinstance(value, IDLModel):
        return json.loads(value.to_json()) if as_json else _brief(value)
    return value


def _text(record: dict[str, Any]) -> str:
    head = f"{record.pop('t'):11.6f} {record.pop('topic')}"
    record.pop("time", None)
    record.pop("type", None)
    return f"{head} {json.dumps(record, default=str)}"


def echo(args: argparse.Namespace) -> int:
    try:
        with LogReader(args.file) as reader:
            for line in _echo_lines(reader, _find(reader, args.topic), args.json):
                print(line)
            for problem in reader.problems:
                print(f"warning: {problem}", file=sys.stderr)
    except LogError as exc:
        print(f"afa log echo: {exc}", file=sys.stderr)
        return EXIT_INVALID
    except BrokenPipeError:  # `afa log echo ... | head`
        return EXIT_OK
    return EXIT_OK


# -- afa log recover ----------------------------------------------------------------------------
def recover(args: argparse.Namespace) -> int:
    try:
        written = recover_file(args.file, args.output)
        with LogReader(args.output) as result:
            duration = result.duration
        with LogReader(args.file) as source:
            problems = source.problems
    except LogError as exc:
        print(f"afa log recover: {exc}", file=sys.stderr)
        return EXIT_INVALID
    for problem in problems:
        print(f"note: {problem}", file=sys.stderr)
    print(f"{args.output}: {written} messages, {duration:.3f} s, recovered from {args.file}")
    return EXIT_OK


# -- afa replay ------------------------------------------------------------------------------
def replay(args: argparse.Namespace) -> int:
    from afa.errors import ConfigError

    speed: float | None
    if args.speed == "max":
        speed = None
    else:
        try:
            speed = float(args.speed)
        except ValueError:
            speed = -1.0
        if not speed > 0:
            print(f"afa replay: --speed takes a positive number or max, not {args.speed!r}",
                  file=sys.stderr)
            return EXIT_INVALID
    try:
        return asyncio.run(_replay(args, speed))
    except (LogError, ConfigError) as exc:
        print(f"afa replay: {exc}", file=sys.stderr)
        return EXIT_INVALID


async def _replay(args: argparse.Namespace, speed: float | None) -> int:
    from afa.log.player import Player, check

    if args.check:
        report = await check(args.file, args.config, only=_names(args.only),
                             skip=_names(args.skip), atol=args.atol)
        print(report.text())
        return EXIT_OK if report.identical else EXIT_DIVERGED
    player = Player(args.file, args.config, speed=speed, start=args.start, end=args.end,
                    loop=args.loop, paused=args.paused, only=_names(args.only),
                    skip=_names(args.skip))
    print(f"replaying {args.file}: re-running {', '.join(c.name for c in player.rerun) or 'none'}"
          f"; publishing {len({c.event for c in player.replayed.values()})} recorded topic(s); "
          f"answering polls for {', '.join(player.servants) or 'no server'}", file=sys.stderr)
    wall = time.monotonic()
    async with _console(args, player), player:
        with _keyboard(player):
            await player.run()
        replayed = player.elapsed - (args.start or 0.0)
    wall = time.monotonic() - wall
    for problem in player.reader.problems:
        print(f"warning: {problem}", file=sys.stderr)
    print(f"replayed {replayed:.1f} s of {args.file} in {wall:.1f} s "
          f"(x{replayed / wall if wall > 0 else float('inf'):.1f}); "
          f"{player.published} events published")
    return EXIT_OK


@contextlib.asynccontextmanager
async def _console(args: argparse.Namespace, player: Any) -> AsyncIterator[None]:
    """The browser console on the replay (``--console``): its replay pane drives the
    player (afa.console)."""
    if getattr(args, "console", None) is None and not getattr(args, "console_control", False):
        yield
        return
    from afa.console import exposure_warning, from_args

    console = from_args(args, player.system, replay=player)
    assert console is not None
    async with console:
        print(f"afa: console at {console.url}", file=sys.stderr, flush=True)
        warning = exposure_warning(console)
        if warning is not None:
            print(f"afa: warning: {warning}", file=sys.stderr)
        yield


KEYS = {
    " ": "pause / resume", ".": "step one message", "s": "step one second",
    "]": "seek +10 s", "[": "seek -10 s", "+": "speed x2", "-": "speed /2",
    "m": "as fast as possible", "1": "real time", "q": "quit",
}


def press(player: Any, key: str) -> Any:
    """Apply one key of KEYS to ``player``; returns the awaitable to run for keys that
    move the replay (step, seek), else None."""
    if key == " ":
        player.resume() if player.paused else player.pause()
    elif key == ".":
        return player.step()
    elif key == "s":
        return player.step_time(1.0)
    elif key in ("[", "]"):
        return player.seek(max(0.0, player.elapsed + (10 if key == "]" else -10)))
    elif key == "+":
        player.speed = (player.speed or 64.0) * 2
    elif key == "-":
        player.speed = (player.speed or 64.0) / 2
    elif key == "m":
        player.speed = None
    elif key == "1":
        player.speed = 1.0
    elif key == "q":
        player.finished.set()
    return None


async def _obey(player: Any, keys: asyncio.Queue[str]) -> None:
    """Keys one at a time, each step or seek finished before the next key (a seek must
    not race a step), then the status line."""
    while True:
        key = await keys.get()
        action = press(player, key)
        if action is not None:
            await action
        speed = "max" if player.speed is None else f"x{player.speed:g}"
        print(f"\r[{'paused' if player.paused else 'playing'} {speed} "
              f"t={player.elapsed:8.2f} s]", end="", file=sys.stderr, flush=True)


@contextlib.contextmanager
def _keyboard(player: Any) -> Iterator[None]:
    """Keys on a terminal (see KEYS); nothing when standard input is not one."""
    stdin = sys.stdin
    if not stdin.isatty():
        yield
        return
    import termios
    import tty

    fd = stdin.fileno()
    saved = termios.tcgetattr(fd)
    loop = asyncio.get_running_loop()
    keys: asyncio.Queue[str] = asyncio.Queue()

    def on_key() -> None:
        for key in os.read(fd, 64).decode(errors="replace"):
            keys.put_nowait(key)

    print("keys: " + ", ".join(f"{k!r} {v}" for k, v in KEYS.items()), file=sys.stderr)
    tty.setcbreak(fd, termios.TCSANOW)  # TCSAFLUSH would drop keys typed ahead
    player.system.tasks.spawn(_obey(player, keys), owner="replay keyboard")
    loop.add_reader(fd, on_key)
    try:
        yield
    finally:
        loop.remove_reader(fd)
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
