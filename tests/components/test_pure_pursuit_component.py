"""Pure Pursuit as a component: Pose events in, VehiclePlan served (seed Table 24),
ArcVote events out every 100 ms (Table 22).

The waypoints are given as WGS84 latitude/longitude; where the component must put them
in the pose frame (metres east and north of the pose's ``initialUTM``) is worked out here
with pyproj (PROJ's UTM), an implementation independent of afa's Krüger series. The
component is probed where its own behaviour shows the conversion: a waypoint counts as
reached when the vehicle comes within the waypoint's tolerance, so poses a centimetre
inside and outside it, on the approach, tell where the component put it.
"""

from __future__ import annotations

import math
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyproj
import pytest
from vehicle_rig import BUMPER, bumper_transformation

from afa import EOutOfBounds, SubscribePublishServer, System, VirtualClock
from afa.events import Subscription
from components.pure_pursuit import PurePursuit
from components.pure_pursuit.component import VOTE_PERIOD
from components.pure_pursuit.parameters import PurePursuitParameters
from idl import (
    Platform,
    PoseTransformIDL,
    StringSequenceIDL,
    TimeIDL,
    VehiclePlan,
    WaypointGroupIDL,
    WaypointIDL,
)

#: Suffield, Alberta (UTM zone 12 N), where the Raptor drove.
START = (50.2712, -111.1834)
ELEVATION = 750.0
TO_UTM = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:32612", always_xy=True)
TO_LATLON = pyproj.Transformer.from_crs("EPSG:32612", "EPSG:4326", always_xy=True)
#: Where the vehicle is probed, inside and outside a waypoint's tolerance (m).
PROBE = 0.01


def utm(lat: float, lon: float) -> tuple[float, float]:
    easting, northing = TO_UTM.transform(lon, lat)
    return float(easting), float(northing)


INITIAL_UTM = np.array([*utm(*START), ELEVATION])


def waypoint_at(east: float, north: float, tolerance: float) -> tuple[WaypointIDL,
                                                                     tuple[float, float]]:
    """A lat/lon waypoint about (east, north) m from the start, and its exact local
    position by pyproj (the lat/lon are rounded as an operator would type them)."""
    lon, lat = TO_LATLON.transform(INITIAL_UTM[0] + east, INITIAL_UTM[1] + north)
    lat, lon = round(lat, 7), round(lon, 7)
    e, n = utm(lat, lon)
    return (WaypointIDL(latitude=lat, longitude=lon, tolerance=tolerance),
            (e - INITIAL_UTM[0], n - INITIAL_UTM[1]))


