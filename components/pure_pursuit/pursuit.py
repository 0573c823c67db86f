"""Pure Pursuit's core (seed §3.3.3; Coulter 1992, CMU-RI-TR-92-01): follow the straight
segments between waypoints and spread the vote as a Gaussian around the ideal arc.

Pure Python + numpy: no asyncio, no framework. The component converts the waypoints'
latitude/longitude to this local frame through ``initialUTM``, feeds each ``Pose``, and
publishes the :class:`~components.arcs.ArcVotes`.

Frames
------
Waypoints and the vehicle position are in a local metric frame, x east, y north (the
world frame of afa/sim/vehicle.py, origin at ``initialUTM``); ``yaw`` is counter-clockwise
from east (rad). The position is the rear axle centre, the reference of the arcs
(:mod:`components.arcs`). The vehicle frame is x forward, y left.

The path
--------
The path is the polyline anchor → w0 → w1 → … → w_last, the *anchor* being where the
vehicle was at the first update after :meth:`PurePursuit.set_waypoints`; in patrol mode
it continues w_last → w0 → w1 … for ever. Target ``i`` is the waypoint being sought; the
*current segment* runs from the previous waypoint (or the anchor) to it.

Look-ahead point, on the line to the target
-------------------------------------------
Project the vehicle onto the line of the current segment and take the point
``lookahead`` metres further along that line, beyond the target if need be (clamped to
the segment's start behind it). The look-ahead never walks round the corner onto the
next segment: the vehicle tracks the line *through* the waypoint, so it passes the
waypoint within its tolerance instead of cutting the corner (every waypoint is a place
the operator asked the vehicle to visit, and the Global Map, FindPath and the mission's
judge count it reached only within its tolerance), and near the goal the point runs
past the goal instead of pulling in, so the vehicle does not spiral onto it (one of the
failure modes in notes/algorithms.md).

Curvature
---------
With the look-ahead point at (x, y) in the vehicle frame and D² = x² + y², the arc from
the rear axle through it has κ* = 2y/D² (Coulter's κ = 2y/l², l the chord). When the
point lies at the look-ahead distance L_d (a straight path ahead) D = L_d and this is
2y/L_d²; when the path bends, D < L_d and 2y/D² is the arc that really reaches the point
(2y/L_d² would undershoot the turn). κ* is clipped to ±κ_max. A point **behind** the
vehicle (x < 0) gets the hardest turn towards its side (left when exactly behind)
instead of the degenerate small curvature 2y/D² gives there. A point at the vehicle
gives κ* = 0.

Waypoint advance
----------------
The target advances (to the next waypoint, or to w0 after w_last on patrol; several in
one update if need be) when the vehicle is within the target's tolerance: its rear axle
or its *front point* (:meth:`PurePursuit.set_front`: the ground under the front bumper,
``ahead``, ``left`` of the rear axle; the rear axle itself until set). That is the rule
the Global Map (which FindPath plans to) uses too, so the behaviours never disagree on
the waypoint sought: a waypoint short of a wall, which the rear axle cannot reach facing
it, is reached by the bumper. Past the target's perpendicular without having reached it (a
detour round an obstacle), the look-ahead point becomes the waypoint itself and the
vehicle turns back to it rather than skipping it. After the last waypoint of a
non-patrol list the behaviour is *finished*. Patrol needs at least two waypoints; with
one it finishes like a plain list.

Votes (seed Figure 12)
----------------------
vote_k = exp(−(κ_k − κ*)²/(2σ_κ²)), divided by its largest value so the best arc votes
1. σ is chosen as a **lateral offset at the look-ahead distance**, σ_y (default 1.0 m,
about the Raptor's half width plus margin): an arc whose curvature differs by Δκ passes
Δκ·L_d²/2 beside the look-ahead point, so σ_κ = 2σ_y/L_d². A longer look-ahead narrows the
Gaussian in curvature, so the miss it tolerates at the look-ahead point stays σ_y. With
27 arcs and L_d = 5 m, σ_κ = 0.08 1/m ≈ 3.4 arcs: votes 0.96 one arc off, 0.61 at σ.
Certainty is 1 (the pose is the component's to judge).

Speeds (m/s, per arc): min(``max_speed``, √(a_lat/|κ_k|)) so that the lateral
acceleration on the arc stays ≤ ``max_lateral_acceleration``, and without patrol also
≤ √(2·``goal_deceleration``·d_goal), d_goal the path distance left to the last waypoint
(|vehicle − target| + the segments after it), so the vehicle can stop there; never below
``min_speed`` while following, so it cannot stall short of the goal's tolerance.
The goal slow-down depends on d_goal only, not on the look-ahead.

Stop and halt
-------------
- Finished, or no waypoints: a *stop* vote: no vetoes, the Gaussian around the straight
  arc, certainty 1, every maxSpeed 0 (the arbiter's speed is the minimum over fresh
  votes, so the vehicle stops, steering straight).
- ``halt`` (Table 24's ``setHalt(true)``): every arc vetoed (:meth:`ArcVotes.halt`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from components.arcs import ArcSet, ArcVotes
from components.pure_pursuit.parameters import PurePursuitParameters
from components.waypoints import reached

__all__ = [
    "PursuitSettings",
    "Waypoint",
    "PursuitOutput",
    "PurePursuit",
    "PursuitState",
    "pursuit_curvature",
    "gaussian_votes",
    "to_vehicle_frame",
]

PursuitState = Literal["following", "finished", "idle", "halted"]


@dataclass(frozen=True)
class PursuitSettings:
    """Pure Pursuit's tuning (module docstring). Lengths m, speeds m/s, accelerations
    m/s². Only ``lookahead`` is a configuration parameter today (``Lookahead``); the
    rest are afa's documented defaults. Raises ValueError for non-positive values
    (``min_speed`` may be 0) or ``min_speed`` above ``max_speed``.
    """

    lookahead: float = 5.0
    sigma_lateral: float = 1.0
    max_speed: float = 2.0
    min_speed: float = 0.3
    max_lateral_acceleration: float = 0.5
    goal_deceleration: float = 0.5

    def __post_init__(self) -> None:
        for name in ("lookahead", "sigma_lateral", "max_speed", "max_lateral_acceleration",
                     "goal_deceleration"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"PursuitSettings.{name} must be finite and > 0, got {value}")
        if not 0.0 <= self.min_speed <= self.max_speed:
            raise ValueError(f"PursuitSettings.min_speed must be in 0..max_speed, got "
                             f"{self.min_speed}")

    @classmethod
    def from_parameters(cls, parameters: PurePursuitParameters, **overrides: float) -> \
            PursuitSettings:
        """Settings with ``Lookahead`` from the configuration and the other defaults."""
        return replace(cls(), lookahead=parameters.Lookahead, **overrides)

    @property
    def sigma_curvature(self) -> float:
        """σ_κ = 2σ_y/L_d² (1/m)."""
        return 2.0 * self.sigma_lateral / self.lookahead**2


@dataclass(frozen=True)
class Waypoint:
    """A waypoint in the local frame (x east, y north, m) with its tolerance (m, > 0).

    Raises ValueError for a non-finite coordinate or a non-positive tolerance.
    """

    x: float
    y: float
    tolerance: float = 2.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.x) and math.isfinite(self.y)):
            raise ValueError(f"waypoint ({self.x}, {self.y}) is not finite")
        if not (math.isfinite(self.tolerance) and self.tolerance > 0.0):
            raise ValueError(f"waypoint tolerance must be > 0, got {self.tolerance}")


def to_vehicle_frame(px: float, py: float, x: float, y: float, yaw: float) -> tuple[float, float]:
    """Point (px, py) of the local frame in the frame of a vehicle at (x, y, yaw):
    (ahead, left)."""
    dx, dy = px - x, py - y
    c, s = math.cos(yaw), math.sin(yaw)
    return c * dx + s * dy, -s * dx + c * dy


def pursuit_curvature(ahead: float, left: float, max_curvature: float) -> float:
    """κ* for a look-ahead point at (ahead, left) in the vehicle frame: 2·left/D²,
    clipped to ±max_curvature; the hardest turn towards a point behind (ahead < 0;
    left when exactly behind); 0 for a point at the vehicle."""
    if ahead < 0.0:
        return max_curvature if left >= 0.0 else -max_curvature
    d2 = ahead * ahead + left * left
    if d2 == 0.0:
        return 0.0
    return min(max(2.0 * left / d2, -max_curvature), max_curvature)


def gaussian_votes(curvatures: NDArray[np.float64], ideal: float,
                   sigma: float) -> NDArray[np.float64]:
    """exp(−(κ_k − ideal)²/(2σ²)) normalised so the largest vote is 1.

    Raises ValueError for a non-positive sigma.
    """
    if not sigma > 0.0:
        raise ValueError(f"sigma must be > 0, got {sigma}")
    z2 = ((curvatures - ideal) / sigma) ** 2
    # exp(-z²/2) / max exp(-z²/2), without underflow when every arc is far from ideal.
    votes: NDArray[np.float64] = np.exp(-0.5 * (z2 - z2.min()))
    return votes


@dataclass(frozen=True, eq=False)
class PursuitOutput:
    """One update's result: the votes to publish and what led to them (for displays).

    ``curvature`` is κ* (nan when there is none: finished, idle, halted);
    ``lookahead_point`` the look-ahead point in the local frame (None likewise);
    ``target`` the index of the waypoint sought (None when not following);
    ``distance_to_goal`` the path distance left (inf on patrol, 0 when finished).
    """

    votes: ArcVotes
    state: PursuitState
    curvature: float
    lookahead_point: tuple[float, float] | None
    target: int | None
    distance_to_goal: float
    advanced: tuple[int, ...] = field(default=())


class PurePursuit:
    """Waypoint following by Gaussian arc votes (module docstring).

    Holds the waypoint list, the target, patrol and halt (seed Table 24's state); call
    :meth:`update` with each pose.
    """

    def __init__(self, arcs: ArcSet, settings: PursuitSettings | None = None) -> None:
        self.arcs = arcs
        self.settings = settings if settings is not None else PursuitSettings()
        self._waypoints: tuple[Waypoint, ...] = ()
        self._patrol = False
        self._halt = False
        self._target = 0
        self._previous: tuple[float, float] | None = None  # start of the current segment
        self._finished = False
        self._front = (0.0, 0.0)  # the front point, ahead and left of the rear axle (m)
        curvatures = np.abs(arcs.curvatures)
        with np.errstate(divide="ignore"):
            turn_limit = np.sqrt(self.settings.max_lateral_acceleration / curvatures)
        self._arc_speed = np.clip(turn_limit, self.settings.min_speed, self.settings.max_speed)
        self._stop_votes = ArcVotes(np.zeros(len(arcs), dtype=bool),
                                    gaussian_votes(arcs.curvatures, 0.0,
                                                   self.settings.sigma_curvature),
                                    np.ones(len(arcs)), np.zeros(len(arcs)))
        self._halt_votes = ArcVotes.halt(len(arcs))

    # --- Table 24 state -------------------------------------------------------------

    def set_waypoints(self, waypoints: Sequence[Waypoint], *, patrol: bool | None = None,
                      first: int = 0) -> None:
        """Replace the list (``setWaypointList``) and seek waypoint ``first`` (0: the
        first) from where the vehicle is at the next update; ``patrol`` also sets patrol
        mode if given. Raises ValueError for ``first`` outside the list."""
        if waypoints and not 0 <= first < len(waypoints):
            raise ValueError(f"first waypoint {first} is outside the {len(waypoints)} given")
        self._waypoints = tuple(waypoints)
        if patrol is not None:
            self._patrol = patrol
        self._target = first if waypoints else 0
        self._previous = None
        self._finished = False

    @property
    def target(self) -> int:
        """Index of the waypoint sought (meaningful while not finished)."""
        return self._target

    @property
    def waypoints(self) -> tuple[Waypoint, ...]:
        """The working list (``getWaypointList``)."""
        return self._waypoints

    @property
    def current_waypoint(self) -> Waypoint | None:
        """The waypoint sought (``getCurrentWaypoint``), None when finished or empty."""
        if self._finished or not self._waypoints:
            return None
        return self._waypoints[self._target]

    @property
    def patrol(self) -> bool:
        return self._patrol

    def set_patrol(self, patrol: bool) -> None:
        """``setPatrolMode``. Turned off, the current pass through the list is the last."""
        self._patrol = patrol

    @property
    def halted(self) -> bool:
        return self._halt

    def set_halt(self, halt: bool) -> None:
        """``setHalt``: while true every arc is vetoed; the waypoint state is kept."""
        self._halt = halt

    @property
    def front(self) -> tuple[float, float]:
        """The front point (ahead, left of the rear axle, m) that reaches waypoints too."""
        return self._front

    def set_front(self, ahead: float, left: float = 0.0) -> None:
        """Where the front point lies on the vehicle (module docstring, Waypoint
        advance). Raises ValueError for a non-finite offset."""
        if not (math.isfinite(ahead) and math.isfinite(left)):
            raise ValueError(f"front point ({ahead}, {left}) is not finite")
        self._front = (float(ahead), float(left))

    @property
    def finished(self) -> bool:
        """True after the last waypoint of a non-patrol list."""
        return self._finished

    # --- one update --------------------------------------------------------------------

    def update(self, x: float, y: float, yaw: float) -> PursuitOutput:
        """Advance the target if the vehicle at (x, y, yaw) reached it, and vote.

        Raises ValueError for a non-finite pose.
        """
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)):
            raise ValueError(f"pose ({x}, {y}, {yaw}) is not finite")
        if self._halt:
            return PursuitOutput(self._halt_votes, "halted", math.nan, None, None, math.nan)
        if not self._waypoints:
            return PursuitOutput(self._stop_votes, "idle", math.nan, None, None, 0.0)
        if self._previous is None:
            self._previous = (x, y)
        advanced = self._advance(x, y, yaw)
        if self._finished:
            return PursuitOutput(self._stop_votes, "finished", math.nan, None, None, 0.0,
                                 advanced)
        point = self._lookahead_point(x, y)
        ahead, left = to_vehicle_frame(point[0], point[1], x, y, yaw)
        kappa = pursuit_curvature(ahead, left, self.arcs.max_curvature)
        votes = gaussian_votes(self.arcs.curvatures, kappa, self.settings.sigma_curvature)
        speed = self._arc_speed
        goal = self._distance_to_goal(x, y)
        if not self._patrol:
            cap = math.sqrt(2.0 * self.settings.goal_deceleration * goal)
            speed = np.clip(speed, None, max(cap, self.settings.min_speed))
        out = ArcVotes(np.zeros(len(self.arcs), dtype=bool), votes, np.ones(len(self.arcs)),
                       speed)
        return PursuitOutput(out, "following", kappa, point, self._target, goal, advanced)

    # --- internals ---------------------------------------------------------------------

    def _segment(self, target: int) -> tuple[tuple[float, float], tuple[float, float]]:
        assert self._previous is not None
        w = self._waypoints[target]
        return self._previous, (w.x, w.y)

    def _advance(self, x: float, y: float, yaw: float) -> tuple[int, ...]:
        """Move the target past every waypoint the rear axle at (x, y) or the front point
        reached; returns their indices."""
        advanced: list[int] = []
        n = len(self._waypoints)
        c, s = math.cos(yaw), math.sin(yaw)
        for _ in range(n):
            _, b = self._segment(self._target)
            w = self._waypoints[self._target]
            if not reached(x, y, c, s, self._front, b[0], b[1], w.tolerance):
                break
            advanced.append(self._target)
            self._previous = b
            if self._target + 1 < n:
                self._target += 1
            elif self._patrol and n >= 2:
                self._target = 0
            else:
                self._finished = True
                break
        return tuple(advanced)

    def _lookahead_point(self, x: float, y: float) -> tuple[float, float]:
        a, b = self._segment(self._target)
        ex, ey = b[0] - a[0], b[1] - a[1]
        length = math.hypot(ex, ey)
        if length == 0.0:
            return b
        ux, uy = ex / length, ey / length
        t = (x - a[0]) * ux + (y - a[1]) * uy  # metres along the segment
        if t >= length:
            return b  # past it without reaching it: go back to it rather than skip it
        t = max(t, 0.0) + self.settings.lookahead  # on the line, beyond b if need be
        return a[0] + t * ux, a[1] + t * uy

    def _distance_to_goal(self, x: float, y: float) -> float:
        if self._patrol and len(self._waypoints) >= 2:
            return math.inf
        w = self._waypoints[self._target]
        total = math.hypot(x - w.x, y - w.y)
        for i in range(self._target + 1, len(self._waypoints)):
            p, q = self._waypoints[i - 1], self._waypoints[i]
            total += math.hypot(q.x - p.x, q.y - p.y)
        return total
