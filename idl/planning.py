"""Planning and goal-seeking structs: plan points, waypoints, arc votes (§3.2.3, §3.3).

Planning grid convention (shared with :class:`idl.maps.PlanMapEventIDL` and the
GlobalMap interface): the *planning frame* is measured in grid cells, so the
GlobalMap's world-to-planning transform includes the scale 1/gridsize; node
``(x, y)`` is the cell whose planning coordinates lie in ``[x, x+1) × [y, y+1)``, i.e.
``PlanMapEventIDL`` layers at ``[x, y]``.
"""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from pydantic import model_validator

from idl._base import Array, field
from idl.common import TimeIDL, _Struct

__all__ = [
    "PlanPointIDL",
    "PlanningBoundaryIDL",
    "WaypointIDL",
    "WaypointGroupIDL",
    "ArcVoteIDL",
    "ArcDecisionIDL",
    "PlannedPathIDL",
    "IMPASSABLE",
    "Cost",
]

#: The cost of a cell that cannot be entered.
IMPASSABLE = math.inf


#: A traversal cost: a float that may be ``inf`` (:data:`IMPASSABLE`). JSON carries it
#: as the string ``"Infinity"``, the IDL's one rule for non-finite numbers.
Cost = float


class PlanPointIDL(_Struct):
    """One node of the GlobalMap planning grid (seed Table 18).

    Costs are per-cell traversal costs: entering a cell of cost c over a step of
    length s costs c·s. They are at least 1 (so FindPath's octile heuristic stays
    admissible) or ``inf`` (:data:`IMPASSABLE`). A query such as ``valid(p)`` needs
    only ``x`` and ``y``; the costs then keep their defaults.
    """

    x: int = field(unit="1", description="planning grid index along the planning x axis")
    y: int = field(unit="1", description="planning grid index along the planning y axis")
    aPrioriCost: Cost = field(1.0, unit="1", ge=1.0, allow_inf_nan=True,
                               description="a priori cost of entering the cell (≥ 1, inf "
                                           "= impassable)")
    sensedCost: Cost = field(1.0, unit="1", ge=1.0, allow_inf_nan=True,
                              description="sensed cost of entering the cell (≥ 1, inf = "
                                          "impassable)")
    sensed: bool = field(False, unit="", description="true once sensing has observed the "
                                                     "cell (else sensedCost is the "
                                                     "free-space assumption)")

    @model_validator(mode="after")
    def _check(self) -> PlanPointIDL:
        for name in ("aPrioriCost", "sensedCost"):
            if math.isnan(getattr(self, name)):
                raise ValueError(f"{name} must not be NaN")
        return self

    @property
    def cost(self) -> float:
        """The cost a planner uses: the sensed cost once sensed, else the a priori one."""
        return self.sensedCost if self.sensed else self.aPrioriCost


class PlanningBoundaryIDL(_Struct):
    """The part of the planning grid a planner may search (§3.2.3), inclusive indices."""

    minX: int = field(unit="1", description="smallest x index inside the boundary")
    minY: int = field(unit="1", description="smallest y index inside the boundary")
    maxX: int = field(unit="1", description="largest x index inside the boundary")
    maxY: int = field(unit="1", description="largest y index inside the boundary")

    @model_validator(mode="after")
    def _check(self) -> PlanningBoundaryIDL:
        if self.maxX < self.minX or self.maxY < self.minY:
            raise ValueError(f"empty planning boundary x {self.minX}..{self.maxX}, "
                             f"y {self.minY}..{self.maxY}")
        return self

    def contains(self, x: int, y: int) -> bool:
        """True if node (x, y) lies inside the boundary."""
        return self.minX <= x <= self.maxX and self.minY <= y <= self.maxY


