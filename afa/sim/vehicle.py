"""The simulated Raptor: a kinematic bicycle on the rear axle, following 2.5-D terrain.

Motion (notes/algorithms.md, "Vehicle simulation"): with speed v and steering angle δ
the rear axle centre moves on a circle of curvature κ = tan(δ)/L (L the wheelbase); each
integration step is that exact arc (a straight line when δ = 0), so the simulated
vehicle drives exactly the arcs the behaviours vote on. Steering and speed follow their
commands through first-order lags (standing for the MPC555's loops) and acceleration
limits; each step is split into sub-steps of at most ``max_substep`` metres so thin
obstacles are not jumped over.

Conventions (explicit, because every emulator depends on them):

- World frame: ENU (x east, y north, z up), metres, origin = the world's origin.
- ``yaw``: radians counter-clockwise from east (ENU); ``heading_deg``: degrees clockwise
  from north (compass). ``heading_deg = 90 - degrees(yaw)`` modulo 360.
- Body frame: x forward, y left, z up at the rear axle centre (docs/geometry.md's
  ``Raptor:RearAxleCenter``); world-from-body rotation R = Rz(yaw)·Ry(pitch)·Rx(roll),
  so **positive pitch is nose down** and **positive roll is left side up**.
- Steering: radians (``steering``) or degrees (``steering_deg``), **positive = left
  turn** (counter-clockwise, positive yaw rate when driving forward).
- Speed: m/s along the body x axis, negative when reversing.

Collision rules: the body footprint (a rectangle ``body_length`` x ``body_width``,
starting ``rear_overhang`` behind the rear axle) over an obstacle sample taller than
``step_height`` above the ground, a wheel contact point over a ditch deeper than
``ditch_depth``, or a footprint corner off the terrain, records a :class:`Collision`
and stops the vehicle; it stays stopped until :meth:`Vehicle.reset`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from afa.sim.terrain import Terrain
from afa.sim.world import World

__all__ = ["VehicleParameters", "VehicleState", "Vehicle", "Collision", "CollisionKind",
           "DriveResult", "run_drive", "GRAVITY"]

#: Below this speed (m/s) a zero speed command brings the vehicle to rest.
STOP_SPEED = 0.01

#: Standard gravity (m/s^2), for the specific force an accelerometer measures.
GRAVITY = 9.80665

CollisionKind = Literal["obstacle", "ditch", "boundary"]


@dataclass(frozen=True)
class VehicleParameters:
    """Raptor dimensions and dynamics. Lengths m, angles deg, times s, speeds m/s."""

    wheelbase: float = 1.9
    track: float = 1.3
    wheel_radius: float = 0.33
    max_steering_deg: float = 30.0          # Table A.13 MaxSteeringAngle
    max_speed: float = 2.0
    max_reverse_speed: float = 1.0
    max_acceleration: float = 1.0           # m/s^2 when speeding up
    max_deceleration: float = 2.0           # m/s^2 when slowing down
    steering_time_constant: float = 0.3
    speed_time_constant: float = 0.5
    body_length: float = 2.85               # rear bumper to front bumper
    body_width: float = 1.4
    rear_overhang: float = 0.4              # rear bumper behind the rear axle
    step_height: float = 0.25               # highest climbable obstacle
    ditch_depth: float = 0.3                # deepest ditch a wheel may cross
    max_substep: float = 0.1                # m of travel per integration sub-step

    def __post_init__(self) -> None:
        for name in ("wheelbase", "track", "wheel_radius", "max_steering_deg", "max_speed",
                     "max_acceleration", "max_deceleration", "body_length", "body_width",
                     "max_substep"):
            if not getattr(self, name) > 0:
                raise ValueError(f"VehicleParameters.{name} must be > 0")
        for name in ("max_reverse_speed", "steering_time_constant", "speed_time_constant",
                     "rear_overhang", "step_height", "ditch_depth"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"VehicleParameters.{name} must be >= 0")
        if self.max_steering_deg >= 89.0:
            raise ValueError("VehicleParameters.max_steering_deg must be < 89")


@dataclass(frozen=True)
class VehicleState:
    """Ground truth at ``time`` (s): pose of the rear axle centre and its rates.

    Angles in radians unless the name says ``_deg``; see the module doc for signs.
    ``distance`` and the wheel distances are cumulative *signed* path lengths (m) of the
    rear axle centre and of each wheel's contact point on its own arc, what wheel
    encoders integrate: backing counts down. ``travelled`` is the rear axle centre's
    path length with backing counted too, the distance the vehicle drove.
    """

    time: float = 0.0
    east: float = 0.0
    north: float = 0.0
    up: float = 0.0
    yaw: float = math.pi / 2
    roll: float = 0.0
    pitch: float = 0.0
    speed: float = 0.0
    steering: float = 0.0
    yaw_rate: float = 0.0
    roll_rate: float = 0.0
    pitch_rate: float = 0.0
    longitudinal_acceleration: float = 0.0
    lateral_acceleration: float = 0.0
    vertical_velocity: float = 0.0
    vertical_acceleration: float = 0.0
    distance: float = 0.0
    travelled: float = 0.0
    front_left_distance: float = 0.0
    front_right_distance: float = 0.0
    rear_left_distance: float = 0.0
    rear_right_distance: float = 0.0

    @property
    def heading_deg(self) -> float:
        """Compass heading: degrees clockwise from north in [0, 360)."""
        return (90.0 - math.degrees(self.yaw)) % 360.0

    @property
    def steering_deg(self) -> float:
        return math.degrees(self.steering)

    @property
    def position(self) -> NDArray[np.float64]:
        """(east, north, up) of the rear axle centre (m)."""
        return np.array([self.east, self.north, self.up])

    def rotation(self) -> NDArray[np.float64]:
        """World-from-body rotation matrix Rz(yaw)·Ry(pitch)·Rx(roll) (3x3)."""
        cy, sy = math.cos(self.yaw), math.sin(self.yaw)
        cp, sp = math.cos(self.pitch), math.sin(self.pitch)
        cr, sr = math.cos(self.roll), math.sin(self.roll)
        return np.array([
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ])

    def transform(self) -> NDArray[np.float64]:
        """World-from-body homogeneous transform (4x4): :meth:`rotation` and
        :attr:`position` (the same expressions, built as one array)."""
        cy, sy = math.cos(self.yaw), math.sin(self.yaw)
        cp, sp = math.cos(self.pitch), math.sin(self.pitch)
        cr, sr = math.cos(self.roll), math.sin(self.roll)
        return np.array([
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr, self.east],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr, self.north],
            [-sp, cp * sr, cp * cr, self.up],
            [0.0, 0.0, 0.0, 1.0],
        ])

    def velocity(self) -> NDArray[np.float64]:
        """Velocity of the rear axle centre in the world frame (m/s)."""
        return np.array([self.speed * math.cos(self.yaw) * math.cos(self.pitch),
                         self.speed * math.sin(self.yaw) * math.cos(self.pitch),
                         self.vertical_velocity])

    def angular_velocity_body(self) -> NDArray[np.float64]:
        """Body-frame angular rate (rad/s) from the Euler rates (what a gyro measures)."""
        sr, cr = math.sin(self.roll), math.cos(self.roll)
        sp, cp = math.sin(self.pitch), math.cos(self.pitch)
        return np.array([self.roll_rate - self.yaw_rate * sp,
                         self.pitch_rate * cr + self.yaw_rate * sr * cp,
                         -self.pitch_rate * sr + self.yaw_rate * cr * cp])

    def acceleration_world(self) -> NDArray[np.float64]:
        """Kinematic acceleration in the world frame (m/s^2): longitudinal along the
        heading, centripetal to the left, vertical from the terrain."""
        cy, sy = math.cos(self.yaw), math.sin(self.yaw)
        a_lon, a_lat = self.longitudinal_acceleration, self.lateral_acceleration
        return np.array([a_lon * cy - a_lat * sy, a_lon * sy + a_lat * cy,
                         self.vertical_acceleration])

    def specific_force_body(self) -> NDArray[np.float64]:
        """What an ideal accelerometer at the rear axle centre reads, body frame (m/s^2):
        R^T (a + g·z); at rest on level ground (0, 0, +9.80665)."""
        f = self.acceleration_world() + np.array([0.0, 0.0, GRAVITY])
        return self.rotation().T @ f


@dataclass(frozen=True)
class Collision:
    """A collision at ``time``: the contact point (east, north), the obstacle index in
    the world file (-1 for ``boundary``) and the kind."""

    time: float
    east: float
    north: float
    obstacle: int
    kind: CollisionKind


@dataclass
class DriveResult:
    """States sampled every ``dt`` by :func:`run_drive`, and the collision, if any."""

    states: list[VehicleState] = field(default_factory=list)
    collision: Collision | None = None

    @property
    def track(self) -> NDArray[np.float64]:
        """(N, 2) east/north of the rear axle centre."""
        return np.array([[s.east, s.north] for s in self.states]).reshape(-1, 2)


class Vehicle:
    """The Raptor's motion model. Step it with :meth:`step`; read :attr:`state`."""

    def __init__(self, parameters: VehicleParameters | None = None,
                 state: VehicleState | None = None) -> None:
        self.parameters = parameters or VehicleParameters()
        self._state = state or VehicleState()
        self._collision: Collision | None = None
        self._footprint_cache: dict[float, NDArray[np.float64]] = {}

    @classmethod
    def from_world(cls, world: World, terrain: Terrain | None = None,
                   parameters: VehicleParameters | None = None) -> Vehicle:
        """A vehicle at the world's start pose, settled on ``terrain`` when given."""
        vehicle = cls(parameters)
        vehicle.reset(world.vehicle.east, world.vehicle.north, world.vehicle.heading,
                      terrain=terrain)
        return vehicle

    @property
    def state(self) -> VehicleState:
        return self._state

    @property
    def collision(self) -> Collision | None:
        """The collision that stopped the vehicle, or None."""
        return self._collision

    def reset(self, east: float, north: float, heading_deg: float, *, speed: float = 0.0,
              steering_deg: float = 0.0, time: float | None = None,
              terrain: Terrain | None = None) -> VehicleState:
        """Place the vehicle (clearing any collision), optionally moving at ``speed``
        with ``steering_deg`` already applied; settles height/roll/pitch on ``terrain``."""
        self._collision = None
        limit = math.radians(self.parameters.max_steering_deg)
        state = VehicleState(time=self._state.time if time is None else time,
                             east=east, north=north, yaw=math.radians(90.0 - heading_deg),
                             speed=speed,
                             steering=max(-limit, min(limit, math.radians(steering_deg))))
        if terrain is not None:
            up, roll, pitch = self._attitude(terrain, east, north, state.yaw)
            state = replace(state, up=up, roll=roll, pitch=pitch)
        self._state = state
        return state

    # ------------------------------------------------------------------ stepping
    def step(self, dt: float, speed_cmd: float, steer_cmd_deg: float,
             terrain: Terrain | None = None) -> VehicleState:
        """Advance ``dt`` seconds under the commands (m/s, deg, + = left), clamped to the
        limits. After a collision the vehicle stays stopped (time still advances).

        Raises ValueError for a negative or non-finite ``dt`` or non-finite commands.
        """
        if not (math.isfinite(dt) and dt >= 0):
            raise ValueError(f"dt must be finite and >= 0, got {dt!r}")
        if not (math.isfinite(speed_cmd) and math.isfinite(steer_cmd_deg)):
            raise ValueError("speed and steering commands must be finite")
        p = self.parameters
        if self._collision is not None:
            self._state = replace(self._state, time=self._state.time + dt, speed=0.0,
                                  yaw_rate=0.0, roll_rate=0.0, pitch_rate=0.0,
                                  longitudinal_acceleration=0.0, lateral_acceleration=0.0,
                                  vertical_velocity=0.0, vertical_acceleration=0.0)
            return self._state
        v_cmd = max(-p.max_reverse_speed, min(p.max_speed, speed_cmd))
        limit = math.radians(p.max_steering_deg)
        d_cmd = max(-limit, min(limit, math.radians(steer_cmd_deg)))
        reach = max(abs(self._state.speed), abs(v_cmd)) * dt
        count = max(1, math.ceil(reach / p.max_substep - 1e-12))
        h = dt / count
        end = self._state.time + dt
        for _ in range(count):
            self._substep(h, v_cmd, d_cmd, terrain)
            if self._collision is not None:
                break
        if self._state.time != end:  # no drift from summing sub-steps
            self._state = replace(self._state, time=end)
        return self._state

    def _substep(self, h: float, v_cmd: float, d_cmd: float, terrain: Terrain | None) -> None:
        p = self.parameters
        s0 = self._state
        if h == 0:
            return
        # first-order lags, exactly discretised
        d1 = d_cmd + (s0.steering - d_cmd) * _decay(h, p.steering_time_constant)
        v_target = v_cmd + (s0.speed - v_cmd) * _decay(h, p.speed_time_constant)
        dv = v_target - s0.speed
        speeding_up = v_target * s0.speed >= 0 and abs(v_target) > abs(s0.speed)
        bound = (p.max_acceleration if speeding_up else p.max_deceleration) * h
        v1 = s0.speed + max(-bound, min(bound, dv))
        if v_cmd == 0.0 and abs(v1) < STOP_SPEED:
            v1 = 0.0  # the brakes hold: the lag would otherwise only approach zero

        travel = 0.5 * (s0.speed + v1) * h          # along the ground, signed
        kappa = math.tan(0.5 * (s0.steering + d1)) / p.wheelbase
        horizontal = travel * math.cos(s0.pitch)
        turn = kappa * horizontal
        chord = horizontal * _sinc(0.5 * turn)
        mid = s0.yaw + 0.5 * turn
        east = s0.east + chord * math.cos(mid)
        north = s0.north + chord * math.sin(mid)
        yaw = _wrap(s0.yaw + turn)

        half = 0.5 * p.track
        lk = p.wheelbase * kappa
        fl = travel * math.hypot(lk, 1.0 - kappa * half)
        fr = travel * math.hypot(lk, 1.0 + kappa * half)
        rl = travel * (1.0 - kappa * half)
        rr = travel * (1.0 + kappa * half)

        if terrain is not None:
            up, roll, pitch = self._attitude(terrain, east, north, yaw)
        else:
            up, roll, pitch = s0.up, s0.roll, s0.pitch
        vz = (up - s0.up) / h
        self._state = VehicleState(
            time=s0.time + h, east=east, north=north, up=up, yaw=yaw, roll=roll, pitch=pitch,
            speed=v1, steering=d1, yaw_rate=turn / h,
            roll_rate=(roll - s0.roll) / h, pitch_rate=(pitch - s0.pitch) / h,
            longitudinal_acceleration=(v1 - s0.speed) / h,
            lateral_acceleration=v1 * turn / h,
            vertical_velocity=vz, vertical_acceleration=(vz - s0.vertical_velocity) / h,
            distance=s0.distance + travel, travelled=s0.travelled + abs(travel),
            front_left_distance=s0.front_left_distance + fl,
            front_right_distance=s0.front_right_distance + fr,
            rear_left_distance=s0.rear_left_distance + rl,
            rear_right_distance=s0.rear_right_distance + rr,
        )
        if terrain is not None:
            collision = self.check_collision(terrain)
            if collision is not None:
                self._collision = collision
                self._state = replace(self._state, speed=0.0)

    # ------------------------------------------------------------------ terrain
    def wheel_contacts(self, east: float | None = None, north: float | None = None,
                       yaw: float | None = None) -> NDArray[np.float64]:
        """(4, 2) east/north of the wheel contact points: rear-left, rear-right,
        front-left, front-right (current pose unless given)."""
        s = self._state
        e = s.east if east is None else east
        n = s.north if north is None else north
        y = s.yaw if yaw is None else yaw
        p = self.parameters
        fwd = np.array([math.cos(y), math.sin(y)])
        left = np.array([-math.sin(y), math.cos(y)])
        half = 0.5 * p.track
        base = np.array([e, n])
        return np.stack([base + half * left, base - half * left,
                         base + p.wheelbase * fwd + half * left,
                         base + p.wheelbase * fwd - half * left])

    def _attitude(self, terrain: Terrain, east: float, north: float,
                  yaw: float) -> tuple[float, float, float]:
        # Least-squares plane through the four contacts of a rectangle: average the
        # pairs. Height: wheel radius above the mean rear contact.
        p = self.parameters
        c, s = math.cos(yaw), math.sin(yaw)
        half = 0.5 * p.track
        le, ln = -half * s, half * c  # half the track to the left
        fe, fn = p.wheelbase * c, p.wheelbase * s
        height = terrain.height_at  # the four points of wheel_contacts(), without numpy
        z = (height(east + le, north + ln), height(east - le, north - ln),
             height(east + fe + le, north + fn + ln), height(east + fe - le, north + fn - ln))
        rear, front = 0.5 * (z[0] + z[1]), 0.5 * (z[2] + z[3])
        left, right = 0.5 * (z[0] + z[2]), 0.5 * (z[1] + z[3])
        pitch = math.atan2(rear - front, p.wheelbase)
        roll = math.atan2(left - right, p.track)
        return float(rear + p.wheel_radius), roll, pitch

    def footprint(self, spacing: float) -> NDArray[np.float64]:
        """(N, 2) body-frame (x forward, y left) sample points covering the footprint
        rectangle at ``spacing`` metres, edges included."""
        cached = self._footprint_cache.get(spacing)
        if cached is not None:
            return cached
        p = self.parameters
        nx = max(2, math.ceil(p.body_length / spacing) + 1)
        ny = max(2, math.ceil(p.body_width / spacing) + 1)
        xs = np.linspace(-p.rear_overhang, p.body_length - p.rear_overhang, nx)
        ys = np.linspace(-p.body_width / 2, p.body_width / 2, ny)
        gx, gy = np.meshgrid(xs, ys, indexing="ij")
        points = np.stack([gx.ravel(), gy.ravel()], axis=1)
        self._footprint_cache[spacing] = points
        return points

    def check_collision(self, terrain: Terrain) -> Collision | None:
        """The collision at the current pose, if any (see module doc for the rules)."""
        p = self.parameters
        s = self._state
        c, sn = math.cos(s.yaw), math.sin(s.yaw)
        e0, e1, n0, n1 = terrain.extent
        back, front, half = -p.rear_overhang, p.body_length - p.rear_overhang, p.body_width / 2
        for x, y in ((back, -half), (back, half), (front, -half), (front, half)):
            e, n = s.east + x * c - y * sn, s.north + x * sn + y * c
            if not (e0 <= e <= e1 and n0 <= n <= n1):
                return Collision(s.time, e, n, -1, "boundary")
        # the footprint's circumscribed circle, around the footprint's centre
        ahead = 0.5 * p.body_length - p.rear_overhang
        if not terrain.near_obstacle(s.east + ahead * c, s.north + ahead * sn,
                                     0.5 * math.hypot(p.body_length, p.body_width)
                                     + terrain.resolution):
            return None
        contacts = self.wheel_contacts()
        relief = np.asarray(terrain.relief(contacts[:, 0], contacts[:, 1]))
        if (relief < -p.ditch_depth).any():
            k = int(np.argmin(relief))
            return Collision(s.time, float(contacts[k, 0]), float(contacts[k, 1]),
                             int(terrain.obstacle_at(contacts[k, 0], contacts[k, 1])), "ditch")
        points = self.footprint(min(0.1, terrain.resolution))
        pe = s.east + points[:, 0] * c - points[:, 1] * sn
        pn = s.north + points[:, 0] * sn + points[:, 1] * c
        relief = np.asarray(terrain.relief(pe, pn))
        if (relief > p.step_height).any():
            k = int(np.argmax(relief))
            return Collision(s.time, float(pe[k]), float(pn[k]),
                             int(terrain.obstacle_at(pe[k], pn[k])), "obstacle")
        return None


