"""Vehicle control structs (seed §3.5, Tables 26, 27).

Speeds are SI (m/s). Miro's ``VelocityIDL`` carried ``long translation`` in mm/s and
the seed's Vehicle Control reports mm/s; afa converts at the MPC555 codec, so no
component sees millimetres.
"""

from __future__ import annotations

from pydantic import model_validator

from idl._base import field
from idl.common import TimeIDL, _Struct

__all__ = ["VelocityIDL", "VelocityDataIDL", "MinMaxVelocityIDL"]


class VelocityIDL(_Struct):
    """A velocity command or report: translation, rotation and steering angle.

    On the Ackermann-steered Raptor the steering angle is what Vehicle Control
    commands (it also holds at zero speed, where ``rotation`` is 0); ``rotation`` is
    the yaw rate, ``translation · tan(steeringAngle) / wheelbase`` for a bicycle model,
    kept for Miro compatibility and for differential-drive platforms.
    """

    translation: float = field(0.0, unit="m/s", allow_inf_nan=False,
                               description="forward speed, reverse negative")
    rotation: float = field(0.0, unit="rad/s", allow_inf_nan=False,
                            description="yaw rate, counter-clockwise positive")
    steeringAngle: float = field(0.0, unit="rad", allow_inf_nan=False,
                                 description="front wheel angle, left positive")


class VelocityDataIDL(_Struct):
    """Vehicle Control's ``VelocityData`` event (seed Table 27): measured and target."""

    time: TimeIDL = field(unit="", description="time stamp of the MPC555 report")
    velocity: VelocityIDL = field(unit="", description="measured velocity and steering")
    target: VelocityIDL = field(default_factory=VelocityIDL, unit="",
                                description="the velocity currently commanded")
    vehicleStarted: bool = field(False, unit="", description="startVehicle() is in effect")
    arbiterEnabled: bool = field(False, unit="", description="setArbiter(true) is in effect: "
                                                             "the Arc Arbiter may command")


class MinMaxVelocityIDL(_Struct):
    """The result of ``getMinMaxVelocity()`` (Miro's four ``out`` parameters, plus
    the steering limit of Table A.13)."""

    minTranslation: float = field(unit="m/s", allow_inf_nan=False,
                                  description="lowest accepted translation (reverse < 0)")
    maxTranslation: float = field(unit="m/s", allow_inf_nan=False,
                                  description="highest accepted translation")
    minRotation: float = field(unit="rad/s", allow_inf_nan=False,
                               description="lowest accepted rotation")
    maxRotation: float = field(unit="rad/s", allow_inf_nan=False,
                               description="highest accepted rotation")
    maxSteeringAngle: float = field(unit="rad", ge=0.0, allow_inf_nan=False,
                                    description="steering limit, either side")

    @model_validator(mode="after")
    def _check(self) -> MinMaxVelocityIDL:
        if self.minTranslation > self.maxTranslation or self.minRotation > self.maxRotation:
            raise ValueError("a minimum exceeds its maximum")
        return self

    def accepts(self, velocity: VelocityIDL) -> bool:
        """True if ``velocity`` lies within every limit."""
        return (self.minTranslation <= velocity.translation <= self.maxTranslation
                and self.minRotation <= velocity.rotation <= self.maxRotation
                and abs(velocity.steeringAngle) <= self.maxSteeringAngle)
