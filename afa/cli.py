"""The command line: ``python -m afa ...``. The only place that calls ``asyncio.run``."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import inspect
import io
import json
import logging
import signal
import sys
import time
from collections.abc import AsyncIterator, Callable, Iterator, Sequence
from contextlib import asynccontextmanager, contextmanager
from pathlib import Path
from typing import Any, cast

from afa.errors import AfaError, ConfigError

log = logging.getLogger("afa.cli")

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_INVALID = 2


LOG_LEVELS = ["debug", "info", "warning", "error"]
LOG_FORMAT = "%(asctime)s %(levelname)-7s %(name)s: %(message)s"


def main(argv: Sequence[str] | None = None, prog: str = "afa") -> int:
    """The ``afa`` script; ``python -m afa`` passes its own ``prog`` for the usage."""
    parser = _parser(prog)
    args = parser.parse_args(argv)
    logging.basicConfig(level=getattr(logging, args.log_level.upper()), format=LOG_FORMAT)
    handler: Callable[[argparse.Namespace], Any] = args.handler
    try:
        if inspect.iscoroutinefunction(handler):  # the text tools (afa.tools)
            return asyncio.run(handler(args))  # type: ignore[no-any-return]
        return handler(args)  # type: ignore[no-any-return]
    except KeyboardInterrupt:
        return EXIT_OK
    except BrokenPipeError:  # `afa decode gps FILE | head`: the reader has had enough
        _silence_stdout()
        return EXIT_OK
    except ConfigError as exc:
        print(str(exc), file=sys.stderr)
        return EXIT_INVALID
    except AfaError as exc:
        print(f"afa: {exc}", file=sys.stderr)
        return EXIT_FAILURE


def _silence_stdout() -> None:
    """Point standard output at /dev/null, so that Python's own flush at exit does not
    complain about the closed pipe once more."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # no real file behind stdout
        pass


