"""FindPath as a component: a real Global Map fed global traversability maps
(``Traverse`` events, as the Traversability Map publishes them), a replayed pose source
serving ModelServer's ``Platform.getPose``, ArcVote and PlannedPath out.

Polls are counted by the framework's poll statistics (``System.polls``), nothing is
mocked. Whether a path keeps clear of the hazards, and where it starts and ends, is
checked here by plain geometry against the hazards the test put in the maps.
"""

from __future__ import annotations

import math
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from vehicle_rig import BUMPER, bumper_transformation

from afa import EOutOfBounds, SubscribePublishServer, System, VirtualClock
from afa.events import Subscription
from components.find_path import FindPath
from components.find_path.parameters import FindPathParameters
from components.global_map import GlobalMap
from components.global_map.parameters import GlobalMapParameters
from idl import (
    GlobalMap as GlobalMapInterface,
)
from idl import (
    Platform,
    PoseTransformIDL,
    Position3DIDL,
    StringSequenceIDL,
    TimeIDL,
    TravMapArrayEventIDL,
    WaypointGroupIDL,
    WaypointIDL,
)

INITIAL_UTM = np.array([500_000.0, 5_570_000.0, 750.0])
CELL = 0.5
#: The Raptor's half width: a planned rear-axle path keeps the body this far from hazards.
HALF_WIDTH = 0.7
#: The traversability maps: 40 m × 40 m around the start, 0.5 m cells (World frame).
TRAV_CELLS = 80
TRAV_ORIGIN = -20.0
PER_CELL_METHODS = ("valid", "getPlanningMap", "getSensingMap", "getMap", "setMap")


class ReplayedPose(SubscribePublishServer):
    """A pose source standing in for ModelServer: ``getPose`` answers the pose the test
    set (its last ``place``), as a replayed log's servant would, and
    ``getTransformation`` the bumper's ground frame."""

    def __init__(self, name: str = "modelServer", service: str = "ModelService") -> None:
        super().__init__(name)
        self.serves(Platform, service)
        self.x = self.y = self.yaw = 0.0

    def place(self, x: float, y: float, yaw: float = 0.0) -> None:
        self.x, self.y, self.yaw = x, y, yaw

    async def getPose(self) -> PoseTransformIDL:
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        h = np.array([[c, -s, 0, self.x], [s, c, 0, self.y], [0, 0, 1, 0], [0, 0, 0, 1]],
                     dtype=np.float64)
        return PoseTransformIDL(time=TimeIDL.from_seconds(self.clock.now()), HTransform=h,
                                initialUTM=INITIAL_UTM)

    async def getWaitPose(self) -> PoseTransformIDL:
        return await self.getPose()

    async def getTransformation(self, A: str, B: str) -> PoseTransformIDL:
        return bumper_transformation(A, B, self.clock.now())

    async def getBodyList(self) -> StringSequenceIDL:
        return StringSequenceIDL(values=())

    async def getBodyFrameList(self, body: str) -> StringSequenceIDL:
        raise EOutOfBounds("a replayed pose has no geometry")


Box = tuple[float, float, float, float]  # x0, x1, y0, y1 (m, world frame)


def traverse(boxes: list[Box], t: float, vehicle: tuple[float, float] = (-15.0, -15.0)
             ) -> TravMapArrayEventIDL:
    """A sensed global traversability map around the start: free ground, hazards in
    ``boxes`` (cells whose centres lie inside), sensed from ``vehicle``."""
    centres = TRAV_ORIGIN + (np.arange(TRAV_CELLS) + 0.5) * CELL
    x, y = np.meshgrid(centres, centres, indexing="ij")
    hazard = np.zeros((TRAV_CELLS, TRAV_CELLS), dtype=np.float32)
    for x0, x1, y0, y1 in boxes:
        hazard[(x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)] = 1.0
    return TravMapArrayEventIDL(
        time=TimeIDL.from_seconds(t), frame="World", mapPose=np.eye(4),
        initialUTM=INITIAL_UTM, gridsize=CELL, originX=TRAV_ORIGIN, originY=TRAV_ORIGIN,
        rows=TRAV_CELLS, cols=TRAV_CELLS, hazard=hazard,
        goodness=np.ones_like(hazard), vehiclePosition=Position3DIDL(x=vehicle[0],
                                                                     y=vehicle[1]),
        vehicleHeading=0.0)


