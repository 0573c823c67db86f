"""Parser entries of the text tools (``afa echo``, ``hz``, ``names``, ``poll``,
``sensor3d``, ``top``); :func:`add_parsers` is called by :mod:`afa.cli`."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from afa.bridge.parameters import DEFAULT_ENDPOINT

__all__ = ["add_parsers"]


def _common(parser: argparse.ArgumentParser) -> None:
    where = parser.add_argument_group("where to look")
    where.add_argument("--connect", action="append", metavar="ENDPOINT",
                       help=f"Zenoh endpoint of a running afa process (default "
                            f"{DEFAULT_ENDPOINT}); repeat for several")
    where.add_argument("--robot", default="*", help="robot name (default: any)")
    where.add_argument("--as", dest="identity", default="tool", metavar="NAME",
                       help="the name this tool calls as (Bridge/AllowCommandFrom)")
    where.add_argument("--log", type=Path, metavar="FILE.mcap",
                       help="read a recording instead of a running system")


def _at(parser: argparse.ArgumentParser, what: str) -> None:
    parser.add_argument("--at", type=float, metavar="T",
                        help=f"with --log: {what} at T seconds after the recording's first "
                             "message (default: its end)")


def _handler(name: str) -> Any:
    async def handler(args: argparse.Namespace) -> int:
        from afa.tools import commands

        if not args.connect:
            args.connect = [DEFAULT_ENDPOINT]
        tool = getattr(commands, name)
        return await tool(args)  # type: ignore[no-any-return]

    handler.__name__ = name
    return handler


def add_parsers(commands: Any) -> None:
    """Add the tools to ``commands`` (the subparsers of ``python -m afa``)."""
    echo = commands.add_parser("echo", help="print events as they arrive")
    echo.add_argument("event", help="event name (Pose, Laser11, Gps, ...)")
    echo.add_argument("--json", action="store_true",
                      help="one JSON line per event, lossless (arrays in base64)")
    echo.add_argument("--count", type=int, default=0, metavar="N", help="stop after N events")
    _common(echo)
    echo.set_defaults(handler=_handler("echo"))

    hz = commands.add_parser("hz", help="rate, jitter and gaps of an event")
    hz.add_argument("event")
    hz.add_argument("--window", type=int, default=100, help="events per report (default 100)")
    hz.add_argument("--every", type=float, default=1.0, metavar="S",
                    help="seconds between reports (default 1)")
    hz.add_argument("--count", type=int, default=0, metavar="N", help="stop after N reports")
    _common(hz)
    hz.set_defaults(handler=_handler("hz"))

    names = commands.add_parser("names", help="the name registry (nsview): served names, "
                                              "interfaces, owners, processes")
    names.add_argument("--json", action="store_true")
    names.add_argument("--all", action="store_true",
                       help="also each process's imported copies of remote names")
    _common(names)
    names.set_defaults(handler=_handler("names"))

    poll = commands.add_parser("poll", help="one typed poll from the shell")
    poll.add_argument("name", help="served name (modelServer's ModelService, Gps, ...)")
    poll.add_argument("method", help="method (getTransformation, getPosition, ...)")
    poll.add_argument("args", nargs="*", metavar="ARG",
                      help="arguments in order or as name=value; JSON for structures, "
                           "@FILE reads one from a file")
    poll.add_argument("--json", action="store_true", help="print the result as JSON")
    poll.add_argument("--timeout", type=float, help="seconds (default: the interface's)")
    _common(poll)
    _at(poll, "answer as the replay would (get...: the latest recorded value; "
              "getWait...: the next one)")
    poll.set_defaults(handler=_handler("poll"))

    sensor = commands.add_parser("sensor3d", help="range points as text, in the Raptor frame "
                                                  "(Sensor3dStream, Sensor3dGet)")
    actions = sensor.add_subparsers(required=True, metavar="ACTION")
    stream = actions.add_parser("stream", help="points of each range event (Laser11, Stereo)")
    stream.add_argument("event")
    get = actions.add_parser("get", help="poll a range sensor for its latest scan")
    get.add_argument("name", help="served name of a Range3dSensor (NodLaserService, ...)")
    get.add_argument("--form", choices=["auto", "laser", "seq", "stereo", "array"],
                     default="auto", help="which scan (Table 31); auto: laser, else stereo")
    get.add_argument("--timeout", type=float)
    get.add_argument("--next", action="store_true",
                     help="with --log: the next scan after --at (the getWait form) rather "
                          "than the latest at or before it")
    _at(get, "the scan")
    for parser, repeat in ((stream, True), (get, False)):
        parser.add_argument("--frame", default="Raptor:RearAxleCenter",
                            help="target frame (ModelServer's getTransformation); 'sensor' "
                                 "leaves the points in the sensor's own frame")
        parser.add_argument("--count", type=int, default=0 if repeat else 1, metavar="N",
                            help="scans to print" + (" (default: until stopped)" if repeat
                                                     else " (default 1)"))
        parser.add_argument("--every", type=int, default=1, metavar="K",
                            help="print every K-th point")
        parser.add_argument("--max-points", type=int, default=0, metavar="N",
                            help="at most N points per scan")
        _common(parser)
    stream.set_defaults(handler=_handler("sensor3d_stream"))
    get.set_defaults(handler=_handler("sensor3d_get"))

    top = commands.add_parser("top", help="the Launcher table: state, health, restarts, "
                                          "events, loop share, memory, refreshed")
    top.add_argument("--interval", type=float, default=2.0, metavar="S",
                     help="seconds between refreshes (default 2)")
    top.add_argument("--once", action="store_true", help="print one table and exit")
    top.add_argument("--count", type=int, default=0, metavar="N", help="stop after N tables")
    _common(top)
    _at(top, "the table (each refresh steps on by --interval of recorded time)")
    top.set_defaults(handler=_handler("top"))
