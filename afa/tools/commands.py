"""The text utilities (the seed's Table 36, §4.1.2-4.1.3 and nsview), as ``afa``
subcommands that attach to a running system over the bridge or read a recording:

- ``afa echo EVENT [--json] [--count N]``: events as they arrive;
- ``afa hz EVENT``: rate, jitter and gaps;
- ``afa names``: the registry (nsview), with interfaces, owners and processes;
- ``afa poll NAME METHOD [ARGS...]``: one typed poll from the shell;
- ``afa sensor3d stream EVENT`` / ``afa sensor3d get NAME``: range points in the vehicle
  frame (Sensor3dStream, Sensor3dGet);
- ``afa top``: the Launcher's table in the terminal.

Each is an ``async def tool(args) -> exit code``; :func:`run_tool` gives them the common
behaviour: Ctrl-C or SIGTERM ends them cleanly (exit 0), so does a closed pipe, and an
unreachable system or a failed call is one line on standard error (exit 1; 2 for a
command line that cannot be understood).
"""

from __future__ import annotations

import argparse
import asyncio
import bisect
import json
import math
import signal
import sys
import time
from collections import deque
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import TypeAdapter, ValidationError

from afa.errors import AfaError, EDevIO, InterfaceError
from afa.events import Event
from afa.tasks import Scope
from afa.tools.attach import Attachment, Unreachable
from afa.tools.source import LiveSource, LogSource, Source, Unavailable
from afa.tools.text import Output, PipeClosed, brief, event_json, event_line, table
from idl import (
    Range3dArrayEventIDL,
    Range3dLaserIDL,
    Range3dSensor,
    Range3dSeqEventIDL,
    Range3dStereoEventIDL,
)
from idl._base import IDLModel, Interface, MethodSpec

__all__ = ["run_tool", "echo", "hz", "names", "poll", "sensor3d_stream", "sensor3d_get",
           "top", "VEHICLE_FRAME"]

EXIT_OK, EXIT_FAILURE, EXIT_USAGE = 0, 1, 2
#: The Raptor frame range points are printed in (ModelServer's vehicle frame).
VEHICLE_FRAME = "Raptor:RearAxleCenter"

Body = Callable[[Source, Output, argparse.Namespace], Awaitable[int]]


