"""What a running process tells the tools about itself (the ``afa/<Robot>/info/<process>``
queryable): its components with their state, health, restarts, events in and out and
share of the loop's time (``afa top``), its names with types and owners (``afa names``),
its catalog (types of every event, ``afa poll`` argument parsing), its clock, memory and
the bridge's counters. JSON, so that any Zenoh client can read it.
"""

from __future__ import annotations

import os
import resource
import socket
import sys
from typing import Any

from pydantic import TypeAdapter, ValidationError
from typing_extensions import TypedDict  # pydantic reads this one on Python < 3.12

from afa.ports import interface_name

__all__ = ["process_info", "memory", "info_problem", "INFO_VERSION"]

#: Bumped when a field changes meaning; tools refuse newer versions.
INFO_VERSION = 1


class _ComponentRow(TypedDict):
    name: str
    type: str
    state: str
    healthy: bool
    detail: str
    restarts: int


class _NameRow(TypedDict):
    name: str
    interface: str
    owner: str
    process: str
    remote: bool


class _InfoDocument(TypedDict):
    """What the tools read of an info document by key (the rest they read with
    defaults): checked before any tool uses a document a peer sent."""

    robot: str
    process: str
    pid: int
    host: str
    components: list[_ComponentRow]
    names: list[_NameRow]
    event_types: dict[str, list[str]]
    catalog: list[dict[str, Any]]


_INFO = TypeAdapter(_InfoDocument)


def info_problem(document: Any) -> str | None:
    """Why ``document`` (a peer's answer on ``afa/<Robot>/info/*``, parsed JSON) is not an
    info document of :data:`INFO_VERSION` the tools can read, or None when it is."""
    if not isinstance(document, dict):
        return f"not a JSON object but {type(document).__name__}"
    if document.get("version") != INFO_VERSION:
        return f"version {document.get('version')!r}, this program reads {INFO_VERSION}"
    try:
        _INFO.validate_python(document, strict=True)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(part) for part in first["loc"])
        return f"{where}: {first['msg']}"
    return None


def memory() -> dict[str, int]:
    """Resident memory of this process now and at its peak, bytes (Linux ``/proc``; the
    peak alone elsewhere)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    peak *= 1 if sys.platform == "darwin" else 1024
    now = 0
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("VmRSS:"):
                    now = int(line.split()[1]) * 1024
                elif line.startswith("VmHWM:"):
                    peak = int(line.split()[1]) * 1024
    except OSError:
        pass
    return {"rss_bytes": now, "peak_rss_bytes": peak}


def names(system: Any) -> list[dict[str, Any]]:
    """Every bound name with its interface, owner and process."""
    rows = []
    for name in system.registry.list():
        obj = system.registry.try_resolve(name)
        owner = system.registry.owner(name)
        interface = getattr(obj, "interface", None)
        process = getattr(obj, "process", None) or system.process
        rows.append({
            "name": name,
            "interface": interface_name(interface) if isinstance(interface, type)
            else type(obj).__name__,
            "owner": getattr(owner, "name", None) or ("system" if owner is system else ""),
            "process": process,
            "remote": process != system.process,
        })
    return rows


def components(system: Any) -> list[dict[str, Any]]:
    meter = system.meter.snapshot() if system.meter is not None else {"accounts": {}}
    accounts = meter["accounts"]
    rows = []
    for name, component in system.components.items():
        health = component.health()
        account = accounts.get(name, {})
        rows.append({
            "name": name, "type": component.type_name, "state": health.state.value,
            "healthy": health.healthy, "detail": health.detail, "restarts": health.restarts,
            "failures": health.failures, "last_error": health.last_error,
            **{f"events_{k}": v for k, v in component.traffic().items()},
            "loop_share": account.get("share"), "loop_busy_s": account.get("busy_s"),
            "loop_longest_s": account.get("longest_s"),
        })
    return rows


def process_info(system: Any, bridge: Any) -> dict[str, Any]:
    """The info document of ``system`` (see the module docstring)."""
    statistics = system.statistics()
    meter = system.meter.snapshot() if system.meter is not None else None
    return {
        "version": INFO_VERSION,
        "robot": system.robot,
        "process": system.process,
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "zid": bridge.zid,
        "clock": {"kind": type(system.clock).__name__, "now": system.clock.now(),
                  "monotonic": system.clock.monotonic()},
        "components": components(system),
        "names": names(system),
        "catalog": system.catalog().as_dicts(),
        "event_types": {name: sorted(types) for name, types in
                        system.catalog().event_types().items()},
        "events": statistics["events"],
        "events_published": statistics["events_published"],
        "events_dropped": statistics["events_dropped"],
        "observers": statistics["observers"],
        "loop": None if meter is None else {
            "wall_s": meter["wall_s"],
            "other": {name: a for name, a in meter["accounts"].items()
                      if name not in system.components}},
        "memory": memory(),
        "bridge": bridge.statistics(),
        "notes": list(system.notes),
    }
