"""Nodding Laser parameters: seed Table A.1, section ``NodLaserConfig``.

One named instance per laser (``Laser11``, ``Laser12``): the instance's ``EventName`` is
both the published event name and the name the component registers in the naming
service, and ``LaserID`` is copied into every Range3d event.

Units: ``-`` marks names and flags, ``1`` a dimensionless number. Angles are degrees,
as Miro writes them.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, field_validator, model_validator

from afa.config.parameters import Parameters, param

__all__ = ["NodLaserParameters", "SICK_RESOLUTIONS"]

#: Angular resolutions of the SICK LMS 2xx in 1/100 degree (SICK telegram listing,
#: variant switch 0x3B; sicktoolbox ``sick_lms_2xx_scan_resolution_t``: 25, 50, 100).
SICK_RESOLUTIONS = (25, 50, 100)


class NodLaserParameters(Parameters):
    """One nodding SICK LMS 211 (seed Table A.1)."""

    EventChannelName: str = param("EventChannel", unit="-",
                                  description="The event channel's name")
    EventName: str = param("Laser11", unit="-", description="Name of events published")
    LaserID: Annotated[int, Field(ge=0)] = param(
        11, unit="1", description="I.D. encoded in the event structure")
    Host: str = param("131.135.74.200", unit="-", description="Nodding Laser I.P. Address")
    Port: Annotated[int, Field(ge=1, le=65535)] = param(
        24750, unit="-", description="Nodding Laser Port Number")
    Baudrate: Annotated[int, Field(gt=0)] = param(
        500000, unit="baud",
        description="Nodding Laser Baudrate (the LMS 211's RS-422 link to the nodding "
                    "controller; the LMS 2xx supports 9600, 19200, 38400 and 500000)")
    Motorrates: Annotated[float, Field(gt=0)] = param(
        15.0, unit="deg/s", description="Nodding Rate Deg/sec")
    LowAngle: float = param(-40.0, unit="deg", description="Lowest Nod angle, degrees")
    HighAngle: float = param(-10.0, unit="deg", description="Highest Nod angle, degrees")
    LaserOffsetAngle: float = param(
        -2.0, unit="deg", description="A tweaking parameter to adjust the mount angle")
    Laserres: int = param(
        50, unit="0.01 deg",
        description="Laser Resolution, see the SICK Manual (angular resolution in 1/100 "
                    "degree: 25, 50 or 100; 50 = 0.5 deg, whose 26.6 ms scan period is "
                    "the seed's Table 1 update rate)")
    MountAngle: float = param(
        -14.0, unit="deg", description="Mount angle of the laser - Used for adaptive nodding")
    MountHeight: Annotated[float, Field(gt=0)] = param(
        3.0, unit="m",
        description="Mounting Ht. above ground (m) - Used for adaptive nodding. The seed's "
                    "3.0 disagrees with Table A.11's LaserHeight 2 m and the geometry "
                    "model (docs/geometry.md); only the adaptive-nodding heuristic uses it")
    ScanDistance: Annotated[float, Field(gt=0)] = param(
        0.2, unit="m", description="Scan distance (m) - Used for adaptive nodding")
    AdaptiveNodding: bool = param(
        False, unit="-",
        description="afa addition: limit the nod to MountAngle and slow it so scan lines "
                    "land at most ScanDistance apart (components/nodding_laser/component.py "
                    "nod_plan); the seed names the inputs but not the switch")

    @field_validator("Laserres")
    @classmethod
    def _sick_resolution(cls, value: int) -> int:
        if value not in SICK_RESOLUTIONS:
            raise ValueError(f"the SICK LMS 2xx resolution is one of {SICK_RESOLUTIONS} "
                             "(1/100 degree)")
        return value

    @model_validator(mode="after")
    def _nod_range(self) -> NodLaserParameters:
        if not self.LowAngle < self.HighAngle:
            raise ValueError(f"LowAngle ({self.LowAngle}) must be below HighAngle "
                             f"({self.HighAngle})")
        return self