async def run_tool(name: str, args: argparse.Namespace, body: Body) -> int:
    """Run ``body`` against the source ``args`` names, until it returns, Ctrl-C, SIGTERM
    or a closed pipe."""
    out = Output()
    try:
        if getattr(args, "log", None) is None and getattr(args, "at", None) is not None:
            raise InterfaceError("--at T chooses a time in a recording: give --log FILE.mcap")
        if getattr(args, "log", None) is None and getattr(args, "next", False):
            raise InterfaceError("--next steps through a recording: give --log FILE.mcap")
        if getattr(args, "log", None) is not None:
            source = LogSource(Path(args.log))
            try:
                return await _until_signal(body(source, out, args))
            finally:
                source.close()
        async with Attachment(args.connect, robot=args.robot, identity=args.identity) as link:
            await link.require()
            return await _until_signal(body(LiveSource(link), out, args))
    except PipeClosed:
        return EXIT_OK
    except (Unreachable, Unavailable) as exc:
        print(f"afa {name}: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    except InterfaceError as exc:
        print(f"afa {name}: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except AfaError as exc:
        print(f"afa {name}: {type(exc).__name__}: {exc}", file=sys.stderr)
        return EXIT_FAILURE


async def _until_signal(work: Awaitable[int]) -> int:
    """``work``'s exit code, or 0 when SIGINT/SIGTERM arrives first."""
    loop = asyncio.get_running_loop()
    stop = asyncio.Event()
    handled = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            loop.add_signal_handler(sig, stop.set)
            handled.append(sig)
        except (NotImplementedError, RuntimeError):  # pragma: no cover - not Unix
            pass

    async def wrapped() -> int:
        return await work

    try:
        async with Scope() as scope:
            task = scope.spawn(wrapped(), "afa-tool")
            waiter = scope.spawn(stop.wait(), "afa-tool-signal")
            await asyncio.wait([task, waiter], return_when=asyncio.FIRST_COMPLETED)
            if task.done():
                waiter.cancel()
                return task.result()
            task.cancel()
            return EXIT_OK
    except BaseExceptionGroup as group:  # the tool's own error, unwrapped
        from afa.tasks import first_error

        raise first_error(group) from None
    finally:
        for sig in handled:
            loop.remove_signal_handler(sig)


def _warn_unknown_event(source: Source, name: str) -> None:
    if not isinstance(source, LiveSource):
        return
    published = set()
    for info in source.attachment._infos or []:
        published |= set(info.get("event_types", {}))
    if name not in published and "*" not in name:
        print(f"warning: no running process declares the event {name!r} (published: "
              f"{', '.join(sorted(published)) or 'none'}); waiting anyway", file=sys.stderr)


# -- echo --------------------------------------------------------------------------------------
async def echo(args: argparse.Namespace) -> int:
    return await run_tool("echo", args, _echo)


async def _echo(source: Source, out: Output, args: argparse.Namespace) -> int:
    _warn_unknown_event(source, args.event)
    count = 0
    async for event in source.events(args.event):
        out.write(event_json(event) if args.json else event_line(event))
        count += 1
        if args.count and count >= args.count:
            break
    return EXIT_OK


# -- hz ------------------------------------------------------------------------------------------
def rate_report(name: str, stamps: list[float], dropped: int = 0) -> str:
    """Rate, period statistics and gaps of ``stamps`` (seconds of the publisher's clock).
    A gap is an interval longer than 1.5 times the median interval."""
    if len(stamps) < 2:
        return f"{name}: {len(stamps)} event(s), no rate yet"
    intervals = np.diff(np.asarray(stamps, dtype=float))
    span = stamps[-1] - stamps[0]
    rate = (len(stamps) - 1) / span if span > 0 else math.inf
    median = float(np.median(intervals))
    gaps = int(np.count_nonzero(intervals > 1.5 * median)) if median > 0 else 0
    line = (f"{name}: {rate:.3f} Hz  period min {intervals.min():.4f} max "
            f"{intervals.max():.4f} mean {intervals.mean():.4f} std {intervals.std():.5f} s  "
            f"window {len(stamps)}  gaps {gaps}")
    if intervals.min() < 0:
        line += "  (out of order)"
    if dropped:
        line += f"  dropped by this tool {dropped}"
    return line


async def hz(args: argparse.Namespace) -> int:
    return await run_tool("hz", args, _hz)


async def _hz(source: Source, out: Output, args: argparse.Namespace) -> int:
    _warn_unknown_event(source, args.event)
    window: deque[float] = deque(maxlen=args.window)
    if isinstance(source, LogSource):  # the whole recording, one report
        async for event in source.events(args.event):
            window.append(event.time)
        out.write(rate_report(args.event, list(window)))
        return EXIT_OK
    reports = 0
    received = 0

    async def consume() -> None:
        nonlocal received
        async for event in source.events(args.event):
            window.append(event.time)
            received += 1

    link = source.attachment if isinstance(source, LiveSource) else None
    async with Scope() as scope:
        consumer = scope.spawn(consume(), "afa-hz")
        try:
            while not args.count or reports < args.count:
                await asyncio.sleep(args.every)
                inbox = getattr(link, "inbox", None)
                dropped = inbox.dropped if inbox is not None else 0
                out.write(rate_report(args.event, list(window), dropped))
                reports += 1
        finally:
            consumer.cancel()
    return EXIT_OK


# -- names ---------------------------------------------------------------------------------------
async def names(args: argparse.Namespace) -> int:
    return await run_tool("names", args, _names)


async def _names(source: Source, out: Output, args: argparse.Namespace) -> int:
    rows = [row for row in await source.names() if args.all or not row.get("remote")]
    rows.sort(key=lambda row: (row["name"], row["process"]))
    if args.json:
        out.write(json.dumps(rows, indent=2))
        return EXIT_OK
    out.write(table(["NAME", "INTERFACE", "OWNER", "PROCESS"],
                    [[row["name"], row["interface"].rpartition(".")[2], row["owner"] or "-",
                      row["process"] + (" (imported)" if row.get("remote") else "")]
                     for row in rows]))
    return EXIT_OK


# -- poll ----------------------------------------------------------------------------------------
def parse_arguments(spec: MethodSpec, words: list[str], label: str) -> dict[str, Any]:
    """The keyword arguments of ``spec`` from the command line: positional words or
    ``name=value``; each parsed by its annotation (JSON for structures and numbers,
    ``@FILE`` reads a JSON file). Raises InterfaceError with the signature."""
    hints = spec.hints()
    names = spec.parameters
    usage = f"{label}({', '.join(f'{n}: {_type(hints.get(n))}' for n in names)})"
    given: dict[str, str] = {}
    positional = [w for w in words if not _is_keyword(w, names)]
    for word in words:
        if _is_keyword(word, names):
            key, _, value = word.partition("=")
            given[key] = value
    if len(positional) > len(names):
        raise InterfaceError(f"too many arguments; the call is {usage}")
    for name, value in zip(names, positional, strict=False):
        if name in given:
            raise InterfaceError(f"{name} given twice; the call is {usage}")
        given[name] = value
    arguments: dict[str, Any] = {}
    for name in names:
        default = spec.signature.parameters[name].default
        if name not in given:
            if default is spec.signature.empty:
                raise InterfaceError(f"missing argument {name}; the call is {usage}")
            continue
        arguments[name] = _parse(given[name], hints.get(name), name, usage)
    return arguments


def _is_keyword(word: str, names: list[str]) -> bool:
    key, sep, _ = word.partition("=")
    return bool(sep) and key in names


def _type(hint: Any) -> str:
    return getattr(hint, "__name__", None) or str(hint).replace("typing.", "")


def _parse(text: str, hint: Any, name: str, usage: str) -> Any:
    if text.startswith("@"):
        try:
            text = Path(text[1:]).read_text()
        except OSError as exc:
            raise InterfaceError(f"{name}: cannot read {text[1:]}: {exc.strerror}") from None
    if hint is None or hint is str:
        return text
    adapter: TypeAdapter[Any] = TypeAdapter(hint)
    try:
        return adapter.validate_json(text)
    except ValidationError:
        pass
    try:
        return adapter.validate_python(text)
    except ValidationError as exc:
        problem = exc.errors(include_url=False)[0]["msg"]
        raise InterfaceError(f"argument {name}={text!r}: {problem}; the call is "
                             f"{usage}") from None


def _show(result: Any, as_json: bool) -> str:
    if isinstance(result, IDLModel):
        if as_json:
            return result.to_json().decode()
        return f"{type(result).__name__} {brief(result)}"
    if as_json:
        return json.dumps(result)
    return "None (false)" if result is None else str(result)


async def poll(args: argparse.Namespace) -> int:
    return await run_tool("poll", args, _poll)


async def _poll(source: Source, out: Output, args: argparse.Namespace) -> int:
    interface, call = _server(source, args.name, args)
    spec = interface.methods.get(args.method)
    if spec is None:
        raise InterfaceError(f"{interface.__name__} has no method {args.method!r}; it has "
                             f"{', '.join(interface.methods)}")
    arguments = parse_arguments(spec, args.args, f"{args.name}.{args.method}")
    out.write(_show(await call(args.method, arguments), args.json))
    return EXIT_OK


Call = Callable[[str, dict[str, Any]], Awaitable[Any]]


def _server(source: Source, name: str, args: argparse.Namespace
            ) -> tuple[type[Interface], Call]:
    """The interface ``name`` serves and how to call it: over the bridge, or from a
    recording, answered as its replay would at ``--at`` (:mod:`afa.log.answers`)."""
    if isinstance(source, LogSource):
        answers = source.answers(args.at)
        interface = answers.servant(name).interface

        async def recorded(method: str, arguments: dict[str, Any]) -> Any:
            return await answers.call(name, method, arguments)

        return interface, recorded
    assert isinstance(source, LiveSource)
    link = source.attachment
    robot, qualified, known = link.server(name)
    if known is None:
        raise Unavailable(f"{name} serves {qualified}, an interface this program does "
                          "not know")
    served: type[Interface] = known

    async def live(method: str, arguments: dict[str, Any]) -> Any:
        return await link.call(robot, name, served, method, arguments, timeout=args.timeout)

    return served, live


# -- sensor3d ------------------------------------------------------------------------------------
def range_points(body: Any) -> np.ndarray | None:
    """The valid points of a range event or scan, ``(n, 3)`` in its sensor frame."""
    valid_points = getattr(body, "valid_points", None)
    if callable(valid_points):
        return np.asarray(valid_points(), dtype=float)
    points = getattr(body, "points", None)
    if isinstance(points, np.ndarray) and points.ndim == 2 and points.shape[1] == 3:
        return np.asarray(points, dtype=float)
    return None


class _Frames:
    """Transforms from sensor frames into the target frame, asked once per frame."""

    def __init__(self, source: Source, target: str) -> None:
        self.source = source
        self.target = target
        self._cache: dict[str, np.ndarray] = {}

    async def apply(self, frame: str, points: np.ndarray) -> np.ndarray:
        if self.target == "sensor":
            return points
        transform = self._cache.get(frame)
        if transform is None:
            transform = self._cache[frame] = await self.source.transformation(self.target,
                                                                             frame)
        return points @ transform[:3, :3].T + transform[:3, 3]


def _print_points(out: Output, label: str, body: Any, points: np.ndarray, target: str,
                  args: argparse.Namespace) -> None:
    shown = points[::max(1, args.every)]
    if args.max_points:
        shown = shown[:args.max_points]
    out.write(f"# {label} t={body.time.to_seconds():.6f} sensor {body.sensorId} frame "
              f"{body.frame} -> {body.frame if target == 'sensor' else target}: "
              f"{len(points)} points, {len(shown)} shown")
    if len(shown):
        out.write("\n".join(f"{x:.3f} {y:.3f} {z:.3f}" for x, y, z in shown.tolist()))


async def sensor3d_stream(args: argparse.Namespace) -> int:
    return await run_tool("sensor3d stream", args, _stream)


async def _stream(source: Source, out: Output, args: argparse.Namespace) -> int:
    _warn_unknown_event(source, args.event)
    frames = _Frames(source, args.frame)
    count = 0
    async for event in _range_events(source, args.event):
        body: Any = event.body
        points = range_points(body)
        assert points is not None
        _print_points(out, event.type, body, await frames.apply(body.frame, points),
                      args.frame, args)
        count += 1
        if args.count and count >= args.count:
            break
    return EXIT_OK


async def _range_events(source: Source, name: str) -> AsyncIterator[Event]:
    refused = 0
    async for event in source.events(name):
        if range_points(event.body) is None:
            refused += 1
            if refused == 1:
                print(f"warning: {event.type} carries {type(event.body).__name__}, not range "
                      "points; skipped", file=sys.stderr)
            continue
        yield event


#: --form -> the Range3dSensor method (Table 31) and what it answers
FORMS = {"laser": "get3dLaserFullScan", "seq": "get3dSeqFullScan",
         "stereo": "get3dStereoFullScan", "array": "get3dArrayFullScan"}
FORMS_TYPES = {"laser": Range3dLaserIDL, "seq": Range3dSeqEventIDL,
               "stereo": Range3dStereoEventIDL, "array": Range3dArrayEventIDL}


async def sensor3d_get(args: argparse.Namespace) -> int:
    return await run_tool("sensor3d get", args, _get)


async def _get(source: Source, out: Output, args: argparse.Namespace) -> int:
    interface, call = _server(source, args.name, args)
    if not issubclass(interface, Range3dSensor):
        raise InterfaceError(f"{args.name} does not serve Range3dSensor")
    frames = _Frames(source, args.frame)
    forms = [args.form] if args.form != "auto" else ["laser", "stereo"]
    for number in range(max(1, args.count)):
        if isinstance(source, LogSource):
            scan = await _recorded_scan(source, call, args, next_one=args.next or number > 0)
        else:
            scan = await _scan(call, forms)
        points = range_points(scan)
        assert points is not None
        _print_points(out, args.name, scan, await frames.apply(scan.frame, points), args.frame,
                      args)
    return EXIT_OK


async def _recorded_scan(source: LogSource, call: Call, args: argparse.Namespace, *,
                         next_one: bool) -> Any:
    """The recorded scan at ``--at`` (the latest at or before it; if there is none, or
    ``next_one``, the next). A getWait reads the recording on, so the form is found
    first, without waiting: the one the recording answers at ``--at``, else at its end."""
    forms = [args.form] if args.form != "auto" else list(FORMS)
    if not next_one:
        try:
            return await _scan(call, forms)
        except EDevIO:
            pass  # nothing before --at: the next
    if len(forms) > 1:
        at_end = source.answers(None)
        scan = await _scan(lambda method, _: at_end.call(args.name, method, {}), forms)
        forms = [next(form for form in forms if isinstance(scan, FORMS_TYPES[form]))]
    return await call(FORMS[forms[0]].replace("FullScan", "WaitFullScan"), {})


async def _scan(call: Call, forms: list[str]) -> Any:
    """The scan of the first of ``forms`` the sensor answers; the last one's error if
    none does."""
    for form in forms:
        try:
            return await call(FORMS[form], {})
        except EDevIO:
            if form == forms[-1]:
                raise
    raise InterfaceError("no scan form given")


# -- top -----------------------------------------------------------------------------------------
def _megabytes(value: int | None) -> str:
    return f"{value / 1e6:.1f} MB" if value else "-"


class _Shares:
    """Share of the loop's time per component between two refreshes."""

    def __init__(self) -> None:
        self._last: dict[tuple[str, str], tuple[float, float]] = {}

    def share(self, process: str, row: dict[str, Any], wall: float | None) -> str:
        busy = row.get("loop_busy_s")
        if busy is None or wall is None:
            return "-"
        key = (process, row["name"])
        previous = self._last.get(key)
        self._last[key] = (busy, wall)
        if previous is None or wall <= previous[1]:
            value = busy / wall if wall > 0 else 0.0
        else:
            value = (busy - previous[0]) / (wall - previous[1])
        return f"{100 * value:.1f}%"


def _traffic(bridge: dict[str, Any]) -> str:
    """The bridge's line of a process's block in ``afa top``."""
    peers = ", ".join(bridge.get("peers", [])) or "none"
    return (f"  bridge: peers {peers}; events out {sum(bridge.get('exported', {}).values())}"
            f", in {sum(bridge.get('imported', {}).values())}, dropped "
            f"{bridge.get('export_dropped', 0) + bridge.get('import', {}).get('dropped', 0)}"
            f", rejected {sum(bridge.get('rejected', {}).values())}; calls served "
            f"{bridge.get('calls_served', 0)}, refused commands "
            f"{bridge.get('commands_refused', 0)}")


def render_top(infos: list[dict[str, Any]], shares: _Shares) -> str:
    """The Launcher table of every process (``afa top``)."""
    blocks = []
    for info in infos:
        loop = info.get("loop") or {}
        wall = loop.get("wall_s")
        bridge = info.get("bridge") or {}
        memory = info.get("memory") or {}
        clock = info.get("clock") or {}
        busy = sum(row.get("loop_busy_s") or 0.0 for row in info["components"])
        when = (f"t={clock.get('monotonic', 0.0):.1f} s" if clock.get("kind") != "WallClock"
                else time.strftime("%H:%M:%S UTC", time.gmtime(clock.get("now", 0.0))))
        head = (f"{info['robot']}/{info['process']}  pid {info['pid']} on {info['host']}  "
                f"{clock.get('kind', '?')} {when}  memory "
                f"{_megabytes(memory.get('rss_bytes'))} (peak "
                f"{_megabytes(memory.get('peak_rss_bytes'))})  components' loop share "
                f"{100 * busy / wall:.1f}%" if wall else
                f"{info['robot']}/{info['process']}  pid {info['pid']}")
        lines = [head]
        if "bridge" in info:  # a recording has none
            lines.append(_traffic(bridge))
        rows = []
        for row in info["components"]:
            health = "ok" if row["healthy"] else (row["detail"] or "unhealthy")
            if len(health) > 40:
                health = health[:39] + "…"
            longest = row.get("loop_longest_s")
            rows.append([row["name"], row["type"], row["state"], health, row["restarts"],
                         row.get("events_in", 0), row.get("events_out", 0),
                         shares.share(info["process"], row, wall),
                         "-" if longest is None else f"{1000 * longest:.1f} ms"])
        blocks.append("\n".join([*lines, table(
            ["COMPONENT", "TYPE", "STATE", "HEALTH", "RESTARTS", "IN", "OUT", "LOOP",
             "LONGEST"], rows)]))
    return "\n\n".join(blocks)


async def top(args: argparse.Namespace) -> int:
    return await run_tool("top", args, _top)


async def _top(source: Source, out: Output, args: argparse.Namespace) -> int:
    if isinstance(source, LogSource):
        return await _top_recorded(source, out, args)
    assert isinstance(source, LiveSource)
    link = source.attachment
    shares = _Shares()
    clear = sys.stdout.isatty() and not args.once
    frames = 0
    while True:
        infos = await link.infos()
        if not infos:
            raise Unreachable(f"the system at {link.where} stopped answering")
        _show_table(out, render_top(infos, shares), clear)
        frames += 1
        if args.once or (args.count and frames >= args.count):
            return EXIT_OK
        await asyncio.sleep(args.interval)


def _show_table(out: Output, text: str, clear: bool) -> None:
    out.write(("\x1b[H\x1b[2J" if clear else "") + text + ("" if clear else "\n"))


async def _top_recorded(source: LogSource, out: Output, args: argparse.Namespace) -> int:
    """The recorded table at ``--at`` (default: the last), then, unless ``--once``, one
    every ``--interval`` of recorded time to the end (paced on a terminal). The loop
    share of the first is over the recorder's period before it."""
    tables = source.statistics()
    times = [t for t, _ in tables]
    at = times[-1] if args.at is None else args.at
    index = bisect.bisect_right(times, at) - 1
    if index < 0:
        raise Unavailable(f"{source.path} has no component statistics at or before "
                          f"{at:g} s; the first is at {times[0]:.3f} s")
    shares = _Shares()
    if index > 0:
        render_top([tables[index - 1][1]], shares)  # the loop share's starting point
    clear = sys.stdout.isatty() and not args.once
    frames = 0
    while True:
        _show_table(out, f"# {source.path.name} at {times[index]:.3f} s\n"
                    + render_top([tables[index][1]], shares), clear)
        frames += 1
        at += args.interval
        if args.once or (args.count and frames >= args.count) or at > times[-1]:
            return EXIT_OK
        index = bisect.bisect_right(times, at) - 1
        if clear:
            await asyncio.sleep(args.interval)
