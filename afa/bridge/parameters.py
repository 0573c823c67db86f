"""The ``Bridge`` section: how a process joins the others over Eclipse Zenoh.

Validating a configuration imports this module, never Zenoh. The section's default set
configures the ``main`` process (a configuration without process groups, or ``afa run
CONFIG --bridge``); an ``<instance>`` named after a process group configures that group's
process (``afa run CONFIG --process vehicle`` reads ``Bridge/vehicle`` if present, else
the default set). Command-line options override single fields
(:func:`bridge_parameters`).

Safe by default: the bridge is off unless enabled (or a process group is run), it
listens on loopback only, multicast scouting is off, and no remote peer may command the
vehicle (``AllowCommandFrom`` is empty).
"""

from __future__ import annotations

import re
from typing import Annotated, Any, Literal

from pydantic import Field, field_validator

from afa.config.parameters import Parameters, param

__all__ = ["BridgeParameters", "DEFAULT_ENDPOINT", "bridge_parameters"]

#: Zenoh's registered port, on loopback: where a single process listens and where the
#: text tools look for a running system by default.
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"

_ENDPOINT = re.compile(r"[a-z][a-z0-9-]*/\S+")
_PATTERN = re.compile(r"[^/$#]+")


class BridgeParameters(Parameters):
    """Section ``Bridge``: the Zenoh bridge of one process (afa addition)."""

    namespace = "Afa"
    Enabled: bool = param(False, description="Run the bridge in this process (`afa run "
                                             "--bridge`; implied by `--process`)")
    Mode: Literal["peer", "client"] = param(
        "peer", description="Zenoh mode: peer (processes connect to each other) or client "
                            "(through a Zenoh router)")
    Listen: list[str] = param(
        [DEFAULT_ENDPOINT], description="Zenoh endpoints to listen on; loopback unless "
                                        "configured otherwise (`tcp/127.0.0.1:0`: any free port)")
    Connect: list[str] = param([], description="Zenoh endpoints of peers (or a router) to "
                                               "connect to")
    MulticastScouting: bool = param(
        False, description="Find peers by UDP multicast (off: only the endpoints above)")
    Export: list[str] = param(["*"], description="Event and served names offered to other "
                                                 "processes (patterns with * ? [...])")
    Import: list[str] = param(["*"], description="Event and served names taken from other "
                                                 "processes (patterns)")
    AllowCommandFrom: list[str] = param(
        [], description="Processes (names or Zenoh ids) allowed to make remote calls that "
                        "move the vehicle (setVelocity, startVehicle, setWaypointList, "
                        "setHalt(false), ...); stopVehicle and setHalt(true) are always allowed")
    EventBuffer: Annotated[int, Field(ge=16)] = param(
        4096, unit="events", description="Imported events waiting for the loop (drop-oldest, "
                                         "counted)")
    ExportBuffer: Annotated[int, Field(ge=16)] = param(
        4096, unit="events", description="Events waiting to be exported (drop-oldest, counted): "
                                         "a slow network never slows a publisher")
    MaxQueries: Annotated[int, Field(ge=1)] = param(
        64, unit="calls", description="Remote polls served at once; more are refused (EDevIO)")
    TimeMaster: str = param(
        "", description="In virtual time (--fast), the process whose clock the others follow "
                        "in lock-step ('' = the group of the first Launcher entry)")
    JoinTimeout: Annotated[float, Field(gt=0)] = param(
        30.0, unit="s", description="Real seconds the time master waits for the other process "
                                    "groups to join")
    Express: bool = param(
        False, description="Send each event on its own instead of letting Zenoh batch small "
                           "ones (batching: a third of the CPU per event and no drops in a "
                           "flood, the same median latency; benchmarks/bridge.py)")
    ZenohConfig: str = param(
        "", description="A Zenoh JSON5 configuration file applied first (TLS, access control); "
                        "relative to the configuration's folder")

    @field_validator("Listen", "Connect")
    @classmethod
    def _endpoints(cls, values: list[str]) -> list[str]:
        for value in values:
            if not _ENDPOINT.fullmatch(value):
                raise ValueError(f"{value!r} is not a Zenoh endpoint (protocol/address, e.g. "
                                 f"{DEFAULT_ENDPOINT})")
        return values

    @field_validator("Export", "Import")
    @classmethod
    def _patterns(cls, values: list[str]) -> list[str]:
        for value in values:
            if not _PATTERN.fullmatch(value):
                raise ValueError(f"{value!r}: a name pattern has no '/', '$' or '#'")
        return values


def bridge_parameters(configuration: Any, process: str | None,
                      **overrides: Any) -> BridgeParameters:
    """The Bridge parameters of ``process`` in ``configuration`` (a validated
    :class:`~afa.config.loader.Configuration`, or None), with ``overrides`` (field name ->
    value; None values are ignored) applied and validated."""
    sets: dict[str, Any] = {}
    if configuration is not None:
        sets = configuration.sections.get("Bridge", {})
    chosen = sets.get(process or "") or sets.get("default") or BridgeParameters()
    values = chosen.model_dump()
    values.update({k: v for k, v in overrides.items() if v is not None})
    return BridgeParameters.model_validate(values)


def _loopback(endpoint: str) -> bool:
    host = endpoint.partition("/")[2].rpartition(":")[0].strip("[]")
    return host in ("127.0.0.1", "localhost", "::1") or host.startswith("127.")


def off_loopback(parameters: BridgeParameters) -> list[str]:
    """The listen and connect endpoints that are not on loopback (for a start-up note)."""
    return [e for e in [*parameters.Listen, *parameters.Connect] if not _loopback(e)]
