"""The Global Map as a component: the test publishes traversability maps (as the
Traversability Map does) and uses the seed's Table 18 interface, the bulk access of
decision 0009 and the PlanMap events, on a virtual clock.

The planning grid here is 50 m x 50 m at 0.5 m (100 x 100 cells) centred on the world
origin: planning node (x, y) is the cell whose world x lies in ``[-25 + 0.5x, -25 +
0.5(x+1))``, likewise y. Costs follow the documented mapping (``accumulate.CostMapping``:
``1 + 9·hazard²`` below hazard 1, infinite at 1; ``UnknownCellCost`` where nothing was
sensed), worked out here by hand.
"""

from __future__ import annotations

import math
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from afa import EOutOfBounds, System, VirtualClock
from components.global_map import GlobalMap, GlobalMapParameters
from idl import (
    GlobalMap as GlobalMapInterface,
)
from idl import (
    PlanningBoundaryIDL,
    PlanPointIDL,
    PoseTransformIDL,
    Position3DIDL,
    TimeIDL,
    TravMapArrayEventIDL,
    WaypointGroupIDL,
    WaypointIDL,
)

UTM = np.array([500_000.0, 5_570_000.0, 750.0])
G = 0.5
HALF = 25.0  # the grid spans -25 .. 25 m both ways
N = 100


def node(x: float, y: float) -> tuple[int, int]:
    """The planning node holding world point (x, y)."""
    return math.floor((x + HALF) / G), math.floor((y + HALF) / G)


def trav_map(t: float, hazard: np.ndarray, *, origin=(-4.0, -4.0), gridsize: float = G,
             vehicle=(0.0, 0.0), goodness: float = 0.9, utm: np.ndarray = UTM
             ) -> TravMapArrayEventIDL:
    rows, cols = hazard.shape
    return TravMapArrayEventIDL(
        time=TimeIDL.from_seconds(t), frame="World", mapPose=np.eye(4), initialUTM=utm,
        gridsize=gridsize, originX=origin[0], originY=origin[1], rows=rows, cols=cols,
        hazard=hazard.astype(np.float32),
        goodness=np.where(np.isnan(hazard), 0.0, goodness).astype(np.float32),
        vehiclePosition=Position3DIDL(x=vehicle[0], y=vehicle[1]), vehicleHeading=0.0)


def scene() -> np.ndarray:
    """16 x 16 cells from (-4, -4): flat (0), a wall (1) at x in [2, 3), y in [-1, 1), a
    rough cell (0.5) at (-2.75, -2.75), and an unobserved corner (NaN) x, y < -3."""
    h = np.zeros((16, 16))
    h[12:14, 6:10] = 1.0  # x = -4 + 0.5i: i 12, 13 -> [2, 3); j 6..9 -> [-1, 1)
    h[2, 2] = 0.5         # x, y in [-3, -2.5)
    h[:2, :2] = np.nan    # x, y in [-4, -3)
    return h


@dataclass
class Rig:
    clock: VirtualClock
    system: System
    global_map: GlobalMap
    events: Any

    @property
    def proxy(self) -> Any:
        return self.system.proxy(GlobalMapInterface, "GlobalMap")

    async def publish(self, body: TravMapArrayEventIDL) -> None:
        self.system.channel.publish("Raptor", "Traverse", body)
        await self.clock.sleep(0.1)

    def stats(self) -> dict[str, Any]:
        return self.global_map.statistics()

    def health(self):
        return self.system.health()["GlobalMapService"]


@asynccontextmanager
async def rig(**overrides: Any):
    clock = VirtualClock()
    values = {"Width": 50000, "Depth": 50000, "Gridsize": 500, "UnknownCellCost": 2.0,
              **overrides}
    component = GlobalMap("GlobalMapService", GlobalMapParameters(**values))
    system = System([component], clock=clock)
    async with system:
        events = system.channel.subscribe("Raptor", "PlanMap", maxsize=1000)
        yield Rig(clock, system, component, events)


def drain(subscription: Any) -> list[Any]:
    out = []
    while (event := subscription.get_nowait()) is not None:
        out.append(event)
    return out


def P(xy: tuple[int, int], **costs: Any) -> PlanPointIDL:
    return PlanPointIDL(x=xy[0], y=xy[1], **costs)


# --- Table 18 ----------------------------------------------------------------------------


