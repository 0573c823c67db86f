"""FindPath (seed §3.3.1, Tables 22, A.9): D* Lite over the Global Map, and path tracking
by arc votes.

FindPath subscribes to nothing (Table 22): it polls. After ``PlanUpdateDelayTime`` it
runs one cycle every ``PlanEventInterval`` seconds:

1. the vehicle pose from ModelServer (``getPose``), the current waypoint from the Global
   Map (``getCurrentWaypoint``);
2. the planning map in bulk (decision 0009): the whole map once (``getPlanMap``), then
   only the window changed since the revision it holds (``getPlanMapChanges``);
3. its own cost grid: the map's planning cost (sensed where sensed, else a priori;
   unknown cells cost ``UnknownCellCost``, the free-space assumption, but no less than
   the median known passable cell: on a hillside the unseen ground is slope too,
   decision 0035, :meth:`CostGrid.update_prior`), with impassable
   cells grown by the vehicle's half width (``InflationRadius``) and a soft margin around
   them (``MarginRadius`` at ``MarginCost``), so a path for the rear axle keeps the body
   clear; cells outside the planning boundary are impassable;
4. D* Lite (:mod:`components.find_path.dstar_lite`): the changed cells update the search
   incrementally, the start moves with the vehicle, and the repair stops at an expansion
   budget beyond which an exact from-scratch plan is cheaper. If the vehicle is more than
   ``TrackingTolerance`` cells from the path it was following, the plan is rebuilt from
   scratch, as the seed's "forced to re-plan". The path followed is the rest of the last
   one while that is passable and not clearly dearer than the new plan (hysteresis:
   two ways round an obstacle that cost nearly the same do not alternate, decision 0043);
5. a drivable path (:mod:`components.find_path.kinematic`, decision 0024): arcs within
   the arc set's curvature, the body as discs, from the vehicle to the D* path's
   point ``RefineDistance`` ahead (where that is the waypoint, a path ends with the rear
   axle near it, or with the ground under the bumper, ``GroundFrame`` from ModelServer,
   where the rear axle cannot come: the Global Map's arrival rule, decision 0042); the
   vote is a narrow Gaussian around the curvature that reaches its point 1.5 m ahead
   (κ = 2y/D²), narrower still on the final approach (decision 0044). The path may
   back (``ReverseCost``, over ground the map has seen, decision 0046): one that starts
   by backing, a vehicle beside a gate it cannot turn into going forwards, puts that
   leg in the vote (``ArcVoteIDL.reverse``) for the arbiter, and the vote's arcs follow
   the best forward-only path meanwhile. When there is no forward path (the vehicle
   stands where none leads onto the plan) every arc is vetoed and the arbiter backs
   out. With refinement off (``RefineDistance`` 0) the
   look-ahead point is the farthest point of the D* path between ``MinLookahead`` and
   ``MaxLookahead`` cells along it to which the path runs nearly straight (within half a
   cell). The vote is published as an ``ArcVote`` (behaviour ``FindPath``), and the D*
   path as ``PlannedPath`` for displays. A waypoint beyond the map's planning limits is
   planned to the passable cell nearest it on the limits (the Global Map moves its grid
   along a mission longer than the grid, decision 0041). With no path (no route, the
   goal impassable and no free cell within its tolerance, or the vehicle off the map)
   the vote vetoes every arc, as the seed says, and the ``PlannedPath`` is empty (cost
   inf), so a display does not keep showing a path FindPath no longer has.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from datetime import UTC, datetime
from typing import Any

import numpy as np
from scipy import ndimage

from afa import SubscribePublishServer
from afa.diagnostics import Stopwatch
from afa.errors import AfaError
from components.arcs import ARC_SET_SECTION, ArcSet, ArcVotes, arc_set_of
from components.find_path.dstar_lite import DStarLite, PlanStatus
from components.find_path.kinematic import Arrival, Refined, Refiner
from components.find_path.parameters import FindPathParameters
from components.pure_pursuit.pursuit import gaussian_votes, pursuit_curvature, to_vehicle_frame
from components.waypoints import ground_point, to_local
from idl import ArcVoteIDL, PlanMapEventIDL, PlannedPathIDL, Platform, TimeIDL, WaypointIDL
from idl import GlobalMap as GlobalMapInterface

__all__ = ["FindPath", "BEHAVIOUR", "CostGrid", "path_cost"]

BEHAVIOUR = "FindPath"
#: How far along a drivable (refined) path the vote aims (m): two of its motions.
REFINED_LOOKAHEAD = 1.5
#: Planning cycles in a row without a path after which FindPath reports itself unhealthy
#: (a single cycle without one is common while a map update closes and reopens a gap).
NO_PATH_UNHEALTHY = 5
#: For a waypoint beyond the map, how far (m) from the limits' point nearest it a
#: passable cell may be taken as the goal.
BEYOND_SEARCH = 10.0
#: Hysteresis between plans (decision 0043): the rest of the last path is kept while it
#: is passable, the vehicle is within ``HOLD_DISTANCE`` cells of it, and it costs no more
#: than the new plan's cost times ``1 + HOLD_SHARE`` plus ``HOLD_SLACK`` metres of
#: cost-1 ground. Under the free-space assumption two ways round an obstacle seen in part
#: often cost nearly the same, and the cheaper one alternated as the vehicle moved.
HOLD_DISTANCE = 4.0
HOLD_SHARE = 0.05
HOLD_SLACK = 1.0
#: A drivable path to the waypoint ends with the rear axle or the bumper's ground point
#: within this share of the waypoint's tolerance (the rest absorbs tracking error).
ARRIVAL_SHARE = 0.75
#: The vote's spread about a drivable path (m of miss at its look-ahead point, one σ).
#: On the way, 0.1 m: σ spans about four arcs of the Raptor's set, so Obstacle
#: Avoidance's preference for room weighs in the choice among them. On the final
#: approach, 0.03 m (about one arc, decision 0044): that path ends in the waypoint's
#: arrival region, often at the end of a tight turn, and an arc one step straighter each
#: cycle drifted the vehicle past the region and round the waypoint again.
ON_THE_WAY_SPREAD = 0.1
ARRIVING_SPREAD = 0.03


class CostGrid:
    """FindPath's copy of the planning map with obstacles grown for the vehicle's size.

    ``raw`` is the map's planning cost; ``blocked`` its impassable cells (inf, or outside
    the planning boundary); ``cost`` what D* Lite plans on: inf within ``inflation``
    cells of a blocked cell, at least ``margin_cost`` within ``margin`` cells, ``raw``
    elsewhere.
    """

    def __init__(self, plan: PlanMapEventIDL, inflation: float, margin: float,
                 margin_cost: float) -> None:
        self.gridsize = plan.gridsize
        self.origin = (plan.originX, plan.originY)
        self.initial_utm = np.array(plan.initialUTM)
        self.revision = plan.revision
        self.inflation, self.margin, self.margin_cost = inflation, margin, margin_cost
        self.unknown = np.isnan(plan.hazard)
        self.a_priori = np.asarray(plan.aPrioriCost, dtype=np.float64).copy()
        self.prior = 1.0  # what an unknown cell is assumed to cost at least
        self.raw = plan.planning_cost().astype(np.float64)
        b = self.boundary = plan.planningBoundary
        self.inside = np.zeros(self.raw.shape, dtype=bool)
        self.inside[b.minX:b.maxX + 1, b.minY:b.maxY + 1] = True
        self.blocked = ~np.isfinite(self.raw) | ~self.inside
        self.cost = self._grow(self.raw, self.blocked)

    @property
    def shape(self) -> tuple[int, int]:
        return self.raw.shape  # type: ignore[return-value]

    def _grow(self, raw: np.ndarray, blocked: np.ndarray) -> np.ndarray:
        if not blocked.any():
            return raw.copy()
        distance = ndimage.distance_transform_edt(~blocked)
        cost = np.where(distance <= self.margin, np.maximum(raw, self.margin_cost), raw)
        cost[distance <= self.inflation] = np.inf
        return cost

    def apply(self, window: PlanMapEventIDL) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Take in a changed window (or a whole map); returns the cells whose grown cost
        changed and their new costs."""
        g = self.gridsize
        i0 = int(round((window.originX - self.origin[0]) / g))
        j0 = int(round((window.originY - self.origin[1]) / g))
        rows, cols = window.rows, window.cols
        area = (slice(i0, i0 + rows), slice(j0, j0 + cols))
        self.unknown[area] = np.isnan(window.hazard)
        self.a_priori[area] = window.aPrioriCost
        self.raw[area] = np.where(self.unknown[area], self._assumed(area),
                                  window.planning_cost())
        self.blocked[area] = ~np.isfinite(self.raw[area]) | ~self.inside[area]
        self.revision = window.revision
        self.initial_utm = np.array(window.initialUTM)
        # the grown cost of a cell depends on raw cells up to `margin` away
        reach = int(math.ceil(self.margin)) + 1
        a0, b0 = max(0, i0 - reach), max(0, j0 - reach)
        a1, b1 = min(self.shape[0], i0 + rows + reach), min(self.shape[1], j0 + cols + reach)
        c0, d0 = max(0, a0 - reach), max(0, b0 - reach)
        c1, d1 = min(self.shape[0], a1 + reach), min(self.shape[1], b1 + reach)
        grown = self._grow(self.raw[c0:c1, d0:d1], self.blocked[c0:c1, d0:d1])
        grown = grown[a0 - c0:a1 - c0, b0 - d0:b1 - d0]
        old = self.cost[a0:a1, b0:b1]
        changed = ~((old == grown) | (np.isinf(old) & np.isinf(grown)))
        xs, ys = np.nonzero(changed)
        new = grown[xs, ys]
        self.cost[a0:a1, b0:b1] = grown
        return xs + a0, ys + b0, new

    def update_prior(self, change: float = 0.1) -> bool:
        """Assume unknown cells cost what the median known passable cell costs (at least
        1, at least their a priori cost): on a hillside every unseen cell will be slope
        too, and a plan through the unseen ground at cost 1 is a detour. Applied (and
        True returned: the costs of every unknown cell changed, plan afresh) when the
        median moved by more than ``change`` of itself."""
        known = ~self.unknown & self.inside & np.isfinite(self.raw)
        if not known.any():
            return False
        prior = max(1.0, float(np.median(self.raw[known])))
        if abs(prior - self.prior) <= change * self.prior:
            return False
        self.prior = prior
        self.raw = np.where(self.unknown, self._assumed(), self.raw)
        self.cost = self._grow(self.raw, self.blocked)
        return True

    def _assumed(self, area: Any = ...) -> np.ndarray:
        """What the unknown cells of ``area`` are assumed to cost: their a priori cost,
        at least the prior."""
        assumed: np.ndarray = np.maximum(self.a_priori[area], self.prior)
        return assumed

    def index(self, x: float, y: float) -> tuple[int, int]:
        """The cell (i, j) holding world point (x, y), inside the grid or not."""
        return (int(math.floor((x - self.origin[0]) / self.gridsize)),
                int(math.floor((y - self.origin[1]) / self.gridsize)))

    def cell_of(self, x: float, y: float) -> tuple[int, int] | None:
        i, j = self.index(x, y)
        if 0 <= i < self.shape[0] and 0 <= j < self.shape[1]:
            return i, j
        return None

    def centre(self, cell: tuple[int, int]) -> tuple[float, float]:
        return (self.origin[0] + (cell[0] + 0.5) * self.gridsize,
                self.origin[1] + (cell[1] + 0.5) * self.gridsize)

    def free_near(self, cell: tuple[int, int], radius: float) -> tuple[int, int] | None:
        """The passable cell nearest ``cell`` within ``radius`` cells (``cell`` itself if
        passable)."""
        if math.isfinite(self.cost[cell]):
            return cell
        r = int(math.ceil(radius))
        i0, j0 = max(0, cell[0] - r), max(0, cell[1] - r)
        block = self.cost[i0:cell[0] + r + 1, j0:cell[1] + r + 1]
        xs, ys = np.nonzero(np.isfinite(block))
        if not len(xs):
            return None
        d = np.hypot(xs + i0 - cell[0], ys + j0 - cell[1])
        k = int(np.argmin(d))
        if d[k] > radius:
            return None
        return int(xs[k] + i0), int(ys[k] + j0)


