"""Obstacle Avoidance parameters: seed Table A.10, section ``ObsAvoid``.

Units: ``-`` marks names and flags, ``1`` a dimensionless number.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from afa.config.parameters import Parameters, param

__all__ = ["ObstacleAvoidanceParameters"]


class ObstacleAvoidanceParameters(Parameters):
    """Candidate arcs scored on the traversability map (seed Table A.10)."""

    CurveMakingConst: Annotated[float, Field(gt=0)] = param(
        0.01, unit="m",
        description="A distance(m) which the algorithm steps through to construct an "
                    "approximation of the candidate arc")
    VehicleRadius: Annotated[float, Field(gt=0)] = param(
        0.5, unit="m",
        description="A radius(m) of a circle which approximates the size of the vehicle")
    MaxVelocity: Annotated[float, Field(gt=0)] = param(
        2.0, unit="m/s", description="The top speed(m/s) which the algorithm will allow for "
                                     "any arc")
    MinVelocity: Annotated[float, Field(ge=0)] = param(
        0.5, unit="m/s", description="The lowest speed(m/s) the algorithm will suggest for "
                                     "any arc before vetoing it")
    NearZone: Annotated[int, Field(ge=0)] = param(
        0, unit="rows",
        description="The number of map rows immediately in front of the vehicle to ignore "
                    "obstacles. Makes it possible to ignore parts of the map.")
    FarZone: Annotated[int, Field(ge=0)] = param(
        39, unit="rows",
        description="The number of map rows immediately in front of the vehicle to "
                    "evaluate. Makes it possible to ignore parts of the map which are too far "
                    "away to be important.")
    DistFactor: Annotated[float, Field(ge=0, le=100)] = param(
        0.0, unit="%",
        description="A percentage by which to discount the cells estimation for distance")
    MinDistDiscount: Annotated[float, Field(ge=0, le=1)] = param(
        1.0, unit="1",
        description="A number between 0 and 1 which indicates how low we can discount for "
                    "distance (1 = no discount)")
    MapDepth: Annotated[int, Field(gt=0)] = param(
        16000, unit="mm", description="The depth of the Traversability Map(mm).")
    MapWidth: Annotated[int, Field(gt=0)] = param(
        16000, unit="mm", description="The width of the Traversability Map(mm).")
    MapGridsize: Annotated[float, Field(gt=0)] = param(
        0.01, unit="mm",
        description="The size of each cell in the Traversability Map(mm). The seed's 0.01 "
                    "cannot be millimetres (the ego traversability map's cells are 500 mm, "
                    "Table A.7); it is kept as printed, and the cell size carried in each "
                    "Traverse event is authoritative")
    DiscountSpeeds: bool = param(
        False, unit="-",
        description="Whether or not the vehicles speed will be controlled based on the "
                    "obstacle map.")
    CostUnknownCells: bool = param(
        False, unit="-",
        description="Whether or not to consider unknown portions of the map as obstacles.")
    VetoUnknownCells: bool = param(
        False, unit="-",
        description="Whether or not to consider unknown portions of the map as obstacles.")
    TraverseEventName: str = param(
        "Traverse", unit="-",
        description="afa addition: subscribed traversability map event name")
    VoteEventName: str = param("ArcVote", unit="-",
                               description="afa addition: name of the ArcVote events published")
    PlatformName: str = param(
        "ModelService", unit="-",
        description="afa addition: name ModelServer's Platform interface is offered under "
                    "(for the ego map frame's place on the vehicle)")
    DiscOffsets: tuple[float, ...] = param(
        (0.0, 0.8, 1.6, 2.4), unit="m",
        description="afa addition: where along the body (m ahead of the rear axle) a disc "
                    "of VehicleRadius is swept along each arc; together they cover the "
                    "body from the rear axle to the front bumper")
    HazardMargin: Annotated[float, Field(ge=0)] = param(
        0.25, unit="m",
        description="afa addition: how far inside its cell's edges a hazard is taken to "
                    "lie (each hazard cell shrunk by it on every side, up to half a cell: "
                    "its centre). The Traversability Map marks the cells beside a step as "
                    "hazards too, so a hazard cell's obstacle lies half a cell or more "
                    "beyond its centre (0.25 m at its 0.5 m cells); 0 is the seed's "
                    "conservative reading, a hazard anywhere in its cell")
    VetoDistance: Annotated[float, Field(gt=0, allow_inf_nan=True)] = param(
        2.5, unit="m",
        description="afa addition: an arc is vetoed when its first obstacle lies within "
                    "this much rear-axle travel; a farther obstacle only shortens its free "
                    "distance (and its vote). inf: any obstacle within the horizon vetoes, "
                    "which leaves no arc to turn on in a tight spot")

    @model_validator(mode="after")
    def _ranges(self) -> ObstacleAvoidanceParameters:
        if self.MinVelocity > self.MaxVelocity:
            raise ValueError(f"MinVelocity ({self.MinVelocity}) exceeds MaxVelocity "
                             f"({self.MaxVelocity})")
        if self.NearZone > self.FarZone:
            raise ValueError(f"NearZone ({self.NearZone}) exceeds FarZone ({self.FarZone})")
        return self