async def test_sensed_costs_follow_the_merged_hazards():
    async with rig() as r:
        await r.publish(trav_map(r.clock.now(), scene()))
        g = r.proxy
        wall, rough, flat = node(2.25, 0.25), node(-2.75, -2.75), node(0.25, 0.25)
        unseen, beyond = node(-3.75, -3.75), node(10.0, 10.0)
        assert await g.getSensingMap(P(wall)) == math.inf
        assert await g.getSensingMap(P(rough)) == pytest.approx(1 + 9 * 0.25)
        assert await g.getSensingMap(P(flat)) == 1.0
        assert await g.getSensingMap(P(unseen)) == 2.0  # UnknownCellCost
        assert await g.getSensingMap(P(beyond)) == 2.0
        for xy in (wall, rough, flat, unseen):
            assert await g.getPlanningMap(P(xy)) == 2.0  # a priori: nothing known
        point = await g.getMap(P(rough))
        assert (point.x, point.y, point.sensed) == (*rough, True)
        assert point.aPrioriCost == 2.0 and point.cost == pytest.approx(3.25)
        assert not (await g.getMap(P(unseen))).sensed
        assert await g.valid(P(flat)) and await g.valid(P(unseen))
        assert not await g.valid(P(wall))          # unreachable
        assert not await g.valid(P((N, 0))) and not await g.valid(P((0, -1)))  # off the grid
        with pytest.raises(EOutOfBounds):
            await g.getSensingMap(P((N, 0)))
        with pytest.raises(EOutOfBounds):
            await g.getMap(P((-1, 5)))
        stats, health = r.stats(), r.health()
    assert stats["maps_merged"] == 1 and stats["cells_changed"] == 16 * 16 - 4
    assert health.healthy


async def test_set_costs_by_hand():
    async with rig() as r:
        g = r.proxy
        a, b = node(5.25, 5.25), node(-5.25, 6.75)
        assert await g.setPlanningMap(P(a, aPrioriCost=math.inf))
        assert not await g.valid(P(a))
        assert await g.getPlanningMap(P(a)) == math.inf
        assert await g.setSensingMap(P(b, sensedCost=7.0))
        assert await g.getSensingMap(P(b)) == 7.0
        assert (await g.getMap(P(b))).sensed
        assert not await g.setPlanningMap(P((N, N), aPrioriCost=3.0))
        assert not await g.setSensingMap(P((-1, 0), sensedCost=3.0))
        # setMap: both costs and the sensed flag at once
        c = node(1.25, 1.25)
        assert await g.setMap(P(c, aPrioriCost=4.0, sensedCost=6.0, sensed=True))
        point = await g.getMap(P(c))
        assert (point.aPrioriCost, point.sensedCost, point.sensed) == (4.0, 6.0, True)
        d = node(1.75, 1.25)
        assert await g.setMap(P(d, aPrioriCost=5.0))  # not sensed: only the a priori cost
        point = await g.getMap(P(d))
        assert (point.aPrioriCost, point.sensedCost, point.sensed) == (5.0, 2.0, False)
        assert not await g.setMap(P((N, 3), aPrioriCost=5.0))
        # a sensed observation overrides the a priori cost for planning
        await r.publish(trav_map(r.clock.now(), np.zeros((16, 16)), origin=(4.0, 4.0)))
        whole = await g.getPlanMap()
        events = drain(r.events)
    assert whole.planning_cost()[a] == 1.0 and whole.aPrioriCost[a] == math.inf
    assert whole.planning_cost()[b] == 7.0 and whole.planning_cost()[d] == 5.0
    assert len(events) == 5  # one per change


async def test_the_transforms_between_world_and_planning_frames():
    async with rig() as r:
        await r.publish(trav_map(r.clock.now(), scene()))
        to_plan = (await r.proxy.getTransformToPlanningFromWorld()).HTransform
        to_world = await r.proxy.getTransformToWorldFromPlanning()
    assert np.allclose(to_plan @ to_world.HTransform, np.eye(4))
    assert np.array_equal(to_world.initialUTM, UTM)
    world = np.array([2.3, -7.9, 0.0, 1.0])
    planning = to_plan @ world
    assert planning[:2] == pytest.approx([(2.3 + HALF) / G, (-7.9 + HALF) / G])
    assert tuple(int(v) for v in np.floor(planning[:2])) == node(2.3, -7.9)


async def test_vehicle_position_from_the_latest_map():
    async with rig() as r:
        assert await r.proxy.getVehiclePosition() is None
        await r.publish(trav_map(r.clock.now(), scene(), vehicle=(1.5, -2.0)))
        await r.publish(trav_map(r.clock.now(), scene(), vehicle=(2.5, -2.5)))
        position = await r.proxy.getVehiclePosition()
    assert (position.x, position.y) == (2.5, -2.5)


