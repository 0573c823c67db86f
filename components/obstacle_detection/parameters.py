"""Obstacle Detection (laser safety catch) parameters: seed Table A.11, section
``ObstacleDetection``.

``LaserHeight`` (2 m) is the nod axis height in the geometry model (docs/geometry.md);
Table A.1's ``MountHeight`` (3.0 m) disagrees and is used only for adaptive nodding.

Units: ``-`` marks names and flags, ``1`` a count.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from afa.config.parameters import Parameters, param

__all__ = ["ObstacleDetectionParameters"]


class ObstacleDetectionParameters(Parameters):
    """Halts the vehicle on positive or negative obstacles just ahead (seed Table A.11)."""

    SafetyHeight: Annotated[float, Field(gt=0)] = param(
        0.3, unit="m", description="The maximum obstacle height considered safe(m)")
    SafetyDepth: Annotated[float, Field(gt=0)] = param(
        0.3, unit="m", description="The maximum obstacle depth considered safe(m)")
    SafetyDist: Annotated[float, Field(gt=0)] = param(
        3.0, unit="m", description="How far in front of the vehicle to check for obstacles(m)")
    VehicleWidth: Annotated[float, Field(gt=0)] = param(
        1.0, unit="m", description="The approximate width of the vehicle(m)")
    DefaultYMax: Annotated[float, Field(gt=0)] = param(
        3.0, unit="m",
        description="How far to the left/right of the vehicle to check for obstacles(m)")
    LaserHeight: Annotated[float, Field(gt=0)] = param(
        2.0, unit="m", description="The height of the laser sensor above the ground")
    NumHitsTolerance: Annotated[int, Field(ge=1)] = param(
        5, unit="1",
        description="How many laser range returns outside the safety height/depth triggers "
                    "an obstacle detection")
    MaxLaserRange: Annotated[int, Field(gt=0)] = param(
        8191, unit="mm",
        description="How far the laser sensor can see (mm) (8191 = 2^13 - 1, the SICK LMS "
                    "2xx's largest millimetre-mode range value)")
    CheckPosObs: bool = param(True, unit="-",
                              description="Whether or not to look for positive obstacles")
    CheckNegObs: bool = param(True, unit="-",
                              description="Whether or not to look for negative obstacles")
    ResetCounter: Annotated[int, Field(ge=0)] = param(
        200, unit="scans",
        description="How many laser scans to wait after a halt before rechecking for "
                    "obstacles")
    RangeEventNames: list[str] = param(
        ["Laser11", "Laser12"], unit="-",
        description="afa addition: subscribed Range3d laser event names (the seed: 'one or "
                    "more range sensors')")
    VoteEventName: str = param("ArcVote", unit="-",
                               description="afa addition: name of the ArcVote events published")
    PlatformName: str = param(
        "ModelService", unit="-",
        description="afa addition: name ModelServer's Platform interface is offered under "
                    "(for the lasers' mounting transforms)")

    @model_validator(mode="after")
    def _some_sensor(self) -> ObstacleDetectionParameters:
        if not self.RangeEventNames:
            raise ValueError("RangeEventNames is empty: the safety catch needs a range sensor")
        return self