class WaypointIDL(_Struct):
    """A GPS waypoint (seed Table 24): latitude/longitude, optional UTM, tolerance."""

    latitude: float = field(unit="deg", ge=-90.0, le=90.0, allow_inf_nan=False,
                            description="WGS84 latitude, north positive")
    longitude: float = field(unit="deg", ge=-180.0, le=180.0, allow_inf_nan=False,
                             description="WGS84 longitude, east positive")
    easting: float | None = field(None, unit="m", allow_inf_nan=False,
                                  description="UTM easting, if the operator gave one")
    northing: float | None = field(None, unit="m", allow_inf_nan=False,
                                   description="UTM northing, if the operator gave one")
    tolerance: float = field(2.0, unit="m", gt=0.0, allow_inf_nan=False,
                             description="the waypoint is reached within this distance")

    @model_validator(mode="after")
    def _check(self) -> WaypointIDL:
        if (self.easting is None) != (self.northing is None):
            raise ValueError("give both easting and northing, or neither")
        return self


class WaypointGroupIDL(_Struct):
    """A waypoint list to follow in order (seed Table 24), optionally on patrol."""

    waypoints: tuple[WaypointIDL, ...] = field((), unit="", description="waypoints in "
                                                                         "order")
    patrolMode: bool = field(False, unit="", description="after the last waypoint, start "
                                                         "again from the first")


_ArcFloat = Annotated[np.ndarray, Array("float32", (None,))]


class ArcVoteIDL(_Struct):
    """One behaviour's votes over the candidate arcs (seed Table 23, §3.3).

    Element k of each array refers to the arc of curvature ``curvatures[k]``
    (1/m, left turns positive, 0 = straight ahead). ``veto[k]`` forbids the arc,
    ``vote[k]`` in 0..1 is its desirability, ``certainty[k]`` in 0..1 the behaviour's
    belief in its data, ``maxSpeed[k]`` the highest acceptable speed on it.
    """

    time: TimeIDL = field(unit="", description="time stamp of the vote")
    behaviour: str = field(unit="", description="the voting behaviour, e.g. PurePursuit, "
                                                "ObstacleAvoidance, FindPath, "
                                                "ObstacleDetection")
    curvatures: Annotated[np.ndarray, Array("float64", (None,))] = field(
        unit="1/m", description="(n,) arc curvatures, left positive")
    veto: Annotated[np.ndarray, Array("bool", (None,))] = field(
        unit="", description="(n,) true vetoes the arc")
    vote: _ArcFloat = field(unit="1", description="(n,) desirability 0..1")
    certainty: _ArcFloat = field(unit="1", description="(n,) belief in the data 0..1")
    maxSpeed: _ArcFloat = field(unit="m/s", description="(n,) highest acceptable speed ≥ 0")
    reverse: float = field(
        0.0, unit="m", ge=0.0, allow_inf_nan=False,
        description="afa addition: the behaviour asks the vehicle to back this far first, "
                    "on curvature reverseCurvature (a planned manoeuvre: FindPath's "
                    "approach to an opening it cannot turn into going forwards); 0 asks "
                    "nothing. The arbiter backs only over ground its map has seen")
    reverseCurvature: float = field(
        0.0, unit="1/m", allow_inf_nan=False,
        description="afa addition: the curvature of the path backed along (left "
                    "positive: the rear swings left and the nose turns right)")

    @model_validator(mode="after")
    def _check(self) -> ArcVoteIDL:
        n = self.curvatures.shape[0]
        for name in ("veto", "vote", "certainty", "maxSpeed"):
            if getattr(self, name).shape[0] != n:
                raise ValueError(f"{name} has {getattr(self, name).shape[0]} entries, "
                                 f"curvatures has {n}")
        if not np.isfinite(self.curvatures).all():
            raise ValueError("curvatures must be finite")
        for name in ("vote", "certainty"):
            values = getattr(self, name)
            if not ((values >= 0.0) & (values <= 1.0)).all():
                raise ValueError(f"{name} must lie in 0..1")
        if not ((self.maxSpeed >= 0.0) & np.isfinite(self.maxSpeed)).all():
            raise ValueError("maxSpeed must be finite and ≥ 0")
        return self

    @property
    def all_vetoed(self) -> bool:
        """True if every arc is vetoed (a halt), or there are no arcs."""
        return bool(self.veto.all())