def waypoint(x: float, y: float, tolerance: float = 2.0) -> WaypointIDL:
    """A waypoint given in UTM, ``(x, y)`` metres from the pose frame's origin (its
    latitude and longitude, which getNextWaypoint matches waypoints by, are rough)."""
    return WaypointIDL(latitude=50.0 + y * 1e-5, longitude=-111.0 + x * 1e-5,
                       easting=UTM[0] + x, northing=UTM[1] + y, tolerance=tolerance)


@pytest.mark.parametrize("patrol", [False, True])
async def test_waypoints_advance_as_the_vehicle_reaches_them(patrol):
    course = [waypoint(10.0, 0.0), waypoint(10.0, 10.0), waypoint(0.0, 10.0)]
    group = WaypointGroupIDL(waypoints=tuple(course), patrolMode=patrol)
    async with rig() as r:
        g = r.proxy
        assert await g.getCurrentWaypoint() is None
        await g.setWaypointList(group)
        assert await g.getWaypointList() == group
        assert await g.getCurrentWaypoint() == course[0]
        assert await g.getNextWaypoint(course[0]) == course[1]
        assert await g.getNextWaypoint(course[2]) == (course[0] if patrol else None)
        assert await g.getNextWaypoint(waypoint(-9.0, -9.0)) is None  # not on the list
        seen = []
        for vehicle in [(0.0, 0.0), (8.5, 0.5), (9.0, 9.0), (1.0, 10.0), (9.0, 0.0)]:
            await r.publish(trav_map(r.clock.now(), scene(), vehicle=vehicle))
            seen.append(await g.getCurrentWaypoint())
        stats = r.stats()
    assert seen[:4] == [course[0], course[1], course[2], course[0] if patrol else None]
    assert seen[4] == (course[1] if patrol else None)
    assert stats["waypoints_reached"] == (4 if patrol else 3)


async def test_a_patrol_of_one_waypoint_finishes_there():
    """A patrol needs two waypoints; with one it is reached once and the mission is
    over (as Pure Pursuit takes it), not reached again on every map while the vehicle
    stands on it."""
    only = waypoint(10.0, 0.0)
    async with rig() as r:
        g = r.proxy
        await g.setWaypointList(WaypointGroupIDL(waypoints=(only,), patrolMode=True))
        assert await g.getNextWaypoint(only) is None
        for _ in range(5):
            await r.publish(trav_map(r.clock.now(), scene(), vehicle=(9.5, 0.0)))
        assert await g.getCurrentWaypoint() is None
        assert r.stats()["waypoints_reached"] == 1


def pose_at(x: float, y: float, utm: np.ndarray = UTM) -> PoseTransformIDL:
    transform = np.eye(4)
    transform[:2, 3] = (x, y)
    return PoseTransformIDL(time=TimeIDL.from_seconds(0.0), HTransform=transform,
                            initialUTM=utm)


async def test_a_waypoint_is_reached_by_the_rear_axle_the_planners_steer():
    """A waypoint under the vehicle's rear axle is reached, though the maps' vehicle
    position (the ground under the front bumper, 2.45 m ahead) is beyond its 2 m
    tolerance: the Global Map judges by the pose, as Pure Pursuit and FindPath steer
    the rear axle. A pose in another world frame is not used."""
    course = (waypoint(0.0, 0.0), waypoint(10.0, 0.0))
    async with rig() as r:
        g = r.proxy
        await g.setWaypointList(WaypointGroupIDL(waypoints=course))
        await r.publish(trav_map(r.clock.now(), scene(), vehicle=(2.45, 0.0)))
        assert await g.getCurrentWaypoint() == course[0]  # the bumper is 2.45 m away
        r.system.channel.publish("Raptor", "Pose", pose_at(0.0, 0.0, UTM + 100.0))
        await r.clock.advance(0.1)
        assert await g.getCurrentWaypoint() == course[0]  # another frame: not used
        r.system.channel.publish("Raptor", "Pose", pose_at(0.3, 0.0))
        await r.clock.advance(0.1)
        assert await g.getCurrentWaypoint() == course[1]
    async with rig() as r:  # before the first map: the pose's own frame places them
        g = r.proxy
        await g.setWaypointList(WaypointGroupIDL(waypoints=course))
        r.system.channel.publish("Raptor", "Pose", pose_at(0.3, 0.0))
        await r.clock.advance(0.1)
        assert await g.getCurrentWaypoint() == course[1]
    async with rig(PoseEventName="") as r:  # without poses, the maps' position decides
        g = r.proxy
        await g.setWaypointList(WaypointGroupIDL(waypoints=course))
        await r.publish(trav_map(r.clock.now(), scene(), vehicle=(2.45, 0.0)))
        r.system.channel.publish("Raptor", "Pose", pose_at(0.3, 0.0))
        await r.clock.advance(0.1)
        assert await g.getCurrentWaypoint() == course[0]