def waypoint(x: float, y: float, tolerance: float = 1.0) -> WaypointIDL:
    # UTM given: the position is exact; lat/lon roughly where that is
    return WaypointIDL(latitude=50.27, longitude=-111.18, easting=INITIAL_UTM[0] + x,
                       northing=INITIAL_UTM[1] + y, tolerance=tolerance)


def clearance(points: np.ndarray, box: Box) -> float:
    """Least distance (m) from the points to the hazard cells of ``box``."""
    x0, x1, y0, y1 = box
    # the cells whose centres lie in the box cover it grown to whole cells
    lo_x = TRAV_ORIGIN + math.floor((x0 - TRAV_ORIGIN) / CELL) * CELL
    hi_x = TRAV_ORIGIN + math.ceil((x1 - TRAV_ORIGIN) / CELL) * CELL
    lo_y = TRAV_ORIGIN + math.floor((y0 - TRAV_ORIGIN) / CELL) * CELL
    hi_y = TRAV_ORIGIN + math.ceil((y1 - TRAV_ORIGIN) / CELL) * CELL
    dx = np.maximum.reduce([lo_x - points[:, 0], np.zeros(len(points)), points[:, 0] - hi_x])
    dy = np.maximum.reduce([lo_y - points[:, 1], np.zeros(len(points)), points[:, 1] - hi_y])
    return float(np.hypot(dx, dy).min())


@dataclass
class Rig:
    clock: VirtualClock
    system: System
    planner: FindPath
    pose: ReplayedPose
    global_map: Any
    votes: Subscription
    paths: Subscription

    def sense(self, boxes: list[Box], vehicle: tuple[float, float] = (-15.0, -15.0)) -> None:
        self.system.channel.publish("Raptor", "Traverse",
                                    traverse(boxes, self.clock.now(), vehicle), origin="test")

    async def until(self, t: float) -> None:
        await self.clock.advance(t - self.clock.monotonic())

    def polls(self, method: str) -> int:
        stats = self.system.polls.statistics.get(("Raptor/GlobalMap", method))
        return 0 if stats is None else stats.calls

    @staticmethod
    def drain(subscription: Subscription) -> list[Any]:
        events = []
        while (event := subscription.get_nowait()) is not None:
            events.append(event)
        return events


@asynccontextmanager
async def rig(goal: WaypointIDL, boxes: list[Box] | None, **parameters: Any
              ) -> AsyncIterator[Rig]:
    clock = VirtualClock(start=0.0)
    planner = FindPath("FindPathService", FindPathParameters(**{
        "PlanUpdateDelayTime": 1.0, **parameters}))
    pose = ReplayedPose()
    system = System([GlobalMap("GlobalMapService", GlobalMapParameters(Width=60000,
                                                                       Depth=60000)),
                     pose, planner], clock=clock)
    async with system:
        votes = system.channel.subscribe("Raptor", "ArcVote", maxsize=1024)
        paths = system.channel.subscribe("Raptor", "PlannedPath", maxsize=1024)
        global_map = await system.resolve(GlobalMapInterface, "GlobalMap")
        r = Rig(clock, system, planner, pose, global_map, votes, paths)
        if boxes is not None:  # None: no map yet
            r.sense(boxes)
        await global_map.setWaypointList(WaypointGroupIDL(waypoints=(goal,)))
        yield r


# --------------------------------------------------------------------------- plans and votes