class ArcDecisionIDL(_Struct):
    """The Arc Arbiter's decision, published for displays as event ``ArcDecision``.

    The seed's arbiter publishes nothing (Table 25); afa's publishes one of these per
    decision so that the console's local map (the seed's LocalMap "with arcs") and logs
    can show *why* the vehicle went where it went. Element k of the arrays refers to the
    arc of curvature ``curvatures[k]`` (the arc set of the votes, left positive).

    ``scores[k]`` is the combined weighted score Σ weight·certainty·vote over the fresh
    votes (computed for vetoed arcs too, for display); ``vetoed[k]`` the union of the
    fresh vetoes. ``index`` is the chosen arc (-1 when there was no arc set to choose
    from); on a fail-safe it is the straight arc and ``failsafe`` names the cause
    (``no-fresh-vote``, ``missing-required``, ``all-vetoed``, ``no-valid-vote``; empty
    otherwise). ``fresh`` lists the behaviours whose votes counted, ``stale`` those seen
    before whose latest vote went stale, ``unknown`` fresh behaviours without a weight.
    """

    time: TimeIDL = field(unit="", description="time of the decision")
    curvatures: Annotated[np.ndarray, Array("float64", (None,))] = field(
        unit="1/m", description="(n,) the candidate arcs' curvatures, left positive")
    scores: Annotated[np.ndarray, Array("float64", (None,))] = field(
        unit="1", description="(n,) combined weighted score of each arc (vetoed included)")
    vetoed: Annotated[np.ndarray, Array("bool", (None,))] = field(
        unit="", description="(n,) true where a fresh vote vetoes the arc")
    index: int = field(-1, unit="1", ge=-1, description="the chosen arc; -1 if none")
    curvature: float = field(0.0, unit="1/m", allow_inf_nan=False,
                             description="the chosen arc's curvature, left positive")
    steeringAngle: float = field(0.0, unit="rad", allow_inf_nan=False,
                                 description="the steering angle commanded, left positive")
    speed: float = field(0.0, unit="m/s", allow_inf_nan=False,
                         description="the speed commanded (0: stop; negative: backing "
                                     "out of a dead end)")
    fresh: tuple[str, ...] = field((), unit="", description="behaviours whose votes counted")
    stale: tuple[str, ...] = field((), unit="", description="behaviours whose latest vote "
                                                            "went stale")
    unknown: tuple[str, ...] = field((), unit="", description="fresh behaviours without a "
                                                              "configured weight")
    failsafe: str = field("", unit="", description="fail-safe cause, empty if none")

    @model_validator(mode="after")
    def _check(self) -> ArcDecisionIDL:
        n = self.curvatures.shape[0]
        for name in ("scores", "vetoed"):
            if getattr(self, name).shape[0] != n:
                raise ValueError(f"{name} has {getattr(self, name).shape[0]} entries, "
                                 f"curvatures has {n}")
        if not np.all(np.isfinite(self.curvatures)) or not np.all(np.isfinite(self.scores)):
            raise ValueError("curvatures and scores must be finite")
        if self.index >= n:
            raise ValueError(f"index {self.index} is outside the {n} arcs")
        return self


_PathPoints = Annotated[np.ndarray, Array("float64", (None, 2))]


class PlannedPathIDL(_Struct):
    """FindPath's planned path, published for displays as event ``PlannedPath``.

    ``points`` are the path's cells from the vehicle to the goal, as world-frame (x east,
    y north) metres from ``initialUTM`` (the frame of ``Pose`` and of the global maps).
    An empty path means no path was found (FindPath then vetoes every arc).
    """

    time: TimeIDL = field(unit="", description="time of the plan")
    points: _PathPoints = field(unit="m", description="(n, 2) world x (east), y (north) "
                                                      "from the vehicle to the goal")
    initialUTM: Annotated[np.ndarray, Array("float64", (3,))] = field(
        unit="m", description="UTM (easting, northing, elevation) of the world frame's "
                              "origin")
    cost: float = field(0.0, unit="1", ge=0.0, allow_inf_nan=True,
                        description="the path's cost (cell costs times step lengths); inf "
                                    "if none")
    goal: WaypointIDL | None = field(None, unit="", description="the waypoint planned to")

    @model_validator(mode="after")
    def _check(self) -> PlannedPathIDL:
        if not np.all(np.isfinite(self.points)) or not np.all(np.isfinite(self.initialUTM)):
            raise ValueError("points and initialUTM must be finite")
        return self
