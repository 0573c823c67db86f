"""What ``afa run`` needs to run one process group of a split configuration: its
command-line options, its clock, and the options of its System. (Parser entries stay in
:mod:`afa.cli`; this keeps the bridge's part of ``afa run`` in one place.)"""

from __future__ import annotations

import argparse
from typing import Any

from afa.clock import Clock

__all__ = ["add_run_arguments", "lockstep_clock", "system_options"]


def add_run_arguments(run: argparse.ArgumentParser) -> None:
    group = run.add_argument_group(
        "across processes (Zenoh bridge, needs the extra afa[zenoh]; docs/distributed.md)")
    group.add_argument("--process", metavar="NAME",
                       help="run only the Launcher entries of process group NAME ('main': "
                            "those without a Process) and bridge to the other groups")
    group.add_argument("--bridge", action="store_true",
                       help="run the bridge, so that other processes and the text tools "
                            "(afa echo, names, poll, top, ...) reach this one (implied by "
                            "--process)")
    group.add_argument("--listen", action="append", metavar="ENDPOINT",
                       help="Zenoh endpoint to listen on (repeatable; replaces "
                            "Bridge/Listen, default tcp/127.0.0.1:7447)")
    group.add_argument("--connect", action="append", metavar="ENDPOINT",
                       help="Zenoh endpoint of another process (repeatable; replaces "
                            "Bridge/Connect)")
    group.add_argument("--allow-command", action="append", metavar="PEER",
                       help="a process (or Zenoh id, or *) allowed to make remote calls "
                            "that move the vehicle (repeatable; replaces "
                            "Bridge/AllowCommandFrom)")


def lockstep_clock(args: argparse.Namespace) -> Clock | None:
    """The clock of a process group in virtual time: a SteppedClock in lock-step with the
    other groups (decision 0011); None when this run needs no lock-step."""
    if not getattr(args, "process", None):
        return None
    pace = getattr(args, "realtime_factor", None)
    if not (args.fast or pace is not None):
        return None
    from afa.bridge.lockstep import SteppedClock

    return SteppedClock(pace=pace)


def system_options(args: argparse.Namespace) -> dict[str, Any]:
    """``process`` and ``bridge`` options for ``System.from_xml``."""
    options: dict[str, Any] = {}
    if getattr(args, "process", None):
        options["process"] = args.process
    overrides = {key: value for key, value in (
        ("Listen", args.listen), ("Connect", args.connect),
        ("AllowCommandFrom", args.allow_command)) if value}
    if overrides:
        options["bridge"] = overrides
    elif args.bridge:
        options["bridge"] = True
    return options


def _bridge(system: Any) -> Any:
    """The run's Bridge service, or None."""
    from afa.bridge.bridge import Bridge

    return next((s for s in system.services if isinstance(s, Bridge)), None)


def summary(system: Any) -> dict[str, Any]:
    """The bridge's part of a run summary (``bridge``: its counters), if it has one."""
    bridge = _bridge(system)
    return {} if bridge is None else {"bridge": bridge.statistics()}


def describe(system: Any) -> str | None:
    """One line saying where the run's bridge listens and connects (None without one)."""
    bridge = _bridge(system)
    if bridge is None:
        return None
    p = bridge.parameters
    return (f"bridge: process {bridge.process!r} of {bridge.robot!r}, listening on "
            f"{', '.join(p.Listen) or 'nothing'}, connecting to "
            f"{', '.join(p.Connect) or 'nothing'}")
