"""FindPath (D* Lite planner and path tracker) parameters: seed Table A.9, section
``FindPath``.

Lookahead and tolerance are in planning grid cells (GlobalMapConfig's ``Gridsize``).
Units: ``-`` marks names and flags.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from afa.config.parameters import Parameters, param

__all__ = ["FindPathParameters"]


class FindPathParameters(Parameters):
    """Path planning over the Global Map and tracking by arc votes (seed Table A.9)."""

    MaxLookahead: Annotated[float, Field(gt=0)] = param(
        20.0, unit="cells",
        description="The maximum distance (in planning grid units) along the planned path "
                    "from the point on the path closest to the vehicle's current position "
                    "that the tracking algorithm will search.")
    MinLookahead: Annotated[float, Field(ge=0)] = param(
        7.0, unit="cells",
        description="The minimum distance (in planning grid units) along the planned path "
                    "from the point on the path closest to the vehicle's current position "
                    "that the tracking algorithm will search.")
    TrackingTolerance: Annotated[float, Field(gt=0)] = param(
        30.0, unit="cells",
        description="The maximum distance (in planning grid units) the vehicle can be from "
                    "the planned path without forcing a replanning episode.")
    PlanUpdateDelayTime: Annotated[float, Field(ge=0)] = param(
        5.0, unit="s", description="The delay (s) prior to the first call to generate a "
                                   "ArcVoteIDL event.")
    PlanEventInterval: Annotated[float, Field(gt=0)] = param(
        1.0, unit="s", description="The interval (s) between successive ArcVoteIDL events.")
    ChannelName: str = param(
        "EventChannel", unit="-",
        description="afa addition: event channel name (named in the seed's section 3.3.1 "
                    "text but absent from Table A.9)")
    GlobalMapName: str = param(
        "GlobalMap", unit="-",
        description="afa addition: name of the Global Map planning interface (Table 18) "
                    "resolved in the naming service")
    VoteEventName: str = param("ArcVote", unit="-",
                               description="afa addition: name of the ArcVote events published")
    PathEventName: str = param(
        "PlannedPath", unit="-",
        description="afa addition: name of the PlannedPath events published for displays")
    PlatformName: str = param(
        "ModelService", unit="-",
        description="afa addition: name ModelServer's Platform interface is offered under "
                    "(polled for the vehicle pose)")
    InflationRadius: Annotated[float, Field(ge=0)] = param(
        1.5, unit="cells",
        description="afa addition: impassable cells are grown by this many planning cells "
                    "(the vehicle's half width, 0.7 m, at 0.5 m cells), so a path for the "
                    "rear axle keeps the body clear")
    MarginRadius: Annotated[float, Field(ge=0)] = param(
        3.0, unit="cells",
        description="afa addition: cells this close to an impassable cell cost at least "
                    "MarginCost, so paths keep a little distance where they can")
    MarginCost: Annotated[float, Field(ge=1)] = param(
        3.0, unit="1", description="afa addition: the least cost of a margin cell")
    RefineDistance: Annotated[float, Field(ge=0)] = param(
        10.0, unit="m",
        description="afa addition: FindPath tracks a drivable path (arcs within the arc "
                    "set's curvature, the body as discs) to the point of the D* "
                    "path this far ahead, rather than the D* path itself, where one is "
                    "found (docs/decisions/0024-kinematic-refinement.md); 0 tracks the "
                    "D* path")
    DiscOffsets: tuple[float, ...] = param(
        (0.0, 0.8, 1.6, 2.4), unit="m",
        description="afa addition: where along the body (m ahead of the rear axle) the "
                    "refinement checks a disc of DiscRadius for obstacles; together they "
                    "cover the body from bumper to bumper")
    GroundFrame: str = param(
        "Raptor: Front-BumperCenter", unit="-",
        description="afa addition: the frame on the ground under the front bumper "
                    "(ModelServer's geometry), where the Global Map also judges a "
                    "waypoint reached: where the rear axle cannot come near the waypoint "
                    "(short of a wall it faces), a drivable path to it ends with this "
                    "point within its tolerance")
    DiscRadius: Annotated[float, Field(gt=0)] = param(
        0.81, unit="m",
        description="afa addition: the radius of the refinement's body discs: with discs "
                    "0.8 m apart over the Raptor's 1.4 m width, sqrt(0.7^2 + 0.4^2) covers "
                    "the whole body")
    ReverseCost: Annotated[float, Field(ge=0)] = param(
        3.0, unit="1",
        description="afa addition: the drivable path may also back (the same arcs in "
                    "reverse, over ground the map has seen), each metre costing this "
                    "many times a metre forwards; a path that starts backing asks the "
                    "arbiter to back first (docs/decisions/0046-planned-reverse.md). 0 "
                    "plans forward arcs only")
    ReverseSwitchCost: Annotated[float, Field(ge=0)] = param(
        3.0, unit="m",
        description="afa addition: what each change between forwards and reverse adds "
                    "to a drivable path's cost, in metres of cost-1 ground")

    @model_validator(mode="after")
    def _lookahead_range(self) -> FindPathParameters:
        if self.MinLookahead > self.MaxLookahead:
            raise ValueError(f"MinLookahead ({self.MinLookahead}) exceeds MaxLookahead "
                             f"({self.MaxLookahead})")
        return self