def pose(x: float, y: float, yaw: float, t: float = 0.0) -> PoseTransformIDL:
    c, s = math.cos(yaw), math.sin(yaw)
    h = np.array([[c, -s, 0.0, x], [s, c, 0.0, y], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    return PoseTransformIDL(time=TimeIDL.from_seconds(t), HTransform=h, initialUTM=INITIAL_UTM)


@dataclass
class Rig:
    clock: VirtualClock
    system: System
    component: PurePursuit
    plan: Any
    votes: Subscription

    def drive_to(self, x: float, y: float, yaw: float) -> None:
        self.system.channel.publish("Raptor", "Pose", pose(x, y, yaw, self.clock.now()),
                                    origin="test")

    async def tick(self, periods: int = 1) -> None:
        await self.clock.advance(periods * VOTE_PERIOD)

    def drain(self) -> list[Any]:
        events = []
        while (event := self.votes.get_nowait()) is not None:
            events.append(event)
        return events

    def last_vote(self) -> Any:
        return self.drain()[-1].body


class Geometry(SubscribePublishServer):
    """ModelServer's geometry as far as Pure Pursuit asks it: where the ground under the
    front bumper lies (the Raptor's: 2.45 m ahead of the rear axle)."""

    def __init__(self) -> None:
        super().__init__("modelServer")
        self.serves(Platform, "ModelService")

    async def getTransformation(self, A: str, B: str) -> PoseTransformIDL:
        return bumper_transformation(A, B, self.clock.now())

    async def getPose(self) -> PoseTransformIDL:
        raise EOutOfBounds("no pose here")

    async def getWaitPose(self) -> PoseTransformIDL:
        raise EOutOfBounds("no pose here")

    async def getBodyList(self) -> StringSequenceIDL:
        return StringSequenceIDL(values=())

    async def getBodyFrameList(self, body: str) -> StringSequenceIDL:
        raise EOutOfBounds("no bodies here")


@asynccontextmanager
async def rig(geometry: bool = False, **parameters: Any) -> AsyncIterator[Rig]:
    clock = VirtualClock(start=1_000.0)
    component = PurePursuit("purePursuit", PurePursuitParameters(**parameters))
    system = System([component, *([Geometry()] if geometry else [])], clock=clock)
    async with system:
        votes = system.channel.subscribe("Raptor", "ArcVote", maxsize=1 << 12)
        plan = await system.resolve(VehiclePlan, "PurePursuit")
        yield Rig(clock, system, component, plan, votes)


def approach(to: tuple[float, float], frm: tuple[float, float], distance: float
             ) -> tuple[float, float, float]:
    """The pose ``distance`` m short of ``to`` on the line from ``frm``, facing ``to``."""
    dx, dy = to[0] - frm[0], to[1] - frm[1]
    length = math.hypot(dx, dy)
    return (to[0] - dx / length * distance, to[1] - dy / length * distance,
            math.atan2(dy, dx))


def is_stop(vote: Any) -> bool:
    return not vote.veto.any() and bool(np.all(vote.maxSpeed == 0.0))


# --------------------------------------------------------------------------- VehiclePlan

async def test_lat_lon_waypoints_are_placed_through_the_poses_initial_utm():
    tolerance = 0.25
    w0, p0 = waypoint_at(31.0, 42.0, tolerance)
    w1, p1 = waypoint_at(-18.0, 75.0, tolerance)
    assert math.dist(p0, (31.0, 42.0)) < 1e-2  # the rounding moved them by millimetres
    group = WaypointGroupIDL(waypoints=(w0, w1))
    async with rig() as r:
        await r.plan.setWaypointList(group)
        assert await r.plan.getWaypointList() == group
        r.drive_to(0.0, 0.0, 0.0)
        await r.tick()
        assert await r.plan.getCurrentWaypoint() == w0
        # just outside w0's tolerance on the approach: still sought
        r.drive_to(*approach(p0, (0.0, 0.0), tolerance + PROBE))
        await r.tick()
        assert await r.plan.getCurrentWaypoint() == w0
        # just inside: reached, w1 is next
        r.drive_to(*approach(p0, (0.0, 0.0), tolerance - PROBE))
        await r.tick()
        assert await r.plan.getCurrentWaypoint() == w1
        assert not is_stop(r.last_vote())
        r.drive_to(*approach(p1, p0, tolerance + PROBE))
        await r.tick()
        assert await r.plan.getCurrentWaypoint() == w1
        r.drive_to(*approach(p1, p0, tolerance - PROBE))
        await r.tick()
        # after the last waypoint of a non-patrol list: none, and a stop vote
        assert await r.plan.getCurrentWaypoint() is None
        assert is_stop(r.last_vote())
        assert r.component.statistics()["waypoints_reached"] == 2


async def test_the_bumper_reaches_a_waypoint_where_modelserver_puts_it():
    """A waypoint the rear axle cannot come to (short of a wall, say) is reached when the
    ground under the front bumper, where ModelServer's geometry puts GroundFrame, comes
    within its tolerance: as the Global Map judges."""
    tolerance = 0.5
    w0, p0 = waypoint_at(20.0, 0.0, tolerance)
    w1, _ = waypoint_at(20.0, 20.0, tolerance)
    async with rig(geometry=True) as r:
        await r.plan.setWaypointList(WaypointGroupIDL(waypoints=(w0, w1)))
        r.drive_to(0.0, 0.0, 0.0)
        await r.tick()
        r.drive_to(*approach(p0, (0.0, 0.0), BUMPER + tolerance + PROBE))
        await r.tick()
        assert await r.plan.getCurrentWaypoint() == w0
        r.drive_to(*approach(p0, (0.0, 0.0), BUMPER + tolerance - PROBE))
        await r.tick()
        assert await r.plan.getCurrentWaypoint() == w1
        assert r.component.health().healthy


async def test_a_ground_frame_modelserver_does_not_know_leaves_the_rear_axle():
    tolerance = 0.5
    w0, p0 = waypoint_at(20.0, 0.0, tolerance)
    async with rig(geometry=True, GroundFrame="Raptor: NoSuchFrame") as r:
        await r.plan.setWaypointList(WaypointGroupIDL(waypoints=(w0,)))
        r.drive_to(*approach(p0, (0.0, 0.0), BUMPER))
        await r.tick(3)
        assert await r.plan.getCurrentWaypoint() == w0  # the bumper would be on it
        assert not is_stop(r.last_vote())
        health = r.component.health()
        assert not health.healthy and "Raptor: NoSuchFrame" in health.detail
        assert r.component.statistics()["unknown_frames"] == 1  # asked once


async def test_the_current_waypoint_is_the_first_before_any_pose_arrives():
    w0, _ = waypoint_at(10.0, 0.0, 1.0)
    w1, _ = waypoint_at(20.0, 0.0, 1.0)
    async with rig() as r:
        assert await r.plan.getCurrentWaypoint() is None
        await r.plan.setWaypointList(WaypointGroupIDL(waypoints=(w0, w1)))
        assert await r.plan.getCurrentWaypoint() == w0
        r.drive_to(0.0, 0.0, 0.0)
        await r.tick()
        assert await r.plan.getCurrentWaypoint() == w0


async def test_patrol_mode_is_served_and_loops_back_to_the_first_waypoint():
    tolerance = 0.5
    w0, p0 = waypoint_at(20.0, 0.0, tolerance)
    w1, p1 = waypoint_at(20.0, 20.0, tolerance)
    async with rig() as r:
        await r.plan.setWaypointList(WaypointGroupIDL(waypoints=(w0, w1)))
        assert await r.plan.getPatrolMode() is False
        await r.plan.setPatrolMode(True)
        assert await r.plan.getPatrolMode() is True
        assert (await r.plan.getWaypointList()).patrolMode is True
        r.drive_to(0.0, 0.0, 0.0)
        await r.tick()
        r.drive_to(*approach(p0, (0.0, 0.0), tolerance / 2))
        await r.tick()
        r.drive_to(*approach(p1, p0, tolerance / 2))
        await r.tick()
        assert await r.plan.getCurrentWaypoint() == w0  # round again
        assert not is_stop(r.last_vote())
        await r.plan.setPatrolMode(False)
        assert await r.plan.getPatrolMode() is False
        # a list given with patrolMode sets it
        await r.plan.setWaypointList(WaypointGroupIDL(waypoints=(w0, w1), patrolMode=True))
        assert await r.plan.getPatrolMode() is True


# --------------------------------------------------------------------------- votes

async def test_votes_every_100_ms_over_the_arc_set():
    w0, _ = waypoint_at(40.0, 0.0, 1.0)
    async with rig() as r:
        r.drain()
        await r.clock.advance(2.0)
        before_pose = r.drain()
        await r.plan.setWaypointList(WaypointGroupIDL(waypoints=(w0,)))
        r.drive_to(0.0, 0.0, 0.0)
        await r.clock.advance(2.0)
        following = r.drain()
    events = before_pose + following
    assert len(events) == 41  # at 0.0, 0.1, ... 4.0 s
    gaps = np.diff([e.time for e in events])
    assert gaps == pytest.approx(np.full(len(gaps), VOTE_PERIOD), abs=1e-9)
    assert {e.body.behaviour for e in events} == {"PurePursuit"}
    assert {e.body.curvatures.tobytes() for e in events} == {
        r.component.arcs.curvatures.tobytes()}
    # no pose and no waypoints: stop votes; then following (moving on some arcs)
    assert all(is_stop(e.body) for e in before_pose)
    assert not is_stop(following[-1].body) and following[-1].body.maxSpeed.max() > 0


@pytest.mark.parametrize(("north", "side"), [(6.0, 1), (-6.0, -1), (0.0, 0)])
async def test_the_vote_turns_towards_the_waypoint(north, side):
    w0, _ = waypoint_at(20.0, north, 1.0)
    async with rig() as r:
        await r.plan.setWaypointList(WaypointGroupIDL(waypoints=(w0,)))
        r.drive_to(0.0, 0.0, 0.0)  # facing east
        await r.tick()
        vote = r.last_vote()
    best = float(vote.curvatures[int(np.argmax(vote.vote))])
    assert np.sign(round(best, 9)) == side  # left turns are positive curvature


async def test_set_halt_vetoes_every_arc_until_released_and_keeps_the_target():
    w0, _ = waypoint_at(30.0, 0.0, 1.0)
    async with rig() as r:
        await r.plan.setHalt(True)
        await r.tick()
        assert r.last_vote().veto.all()  # even before a pose or waypoints
        await r.plan.setWaypointList(WaypointGroupIDL(waypoints=(w0,)))
        r.drive_to(0.0, 0.0, 0.0)
        await r.tick(3)
        assert all(e.body.veto.all() for e in r.drain())
        assert await r.plan.getCurrentWaypoint() == w0
        await r.plan.setHalt(False)
        await r.tick()
        vote = r.last_vote()
        assert not vote.veto.any() and vote.maxSpeed.max() > 0


async def test_an_empty_list_votes_to_stop():
    w0, _ = waypoint_at(30.0, 0.0, 1.0)
    async with rig() as r:
        await r.plan.setWaypointList(WaypointGroupIDL(waypoints=(w0,)))
        r.drive_to(0.0, 0.0, 0.0)
        await r.tick()
        assert not is_stop(r.last_vote())
        await r.plan.setWaypointList(WaypointGroupIDL())
        await r.tick()
        assert is_stop(r.last_vote())
        assert await r.plan.getCurrentWaypoint() is None