def _parser(prog: str = "afa") -> argparse.ArgumentParser:
    from afa import __version__

    parser = argparse.ArgumentParser(
        prog=prog,
        description="afa: the Architecture for Autonomy (DRDC Raptor UGV) on asyncio.")
    parser.add_argument("--version", action="version", version=f"afa {__version__}")
    parser.add_argument("--log-level", default="warning", choices=LOG_LEVELS,
                        help="logging level (default warning; also after the command)")
    commands = parser.add_subparsers(required=True, metavar="COMMAND")

    run = commands.add_parser("run", help="run the components a configuration file enables")
    run.add_argument("config", type=Path, help="Miro XML configuration (configs/raptor.xml)")
    run.add_argument("--sim", action="store_true", help="run against the simulated world")
    run.add_argument("--world", help="world for --sim: a file, or the name of a shipped world "
                                      f"({', '.join(_shipped_worlds()) or 'none found'})")
    run.add_argument("--duration", type=float,
                     help="stop this many seconds (clock time) after the stack has started")
    run.add_argument("--seed", type=int, default=0, help="random seed for the simulation")
    run.add_argument("--fast", action="store_true",
                     help="virtual time, as fast as possible (needs --sim)")
    run.add_argument("--realtime-factor", type=float, metavar="N",
                     help="virtual time paced at N times real time (needs --sim)")
    run.add_argument("--teleop", action="store_true",
                     help="with --sim: drive the world's <drive> script through Vehicle "
                          "Control instead of the autonomous mission")
    run.add_argument("--summary", type=Path, help="write a JSON run summary here")
    run.add_argument("--expose", action="store_true",
                     help="with --sim: serve serial emulators on pseudo-terminals and the "
                          "lasers on loopback TCP (real transports; not with --fast)")
    run.add_argument("--strict", action="store_true",
                     help="fail if a configured component is not implemented yet")
    run.add_argument("--record", type=Path, metavar="FILE.mcap",
                     help="record every event, poll and viewer channel to an MCAP file "
                          "(docs/logs.md)")
    run.add_argument("--record-events", metavar="PATTERNS",
                     help="with --record: only these event names (comma-separated, "
                          "wildcards allowed: 'Pose,Gps,Laser*')")
    run.add_argument("--record-compression", choices=["zstd", "lz4", "none"], default="zstd",
                     help="with --record: chunk compression (default zstd)")
    run.add_argument("--record-no-viewer", action="store_true",
                     help="with --record: leave out the Foxglove viewer channels")
    from afa.console import add_arguments as add_console_arguments

    add_console_arguments(run)
    from afa.bridge.runner import add_run_arguments

    add_run_arguments(run)
    run.set_defaults(handler=_run)

    _log_parsers(commands)

    config = commands.add_parser("config", help="check, show or generate configuration")
    config_commands = config.add_subparsers(required=True, metavar="ACTION")
    check = config_commands.add_parser("check", help="validate a configuration file")
    check.add_argument("config", type=Path)
    check.set_defaults(handler=_config_check)
    show = config_commands.add_parser("show", help="print every effective parameter value")
    show.add_argument("config", type=Path)
    show.add_argument("--json", action="store_true",
                      help="as {section: {instance: {parameter: value}}}")
    show.set_defaults(handler=_config_show)
    defaults = config_commands.add_parser("defaults",
                                          help="write a file of every component's defaults")
    defaults.add_argument("-o", "--output", type=Path, help="file to write (default: stdout)")
    defaults.set_defaults(handler=_config_defaults)

    reference = config_commands.add_parser(
        "reference", help="print the parameter reference (docs/parameters.md)")
    reference.set_defaults(handler=_config_reference)

    graph = commands.add_parser("graph", help="print the data-flow graph of a configuration")
    graph.add_argument("config", type=Path)
    graph.add_argument("--format", choices=["text", "mermaid", "dot", "json"], default="text",
                       help="text (default), Mermaid, Graphviz DOT, or the catalog as JSON")
    graph.set_defaults(handler=_graph)

    decode = commands.add_parser("decode", help="decode a raw device capture to JSON lines")
    decode.add_argument("device", help="device codec: " + ", ".join(_decoders()))
    decode.add_argument("file", type=Path, help="raw capture ('-' for stdin)")
    decode.set_defaults(handler=_decode)

    from afa.tools.cli import add_parsers as add_tool_parsers

    add_tool_parsers(commands)
    _log_level_everywhere(parser)
    return parser


