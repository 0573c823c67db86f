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

    @model_validator(mode="after")
    def _lookahead_range(self) -> FindPathParameters:
        if self.MinLookahead > self.MaxLookahead:
            raise ValueError(f"MinLookahead ({self.MinLookahead}) exceeds MaxLookahead "
                             f"({self.MaxLookahead})")
        return self