async def test_the_planning_boundary_is_clipped_and_limits_valid():
    async with rig() as r:
        g = r.proxy
        assert await g.getPlanningBoundary() == PlanningBoundaryIDL(minX=0, minY=0,
                                                                    maxX=N - 1, maxY=N - 1)
        assert await g.setPlanningBoundary(PlanningBoundaryIDL(minX=-10, minY=20, maxX=40,
                                                               maxY=500))
        assert await g.getPlanningBoundary() == PlanningBoundaryIDL(minX=0, minY=20, maxX=40,
                                                                    maxY=N - 1)
        assert await g.valid(P((40, 20))) and not await g.valid(P((41, 20)))
        assert not await g.valid(P((10, 19)))
        # a boundary entirely off the grid is refused and the old one kept
        assert not await g.setPlanningBoundary(PlanningBoundaryIDL(minX=200, minY=0,
                                                                   maxX=300, maxY=5))
        assert (await g.getPlanningBoundary()).maxX == 40
        whole = await g.getPlanMap()
    assert whole.planningBoundary.maxX == 40


async def test_the_grid_moves_along_a_mission_longer_than_it_keeping_what_it_sensed():
    """A waypoint 60 m away on a 50 m grid: the grid moves along the leg (the vehicle
    6.25 m, an eighth of the grid, from its trailing edge); the wall sensed before the
    move is still where it was on the ground, the cells that came in are unknown, the
    operator's boundary stays on the same ground, and a planner learns of it all from a
    PlanMap of the whole grid with its new origin."""
    async with rig() as r:
        g = r.proxy
        await r.publish(trav_map(r.clock.now(), scene()))
        wall = node(2.25, 0.25)
        assert await g.getSensingMap(P(wall)) == math.inf
        assert await g.setPlanningBoundary(PlanningBoundaryIDL(minX=10, minY=0, maxX=60,
                                                               maxY=N - 1))
        drain(r.events)
        await g.setWaypointList(WaypointGroupIDL(waypoints=(waypoint(60.0, 0.0),)))
        moved = drain(r.events)
        to_planning = (await g.getTransformToPlanningFromWorld()).HTransform
        shift = round(HALF / G - to_planning[0, 3])  # cells the origin moved along x
        assert 30 <= shift <= 40 and to_planning[1, 3] == pytest.approx(HALF / G)
        assert r.stats()["grid_moves"] == 1
        assert len(moved) == 1 and moved[0].body.fullRows == 0
        assert moved[0].body.originX == pytest.approx(-HALF + shift * G)
        # the wall: the same ground, another node; the ground ahead: unknown
        assert await g.getSensingMap(P((wall[0] - shift, wall[1]))) == math.inf
        assert await g.getSensingMap(P((N - 1, N // 2))) == 2.0
        assert not (await g.getMap(P((N - 1, N // 2)))).sensed
        # the boundary: world cells 10..60 along x, now cells 0..60 - shift
        assert await g.getPlanningBoundary() == PlanningBoundaryIDL(
            minX=0, minY=0, maxX=60 - shift, maxY=N - 1)
        # a map arriving after the move lands on its own ground
        await r.publish(trav_map(r.clock.now(), scene(), origin=(10.0, -4.0)))
        assert await g.getSensingMap(P(node(16.25 - shift * G, 0.25))) == math.inf
        # nothing moves while the vehicle keeps more than half the lead ahead
        await r.publish(trav_map(r.clock.now(), scene(), vehicle=(5.0, 0.0)))
        assert r.stats()["grid_moves"] == 1


# --- bulk access and PlanMap events ---------------------------------------------------------


async def test_plan_map_changes_return_only_the_changed_window():
    async with rig() as r:
        g = r.proxy
        await r.publish(trav_map(r.clock.now(), scene()))
        whole = await g.getPlanMap()
        revision = whole.revision
        assert (whole.rows, whole.cols, whole.fullRows, whole.fullCols) == (N, N, 0, 0)
        assert await g.getPlanMapChanges(revision) is None  # nothing new
        rough = node(-2.75, -2.75)
        wall = node(2.25, 0.25)
        assert await g.setSensingMap(P(rough, sensedCost=9.0))
        assert await g.setSensingMap(P(wall, sensedCost=1.0))
        changes = await g.getPlanMapChanges(revision)
        # the window spans both changed cells, no more
        assert changes.revision == revision + 2
        assert (changes.fullRows, changes.fullCols) == (N, N)
        assert (changes.rows, changes.cols) == (wall[0] - rough[0] + 1, wall[1] - rough[1] + 1)
        i0 = round((changes.originX - whole.originX) / G)
        j0 = round((changes.originY - whole.originY) / G)
        assert (i0, j0) == rough
        assert changes.sensedCost[0, 0] == 9.0 and changes.sensedCost[-1, -1] == 1.0
        latest = await g.getPlanMapChanges(revision + 1)  # only the second change
        assert (latest.rows, latest.cols) == (1, 1)
        # a change covering most of the grid comes back whole
        wide = np.zeros((80, 80))
        await r.publish(trav_map(r.clock.now(), wide, origin=(-20.0, -20.0)))
        assert (await g.getPlanMapChanges(revision)).fullRows == 0
        # so does a revision the Global Map never had
        assert (await g.getPlanMapChanges(10_000)).rows == N
        events = drain(r.events)
    # one PlanMap event per change: the first merge (256 cells) as a window, the wide one
    # (6400 of 10,000 cells) whole
    assert [(e.body.rows, e.body.fullRows) for e in events] == [(16, N), (1, N), (1, N),
                                                               (N, 0)]
    assert [e.body.revision for e in events] == [1, 2, 3, 4]


async def test_a_map_that_changes_no_cost_publishes_nothing():
    async with rig() as r:
        await r.publish(trav_map(r.clock.now(), scene()))
        await r.publish(trav_map(r.clock.now(), scene()))
        events, stats = drain(r.events), r.stats()
    assert len(events) == 1 and stats["maps_merged"] == 2 and stats["revision"] == 1


async def test_a_moved_world_origin_starts_the_map_again():
    async with rig() as r:
        await r.publish(trav_map(r.clock.now(), scene()))
        moved = UTM + np.array([100.0, 0.0, 0.0])
        await r.publish(trav_map(r.clock.now(), np.zeros((4, 4)), origin=(10.0, 10.0),
                                 utm=moved))
        wall = await r.proxy.getSensingMap(P(node(2.25, 0.25)))
        whole = await r.proxy.getPlanMap()
    assert wall == 2.0  # forgotten: it was in the old frame
    assert np.array_equal(whole.initialUTM, moved)
    assert int((~np.isnan(whole.hazard)).sum()) == 16


# --- bad input ----------------------------------------------------------------------------


async def test_a_map_from_the_future_is_refused_and_later_maps_still_update_the_cells():
    async with rig() as r:
        await r.publish(trav_map(r.clock.now(), scene()))
        future = np.ones((16, 16))
        await r.publish(trav_map(r.clock.now() + 3600.0, future))
        refused = r.health()
        flat = await r.proxy.getSensingMap(P(node(0.25, 0.25)))
        # the present still gets through: the wall has been removed
        await r.clock.sleep(3.0)
        await r.publish(trav_map(r.clock.now(), np.zeros((16, 16))))
        wall = await r.proxy.getSensingMap(P(node(2.25, 0.25)))
        stats, recovered = r.stats(), r.health()
    assert flat == 1.0 and wall == 1.0
    assert stats["future_maps"] == 1 and stats["maps_merged"] == 2
    assert not refused.healthy and "Traverse maps stamped in the future" in refused.detail
    assert recovered.healthy


async def test_a_coarser_map_is_refused_a_finer_one_merged_at_its_worst():
    async with rig() as r:
        await r.publish(trav_map(r.clock.now(), np.zeros((4, 4)), gridsize=1.0))
        refused, stats = r.health(), r.stats()
        assert await r.proxy.getSensingMap(P(node(-3.5, -3.5))) == 2.0  # not merged
        fine = np.zeros((8, 8))  # 0.25 m cells over [-4, -2) both ways
        fine[1, 1] = 1.0        # a quarter of the planning cell x, y in [-4, -3.5)
        fine[2, 2] = 0.5        # a quarter of the planning cell x, y in [-3.5, -3)
        await r.publish(trav_map(r.clock.now(), fine, gridsize=0.25))
        worst = [await r.proxy.getSensingMap(P(node(x, x))) for x in (-3.75, -3.25, -2.25)]
        later = r.stats()
    assert stats["grid_mismatch"] == 1 and stats["maps_merged"] == 0
    assert not refused.healthy
    assert "Traverse maps with 1 m cells, coarser than the planning grid's 0.5 m" \
        in refused.detail
    assert worst == [math.inf, pytest.approx(3.25), 1.0]
    assert later["maps_merged"] == 1