def _log_level_everywhere(parser: argparse.ArgumentParser) -> None:
    """Accept ``--log-level`` after any command too (``afa run X --log-level info``); given
    there, it overrides the one before the command."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for command in action.choices.values():
                command.add_argument("--log-level", default=argparse.SUPPRESS,
                                     choices=LOG_LEVELS, help="logging level (default warning)")
                _log_level_everywhere(command)


def _log_parsers(commands: Any) -> None:
    """``afa replay`` and ``afa log info|echo|recover`` (their code: afa.log.cli)."""
    replay = commands.add_parser(
        "replay", help="replay a recording into the components of a configuration")
    replay.add_argument("file", type=Path, help="the recording (FILE.mcap)")
    replay.add_argument("config", type=Path, nargs="?",
                        help="configuration to replay into (default: the recorded one)")
    replay.add_argument("--speed", default="1", metavar="X|max",
                        help="multiple of real time, or max (virtual time; default 1)")
    replay.add_argument("--start", type=float, metavar="T", help="start T s into the recording")
    replay.add_argument("--end", type=float, metavar="T", help="stop T s into the recording")
    replay.add_argument("--loop", action="store_true", help="start again at the end")
    replay.add_argument("--paused", action="store_true",
                        help="start paused (space resumes; see the keys in docs/logs.md)")
    replay.add_argument("--only", metavar="NAMES",
                        help="comma-separated components to re-run and/or topics to replay")
    replay.add_argument("--skip", metavar="NAMES",
                        help="comma-separated components not to re-run and/or topics not "
                             "to replay")
    replay.add_argument("--check", action="store_true",
                        help="re-run in virtual time and compare every output with the "
                             "recorded one; stop at the first divergence (exit 3)")
    replay.add_argument("--atol", type=float, default=0.0,
                        help="with --check: absolute tolerance for numbers (default 0: exact)")
    from afa.console import add_arguments as add_console_arguments

    add_console_arguments(replay)
    replay.set_defaults(handler=_log_handler("replay"))

    log_parser = commands.add_parser("log", help="inspect and repair recordings")
    actions = log_parser.add_subparsers(required=True, metavar="ACTION")
    info = actions.add_parser("info", help="duration, topics, counts, rates, polls, drops")
    info.add_argument("file", type=Path)
    info.add_argument("--json", action="store_true", help="as one JSON document")
    info.set_defaults(handler=_log_handler("info"))
    echo = actions.add_parser("echo", help="print one topic's messages")
    echo.add_argument("file", type=Path)
    echo.add_argument("topic", help="event name (Pose), topic (/Raptor/Pose) or poll topic")
    echo.add_argument("--json", action="store_true", help="one JSON document per line")
    echo.set_defaults(handler=_log_handler("echo"))
    recover = actions.add_parser("recover", help="rewrite a cut-off or damaged recording whole")
    recover.add_argument("file", type=Path, help="the damaged recording")
    recover.add_argument("output", type=Path, help="the file to write")
    recover.set_defaults(handler=_log_handler("recover"))


def _log_handler(name: str) -> Callable[[argparse.Namespace], int]:
    def handler(args: argparse.Namespace) -> int:
        from afa.log import cli

        return int(getattr(cli, name)(args))

    return handler


# -- config -----------------------------------------------------------------------------
def _load(path: Path) -> Any:
    from afa.config.loader import load_configuration

    return load_configuration(path)


def _catalog(path: Path) -> Any:
    """The catalog of the system ``path`` describes (components built, not started)."""
    from afa.system import System

    return System.from_xml(path, real_devices=False).catalog()


def _config_check(args: argparse.Namespace) -> int:
    from afa.system import System

    config = _load(args.config)
    system = System.from_xml(args.config, real_devices=False)
    warnings = [f"{args.config}: warning: {line}" for line in system.catalog().problems()]
    lines = dict(zip((entry.Name for entry in config.launcher.Components),
                     config.launcher_lines, strict=False))
    for device, users in system.port_conflicts().items():
        first = min(lines.get(name, 0) for name, _ in users)
        named = ", ".join(f"{name} at {baud}" for name, baud in users)
        warnings.append(f"{args.config}:{first}: warning: serial port {device} is named by "
                        f"components at different baud rates ({named}): one connection "
                        "cannot serve both; give each device its own port")
    for line in warnings:
        print(line, file=sys.stderr)
    broken = system.file_problems()
    for name, problem in broken.items():
        print(f"{args.config}:{lines.get(name, 0)}: {name}: {problem}", file=sys.stderr)
    if broken:
        print(f"{args.config}: invalid: {len(broken)} component(s) cannot read their files",
              file=sys.stderr)
        return EXIT_INVALID
    count = sum(len(sets) for sets in config.sections.values())
    print(f"{args.config}: valid ({len(config.sections)} sections, {count} parameter sets, "
          f"robot {config.robot!r}, {len(config.launcher.Components)} launcher entries"
          f"{f', {len(warnings)} warning(s)' if warnings else ''})")
    return EXIT_OK


def _graph(args: argparse.Namespace) -> int:
    catalog = _catalog(args.config)
    if args.format == "json":
        print(json.dumps(catalog.as_dicts(), indent=2))
    else:
        sys.stdout.write(getattr(catalog, args.format)())
    return EXIT_OK


def _config_show(args: argparse.Namespace) -> int:
    config = _load(args.config)
    if args.json:
        print(config.to_json())
        return EXIT_OK
    for section, sets in config.as_dict().items():
        for instance, values in sets.items():
            print(f"[{section}/{instance}]")
            for name, value in values.items():
                print(f"  {name} = {json.dumps(value)}")
    return EXIT_OK


def _config_defaults(args: argparse.Namespace) -> int:
    from afa.config.writer import defaults_document

    text = defaults_document()
    if args.output is None:
        sys.stdout.write(text)
        return EXIT_OK
    try:
        args.output.write_text(text)
    except OSError as exc:
        print(f"afa config defaults: cannot write {args.output}: {exc.strerror or exc}",
              file=sys.stderr)
        return EXIT_INVALID
    print(f"{args.output}: every component type with its defaults; run it with "
          f"`afa run {args.output} --sim` (`afa config check {args.output}` for what to "
          "change before a vehicle)", file=sys.stderr)
    return EXIT_OK


def _config_reference(args: argparse.Namespace) -> int:
    from afa.config.reference import reference_markdown

    sys.stdout.write(reference_markdown())
    return EXIT_OK


# -- decode -----------------------------------------------------------------------------
def _decoders() -> list[str]:
    from afa import registry

    return registry.decoders()


_DECODE_READ = 65536  # bytes read from the input at a time (memory stays bounded)


def _decode(args: argparse.Namespace) -> int:
    import dataclasses

    from afa import registry

    decoder = registry.load_decoder(args.device)()
    sample = bytearray()  # the input's first 64 KiB, for the hint when nothing decodes
    total = messages = 0
    with contextlib.ExitStack() as stack:
        try:
            source = cast(io.BufferedIOBase, sys.stdin.buffer if str(args.file) == "-"
                          else stack.enter_context(args.file.open("rb")))
        except OSError as exc:
            print(f"afa decode: cannot read {args.file}: {exc.strerror}", file=sys.stderr)
            return EXIT_INVALID
        # a stream, not read whole: an endless input (/dev/zero, a serial port, a pipe) is
        # decoded as it comes, in bounded memory
        while True:
            try:
                chunk = source.read1(_DECODE_READ)
            except OSError as exc:
                print(f"afa decode: cannot read {args.file}: {exc.strerror}", file=sys.stderr)
                return EXIT_INVALID
            if not chunk:
                break
            total += len(chunk)
            if len(sample) < _DECODE_READ:
                sample += chunk[:_DECODE_READ - len(sample)]
            for offset in range(0, len(chunk), 4096):
                for message in decoder.feed(chunk[offset:offset + 4096]):
                    messages += 1
                    inner = getattr(message, "message", None)  # framed links wrap it
                    kind = type(inner if dataclasses.is_dataclass(inner) else message).__name__
                    record = {"type": kind, **_jsonable(dataclasses.asdict(message))}
                    print(json.dumps(record, allow_nan=False))
            sys.stdout.flush()  # what this read decoded, now (a live input)
    stats = decoder.stats
    print(json.dumps({"statistics": {"messages": messages, "checksum_failures":
                                     stats.checksum_failures, "malformed": stats.malformed,
                                     "bytes_skipped": stats.bytes_skipped + decoder.buffered,
                                     "bytes": total}}))
    if messages == 0:
        sys.stdout.flush()
        print(f"afa decode: nothing decoded from {args.file} as {args.device} "
              f"({total} bytes{_other_decoders(args.device, bytes(sample))})", file=sys.stderr)
        return EXIT_FAILURE
    return EXIT_OK


def _other_decoders(device: str, data: bytes) -> str:
    """What the other decoders make of (the first 64 KiB of) ``data``, for a hint."""
    from afa import registry

    if not data:
        return ": the input is empty"
    sample, found = data[:65536], []
    for name in registry.decoders():
        if name != device:
            count = len(registry.load_decoder(name)().feed(sample))
            if count:
                found.append((count, name))
    if not found:
        return "; no other decoder finds anything in it either"
    count, name = max(found)
    return f"; is it a {name} capture? the {name} decoder finds {count} message(s) in it"


def _jsonable(value: Any) -> Any:
    import datetime
    import enum
    import math

    import numpy as np

    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return _jsonable(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None  # JSON has no NaN or infinity: a missing value
    if isinstance(value, enum.Enum):
        return value.value if isinstance(value.value, (str, int, float)) else value.name
    if isinstance(value, bytes):
        return value.hex()
    if isinstance(value, (datetime.date, datetime.time)):
        return value.isoformat()
    return value


# -- run --------------------------------------------------------------------------------
def _shipped_worlds() -> list[str]:
    folder = Path(__file__).resolve().parent.parent / "configs" / "worlds"
    return sorted(p.stem for p in folder.glob("*.xml"))


def _world_path(text: str) -> Path:
    """A world file, or the name of a shipped world (``rock-field``)."""
    path = Path(text)
    if path.exists() or path.suffix:
        return path
    shipped = Path(__file__).resolve().parent.parent / "configs" / "worlds" / f"{text}.xml"
    if shipped.exists():
        return shipped
    from afa.registry import suggest

    raise ConfigError(f"no world file or shipped world {text!r}"
                      f"{suggest(text, _shipped_worlds())}; shipped worlds: "
                      f"{', '.join(_shipped_worlds())}")


def _run(args: argparse.Namespace) -> int:
    needs_sim = {"--fast": args.fast, "--world": args.world is not None,
                 "--expose": args.expose, "--teleop": args.teleop,
                 "--realtime-factor": args.realtime_factor is not None}
    if not args.sim and any(needs_sim.values()):
        used = ", ".join(name for name, given in needs_sim.items() if given)
        print(f"afa run: {used} need(s) --sim (real devices run in real time).",
              file=sys.stderr)
        return EXIT_INVALID
    if args.fast and args.realtime_factor is not None:
        print("afa run: --fast (as fast as possible) and --realtime-factor exclude each "
              "other.", file=sys.stderr)
        return EXIT_INVALID
    if args.realtime_factor is not None and not args.realtime_factor > 0:
        print("afa run: --realtime-factor must be positive.", file=sys.stderr)
        return EXIT_INVALID
    if args.expose and args.fast:
        print("afa run: --expose uses real pseudo-terminals and sockets, whose timing virtual "
              "time cannot control; run it without --fast.", file=sys.stderr)
        return EXIT_INVALID
    return asyncio.run(_run_system(args))


def _simulator() -> Any:
    """The simulation registered under the entry-point group ``afa.simulators``."""
    from afa import registry

    found = registry.simulators()
    if not found:
        raise AfaError("no simulator is installed (entry-point group afa.simulators); "
                       "is afa installed? pip install -e .")
    return found[sorted(found)[0]].load()


def run_clock(fast: bool = False, realtime_factor: float | None = None) -> Any:
    """The clock of ``afa run``: ``--fast``, virtual time as fast as possible;
    ``--realtime-factor N``, virtual time paced at N times real time (in Python:
    ``VirtualClock(pace=N)``); neither, the wall clock."""
    from afa.clock import VirtualClock, WallClock

    if fast:
        return VirtualClock()
    if realtime_factor is not None:
        return VirtualClock(pace=realtime_factor)
    return WallClock()


async def _run_system(args: argparse.Namespace) -> int:
    from afa.clock import Clock

    clock: Clock = run_clock(args.fast, args.realtime_factor)
    from afa.bridge.runner import lockstep_clock

    clock = lockstep_clock(args) or clock  # a process group in lock-step (decision 0011)
    with _log_times(clock):
        return await _run_on(args, clock)


@contextmanager
def _log_times(clock: Any) -> Iterator[None]:
    """In virtual time (``--fast``, ``--realtime-factor``), stamp log lines with the clock's
    seconds since the run began (``t=  12.345``) instead of wall-clock dates; the root
    handlers' formatters are restored afterwards."""
    from afa.clock import VirtualClock

    handlers = logging.getLogger().handlers
    if not isinstance(clock, VirtualClock) or not handlers:
        yield
        return
    start = clock.monotonic()

    class ClockFormatter(logging.Formatter):
        def formatTime(self, record: logging.LogRecord, datefmt: str | None = None) -> str:
            return f"t={clock.monotonic() - start:9.3f}"

    saved = [handler.formatter for handler in handlers]
    for handler in handlers:
        handler.setFormatter(ClockFormatter(LOG_FORMAT))
    try:
        yield
    finally:
        for handler, formatter in zip(handlers, saved, strict=True):
            handler.setFormatter(formatter)


