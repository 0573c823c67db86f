"""Obstacle Detection (seed §3.3.4, Tables 22, A.11): the laser safety catch.

On every scan of the lasers it subscribes to (``RangeEventNames``, either IDL form), it
puts the valid returns into the laser-level vehicle frame (ModelServer's
``getTransformation`` from the vehicle frame to the scan's frame, polled once per
frame), counts those inside the corridor ahead that stand above ``SafetyHeight`` or lie
below ``SafetyDepth`` (:mod:`components.obstacle_detection.detect`) and publishes the
result as an ``ArcVote`` (behaviour ``ObstacleDetection``): a halt (every arc vetoed) at
``NumHitsTolerance`` hits, then nothing for ``ResetCounter`` scans, else a clear vote.
The halt is published in the handler of the scan that showed the obstacle, so it reaches
the arbiter, and through it the vehicle, within that scan period. A clear vote weighs
nothing in the arbiter's sum: one goes out at once after a halt (it replaces the halt),
and otherwise at most every ``CLEAR_REFRESH`` seconds, which keeps the catch's vote
fresh and visible at a tenth of the scan rate's events (two lasers scan 75 times a
second; each vote is an arbiter decision and a recorded event). Scans in a frame
ModelServer does not know are ignored, and the component reports itself unhealthy.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from afa import EOutOfBounds, Event, SubscribePublishServer
from afa.clock import TIME_TOLERANCE
from afa.errors import AfaError
from components.arcs import ARC_SET_SECTION, ArcSet, arc_set_of
from components.obstacle_detection.detect import ObstacleDetector
from components.obstacle_detection.parameters import ObstacleDetectionParameters
from components.waypoints import VEHICLE_FRAME
from idl import ArcVoteIDL, Platform, Range3dLaserIDL, Range3dSeqEventIDL, TimeIDL

__all__ = ["ObstacleDetection", "BEHAVIOUR", "VEHICLE_FRAME"]

BEHAVIOUR = "ObstacleDetection"
#: A clear vote goes out at most this often (s), Pure Pursuit's rate; far inside
#: ``StaleVoteTime`` (1.5 s). Halts, and the first clear vote after one, go out at once.
CLEAR_REFRESH = 0.1


class ObstacleDetection(SubscribePublishServer[ObstacleDetectionParameters]):
    """The safety catch (module docstring)."""

    def __init__(self, name: str, parameters: ObstacleDetectionParameters | None = None,
                 ) -> None:
        super().__init__(name, parameters)
        p = self.parameters
        self.votes = self.publishes(p.VoteEventName, ArcVoteIDL)
        for event_name in p.RangeEventNames:
            self.subscribes(event_name, (Range3dSeqEventIDL, Range3dLaserIDL), self._on_scan,
                            maxsize=4, required=True)
        self.platform = self.uses(Platform, p.PlatformName)
        self.arcs = ArcSet.from_parameters()
        self.detector = ObstacleDetector(p, self.arcs)
        self._frames: dict[str, np.ndarray | None] = {}
        self.counters = {"scans": 0, "halts": 0, "unknown_frames": 0, "no_geometry": 0}
        self._cleared_at: float | None = None  # when the last clear vote went out

    async def setup(self) -> None:
        self.arcs = arc_set_of(self.context.section(ARC_SET_SECTION))
        self.detector = ObstacleDetector(self.parameters, self.arcs)
        self._cleared_at = None

    async def _on_scan(self, event: Event) -> None:
        scan: Range3dSeqEventIDL | Range3dLaserIDL = event.body  # type: ignore[assignment]
        transform = await self._transform(scan.frame)
        if transform is None:
            return
        points = np.asarray(scan.valid_points(), dtype=np.float64)
        aligned = points @ transform[:3, :3].T
        aligned[:, 1] += transform[1, 3]  # on the centre line, at the laser's x and height
        result = self.detector.update(aligned)
        self.counters["scans"] += 1
        if result.votes is None:
            return
        now = self.clock.monotonic()
        if not result.halt:
            last = self._cleared_at
            if last is not None and now - last < CLEAR_REFRESH - TIME_TOLERANCE:
                return  # the clear vote out is fresh, and this one says the same
            self._cleared_at = now
        else:
            self._cleared_at = None  # the next clear vote replaces the halt at once
            self.counters["halts"] += 1
            self.log.warning("%s: halt: %d returns above %.2f m or below %.2f m within "
                             "%.1f m ahead", self.name, result.hits.total if result.hits else 0,
                             self.parameters.SafetyHeight, self.parameters.SafetyDepth,
                             self.parameters.SafetyDist)
        self.votes.publish(result.votes.to_idl(time=TimeIDL.from_seconds(self.clock.now()),
                                               behaviour=BEHAVIOUR, arcs=self.arcs))

    async def _transform(self, frame: str) -> np.ndarray | None:
        """^V T_frame, polled once per frame; None (counted) if ModelServer does not know
        the frame or cannot be reached yet."""
        if frame in self._frames:
            known = self._frames[frame]
            if known is None:
                self.counters["unknown_frames"] += 1
            return known
        try:
            pose = await self.platform.getTransformation(VEHICLE_FRAME, frame)
        except EOutOfBounds as exc:
            self.log.warning("%s: ModelServer does not know frame %r (%s): its scans are "
                             "ignored", self.name, frame, exc)
            self._frames[frame] = None
            self.counters["unknown_frames"] += 1
            # a safety catch blind to a laser is not healthy, whatever the others see
            self.set_health(False, f"scans in frame {frame!r} are ignored: ModelServer "
                                   "does not know the frame")
            return None
        except AfaError:
            self.counters["no_geometry"] += 1  # not bound yet, or timed out: ask again later
            return None
        self._frames[frame] = np.asarray(pose.HTransform, dtype=np.float64)
        return self._frames[frame]

    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        stats.update(self.counters)
        stats["state"] = self.detector.state
        return stats
