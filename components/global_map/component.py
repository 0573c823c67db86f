"""The Global Map (seed §3.2.3, Table 18): the cumulative planning map of the mission area.

- Subscribes to the global traversability map (``TraverseEventName``) and merges every
  one into the planning grid (``Width`` × ``Depth`` at ``Gridsize``, first centred on the
  pose frame's origin, the start; :mod:`components.global_map.accumulate`: an a priori cost
  layer and a sensed cost layer, cost ≥ 1 for traversable cells and inf for hazards, so
  D* Lite's octile heuristic stays admissible).
- Publishes ``PlanMapEventName`` (PlanMapEventIDL) after each merge that changed a cost:
  only the changed window when it is smaller than the grid (the seed: to trigger the
  redisplay of the developing map; afa: also a log of the planner's input).
- Serves Table 18 under ``InterfaceName`` with the seed's semantics (planning node
  (x, y) is cell [x, y]; see :mod:`idl.planning`), and the bulk access of decision 0009
  (``getPlanMap``, ``getPlanMapChanges(revision)``) that FindPath plans from.
- Keeps the waypoint list (set as Pure Pursuit's is) and the current waypoint: it
  advances when the vehicle comes within the waypoint's tolerance, by its rear axle
  (``PoseEventName``, the point Pure Pursuit and FindPath steer; from the first pose, so
  a waypoint where the vehicle starts is reached at once) or by the ground under its
  front bumper (the traversability maps' vehicle position), and wraps in patrol mode
  (a patrol needs two waypoints: with one it finishes, as Pure Pursuit's does).
- Keeps the mission inside the grid (decision 0041): when the vehicle or the
  waypoints ahead of it come within ``MISSION_MARGIN`` of the grid's edge, the grid
  moves by whole cells (:func:`~components.global_map.accumulate.mission_shift`) to
  hold the vehicle and as many of the waypoints ahead as fit; what it had sensed
  inside the new placement is kept, and the planning boundary stays where the operator
  set it on the ground (it is kept whole and clipped to each placement).
  A PlanMap of the whole grid, with its new origin, tells the planner.
- Bad input is counted in ``statistics()``, not merged, and makes the component
  unhealthy until a map is accepted ``BAD_INPUT_WINDOW`` seconds later (its detail naming
  it, :mod:`components.bad_input`): a map stamped more than ``FUTURE_TOLERANCE`` ahead
  of the clock (``future_maps``: merged, its stamp would make every later observation
  of its cells look older than it, so none could ever replace it), and a map coarser
  than the planning grid (``grid_mismatch``: each of its cells would reach only the one
  planning cell holding its centre, leaving the others free for the planner; an equal
  or finer map is merged, several cells into one at their highest hazard).
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

from afa import Event, SubscribePublishServer
from afa.errors import EOutOfBounds
from components.bad_input import BAD_INPUT_WINDOW, FUTURE_TOLERANCE, BadInputLog
from components.global_map.accumulate import CostMapping, PlanningGrid, Region, mission_shift
from components.global_map.parameters import GlobalMapParameters
from components.waypoints import to_local
from idl import GlobalMap as GlobalMapInterface
from idl import (
    PlanMapEventIDL,
    PlanningBoundaryIDL,
    PlanPointIDL,
    PoseTransformIDL,
    Position3DIDL,
    TimeIDL,
    TravMapArrayEventIDL,
    WaypointGroupIDL,
    WaypointIDL,
)

__all__ = ["GlobalMap", "CHANGE_LOG", "MISSION_MARGIN"]

#: How many merges' changed windows are remembered for getPlanMapChanges.
CHANGE_LOG = 512
#: The mission is kept this far (m) inside the grid's edges, or an eighth of the grid's
#: size when that is less: room to plan round an obstacle at a waypoint or at the edge.
MISSION_MARGIN = 15.0


class GlobalMap(SubscribePublishServer[GlobalMapParameters]):
    """The Global Map (module docstring)."""

    def __init__(self, name: str, parameters: GlobalMapParameters | None = None) -> None:
        super().__init__(name, parameters)
        p = self.parameters
        self.subscribes(p.TraverseEventName, TravMapArrayEventIDL, self._on_map, maxsize=4,
                        required=True)
        if p.PoseEventName:
            self.subscribes(p.PoseEventName, PoseTransformIDL, self._on_pose, maxsize=4)
        self.plan_maps = self.publishes(p.PlanMapEventName, PlanMapEventIDL)
        self.serves(GlobalMapInterface, p.InterfaceName)
        self.grid = self._new_grid()
        self.revision = 0
        self._log: deque[tuple[int, Region]] = deque(maxlen=CHANGE_LOG)
        self.boundary = self._whole()
        # the operator's planning boundary in the cells of the grid's first placement
        # (None: the whole grid), and how far the grid has moved since (cells)
        self._fence: tuple[int, int, int, int] | None = None
        self._moved = (0, 0)
        self.waypoints = WaypointGroupIDL()
        self._local: tuple[tuple[float, ...], list[tuple[float, float]]] = ((), [])
        self.current = 0
        self.finished = False
        self.initial_utm: np.ndarray | None = None
        self.vehicle: Position3DIDL | None = None
        self.axle: tuple[float, float] | None = None  # the latest pose's, in the maps' frame
        self.heading = 0.0
        self._whole_map: PlanMapEventIDL | None = None
        self.bad_input = BadInputLog(BAD_INPUT_WINDOW)
        self.counters = {"maps_merged": 0, "cells_changed": 0, "plan_maps_published": 0,
                         "waypoints_reached": 0, "cells_outside": 0, "future_maps": 0,
                         "grid_mismatch": 0, "grid_moves": 0}

    async def setup(self) -> None:
        self.bad_input.clear()

    def _new_grid(self) -> PlanningGrid:
        p = self.parameters
        return PlanningGrid.centred(0.0, 0.0, p.Width / 1000.0, p.Depth / 1000.0,
                                    p.Gridsize / 1000.0, CostMapping(unknown=p.UnknownCellCost))

    def _whole(self) -> PlanningBoundaryIDL:
        rows, cols = self.grid.geometry.shape
        return PlanningBoundaryIDL(minX=0, minY=0, maxX=rows - 1, maxY=cols - 1)

    # -- merging ---------------------------------------------------------------------------
    def _bad(self, counter: str, what: str) -> None:
        self.counters[counter] += 1
        self.bad_input.note(what, self.clock.monotonic())
        self._update_health()

    def _update_health(self) -> None:
        problems = self.bad_input.recent(self.clock.monotonic())
        self.set_health(not problems, "; ".join(problems))

    def _on_map(self, event: Event) -> None:
        body: TravMapArrayEventIDL = event.body  # type: ignore[assignment]
        if body.time.to_seconds() > self.clock.now() + FUTURE_TOLERANCE:
            self._bad("future_maps", f"{event.type} maps stamped in the future (ignored)")
            return
        planning = self.grid.geometry.gridsize
        if body.gridsize > planning * (1.0 + 1e-9):
            self._bad("grid_mismatch", f"{event.type} maps with {body.gridsize:g} m cells, "
                                       f"coarser than the planning grid's {planning:g} m "
                                       "(ignored)")
            return
        self._update_health()
        if self.initial_utm is None or not np.array_equal(body.initialUTM, self.initial_utm):
            if self.initial_utm is not None:
                self.log.warning("%s: the world frame's origin moved: the map starts again",
                                 self.name)
                self.grid = self._new_grid()
                self._moved = (0, 0)
                self.boundary = self._placed_boundary() or self._whole()
                self._changed(Region(0, self.grid.geometry.rows, 0, self.grid.geometry.cols))
            self.initial_utm = np.array(body.initialUTM)
            self.axle = None  # placed in no frame or another: the next pose places it
        self.vehicle = body.vehiclePosition
        self.heading = body.vehicleHeading
        self._keep_mission_inside()
        change = self.grid.merge(body.hazard, body.goodness, body.mapPose, body.originX,
                                 body.originY, body.gridsize, body.time.to_seconds())
        self.counters["maps_merged"] += 1
        self.counters["cells_outside"] += change.outside
        self._track_waypoint()
        if change.cost_region is not None:
            self.counters["cells_changed"] += len(change)
            self._changed(change.cost_region)

    def _changed(self, region: Region) -> None:
        self.revision += 1
        self._log.append((self.revision, region))
        self._whole_map = None
        window = region if region.size * 2 < self.grid.geometry.size else None
        self.plan_maps.publish(self._event(window))
        self.counters["plan_maps_published"] += 1

    def _event(self, region: Region | None) -> PlanMapEventIDL:
        geometry = region.geometry(self.grid.geometry) if region is not None \
            else self.grid.geometry
        rows, cols = self.grid.geometry.shape
        return PlanMapEventIDL(
            time=TimeIDL.from_seconds(self.clock.now()), frame="World", mapPose=np.eye(4),
            initialUTM=self.initial_utm if self.initial_utm is not None else np.zeros(3),
            gridsize=geometry.gridsize, originX=geometry.origin_x, originY=geometry.origin_y,
            rows=geometry.rows, cols=geometry.cols, **self.grid.layers(region),
            vehiclePosition=self.vehicle or Position3DIDL(), vehicleHeading=self.heading,
            planningBoundary=self.boundary, revision=self.revision,
            fullRows=rows if region is not None else 0,
            fullCols=cols if region is not None else 0)

    # -- waypoints -------------------------------------------------------------------------
    def _on_pose(self, event: Event) -> None:
        pose: PoseTransformIDL = event.body  # type: ignore[assignment]
        if self.initial_utm is not None and not np.array_equal(pose.initialUTM,
                                                               self.initial_utm):
            return  # not the maps' frame
        x, y = float(pose.HTransform[0, 3]), float(pose.HTransform[1, 3])
        if math.isfinite(x) and math.isfinite(y) and np.any(pose.initialUTM):
            # before the first map the pose's own frame places the waypoints: a waypoint
            # where the vehicle starts is reached before it drives away
            self.axle = (x, y)
            self._track_waypoint(np.asarray(pose.initialUTM))

    def _track_waypoint(self, frame: np.ndarray | None = None) -> None:
        """Advance the current waypoint when the vehicle is within its tolerance: its
        rear axle (the latest pose) or the ground under its front bumper (the latest
        map's vehicle position); ``frame`` the initialUTM that places them (default the
        maps')."""
        points = self.waypoints.waypoints
        frame = self.initial_utm if frame is None else frame
        if not points or self.finished or frame is None:
            return
        where = [] if self.axle is None else [self.axle]
        if self.vehicle is not None and self.initial_utm is not None:
            where.append((self.vehicle.x, self.vehicle.y))
        target = points[self.current]
        x, y = self._waypoints_in(frame)[self.current]
        if not any(math.hypot(vx - x, vy - y) <= target.tolerance for vx, vy in where):
            return
        self.counters["waypoints_reached"] += 1
        if self.current + 1 < len(points):
            self.current += 1
        elif self.waypoints.patrolMode and len(points) >= 2:
            self.current = 0
        else:  # the last one; a patrol of one waypoint finishes too, as Pure Pursuit's
            self.finished = True

    def _waypoints_in(self, frame: np.ndarray) -> list[tuple[float, float]]:
        """The waypoints in the world frame of ``frame`` (an initialUTM), converted once
        per list and frame (a conversion costs tens of microseconds; poses come 14 times
        a second)."""
        key = tuple(float(v) for v in frame)
        if self._local[0] != key:
            self._local = (key, [to_local(w, frame) for w in self.waypoints.waypoints])
        return self._local[1]

    def _keep_mission_inside(self) -> None:
        """Move the grid when the vehicle or the waypoints ahead come near its edge."""
        if self.vehicle is None or self.initial_utm is None:
            return
        points = self._waypoints_in(self.initial_utm)
        ahead = [] if self.finished else points[self.current:]
        if self.waypoints.patrolMode and not self.finished:
            ahead = ahead + points[:self.current]
        geometry = self.grid.geometry
        margin = min(MISSION_MARGIN, geometry.rows * geometry.gridsize / 8,
                     geometry.cols * geometry.gridsize / 8)
        di, dj = mission_shift(geometry, (self.vehicle.x, self.vehicle.y), ahead, margin)
        if not (di or dj):
            return
        self.grid.shift(di, dj)
        self._moved = (self._moved[0] + di, self._moved[1] + dj)
        self.boundary = self._placed_boundary() or self._whole()
        rows, cols = geometry.shape
        self.counters["grid_moves"] += 1
        self.log.info("%s: the planning grid moved %d, %d cells to keep the mission inside",
                      self.name, di, dj)
        self._changed(Region(0, rows, 0, cols))

    # -- Table 18 ----------------------------------------------------------------------------
    def _cell(self, p: PlanPointIDL) -> tuple[int, int]:
        if not bool(self.grid.contains(p.x, p.y)):
            rows, cols = self.grid.geometry.shape
            raise EOutOfBounds(f"node ({p.x}, {p.y}) is outside the {rows}x{cols} planning "
                               "grid")
        return p.x, p.y

    async def valid(self, p: PlanPointIDL) -> bool:
        if not bool(self.grid.contains(p.x, p.y)) or not self.boundary.contains(p.x, p.y):
            return False
        return bool(np.isfinite(self.grid.cost_at(np.array([p.x]), np.array([p.y]))[0]))

    async def getPlanningMap(self, p: PlanPointIDL) -> float:
        i, j = self._cell(p)
        return float(self.grid.a_priori[i, j])

    async def getSensingMap(self, p: PlanPointIDL) -> float:
        i, j = self._cell(p)
        return float(self.grid.sensed_cost[i, j])

    async def setPlanningMap(self, p: PlanPointIDL) -> bool:
        if not bool(self.grid.contains(p.x, p.y)):
            return False
        change = self.grid.set_a_priori(p.x, p.y, p.aPrioriCost)
        if change.cost_region is not None:
            self._changed(change.cost_region)
        return True

    async def setSensingMap(self, p: PlanPointIDL) -> bool:
        if not bool(self.grid.contains(p.x, p.y)):
            return False
        change = self.grid.set_sensed(p.x, p.y, p.sensedCost, self.clock.now())
        if change.cost_region is not None:
            self._changed(change.cost_region)
        return True

    async def getMap(self, p: PlanPointIDL) -> PlanPointIDL:
        i, j = self._cell(p)
        return PlanPointIDL(x=i, y=j, aPrioriCost=float(self.grid.a_priori[i, j]),
                            sensedCost=float(self.grid.sensed_cost[i, j]),
                            sensed=bool(self.grid.sensed[i, j]))

    async def setMap(self, p: PlanPointIDL) -> bool:
        if not bool(self.grid.contains(p.x, p.y)):
            return False
        changes = [self.grid.set_a_priori(p.x, p.y, p.aPrioriCost)]
        if p.sensed:
            changes.append(self.grid.set_sensed(p.x, p.y, p.sensedCost, self.clock.now()))
        if any(c.cost_region is not None for c in changes):
            self._changed(Region(p.x, p.x + 1, p.y, p.y + 1))
        return True

    async def getTransformToPlanningFromWorld(self) -> PoseTransformIDL:
        return self._transform(self.grid.planning_from_world())

    async def getTransformToWorldFromPlanning(self) -> PoseTransformIDL:
        return self._transform(self.grid.world_from_planning())

    def _transform(self, matrix: np.ndarray) -> PoseTransformIDL:
        return PoseTransformIDL(time=TimeIDL.from_seconds(self.clock.now()), HTransform=matrix,
                                initialUTM=self.initial_utm if self.initial_utm is not None
                                else np.zeros(3))

    async def getVehiclePosition(self) -> Position3DIDL | None:
        return self.vehicle

    async def getNextWaypoint(self, current: WaypointIDL) -> WaypointIDL | None:
        points = self.waypoints.waypoints
        for index, point in enumerate(points):
            if (point.latitude, point.longitude) == (current.latitude, current.longitude):
                if index + 1 < len(points):
                    return points[index + 1]
                return points[0] if self.waypoints.patrolMode and len(points) >= 2 \
                    else None
        return None

    async def setWaypointList(self, waypoints: WaypointGroupIDL) -> None:
        self.waypoints = waypoints
        self._local = ((), [])
        self.current = 0
        self.finished = False
        self._keep_mission_inside()

    async def getWaypointList(self) -> WaypointGroupIDL:
        return self.waypoints

    async def getCurrentWaypoint(self) -> WaypointIDL | None:
        if self.finished or not self.waypoints.waypoints:
            return None
        return self.waypoints.waypoints[self.current]

    def _placed_boundary(self, fence: tuple[int, int, int, int] | None = None
                         ) -> PlanningBoundaryIDL | None:
        """The operator's boundary (``fence``, default the one set) in the grid's cells
        where it lies now, clipped to the grid; the whole grid when none is set; None
        when none of it is inside."""
        fence = self._fence if fence is None else fence
        if fence is None:
            return self._whole()
        rows, cols = self.grid.geometry.shape
        di, dj = self._moved
        clipped = (max(0, fence[0] - di), max(0, fence[1] - dj),
                   min(rows - 1, fence[2] - di), min(cols - 1, fence[3] - dj))
        if clipped[2] < clipped[0] or clipped[3] < clipped[1]:
            return None
        return PlanningBoundaryIDL(minX=clipped[0], minY=clipped[1], maxX=clipped[2],
                                   maxY=clipped[3])

    async def setPlanningBoundary(self, boundary: PlanningBoundaryIDL) -> bool:
        di, dj = self._moved
        fence = (boundary.minX + di, boundary.minY + dj, boundary.maxX + di,
                 boundary.maxY + dj)
        placed = self._placed_boundary(fence)
        if placed is None:
            return False
        self._fence = fence  # kept whole: the grid may move over more of it later
        if placed != self.boundary:
            self.boundary = placed
            # a planner holding the map must learn the new limits: a change of the whole
            rows, cols = self.grid.geometry.shape
            self._changed(Region(0, rows, 0, cols))
        return True

    async def getPlanningBoundary(self) -> PlanningBoundaryIDL:
        return self.boundary

    async def getPlanMap(self) -> PlanMapEventIDL:
        if self._whole_map is None:
            self._whole_map = self._event(None)
        return self._whole_map

    async def getPlanMapChanges(self, revision: int) -> PlanMapEventIDL | None:
        if revision == self.revision:
            return None
        oldest = self._log[0][0] if self._log else self.revision + 1
        if revision > self.revision or revision < oldest - 1:
            return await self.getPlanMap()
        regions = [region for rev, region in self._log if rev > revision]
        union = Region(min(r.i0 for r in regions), max(r.i1 for r in regions),
                       min(r.j0 for r in regions), max(r.j1 for r in regions))
        if union.size * 2 >= self.grid.geometry.size:
            return await self.getPlanMap()
        return self._event(union)

    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        stats.update(self.counters)
        stats["revision"] = self.revision
        stats["current_waypoint"] = None if self.finished else self.current
        return stats
