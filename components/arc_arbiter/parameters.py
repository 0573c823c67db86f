"""Arc Arbiter parameters: seed Table A.12, section ``ArcArbiter``.

A vote is stale ``StaleVoteTimeSec`` seconds plus ``StaleVoteTimeUSec`` microseconds
after its time stamp (a ``TimeIDL {sec, usec}`` split, 1.5 s by default).

Units: ``-`` marks names, ``1`` a dimensionless weight.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from afa.config.parameters import Parameters, param

__all__ = ["ArcArbiterParameters"]

Weight = Annotated[float, Field(ge=0)]


class ArcArbiterParameters(Parameters):
    """Weighted arc votes, vetoes and maximum speed into one command (seed Table A.12)."""

    ObsWeight: Weight = param(
        1.0, unit="1",
        description="The importance of Obstacle Avoidance's votes (1 being standard)")
    PursuitWeight: Weight = param(1.0, unit="1",
                                  description="The importance of Pure Pursuit's votes")
    PlannerWeight: Weight = param(1.0, unit="1",
                                  description="The importance of Find Path's votes")
    LaserSafetyWeight: Weight = param(
        1.0, unit="1", description="The importance of Obstacle Detections's votes")
    TransVelocitySetPoint: Annotated[float, Field(ge=0)] = param(
        0.5, unit="m/s", description="The maximum allowed vehicle speed (m/s)")
    StaleVoteTimeSec: Annotated[int, Field(ge=0)] = param(
        1, unit="s",
        description="How long to hang on to a vote before considering it stale (whole "
                    "seconds part)")
    StaleVoteTimeUSec: Annotated[int, Field(ge=0, le=999999)] = param(
        500000, unit="us",
        description="How long to hang on to a vote before considering it stale "
                    "(microseconds part)")
    VoteEventName: str = param("ArcVote", unit="-",
                               description="afa addition: subscribed ArcVote event name")
    VehicleControlName: str = param(
        "RaptorMotion", unit="-",
        description="afa addition: name of the Vehicle Control interface whose setVelocity "
                    "the arbiter calls (RaptorCommandConfig's RaptorMotionEvent)")
    DecisionEventName: str = param(
        "ArcDecision", unit="-",
        description="afa addition: name of the ArcDecision events published for displays "
                    "and logs (the seed's arbiter publishes nothing)")
    RequiredBehaviours: list[str] = param(
        [], unit="-",
        description="afa addition: behaviours without whose fresh vote the vehicle stops "
                    "(e.g. PurePursuit: Obstacle Avoidance alone must not wander); empty as "
                    "in the seed")

    RecoverAfter: Annotated[float, Field(ge=0)] = param(
        3.0, unit="s",
        description="afa addition: back out of a dead end after every arc has been vetoed "
                    "this long (components/arc_arbiter/recovery.py); 0: never, stand still "
                    "as the seed's arbiter does")
    RecoverDistance: Annotated[float, Field(gt=0, le=10)] = param(
        2.5, unit="m", description="afa addition: how far one back-out reverses")
    RecoverSpeed: Annotated[float, Field(gt=0, le=1)] = param(
        0.3, unit="m/s", description="afa addition: the reversing speed of a back-out")
    RecoverLimit: Annotated[int, Field(ge=0)] = param(
        3, unit="1",
        description="afa addition: back-outs in a row (no decision between them lets the "
                    "vehicle drive) after which the arbiter stands and reports itself "
                    "unhealthy: votes that stay vetoed (no path to the waypoint at all) "
                    "must not reverse the vehicle blind for ever; 0: no limit")
    TraverseEventName: str = param(
        "Traverse", unit="-",
        description="afa addition: the global Traversability map (TravMapArrayEventIDL) "
                    "a back-out is checked on (no sensor looks behind the vehicle)")
    VehicleRadius: Annotated[float, Field(gt=0)] = param(
        0.7, unit="m",
        description="afa addition: radius of the discs swept backwards in a back-out "
                    "(Obstacle Avoidance's VehicleRadius)")
    DiscOffsets: tuple[float, ...] = param(
        (0.0, 0.8, 1.6, 2.4), unit="m",
        description="afa addition: where along the body (m ahead of the rear axle) the "
                    "back-out's discs ride (Obstacle Avoidance's DiscOffsets)")
    RecoverMargin: Annotated[float, Field(ge=0, le=2)] = param(
        0.3, unit="m",
        description="afa addition: how much further than VehicleRadius the back-out's "
                    "discs keep from hazard cells: the body's corners outside the discs "
                    "(0.11 m on the Raptor) and the error of the map's placement of the "
                    "vehicle (decimetres, the GPS's), which nothing behind the vehicle "
                    "corrects")
    StartApron: Annotated[float, Field(ge=0, le=20)] = param(
        4.0, unit="m",
        description="afa addition: a back-out may cross unmapped ground this far behind "
                    "the rear axle where the arbiter first saw the vehicle on a map, and "
                    "this far either side of its centre line (at least 2 VehicleRadius): "
                    "the vehicle was put there (components/arc_arbiter/recovery.py, "
                    "decision 0045); 0: only mapped ground")
    MapFrameOffset: float = param(
        2.45, unit="m",
        description="afa addition: how far ahead of the rear axle the Traversability "
                    "map's vehiclePosition lies (its ego frame, Raptor:Front-BumperCenter; "
                    "docs/geometry.md)")

    @property
    def stale_vote_time(self) -> float:
        """The stale-vote age in seconds (StaleVoteTimeSec + StaleVoteTimeUSec / 1e6)."""
        return self.StaleVoteTimeSec + self.StaleVoteTimeUSec / 1_000_000
