"""Which remote calls command the vehicle, and who may make them (SPEC §4 "safe by
default"; issue 14, item 3).

A call *commands* when it can set the vehicle moving or change who drives it:

==========================  ===========================================================
interface                   commanding methods
==========================  ===========================================================
VehicleControl              ``setVelocity``, ``setJoystickVelocity``, ``startVehicle``,
                            ``setArbiter``
VehiclePlan (Pure Pursuit)  ``setWaypointList``, ``setPatrolMode``, ``setHalt(false)``
GlobalMap                   ``setWaypointList`` (FindPath plans to these waypoints)
==========================  ===========================================================

``stopVehicle`` and ``setHalt(true)`` only ever stop the vehicle and are allowed from
anyone, as a kill switch should be. Every other method reads or writes data that does
not move the vehicle by itself.

A process refuses a commanding call that arrives over the bridge unless its
``Bridge/AllowCommandFrom`` names the caller (a process name, a Zenoh id, or ``*``): the
call raises :class:`~afa.errors.CommandRefused` at the caller. The caller's name is what
the caller says it is: on a network, Zenoh's TLS with client certificates and its access
control rules are what make it true (``docs/distributed.md``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from afa.errors import CommandRefused
from idl import GlobalMap, VehicleControl, VehiclePlan
from idl._base import Interface

__all__ = ["commands", "check_command", "COMMANDING"]


def _always(arguments: dict[str, Any]) -> bool:
    return True


#: (interface, method) -> does this call, with these arguments, command the vehicle?
COMMANDING: dict[tuple[type[Interface], str], Callable[[dict[str, Any]], bool]] = {
    (VehicleControl, "setVelocity"): _always,
    (VehicleControl, "setJoystickVelocity"): _always,
    (VehicleControl, "startVehicle"): _always,
    (VehicleControl, "setArbiter"): _always,
    (VehiclePlan, "setWaypointList"): _always,
    (VehiclePlan, "setPatrolMode"): _always,
    (VehiclePlan, "setHalt"): lambda arguments: not arguments.get("halt", False),
    (GlobalMap, "setWaypointList"): _always,
}


def commands(interface: type[Interface], method: str, arguments: dict[str, Any]) -> bool:
    """Whether calling ``interface.method(**arguments)`` commands the vehicle (an
    interface derived from a listed one inherits its rule)."""
    for (base, name), rule in COMMANDING.items():
        if name == method and issubclass(interface, base):
            return rule(arguments)
    return False


def check_command(interface: type[Interface], method: str, arguments: dict[str, Any],
                  caller: Sequence[str], allowed: Sequence[str], *, server: str) -> None:
    """Raise :class:`~afa.errors.CommandRefused` if the call commands the vehicle and no
    identity in ``caller`` (process name, Zenoh id) is in ``allowed`` (``*``: anyone)."""
    if not commands(interface, method, arguments):
        return
    if "*" in allowed or any(identity and identity in allowed for identity in caller):
        return
    who = caller[0] if caller and caller[0] else "an unnamed peer"
    raise CommandRefused(
        f"{server}.{method} from {who} refused: remote calls that move the vehicle are "
        "off unless the serving process's Bridge/AllowCommandFrom names the caller")