class FindPath(SubscribePublishServer[FindPathParameters]):
    """FindPath (module docstring). The seed files it under PSR (its "reactor" is the
    planning timer); it polls and publishes, so it is written as a server here."""

    def __init__(self, name: str, parameters: FindPathParameters | None = None) -> None:
        super().__init__(name, parameters)
        p = self.parameters
        self.votes = self.publishes(p.VoteEventName, ArcVoteIDL)
        self.paths = self.publishes(p.PathEventName, PlannedPathIDL)
        self.global_map = self.uses(GlobalMapInterface, p.GlobalMapName)
        self.platform = self.uses(Platform, p.PlatformName)
        self.arcs = ArcSet.from_parameters()
        self._refiner: Refiner | None = None
        self._forward: Refiner | None = None  # forward arcs only, when _refiner backs too
        #: the back the last drivable path starts with: (m, curvature), None for none
        self.reverse: tuple[float, float] | None = None
        self._steering: float | None = None  # the curvature of the last drivable vote
        self.grid: CostGrid | None = None
        self.planner: DStarLite | None = None
        self.goal: tuple[int, int] | None = None
        self.path: list[tuple[int, int]] = []
        self.refined: Refined | None = None
        self.plan_times: list[float] = []
        self.refine_times: list[float] = []
        self.counters = {"cycles": 0, "plans": 0, "replans": 0, "tracking_replans": 0,
                         "prior_changes": 0,
                         "no_path": 0, "cells_updated": 0, "poll_errors": 0,
                         "refined": 0, "undrivable": 0, "invalid_poses": 0,
                         "unknown_frames": 0, "bumper_arrivals": 0, "held_paths": 0,
                         "reverse_requests": 0}
        self._no_path_streak = 0  # planning cycles in a row that found no path
        self._no_path_since = 0.0  # when the streak began (clock time)
        self.beyond = False  # the waypoint lies beyond the planning limits
        self.waypoint: tuple[float, float, float] | None = None  # x, y, tolerance (m)
        #: where GroundFrame sits on the vehicle (ahead, left of the rear axle, m): None
        #: until ModelServer answers, False when it does not know the frame
        self.front: tuple[float, float] | bool | None = None

    async def setup(self) -> None:
        self.arcs = arc_set_of(self.context.section(ARC_SET_SECTION))
        self._refiner = self._forward = None
        self.reverse = None
        self._steering = None
        self.grid = self.planner = None
        self.goal = None
        self.path = []
        self._no_path_streak = 0
        self.front = None

    async def run(self) -> None:
        p = self.parameters
        await self.bound(self.global_map)
        await self.bound(self.platform)
        await self.clock.sleep(p.PlanUpdateDelayTime)
        async for _ in self.clock.periodic(p.PlanEventInterval):
            try:
                await self._cycle()
            except AfaError as exc:  # a server restarting: the next cycle tries again
                self.counters["poll_errors"] += 1
                self.log.info("%s: planning cycle skipped: %s", self.name, exc)
                self.set_health(False, f"planning cycle skipped: {exc}")

    async def _cycle(self) -> None:
        self.counters["cycles"] += 1
        waypoint = await self.global_map.getCurrentWaypoint()
        if waypoint is None:
            self.set_health(True, "no mission")
            return  # no mission, or finished: FindPath has no opinion
        pose = await self.platform.getPose()
        if not pose.poseValidFlag:
            self.counters["invalid_poses"] += 1  # still the best estimate: plan from it
        grid = await self._map()
        x, y = float(pose.HTransform[0, 3]), float(pose.HTransform[1, 3])
        yaw = math.atan2(float(pose.HTransform[1, 0]), float(pose.HTransform[0, 0]))
        start = grid.cell_of(x, y)
        goal = self._goal_cell(grid, waypoint)
        if start is None or goal is None:
            if start is None:
                reason = "the vehicle is off the map"
            elif not grid.initial_utm.any():
                reason = "no map merged yet"
            elif self.beyond:
                reason = "no passable cell on the map's edge towards it"
            else:
                reason = "it lies in an obstacle: no passable cell within its tolerance"
            self._no_path(grid, waypoint, reason)
            return
        with Stopwatch() as watch:  # processing time, for statistics only
            status = self._plan(grid, start, goal)
        self.plan_times.append(watch.seconds)
        del self.plan_times[:-1000]
        if status is not PlanStatus.DONE or self.planner is None:
            self._no_path(grid, waypoint, "no route reaches it" if status is
                          PlanStatus.NO_PATH else "the search ran out of its budget")
            return
        self.path, followed_cost = self._hold(grid, start, self.planner.path(),
                                              self.planner.cost_to_goal())
        if self.front is None:
            await self._front_point()
        with Stopwatch() as watch:
            self.refined, undrivable, arriving = self._refine(grid, (x, y, yaw))
        self.refine_times.append(watch.seconds)
        del self.refine_times[:-1000]
        if self.refined is not None:
            # a drivable path starts at the vehicle: steer by its next metres (pursuit
            # of a point on an arc through the vehicle gives that arc's curvature)
            point = self.refined.at(REFINED_LOOKAHEAD)
            spread = ARRIVING_SPREAD if arriving else ON_THE_WAY_SPREAD
        else:
            # the D* path (refinement off, or no drivable way onto the plan: then every
            # arc is vetoed below, the arbiter backs out to make room, and the votes
            # still say where the plan goes, so the back-out swings the nose towards it,
            # decision 0018)
            point = self._lookahead([grid.centre(c) for c in self.path], (x, y),
                                    grid.gridsize)
            spread = 1.0  # as Pure Pursuit
        ahead, left = to_vehicle_frame(point[0], point[1], x, y, yaw)
        kappa = pursuit_curvature(ahead, left, self.arcs.max_curvature)
        self._steering = kappa if self.refined is not None else None
        n = len(self.arcs)
        sigma = 2.0 * spread / max(math.hypot(ahead, left), 1.0) ** 2
        votes = ArcVotes(np.full(n, undrivable, dtype=bool),
                         gaussian_votes(self.arcs.curvatures, kappa, sigma), np.ones(n),
                         np.full(n, 2.0))
        stamp = TimeIDL.from_seconds(self.clock.now())
        body = votes.to_idl(time=stamp, behaviour=BEHAVIOUR, arcs=self.arcs)
        if self.reverse is not None:
            body = body.model_copy(update={"reverse": self.reverse[0],
                                           "reverseCurvature": self.reverse[1]})
        self.votes.publish(body)
        centres = np.array([grid.centre(c) for c in self.path], dtype=np.float64)
        self.paths.publish(PlannedPathIDL(time=stamp, points=centres.reshape(-1, 2),
                                          initialUTM=grid.initial_utm,
                                          cost=followed_cost, goal=waypoint))
        self._no_path_streak = 0
        if not pose.poseValidFlag:
            self.set_health(False, "planning from a pose marked invalid (poseValidFlag "
                                   "false)")
        elif self.front is False:
            self.set_health(False, f"ModelServer does not know GroundFrame "
                                   f"{self.parameters.GroundFrame!r}: a path to the "
                                   "waypoint must bring the rear axle to it")
        elif undrivable:
            self.set_health(True, "no drivable way onto the plan from here: backing out")
        else:
            self.set_health(True, "planning towards a waypoint beyond the map, to its edge"
                            if self.beyond else "planning")

    async def _map(self) -> CostGrid:
        p = self.parameters
        if self.grid is None or not self.grid.initial_utm.any():  # no map merged yet
            plan = await self.global_map.getPlanMap()
            self.grid = CostGrid(plan, p.InflationRadius, p.MarginRadius, p.MarginCost)
            self.planner = None
            return self.grid
        window = await self.global_map.getPlanMapChanges(self.grid.revision)
        if window is None:
            return self.grid
        moved = (window.originX, window.originY) != self.grid.origin
        if (window.fullRows == 0 and (moved or window.rows * window.cols != self.grid.raw.size)) \
                or window.planningBoundary != self.grid.boundary:
            if window.fullRows:  # a window of a map with new limits: fetch the whole
                window = await self.global_map.getPlanMap()
            self.grid = CostGrid(window, p.InflationRadius, p.MarginRadius, p.MarginCost)
            self.planner = None  # another map or other limits: plan afresh
            return self.grid
        xs, ys, new = self.grid.apply(window)
        if self.grid.update_prior():
            self.counters["prior_changes"] += 1
            self.planner = None  # every unknown cell's cost changed: plan afresh
            return self.grid
        if self.planner is not None and len(xs):
            self.counters["cells_updated"] += self.planner.update_costs(xs, ys, new)
        return self.grid

    def _goal_cell(self, grid: CostGrid, waypoint: WaypointIDL) -> tuple[int, int] | None:
        """The waypoint's cell, or a passable one within its tolerance (cells outside
        the operator's planning boundary are impassable); for a waypoint beyond the
        grid, the passable cell nearest it within ``BEYOND_SEARCH`` of the planning
        limits' point nearest it: the plan leads that way, and the Global Map moves its
        grid before the vehicle gets there (decision 0041)."""
        if not grid.initial_utm.any():  # no map merged yet: no world frame to plan in
            return None
        gx, gy = to_local(waypoint, grid.initial_utm)
        self.waypoint = (gx, gy, waypoint.tolerance)
        cell = grid.cell_of(gx, gy)
        self.beyond = cell is None
        if cell is not None:
            return grid.free_near(cell, waypoint.tolerance / grid.gridsize)
        b = grid.boundary
        i, j = grid.index(gx, gy)
        nearest = (min(max(i, b.minX), b.maxX), min(max(j, b.minY), b.maxY))
        return grid.free_near(nearest, BEYOND_SEARCH / grid.gridsize)

    def _plan(self, grid: CostGrid, start: tuple[int, int], goal: tuple[int, int]
              ) -> PlanStatus:
        tolerance = self.parameters.TrackingTolerance
        if self.planner is None:
            self.planner = DStarLite(grid.cost, start, goal)
            self.goal = goal
            self.counters["plans"] += 1
            return self.planner.replan()
        if goal != self.goal:
            self.planner.move_start(start)
            self.planner.set_goal(goal)
            self.goal = goal
            self.counters["plans"] += 1
            return self.planner.replan()
        self.planner.move_start(start)
        if self.path and min(math.hypot(start[0] - c[0], start[1] - c[1])
                             for c in self.path) > tolerance:
            self.counters["tracking_replans"] += 1
            return self.planner.rebuild()
        self.counters["replans"] += 1
        return self.planner.replan()

    def _hold(self, grid: CostGrid, start: tuple[int, int], path: list[tuple[int, int]],
              cost: float) -> tuple[list[tuple[int, int]], float]:
        """The path to follow and its cost: the new plan ``path`` (of ``cost``), or the
        rest of the last one from its cell nearest the vehicle, under the hysteresis of
        ``HOLD_SHARE`` and ``HOLD_SLACK`` (decision 0043)."""
        old = self.path
        if not old or not path or old[-1] != path[-1]:
            return path, cost  # nothing to hold, or another goal
        distances = [math.hypot(start[0] - c[0], start[1] - c[1]) for c in old]
        k = int(np.argmin(distances))
        if distances[k] > HOLD_DISTANCE:
            return path, cost
        rest = old[k:]
        held = path_cost(grid.cost, rest if rest[0] == start else [start, *rest])
        if held <= cost * (1.0 + HOLD_SHARE) + HOLD_SLACK / grid.gridsize and held != cost:
            self.counters["held_paths"] += 1
            return rest, held
        return path, cost

    def _refine(self, grid: CostGrid, pose: tuple[float, float, float]
                ) -> tuple[Refined | None, bool, bool]:
        """A drivable path (:mod:`components.find_path.kinematic`) from the vehicle to
        the D* path's point ``RefineDistance`` ahead (its end if nearer), in any heading:
        beyond a gate, the gate aligns it. Where that is the path's end, the waypoint's
        cell, the path ends where the Global Map counts the waypoint reached
        (:meth:`_to_waypoint`). Returns the path, whether the search found none (the
        vehicle must back out first), and whether it is the final approach (the path
        ends at the waypoint); (None, False, False) when refinement is off or the path
        is a single cell."""
        p = self.parameters
        self.reverse = None
        if p.RefineDistance <= 0.0 or len(self.path) < 2:
            return None, False, False
        centres = [grid.centre(c) for c in self.path]
        travelled, k = 0.0, 0
        while k + 1 < len(centres) and travelled < p.RefineDistance:
            travelled += math.dist(centres[k], centres[k + 1])
            k += 1
        if self._refiner is None:
            def refiner(reverse: float) -> Refiner:
                return Refiner(0.9 * self.arcs.max_curvature, tuple(p.DiscOffsets),
                               p.DiscRadius, hazard_margin=0.5 * grid.gridsize,
                               reverse_cost=reverse, switch_cost=p.ReverseSwitchCost)
            self._refiner = refiner(p.ReverseCost)
            self._forward = refiner(0.0) if p.ReverseCost > 0.0 else self._refiner
        seen = ~grid.unknown if p.ReverseCost > 0.0 else None

        # The body discs keep the refined path clear; the cells D* leaves out for the
        # rear axle (within InflationRadius) are open to it at twice the margin's cost,
        # so it may pass closer than D* would, where the body fits (a slalom's gap).
        def searcher(refiner: Refiner) -> Callable[[Arrival | None], Refined | None]:
            def search(arrival: Arrival | None) -> Refined | None:
                return refiner.plan(grid.blocked, grid.cost, grid.origin, grid.gridsize,
                                    pose, (*centres[k], None), curvature=self._steering,
                                    open_cost=2.0 * p.MarginCost, arrival=arrival,
                                    seen=seen)
            return search

        arriving = not (k + 1 < len(centres) or self.beyond or self.waypoint is None)

        def refine(refiner: Refiner) -> Refined | None:
            if arriving:
                assert self.waypoint is not None
                return self._to_waypoint(searcher(refiner), *self.waypoint)
            return searcher(refiner)(None)

        refined = refine(self._refiner)
        sign, leg = refined.first_leg() if refined is not None else (1, 0)
        if refined is not None and sign < 0:
            # the way on starts by backing (decision 0046): ask the arbiter for that leg,
            # and vote for the best forward way meanwhile (the arbiter may refuse)
            self.reverse = (leg * refined.step,
                            float(np.mean(refined.curvatures[:leg])))
            self.counters["reverse_requests"] += 1
            assert self._forward is not None
            refined = refine(self._forward)
        self.counters["refined" if refined is not None else "undrivable"] += 1
        return refined, refined is None, arriving

    def _to_waypoint(self, search: Callable[[Arrival | None], Refined | None], x: float,
                     y: float, tolerance: float) -> Refined | None:
        """The drivable path to the waypoint (decision 0042): the rear axle within
        ``ARRIVAL_SHARE`` of its tolerance, the point the arcs turn about, so the vehicle
        passes a waypoint where the next leg turns away without first pointing at it;
        unless the rear axle cannot come there, or only by a detour longer than the body
        (a waypoint short of a wall it faces): then the bumper's ground point."""
        radius = ARRIVAL_SHARE * tolerance
        rear = search((x, y, radius, 0.0, 0.0))
        if not isinstance(self.front, tuple) or self.front == (0.0, 0.0):
            return rear
        ahead, left = self.front
        front = search((x, y, radius, ahead, left))
        if front is None or (rear is not None and len(rear.poses) * rear.step
                             <= len(front.poses) * front.step + abs(ahead) + rear.step):
            return rear
        self.counters["bumper_arrivals"] += 1
        return front

    async def _front_point(self) -> None:
        """Where ``GroundFrame`` sits on the vehicle, from ModelServer (polled until it
        answers; a frame it does not know leaves the rear axle as the only arrival
        point, and the component unhealthy: its health names the frame)."""
        self.front = await ground_point(self.platform, self.parameters.GroundFrame, self.log)
        if self.front is False:
            self.counters["unknown_frames"] += 1
        # None: not reachable yet, the next cycle asks again

    def _lookahead(self, points: list[tuple[float, float]], vehicle: tuple[float, float],
                   gridsize: float) -> tuple[float, float]:
        """The farthest of ``points`` between Min- and MaxLookahead cells along them to
        which they run within half a cell of the straight line from the vehicle."""
        p = self.parameters
        if len(points) < 2:
            return points[-1] if points else vehicle
        g = gridsize
        travelled = 0.0
        chosen = points[-1]
        for k in range(1, len(points)):
            travelled += math.dist(points[k - 1], points[k]) / g
            if travelled < p.MinLookahead:
                chosen = points[k]
                continue
            if travelled > p.MaxLookahead or not _straight(vehicle, points[:k + 1], 0.5 * g):
                break
            chosen = points[k]
        return chosen

    def _no_path(self, grid: CostGrid, waypoint: WaypointIDL, reason: str) -> None:
        """Veto every arc, and publish the empty path (displays drop the old one);
        ``reason`` goes in the health detail."""
        self.counters["no_path"] += 1
        self._no_path_streak += 1
        if self._no_path_streak == 1:
            self._no_path_since = self.clock.now()
        if self._no_path_streak >= NO_PATH_UNHEALTHY:  # one detail for the streak: one log
            since = datetime.fromtimestamp(self._no_path_since, UTC).strftime("%H:%M:%S")
            self.set_health(False, f"no path to the waypoint since {since} UTC, {reason}: "
                                   "every arc vetoed")
        self.path = []
        stamp = TimeIDL.from_seconds(self.clock.now())
        self.votes.publish(ArcVotes.halt(len(self.arcs)).to_idl(
            time=stamp, behaviour=BEHAVIOUR, arcs=self.arcs))
        self.paths.publish(PlannedPathIDL(time=stamp, points=np.zeros((0, 2)),
                                          initialUTM=grid.initial_utm, cost=math.inf,
                                          goal=waypoint))

    def statistics(self) -> dict[str, Any]:
        stats = super().statistics()
        stats.update(self.counters)
        for key, seconds in (("plan_ms", self.plan_times), ("refine_ms", self.refine_times)):
            if seconds:
                times = np.array(seconds) * 1000.0
                stats[key] = {"mean": round(float(times.mean()), 3),
                              "p95": round(float(np.percentile(times, 95)), 3),
                              "max": round(float(times.max()), 3)}
        if self.planner is not None:
            stats["planner"] = dataclasses.asdict(self.planner.statistics())
        return stats


def path_cost(cost: np.ndarray, cells: list[tuple[int, int]]) -> float:
    """What D* Lite charges along ``cells`` (each step: its length in cells times the cost
    of the cell it enters; inf through an impassable one). Consecutive cells need not be
    neighbours (the first step, from the vehicle onto a held path)."""
    if len(cells) < 2:
        return 0.0
    ij = np.asarray(cells, dtype=np.intp)
    steps = np.hypot(*np.diff(ij, axis=0).T)
    return float(np.sum(steps * cost[ij[1:, 0], ij[1:, 1]]))


def _straight(origin: tuple[float, float], points: list[tuple[float, float]],
              tolerance: float) -> bool:
    """Whether every point lies within ``tolerance`` of the line from ``origin`` to the
    last point."""
    ex, ey = points[-1][0] - origin[0], points[-1][1] - origin[1]
    length = math.hypot(ex, ey)
    if length == 0.0:
        return True
    return all(abs((px - origin[0]) * ey - (py - origin[1]) * ex) / length <= tolerance
               for px, py in points)