async def _run_on(args: argparse.Namespace, clock: Any) -> int:
    from afa.bridge.runner import describe as describe_bridge
    from afa.bridge.runner import summary as bridge_summary
    from afa.bridge.runner import system_options
    from afa.errors import StartupError, TaskFailed
    from afa.system import System

    simulation = None
    options: dict[str, Any] = {"strict": args.strict, "clock": clock, **system_options(args)}
    if args.sim:
        simulation_cls = _simulator()
        world = _world_path(args.world) if args.world else simulation_cls.default_world()
        simulation = simulation_cls(world, clock, seed=args.seed, expose=args.expose,
                                    teleop=args.teleop)
        if args.expose:
            simulation.announce = _print_endpoint
        options["devices"] = simulation.device_for
        if (simulation.time_limit is None and args.duration is None
                and _console_args(args) is None and not getattr(args, "bridge", False)
                and getattr(args, "process", None) is None):
            # nothing would drive the vehicle and nothing would end the run
            name = simulation.world.name
            why = ("has no <drive> script for --teleop" if simulation.world.mission.waypoints
                   else "has no mission and no <drive> script")
            print(f"afa run: world {name!r} {why}: nothing would drive and the run would not "
                  "end; drive its mission (without --teleop), or give --duration S or a "
                  "--console to drive it from", file=sys.stderr)
            return EXIT_INVALID
    system = System.from_xml(args.config, **options)
    if simulation is not None and args.process and not simulation.fakes:
        simulation = None  # its devices run in another process group, and so does the world
    if simulation is not None:
        simulation.attach(system)
    recorder = None
    if args.record is not None:
        from afa.log.cli import start_recording

        recorder = start_recording(args, system, simulation)
    console = _console(args, system, simulation)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            loop.add_signal_handler(sig, stop.set)
        except (NotImplementedError, RuntimeError):  # pragma: no cover - non-Unix
            pass
    wall_start = time.monotonic()
    clock_start = clock.monotonic()
    try:
        async with _serving(console), system:
            if not logging.getLogger("afa.system").isEnabledFor(logging.WARNING):
                for note in system.notes:  # logged as warnings, unless those are hidden
                    print(f"afa: {note}", file=sys.stderr)
            bridged = describe_bridge(system)
            if bridged is not None:
                print(f"afa: {bridged}", file=sys.stderr, flush=True)
            duration, finished = args.duration, None
            if simulation is not None and duration is None:
                # a simulated run ends with its mission (or drive script), or at its limit
                duration, finished = simulation.time_limit, simulation.finished
            async with _simulating(simulation):
                await _until_stopped(system, stop, duration,
                                     _progress(system, simulation, clock, clock_start,
                                               wall_start), finished)
            if recorder is not None:
                await recorder.drain()
            summary = _summary(system, clock_start, wall_start)
            if recorder is not None:
                summary["recording"] = {"file": str(args.record), **recorder.statistics()}
            summary.update(bridge_summary(system))
            if simulation is not None:
                summary.update(simulation.summary())
    except StartupError as exc:
        await _close(simulation)
        print(f"afa run: the system did not start. {exc}".replace("\n", " "), file=sys.stderr)
        return EXIT_FAILURE
    except TaskFailed as exc:
        await _close(simulation)
        print(f"afa run: stopped: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    finally:
        if recorder is not None:
            recorder.finish()  # the index and summary; what was flushed is safe anyway
    await _close(simulation)
    if simulation is not None and not simulation.teleop:
        # planned once the system has stopped: seconds of CPU that, while the drivers
        # ran on the wall clock, starved them (every link "lost" at the end of the run)
        summary.update(simulation.course_reference())
    _print_summary(summary)
    if args.summary is not None:
        args.summary.write_text(json.dumps(summary, indent=2))
    if not summary["stack_up"]:
        down = [f"{name} ({info['detail'] or info['state']})"
                for name, info in summary["components"].items()
                if not info["ever_healthy"] and not info["waiting"]]
        hint = ""
        if not args.sim:
            from afa.component import PublishServerReactor

            drivers = [summary["components"][name] for name, component
                       in system.components.items()
                       if isinstance(component, PublishServerReactor)
                       and name in summary["components"]]
            if any("cannot open device" in info["detail"] for info in drivers):
                hint = " No devices found; did you mean --sim?"
            elif drivers and not any(info["ever_healthy"] for info in drivers):
                hint = " No device answered; did you mean --sim?"
        print(f"afa run: the stack never came up: {'; '.join(down)}.{hint}", file=sys.stderr)
        return EXIT_FAILURE
    if (simulation is not None and args.duration is None and not stop.is_set()
            and summary.get("mode") == "autonomous" and not summary.get("mission_complete")):
        print(f"afa run: the mission was not completed within its time limit "
              f"({summary['waypoints_reached']}/{summary['waypoints_total']} waypoints in "
              f"{summary['sim_time_s']:.0f} s).", file=sys.stderr)
        return EXIT_FAILURE
    return EXIT_OK


def _print_endpoint(component: str, endpoint: str) -> None:
    """``--expose``: where each emulated device is served (a pseudo-terminal a serial
    tool can open, or a loopback TCP port)."""
    print(f"afa: {component} emulated on {endpoint}", file=sys.stderr, flush=True)


def _console_args(args: argparse.Namespace) -> Any:
    """What ``--console``/``--console-control`` ask for, or None."""
    if getattr(args, "console", None) is None and not getattr(args, "console_control", False):
        return None
    return getattr(args, "console", None) or True


def _console(args: argparse.Namespace, system: Any, simulation: Any) -> Any:
    """The browser console ``--console`` asks for, or None (afa.console)."""
    if _console_args(args) is None:
        return None
    from afa.console import from_args

    return from_args(args, system, truth=simulation)


@asynccontextmanager
async def _serving(console: Any) -> AsyncIterator[None]:
    """Serve the console (if any) around the system's run; print its address."""
    if console is None:
        yield
        return
    from afa.console import exposure_warning

    async with console:
        print(f"afa: console at {console.url}", file=sys.stderr, flush=True)
        warning = exposure_warning(console)
        if warning is not None:
            print(f"afa: warning: {warning}", file=sys.stderr)
        yield


async def _close(simulation: Any) -> None:
    if simulation is not None:
        await simulation.aclose()


def _simulating(simulation: Any) -> Any:
    from contextlib import nullcontext

    return nullcontext() if simulation is None else simulation.running()


async def _until_stopped(system: Any, stop: asyncio.Event, duration: float | None,
                         progress: Any, finished: asyncio.Event | None = None) -> None:
    """Run the system until ``duration``, a signal, ``finished``, or a failure (raised);
    print progress meanwhile."""
    from afa.tasks import Scope, first_error

    try:
        async with Scope() as scope:
            runner = scope.spawn(system.run(duration, until=finished), "afa-run")
            signalled = scope.spawn(stop.wait(), "afa-signal")
            reporter = scope.spawn(progress, "afa-progress")
            done, _ = await asyncio.wait([runner, signalled],
                                         return_when=asyncio.FIRST_COMPLETED)
            for task in (runner, signalled, reporter):
                task.cancel()
            for task in done:
                task.result()
    except BaseExceptionGroup as group:  # the failure itself (TaskFailed: one line)
        raise first_error(group) from None


async def _progress(system: Any, simulation: Any, clock: Any, clock_start: float,
                    wall_start: float) -> None:
    """One progress line every 10 s of clock time (stderr)."""
    async for _ in clock.periodic(10.0, first=clock_start + 10.0):
        elapsed = clock.monotonic() - clock_start
        wall = max(1e-9, time.monotonic() - wall_start)
        where = simulation.progress() if simulation is not None else ""
        print(f"t={elapsed:7.1f} s  x{elapsed / wall:6.1f} real time  {where}", file=sys.stderr)


def _summary(system: Any, clock_start: float, wall_start: float) -> dict[str, Any]:
    wall = time.monotonic() - wall_start
    elapsed = system.clock.monotonic() - clock_start
    statistics = system.statistics()
    health = system.health()
    return {
        "sim_time_s": round(elapsed, 6),
        "wall_time_s": round(wall, 6),
        "realtime_factor": round(elapsed / wall, 3) if wall > 0 else None,
        "events": statistics["events"],
        "events_dropped": statistics["events_dropped"],
        "component_errors": {name: h.failures for name, h in health.items() if h.failures},
        "components": {name: {"state": h.state.value, "healthy": h.healthy, "detail": h.detail,
                              "ever_healthy": h.ever_healthy, "waiting": list(h.waiting),
                              "restarts": h.restarts, "last_error": h.last_error}
                       for name, h in health.items()},
        # up: every component was healthy at some moment, or is itself fine and only
        # waiting for an input that has not come yet (a map filling for MapUpdateTime)
        "stack_up": all(h.ever_healthy or h.waiting for h in health.values()),
        "not_started": list(system.notes),
    }


def _maps_line(maps: dict[str, Any]) -> str:
    """The summary's ``maps`` section in one line."""
    parts = []
    terrain, hazards = maps.get("terrain"), maps.get("hazards")
    for name, part in (("terrain", terrain), ("hazards", hazards)):
        if part and "error" in part:
            parts.append(f"{name}: {part['error']}")
    terrain = None if terrain is None or "error" in terrain else terrain
    hazards = None if hazards is None or "error" in hazards else hazards
    if terrain:
        parts.append(f"terrain RMS height error {terrain['rms_height_error_m']} m "
                     f"({terrain['rms_height_error_centred_m']} m about its offset of "
                     f"{terrain['height_offset_m']} m)")
    if hazards:
        parts.append(f"obstacle cells within {maps['detection_range_m']:g} m of the track "
                     f"detected {hazards['detected_cells']}/{hazards['obstacle_cells']} "
                     f"({hazards['unobserved_obstacle_cells']} never seen), false hazards "
                     f"{hazards['false_hazard_cells']}/{hazards['free_observed_cells']} "
                     "observed free cells")
    return "maps: " + ("; ".join(parts) if parts else "none built")


def _print_summary(summary: dict[str, Any]) -> None:
    events = sum(summary["events"].values())
    unhealthy = sum(not info["healthy"] for info in summary["components"].values())
    if "world" in summary:
        pose = summary.get("pose_error") or {}
        print(f"world {summary['world']}: {summary['distance_m']:.1f} m driven, "
              f"{len(summary['collisions'])} collision(s), waypoints "
              f"{summary['waypoints_reached']}/{summary['waypoints_total']}, pose RMS "
              f"{pose.get('rms_position_m', 'n/a')} m / {pose.get('rms_heading_deg', 'n/a')} deg")
    if summary.get("mode") == "autonomous":
        ratio = summary.get("path_ratio")
        print(f"mission: {'complete' if summary['mission_complete'] else 'NOT complete'}"
              + (f" in {summary['mission_complete_time_s']:.0f} s, "
                 f"{summary['mission_distance_m']:.1f} m" if summary["mission_complete"]
                 else "")
              + (f" ({ratio:.2f}x the shortest course of {summary['oracle_distance_m']:.1f} m)"
                 if ratio is not None else "")
              + f"; least clearance {summary['clearance_m']} m, {summary['halts']} halt(s), "
              f"{summary['oscillation_per_min']} steering reversals/min")
    if summary.get("maps"):
        print(_maps_line(summary["maps"]))
    print(f"ran {summary['sim_time_s']:.1f} s in {summary['wall_time_s']:.1f} s wall; "
          f"{events} events, {summary['events_dropped']} dropped; "
          f"{len(summary['component_errors'])} component(s) with errors"
          + (f", {unhealthy} of {len(summary['components'])} unhealthy" if unhealthy else ""))
    for name, info in summary["components"].items():
        flag = "ok" if info["healthy"] else f"UNHEALTHY {info['detail']}".strip()
        if not info["ever_healthy"]:
            flag += " (no input yet)" if info["waiting"] else " (never came up)"
        print(f"  {name:24s} {info['state']:9s} restarts={info['restarts']:<3d} {flag}")
