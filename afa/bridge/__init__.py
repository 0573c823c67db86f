"""Components across processes and machines, over Eclipse Zenoh (SPEC §3.11).

A :class:`~afa.bridge.bridge.Bridge` in a running :class:`~afa.System` exports the
events and served interfaces its configuration selects and imports the other processes'
ones into the local event channel and name registry, so components never know whether a
peer is local. See ``docs/distributed.md`` and decisions 0011 (time) and 0012 (bridge).

Importing this package imports neither Zenoh nor the system: the parameter model is
read by every configuration check; :class:`Bridge` is loaded on first use.
"""

from __future__ import annotations

from typing import Any

from afa.bridge.parameters import DEFAULT_ENDPOINT, BridgeParameters, bridge_parameters

__all__ = ["Bridge", "BridgeParameters", "DEFAULT_ENDPOINT", "bridge_parameters"]


def __getattr__(name: str) -> Any:
    if name == "Bridge":
        from afa.bridge.bridge import Bridge

        return Bridge
    raise AttributeError(f"module 'afa.bridge' has no attribute {name!r}")