def _decay(h: float, tau: float) -> float:
    return math.exp(-h / tau) if tau > 0 else 0.0


def _sinc(x: float) -> float:
    """sin(x)/x, exact at 0 (the chord of an arc of turn 2x is travel * sinc(x))."""
    if abs(x) < 1e-4:
        return 1.0 - x * x / 6.0
    return math.sin(x) / x


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def run_drive(world: World, terrain: Terrain | None = None, *, dt: float = 0.05,
              duration: float | None = None,
              parameters: VehicleParameters | None = None) -> DriveResult:
    """Drive the world's drive script from its start pose, sampling every ``dt`` s,
    until ``duration`` (default: the last command time + 5 s) or a collision.

    Builds the terrain from the world when not given. Raises ValueError for dt <= 0.
    """
    if not dt > 0:
        raise ValueError("dt must be > 0")
    if terrain is None:
        terrain = Terrain.from_spec(world.terrain, world.obstacles)
    vehicle = Vehicle.from_world(world, terrain, parameters)
    end = world.drive_duration + 5.0 if duration is None else duration
    result = DriveResult(states=[vehicle.state])
    steps = int(math.ceil(end / dt - 1e-9))
    for k in range(steps):
        speed, steering = world.command_at(k * dt)
        state = vehicle.step(dt, speed, steering, terrain)
        result.states.append(state)
        if vehicle.collision is not None:
            result.collision = vehicle.collision
            break
    return result