async def test_it_plans_round_a_wall_publishes_the_path_and_votes_each_interval():
    wall: Box = (8.0, 9.0, -6.0, 6.0)
    goal = waypoint(16.0, 0.0)
    interval = FindPathParameters().PlanEventInterval
    async with rig(goal, [wall]) as r:
        await r.until(0.9)
        assert r.drain(r.votes) == [] and r.drain(r.paths) == []  # PlanUpdateDelayTime
        await r.until(5.5)
        votes, paths = r.drain(r.votes), r.drain(r.paths)
    assert len(votes) == len(paths) == 5
    assert np.diff([e.time for e in votes]) == pytest.approx([interval] * 4)
    assert votes[0].time >= 1.0
    path = paths[-1].body
    assert path.goal == goal and np.array_equal(path.initialUTM, INITIAL_UTM)
    assert math.dist(path.points[0], (0.0, 0.0)) <= CELL
    assert math.dist(path.points[-1], (16.0, 0.0)) <= goal.tolerance + CELL
    assert clearance(path.points, wall) >= HALF_WIDTH  # round the wall, body clear
    assert np.abs(path.points[:, 1]).max() > 6.0
    assert math.isfinite(path.cost) and path.cost > 16.0
    vote = votes[-1].body
    assert vote.behaviour == "FindPath" and not vote.veto.any()
    assert vote.maxSpeed.max() > 0


async def test_with_no_path_it_vetoes_every_arc_and_shows_no_path():
    goal = waypoint(16.0, 0.0)
    pen = [(13.0, 19.0, -3.0, -2.5), (13.0, 19.0, 2.5, 3.0), (13.0, 13.5, -3.0, 3.0),
           (18.5, 19.0, -3.0, 3.0)]  # a closed pen round the goal
    async with rig(goal, pen) as r:
        await r.until(3.5)
        votes, paths = r.drain(r.votes), r.drain(r.paths)
        stats = r.planner.statistics()
    assert votes and all(e.body.veto.all() for e in votes)
    assert stats["no_path"] == len(votes)
    assert paths and all(len(e.body.points) == 0 for e in paths)  # displays clear the path
    assert all(e.body.goal == goal and math.isinf(e.body.cost) for e in paths)


async def test_health_says_planning_and_turns_unhealthy_when_no_path_persists():
    """An operator sees FindPath planning, and sees it unhealthy (not "ok") once no path
    has been found for NO_PATH_UNHEALTHY cycles in a row."""
    from components.find_path.component import NO_PATH_UNHEALTHY
    wall: Box = (8.0, 9.0, -6.0, 6.0)
    async with rig(waypoint(16.0, 0.0), [wall]) as r:
        await r.until(2.5)
        health = r.planner.health()
        assert health.healthy and health.detail == "planning"
    pen = [(13.0, 19.0, -3.0, -2.5), (13.0, 19.0, 2.5, 3.0), (13.0, 13.5, -3.0, 3.0),
           (18.5, 19.0, -3.0, 3.0)]
    async with rig(waypoint(16.0, 0.0), pen) as r:
        await r.until(NO_PATH_UNHEALTHY - 0.5)  # cycles at 1, 2, ...: one short
        assert r.planner.health().healthy
        await r.until(NO_PATH_UNHEALTHY + 0.5)
        health = r.planner.health()
        assert not health.healthy
        assert "no path to the waypoint since 00:00:01 UTC, no route reaches it" in \
            health.detail
        await r.until(NO_PATH_UNHEALTHY + 3.5)  # the same streak: the same detail, logged once
        assert r.planner.health().detail == health.detail


async def test_a_waypoint_inside_an_obstacle_is_reported_as_such():
    """The operator put the waypoint in a building: no cell within its tolerance is
    passable. FindPath vetoes (the seed's no-plan vote) and its health says why."""
    from components.find_path.component import NO_PATH_UNHEALTHY
    building: Box = (13.0, 19.0, -3.0, 3.0)
    async with rig(waypoint(16.0, 0.0, tolerance=1.0), [building]) as r:
        await r.until(NO_PATH_UNHEALTHY + 0.5)
        votes = r.drain(r.votes)
        health = r.planner.health()
    assert votes and all(e.body.veto.all() for e in votes)
    assert not health.healthy and "it lies in an obstacle" in health.detail


async def test_before_the_first_map_it_vetoes_rather_than_plan_in_no_frame():
    """Until a map is merged the Global Map has no world frame (initialUTM zero): the
    waypoint has no place on the grid, and FindPath must not read it as one beyond the
    map and steer for an edge."""
    async with rig(waypoint(16.0, 0.0), None) as r:
        await r.until(3.5)
        votes = r.drain(r.votes)
        detail = r.planner.health().detail
    assert votes and all(e.body.veto.all() for e in votes)
    assert "beyond" not in detail


