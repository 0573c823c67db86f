"""The browser console: the seed's Qt tools (Launcher, QtMap, LocalMap, qtEventPose,
QtBodyViewer, QtRange3dSensor, qtEventStereo, qtHealthSafety, qtRaptor, qtEventImu) as one
page served by the running system (``docs/console.md``, decision 0013).

::

    console = Console(system, ConsoleOptions(port=8765))    # before the system starts
    async with console:                                      # serves http://127.0.0.1:8765/
        async with system:
            await system.run()

From the command line: ``python -m afa run CONFIG --sim --console 8765`` (loopback),
``--console 0.0.0.0:8765`` (every interface; the page is then opened by IP address, or by
a name given with ``--console-host-name NAME``), ``--console-control`` to allow the start,
stop and restart buttons and vehicle commands ("stop vehicle" always works).

The server needs the optional extra ``console`` (aiohttp): ``pip install 'afa[console]'``.
Errors: :class:`ConsoleError` (an :class:`~afa.errors.AfaError` and a ``RuntimeError``)
for a missing extra or an address that cannot be used.
"""

from __future__ import annotations

import argparse
import importlib.util
from dataclasses import dataclass, field
from typing import Any

from afa.console.guard import ControlGuard, host_name, is_loopback, parse_address
from afa.console.hub import ConsoleHub, GroundTruth, HubOptions, Session
from afa.console.launcher import CONSOLE_TASK
from afa.console.replay import ReplayControl, replay_control
from afa.errors import AfaError

__all__ = ["Console", "ConsoleOptions", "ConsoleError", "ConsoleHub", "Session",
           "GroundTruth", "ReplayControl", "replay_control", "parse_address",
           "add_arguments", "from_args", "exposure_warning", "EXTRA"]

#: The optional extra that brings the console's web server.
EXTRA = "console"
DEFAULT_PORT = 8765


class ConsoleError(AfaError, RuntimeError):
    """The console cannot run: its optional extra is missing, or it cannot listen."""


@dataclass
class ConsoleOptions:
    """Where the console listens and what it allows (see :mod:`afa.console.guard`).

    ``port`` 0 picks a free port. ``control`` allows starting, stopping and restarting
    components and commanding the vehicle from the page. ``host_names`` are names the
    page may be opened by (``vehicle.lan``) besides the loopback names, or, beyond
    loopback, IP addresses. ``reference_frame`` is the frame of the 3-D view. ``rates``
    overrides default stream rates per kind. ``max_pages`` is how many pages (WebSockets)
    may be connected at once; one more is refused (503) and counted, so a client opening
    sockets in a loop cannot make the server copy every frame to thousands of them.
    """

    host: str = "127.0.0.1"
    port: int = DEFAULT_PORT
    control: bool = False
    host_names: list[str] = field(default_factory=list)
    reference_frame: str = "Raptor:RearAxleCenter"
    status_period: float = 1.0
    rates: dict[str, float] = field(default_factory=dict)
    max_pages: int = 16


def _require_server() -> None:
    if importlib.util.find_spec("aiohttp") is None:
        raise ConsoleError(
            f"the browser console needs the optional extra {EXTRA!r} (aiohttp): "
            f"pip install 'afa[{EXTRA}]'")


class Console:
    """The console of one system: the hub (data) and the web server.

    Make it before the system starts (its observer then sees every event and its loop
    profiler every task); ``async with console`` serves until the block ends. It may
    outlive the system's start and stop. Raises :class:`ConsoleError` when aiohttp is
    not installed (at construction) or the address cannot be used (at start).
    """

    def __init__(self, system: Any, options: ConsoleOptions | None = None, *,
                 truth: GroundTruth | None = None, replay: Any = None) -> None:
        _require_server()
        self.options = options or ConsoleOptions()
        self.system = system
        self.hub = ConsoleHub(system, HubOptions(
            reference_frame=self.options.reference_frame,
            status_period=self.options.status_period, rates=dict(self.options.rates)),
            truth=truth, replay=None if replay is None else replay_control(replay))
        self.guard = ControlGuard(self.options.host, self.options.port, self.options.control,
                                  frozenset(map(host_name, self.options.host_names)))
        self._server: Any = None

    @property
    def port(self) -> int:
        return self.guard.port

    @property
    def url(self) -> str:
        """The page's address; with control allowed, the token in the fragment."""
        host = self.options.host
        if host in ("0.0.0.0", ""):
            host = "127.0.0.1"
        elif host == "::":
            host = "[::1]"
        elif ":" in host:
            host = f"[{host}]"
        base = f"http://{host}:{self.port}/"
        return f"{base}#token={self.guard.token}" if self.options.control else base

    async def start(self) -> str:
        """Start the hub and the server; returns :attr:`url`."""
        from afa.console.server import ConsoleServer

        await self.hub.start()
        server = ConsoleServer(self.hub, self.guard, max_pages=self.options.max_pages)
        # the server's connection tasks inherit this context: the profiler knows them
        token = CONSOLE_TASK.set(True)
        try:
            await server.start()
        except OSError as exc:
            await self.hub.aclose()
            raise ConsoleError(f"the console cannot listen on {self.options.host}:"
                               f"{self.options.port}: {exc.strerror or exc}") from exc
        finally:
            CONSOLE_TASK.reset(token)
        self._server = server
        return self.url

    async def stop(self) -> None:
        if self._server is not None:
            await self._server.stop()
            self._server = None
        await self.hub.aclose()

    async def __aenter__(self) -> Console:
        await self.start()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.stop()


# -- command line ---------------------------------------------------------------------------


def _address(text: str) -> tuple[str, int]:
    try:
        return parse_address(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _host_name(text: str) -> str:
    try:
        return host_name(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--console [HOST:]PORT``, ``--console-control`` and ``--console-host-name`` to
    a command (``afa run``, ``afa replay``)."""
    parser.add_argument(
        "--console", type=_address, metavar="[HOST:]PORT",
        help="serve the browser console on PORT (127.0.0.1 unless HOST is given; port 0 "
             "picks a free one); needs pip install 'afa[console]'")
    parser.add_argument(
        "--console-control", action="store_true",
        help="let the console start, stop and restart components and command the vehicle "
             "('stop vehicle' always works); the printed URL carries the control token")
    parser.add_argument(
        "--console-host-name", type=_host_name, action="append", default=[], metavar="NAME",
        help="a name the console's page may be opened by (e.g. vehicle.lan; repeat for "
             "more); beyond loopback only IP addresses are accepted otherwise")


def from_args(args: argparse.Namespace, system: Any, *, truth: GroundTruth | None = None,
              replay: Any = None) -> Console | None:
    """The console ``--console`` asks for (None without it). Raises ConsoleError for
    ``--console-control`` without ``--console``, or when aiohttp is missing."""
    address = getattr(args, "console", None)
    if address is None:
        if getattr(args, "console_control", False):
            raise ConsoleError("--console-control needs --console [HOST:]PORT")
        return None
    host, port = address
    return Console(system, ConsoleOptions(host=host, port=port,
                                          control=bool(args.console_control),
                                          host_names=list(args.console_host_name)),
                   truth=truth, replay=replay)


def exposure_warning(console: Console) -> str | None:
    """A warning when the console listens beyond loopback (with or without control)."""
    if is_loopback(console.options.host):
        return None
    what = "and accepts control requests (with the token)" if console.options.control else \
        "(view only)"
    return (f"the console listens on {console.options.host}:{console.port}, reachable from "
            f"other machines, {what}")

