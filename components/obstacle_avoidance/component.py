"""Obstacle Avoidance (seed §3.3.2, Tables 22, A.10): candidate arcs scored on the
egocentric traversability map.

On every ego traversability map (``<TraverseEventName>Ego``, EtravMapArrayEventIDL;
Table 22 gives 500 ms, the map's own period at the Traversability Map's
``MapEventInterval``) it sweeps discs of ``VehicleRadius`` (at ``DiscOffsets`` along the
body) along every candidate arc in ``CurveMakingConst`` steps between the ``NearZone`` and
``FarZone`` rows (:mod:`components.obstacle_avoidance.sweep`; the arc-to-cell tables are
built once per map geometry), vetoes arcs that meet a hazard, votes by the free distance
along each arc and publishes an ``ArcVote`` (behaviour ``ObstacleAvoidance``). Where the
ego map frame sits on the vehicle comes from ModelServer (``getTransformation`` of the
map's frame), once; maps in a frame ModelServer does not know are ignored, and the
component reports itself unhealthy.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from afa import EOutOfBounds, Event, SubscribePublishServer
from afa.errors import AfaError
from components.arcs import ARC_SET_SECTION, ArcSet, arc_set_of
from components.obstacle_avoidance.parameters import ObstacleAvoidanceParameters
from components.obstacle_avoidance.sweep import ArcSweeper, SweepScores
from components.waypoints import VEHICLE_FRAME
from idl import ArcVoteIDL, EtravMapArrayEventIDL, Platform, TimeIDL

__all__ = ["ObstacleAvoidance", "BEHAVIOUR", "VEHICLE_FRAME"]

BEHAVIOUR = "ObstacleAvoidance"


class ObstacleAvoidance(SubscribePublishServer[ObstacleAvoidanceParameters]):
    """The Obstacle Avoidance behaviour (module docstring)."""

    def __init__(self, name: str, parameters: ObstacleAvoidanceParameters | None = None,
                 ) -> None:
        super().__init__(name, parameters)
        p = self.parameters
        self.votes = self.publishes(p.VoteEventName, ArcVoteIDL)
        self.subscribes(p.TraverseEventName + "Ego", EtravMapArrayEventIDL, self._on_map,
                        maxsize=2, required=True)
        self.platform = self.uses(Platform, p.PlatformName)
        self.arcs = ArcSet.from_parameters()
        self.sweepers: dict[str, ArcSweeper | None] = {}
        self.last: SweepScores | None = None
        self.counters = {"maps": 0, "votes": 0, "unknown_frames": 0, "no_geometry": 0,
                         "all_vetoed": 0}

    async def setup(self) -> None:
        self.arcs = arc_set_of(self.context.section(ARC_SET_SECTION))
        self.sweepers.clear()

    async def _on_map(self, event: Event) -> None:
        trav: EtravMapArrayEventIDL = event.body  # type: ignore[assignment]
        self.counters["maps"] += 1
        sweeper = await self._sweeper(trav.frame)
        if sweeper is None:
            return
        scores = sweeper.score_map(trav)
        self.last = scores
        if scores.votes.all_vetoed:
            self.counters["all_vetoed"] += 1
        self.votes.publish(scores.votes.to_idl(time=TimeIDL.from_seconds(self.clock.now()),
                                               behaviour=BEHAVIOUR, arcs=self.arcs))
        self.counters["votes"] += 1

    async def _sweeper(self, frame: str) -> ArcSweeper | None:
        """The sweeper for maps attached to ``frame`` (its place from ModelServer)."""
        if frame in self.sweepers:
            return self.sweepers[frame]
        try:
            pose = await self.platform.getTransformation(VEHICLE_FRAME, frame)
        except EOutOfBounds as exc:
            self.log.warning("%s: ModelServer does not know the map frame %r (%s): its maps "
                             "are ignored", self.name, frame, exc)
            self.sweepers[frame] = None
            self.counters["unknown_frames"] += 1
            self.set_health(False, f"maps in frame {frame!r} are ignored: ModelServer does "
                                   "not know the frame")
            return None
        except AfaError:
            self.counters["no_geometry"] += 1  # not reachable yet: the next map asks again
            return None
        origin = np.asarray(pose.HTransform)[:2, 3]
        sweeper = ArcSweeper(self.arcs, self.parameters,
                             map_frame=(float(origin[0]), float(origin[1])),
                             disc_offsets=self.parameters.DiscOffsets)
        self.sweepers[frame] = sweeper
        return sweeper

    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        stats.update(self.counters)
        return stats