async def test_a_waypoint_beyond_the_map_is_planned_to_its_edge_then_on_as_the_map_moves():
    """The waypoint lies 100 m east, beyond the 60 m Global Map: FindPath plans to the
    map's edge nearest it and says so; when the Global Map moves along the leg (its
    next merge), FindPath plans afresh on the moved grid, further east."""
    async with rig(waypoint(100.0, 0.0), []) as r:
        await r.until(2.5)
        assert r.planner.health().detail == ("planning towards a waypoint beyond the map, "
                                             "to its edge")
        before = r.drain(r.paths)[-1].body.points
        assert 29.0 <= before[-1][0] < 30.0 and abs(before[-1][1]) <= CELL  # the east edge
        plans = r.planner.statistics()["plans"]
        r.pose.place(12.0, 0.0)  # driven on: the grid's lead ahead is used up
        r.sense([], vehicle=(12.0, 0.0))  # its next map: the Global Map moves along the leg
        await r.until(4.5)
        after = r.drain(r.paths)[-1].body.points
        stats = r.planner.statistics()
    assert stats["plans"] == plans + 1  # afresh, on the moved grid
    assert math.dist(after[0], (12.0, 0.0)) <= CELL
    assert after[-1][0] > 45.0 and abs(after[-1][1]) <= CELL
    assert np.all(np.diff(after[:, 0]) > 0)  # straight on east


async def test_a_waypoint_short_of_a_wall_is_driven_to_bumper_first():
    """The waypoint 1.2 m short of a wall ahead, 5.5 m off: the rear axle cannot come to
    it facing the wall, nor swing round to come in side-on in the room left, so the
    drivable path ends where the ground under the bumper (ModelServer's GroundFrame) is
    within the waypoint's tolerance, as the Global Map judges arrival: straight on."""
    wall: Box = (9.7, 10.3, -6.0, 6.0)
    goal = waypoint(8.5, 0.0, tolerance=2.0)
    async with rig(goal, [wall]) as r:
        r.pose.place(3.0, 0.0)
        await r.until(1.5)
        refined = r.planner.refined
        vote = r.drain(r.votes)[-1].body
        stats = r.planner.statistics()
    assert refined is not None and not vote.veto.any()
    assert stats["bumper_arrivals"] == 1
    x, y, h = refined.poses[-1]
    bumper = (x + BUMPER * math.cos(h), y + BUMPER * math.sin(h))
    assert math.dist(bumper, (8.5, 0.0)) <= goal.tolerance
    assert max(abs(p[1]) for p in refined.poses) <= 0.5  # straight at it
    assert x + BUMPER + 0.4 < wall[0]  # and the body short of the wall


async def test_a_waypoint_in_the_open_is_driven_to_rear_axle_first():
    """Where the rear axle can come to the waypoint, the path brings it there (the point
    the arcs turn about): the vehicle passes the waypoint rather than pointing its bumper
    at it and turning late for the next leg."""
    goal = waypoint(8.5, 0.0, tolerance=2.0)
    async with rig(goal, []) as r:
        r.pose.place(3.0, 0.0)
        await r.until(1.5)
        refined = r.planner.refined
        stats = r.planner.statistics()
    assert refined is not None and stats["bumper_arrivals"] == 0
    x, y, _ = refined.poses[-1]
    assert math.dist((x, y), (8.5, 0.0)) <= 0.75 * goal.tolerance


async def test_a_ground_frame_modelserver_does_not_know_is_reported_not_fatal():
    async with rig(waypoint(16.0, 0.0), [], GroundFrame="Raptor: NoSuchFrame") as r:
        await r.until(2.5)
        votes = r.drain(r.votes)
        health = r.planner.health()
        stats = r.planner.statistics()
    assert votes and not votes[-1].body.veto.any()  # it plans and votes on
    assert stats["unknown_frames"] == 1  # asked once
    assert not health.healthy and "Raptor: NoSuchFrame" in health.detail


