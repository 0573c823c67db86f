"""Pure Pursuit (seed §3.3.3, Tables 22, 24): follows the straight segments between GPS
waypoints, voting for arcs as a Gaussian around the pursuit arc.

- Subscribes to ``Pose`` (PoseTransformIDL); every 100 ms (Table 22) it runs the
  pursuit core (:mod:`components.pure_pursuit.pursuit`) at the latest pose and publishes
  an ``ArcVote`` (behaviour ``PurePursuit``) over the candidate arc set
  (:mod:`components.arcs`, section ``CandidateArcs``).
- Serves VehiclePlan (Table 24) under ``InterfaceName``: ``setWaypointList`` takes
  latitude/longitude waypoints, converted into the pose frame through ``initialUTM``
  (:mod:`components.waypoints`) when the first pose arrives (and again, keeping the
  progress, if the pose frame's origin changes); ``setHalt(true)`` vetoes every arc until
  ``setHalt(false)``; after the last waypoint of a non-patrol list it votes to stop.
- A waypoint is reached when the rear axle or the ground under the front bumper comes
  within its tolerance, as the Global Map judges it: where that ground point
  (``GroundFrame``) lies on the vehicle it asks ModelServer (``getTransformation``,
  ``PlatformName``) until it answers; a frame ModelServer does not know leaves the rear
  axle alone, and the component unhealthy, its detail naming the frame.
- Before the first pose, or with no waypoints, it votes to stop (speed 0 on every arc):
  a vote that keeps the arbiter informed rather than silent.
"""

from __future__ import annotations

import math
from typing import Any

from afa import Event, SubscribePublishServer
from components.arcs import ARC_SET_SECTION, ArcSet, ArcVotes, arc_set_of
from components.pure_pursuit.parameters import PurePursuitParameters
from components.pure_pursuit.pursuit import PurePursuit as PursuitCore
from components.pure_pursuit.pursuit import PursuitOutput, PursuitSettings, Waypoint
from components.waypoints import ground_point, to_local
from idl import (
    ArcVoteIDL,
    Platform,
    PoseTransformIDL,
    TimeIDL,
    VehiclePlan,
    WaypointGroupIDL,
    WaypointIDL,
)

__all__ = ["PurePursuit", "BEHAVIOUR", "VOTE_PERIOD"]

BEHAVIOUR = "PurePursuit"
#: Table 22: Pure Pursuit votes every 100 ms.
VOTE_PERIOD = 0.1