# --------------------------------------------------------------------------- replanning

async def test_sensed_changes_repair_the_plan_incrementally_from_bulk_map_reads():
    goal = waypoint(16.0, 0.0)
    async with rig(goal, []) as r:
        await r.until(2.5)  # two cycles on open ground
        straight = r.drain(r.paths)[-1].body
        assert np.abs(straight.points[:, 1]).max() <= CELL  # straight to the goal
        wall: Box = (8.0, 9.0, -6.0, 6.0)
        r.sense([wall])  # the sensors see a wall across the path
        await r.until(4.5)
        after = r.drain(r.paths)[-1].body
        stats = r.planner.statistics()
        cycles = stats["cycles"]
        whole, changes = r.polls("getPlanMap"), r.polls("getPlanMapChanges")
        per_cell = {m: r.polls(m) for m in PER_CELL_METHODS}
    assert clearance(after.points, wall) >= HALF_WIDTH
    assert stats["plans"] == 1  # one search from scratch; the rest repaired it
    assert stats["replans"] == cycles - 1 and stats["tracking_replans"] == 0
    assert stats["cells_updated"] > 0
    # the map in bulk: the whole once, then only the changes; never cell by cell
    assert whole == 1 and changes == cycles - 1
    assert per_cell == dict.fromkeys(PER_CELL_METHODS, 0)


async def test_off_the_path_by_more_than_the_tracking_tolerance_it_plans_afresh():
    goal = waypoint(16.0, 0.0)
    tolerance = FindPathParameters().TrackingTolerance  # planning cells
    async with rig(goal, []) as r:
        await r.until(1.5)
        assert r.planner.statistics()["tracking_replans"] == 0
        # within the tolerance of the path: a repair
        r.pose.place(4.0, (tolerance - 2) * CELL)
        await r.until(2.5)
        assert r.planner.statistics()["tracking_replans"] == 0
        # beyond it: rebuilt from scratch, from where the vehicle is
        r.pose.place(4.0, -(tolerance + 2) * CELL)
        await r.until(3.5)
        stats = r.planner.statistics()
        path = r.drain(r.paths)[-1].body
    assert stats["tracking_replans"] == 1
    assert math.dist(path.points[0], (4.0, -(tolerance + 2) * CELL)) <= CELL
    assert math.dist(path.points[-1], (16.0, 0.0)) <= goal.tolerance + CELL


async def test_it_holds_its_way_round_a_wall_until_the_other_is_much_cheaper_or_it_is_blocked():
    """Hysteresis between plans (decision 0043): two ways round a wall that cost nearly
    the same do not alternate as the vehicle moves; a blocked way is left at once."""
    goal = waypoint(16.0, 0.0)
    wall: Box = (8.0, 9.0, -6.0, 6.0)  # across the line, both ends 6 m off it
    async with rig(goal, [wall]) as r:
        await r.until(2.5)
        first = r.drain(r.paths)[-1].body.points
        side = float(np.sign(first[np.argmin(np.abs(first[:, 0] - 8.5)), 1]))
        assert side != 0.0
        # a metre towards the other end: that way is now the shorter, by about a metre
        r.pose.place(0.0, -side * 1.0)
        await r.until(3.5)
        held = r.drain(r.paths)[-1].body.points
        optimal = np.array([r.planner.grid.centre(c) for c in r.planner.planner.path()])
        # the held way still passes the wall on the first side; D* alone would switch
        assert np.sign(held[np.argmin(np.abs(held[:, 0] - 8.5)), 1]) == side
        assert np.sign(optimal[np.argmin(np.abs(optimal[:, 0] - 8.5)), 1]) == -side
        assert r.planner.statistics()["held_paths"] >= 1
        # the wall turns out to run on past the held end: that way is blocked
        r.sense([wall, (8.0, 9.0, 6.0, 19.0) if side > 0 else (8.0, 9.0, -19.0, -6.0)])
        await r.until(5.5)
        switched = r.drain(r.paths)[-1].body.points
    assert np.sign(switched[np.argmin(np.abs(switched[:, 0] - 8.5)), 1]) == -side
    assert clearance(switched, wall) >= HALF_WIDTH