class PurePursuit(SubscribePublishServer[PurePursuitParameters]):
    """The Pure Pursuit behaviour (module docstring)."""

    def __init__(self, name: str, parameters: PurePursuitParameters | None = None) -> None:
        super().__init__(name, parameters)
        p = self.parameters
        self.votes = self.publishes(p.VoteEventName, ArcVoteIDL)
        self.subscribes(p.PoseEventName, PoseTransformIDL, self._on_pose, maxsize=4,
                        required=True)
        self.serves(VehiclePlan, p.InterfaceName)
        self.platform = self.uses(Platform, p.PlatformName)
        self.arcs = ArcSet.from_parameters()
        self.settings = PursuitSettings.from_parameters(p)
        self.core = PursuitCore(self.arcs, self.settings)
        self.group = WaypointGroupIDL()
        self.pose: PoseTransformIDL | None = None
        self.last: PursuitOutput | None = None
        self._origin: tuple[float, float] | None = None  # initialUTM the list is in
        #: whether ModelServer has answered where GroundFrame lies (True, or False when
        #: it does not know the frame); None until then
        self.front_known: bool | None = None
        self.counters = {"votes": 0, "waypoints_reached": 0, "invalid_poses": 0,
                         "unknown_frames": 0}

    async def setup(self) -> None:
        arcs = arc_set_of(self.context.section(ARC_SET_SECTION))
        if arcs.curvatures.tobytes() != self.arcs.curvatures.tobytes():
            self.arcs = arcs
            core = PursuitCore(arcs, self.settings)
            core.set_patrol(self.core.patrol)
            core.set_halt(self.core.halted)
            core.set_front(*self.core.front)
            self.core = core
            self._origin = None

    async def run(self) -> None:
        self.spawn(self._front_point(), f"{self.name}:geometry")
        async for _ in self.clock.periodic(VOTE_PERIOD):
            self._vote()

    async def _front_point(self) -> None:
        """Where ``GroundFrame`` lies on the vehicle, from ModelServer (module
        docstring): asked once a vote period until it answers, beside the votes (a slow
        answer never delays one)."""
        frame = self.parameters.GroundFrame
        while (front := await ground_point(self.platform, frame, self.log)) is None:
            await self.clock.sleep(VOTE_PERIOD)  # not reachable yet: ask again
        if front is False:
            self.front_known = False
            self.counters["unknown_frames"] += 1
            self.set_health(False, f"ModelServer does not know GroundFrame {frame!r}: "
                                   "waypoints are reached by the rear axle only")
            return
        self.core.set_front(*front)
        self.front_known = True

    def _on_pose(self, event: Event) -> None:
        pose: PoseTransformIDL = event.body  # type: ignore[assignment]
        if not pose.poseValidFlag:
            self.counters["invalid_poses"] += 1  # still the best estimate: keep using it
        self.pose = pose

    def _vote(self) -> None:
        pose = self.pose
        if pose is None:
            votes = (ArcVotes.halt(len(self.arcs)) if self.core.halted
                     else PursuitCore(self.arcs, self.settings).update(0.0, 0.0, 0.0).votes)
        else:
            self._convert(pose)
            h = pose.HTransform
            output = self.core.update(float(h[0, 3]), float(h[1, 3]),
                                      math.atan2(float(h[1, 0]), float(h[0, 0])))
            self.counters["waypoints_reached"] += len(output.advanced)
            self.last = output
            votes = output.votes
        self.votes.publish(votes.to_idl(time=TimeIDL.from_seconds(self.clock.now()),
                                        behaviour=BEHAVIOUR, arcs=self.arcs))
        self.counters["votes"] += 1

    def _convert(self, pose: PoseTransformIDL) -> None:
        """Put the latitude/longitude list into the pose frame if it is not in it yet
        (a restarted ModelServer may choose a new ``initialUTM``: progress is kept)."""
        origin = (float(pose.initialUTM[0]), float(pose.initialUTM[1]))
        if origin == self._origin or not self.group.waypoints:
            return
        first = 0
        if self._origin is not None and not self.core.finished:
            first = self.core.target
        points = [Waypoint(*to_local(w, pose.initialUTM), tolerance=w.tolerance)
                  for w in self.group.waypoints]
        self.core.set_waypoints(points, first=first)
        self._origin = origin

    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        stats.update(self.counters)
        stats["state"] = None if self.last is None else self.last.state
        return stats

    # -- VehiclePlan (Table 24) ------------------------------------------------------------
    async def setWaypointList(self, waypoints: WaypointGroupIDL) -> None:
        self.group = waypoints
        self._origin = None
        self.core.set_waypoints([], patrol=waypoints.patrolMode)
        if self.pose is not None:
            self._convert(self.pose)

    async def getWaypointList(self) -> WaypointGroupIDL:
        return self.group.model_copy(update={"patrolMode": self.core.patrol})

    async def getCurrentWaypoint(self) -> WaypointIDL | None:
        if not self.group.waypoints:
            return None
        if self._origin is None:  # no pose yet to place the list: the first is sought
            return self.group.waypoints[0]
        if self.core.current_waypoint is None:
            return None
        return self.group.waypoints[self.core.target]

    async def setPatrolMode(self, patrol: bool) -> None:
        self.core.set_patrol(patrol)

    async def getPatrolMode(self) -> bool:
        return self.core.patrol

    async def setHalt(self, halt: bool) -> None:
        self.core.set_halt(halt)
