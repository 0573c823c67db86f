"""ModelServer's pose filter: a planar EKF fusing GPS, IMU and front-wheel odometry.

Seed §3.2.4 ("Pose Estimation"): ModelServer consumes GPS, IMU and odometry events and
calls a localization filter on each one; the result is published as a ``Pose`` event
(``PoseTransformIDL``, seed Table 21) whose ``HTransform`` position is measured from
``initialUTM`` and whose ``poseValidFlag`` warns that the pose is questionable. The seed
also describes the "fidget": while the vehicle stands still, after ``FidgetDelay`` the
gyro bias is captured every ``FidgetPeriod`` (Table A.8). ``UseRawPose`` selects the
unfiltered GPS/IMU solution instead (:class:`RawPose`).

This module is pure Python + numpy: plain floats in, small dataclasses out, no asyncio
and no framework imports; the ModelServer component feeds it events and publishes.

Conventions (docs/geometry.md, ROS REP 103)
-------------------------------------------
- World frame: east, north, up (ENU), metres, the UTM grid (easting, northing) of the
  first fix, kept for the whole run; the ModelServer component turns the IMU's and the
  receiver's true headings into it by the grid convergence (decision 0029).
- Vehicle frame: the reference ``Raptor:RearAxleCenter``; x forward, y left, z up.
- ``heading`` / ``yaw``: ENU yaw, radians, counter-clockwise from **east**, wrapped to
  [-pi, pi). Compass headings (GPS track over ground, clockwise from **north**) convert
  with :func:`enu_yaw_from_compass` and :func:`compass_from_enu_yaw`. The 3DM-GX1's own
  Euler angles are NED-style (x forward, y right, z down); :func:`enu_attitude_from_ned`
  converts them (roll kept, pitch negated, yaw = pi/2 - yaw).
- Yaw rate: rad/s about the vehicle's up axis, counter-clockwise (left turn) positive,
  i.e. the negated ``rateZ`` of the 3DM-GX1 sensor frame (z down).

State and model
---------------
x = [east, north, yaw, speed, yaw_rate, gyro_bias] (m, m, rad, m/s, rad/s, rad/s);
positions are held relative to the first GPS fix (an internal origin) so the covariance
algebra never sees UTM-sized numbers, and reported back in absolute coordinates. The
motion model is constant speed and constant turn rate (CTRV) over each step, integrated
exactly as a circular arc (:func:`ctrv_transition`), the bias a random walk. Process
noise (:class:`PoseFilterTuning`, values for an ATV-sized vehicle such as the Raptor):

====================  =================  ===============================================
noise                 default            why
====================  =================  ===============================================
acceleration PSD      0.5 m^2/s^3        speed changes of ~1 m/s within a second or two
yaw acceleration PSD  0.1 rad^2/s^3      steering changes yaw rate ~0.3 rad/s per second
position PSD          0.01 m^2/s         side slip and lever-arm errors of a skid-prone ATV
yaw PSD               1e-5 rad^2/s       heading model error (~0.2 deg per sqrt(s))
bias PSD              1e-8 rad^2/s^3     gyro bias random walk (1e-4 rad/s per sqrt(s))
====================  =================  ===============================================

Measurements
------------
- GPS position of the antenna (lever arm ``antenna_offset`` in the vehicle frame),
  gated by the Mahalanobis distance against the chi-square quantile with 2 degrees of
  freedom (``gate_probability`` 0.999 -> 13.82). Rejections are counted; after more than
  ``max_consecutive_rejections`` in a row the filter believes the GPS (a real jump, e.g. a
  change of differential mode) and resets its position to the fix.
- GPS speed over ground and track are of the antenna, whose velocity in the vehicle
  frame is (v - w a_y, w a_x) for lever arm a. The speed (std ``gps_velocity_std``) is
  fused as the along part v - w a_y (the across part w a_x, with w from the state, is
  stripped first), forward unless the state says reversing. The track is a heading
  measurement, track = yaw + atan2(w a_x, v - w a_y) (the antenna's drift angle in a
  turn; near pi when reversing), used only when the speed is at least
  ``track_min_speed``, because the track of a stationary receiver is noise (seed
  §3.2.4); its std is atan(velocity std / speed), gated with 1 degree of freedom.
- Gyro yaw rate: measured = true rate + bias. Optional absolute yaw (the 3DM-GX1's
  magnetometer-stabilised yaw): gated (1 degree of freedom) and fused with a large std;
  it refines a heading but never establishes one (hard-iron and declination errors).
- Odometry: cumulative front-wheel distances give each front wheel's mean speed between
  successive calls. A front wheel at (wheelbase, +-track/2) of a vehicle moving at rear
  axle speed v and yaw rate w rolls at hypot(v -+ w track/2, w wheelbase) (rigid body,
  Ackermann steering, no slip). The across part w wheelbase is stripped (w from the
  state), leaving the linear along = v -+ w track/2: the wheels' mean is the speed and
  their difference over the track a yaw rate, much weaker than the gyro's (wheel std
  ``wheel_speed_std`` + ``wheel_speed_scale_std`` |speed|). Gated with 2 degrees of
  freedom (wheel slip), rejections counted.

Stationary detection and the fidget (seed §3.2.4, Table A.8)
------------------------------------------------------------
The vehicle is *stationary* while the latest report of every speed source says so:
odometry (both wheels below ``stationary_speed``) and GPS speed (below
``stationary_gps_speed``); a source reporting motion ends it. With neither source, raw
GPS fixes staying for ``stationary_gps_time`` within max(``stationary_radius``, 4.5 std)
of their mean since the stop began count as stationary (fidget only: no zero-velocity
update, as a crawl cannot be told from a stop). While a speed source says stationary the
filter applies a zero-velocity update (speed 0, yaw rate 0), so the gyro reading is all
bias and the heading does not drift. After ``fidget_delay`` seconds stationary the gyro
rates are averaged, and every ``fidget_period`` seconds the mean so far (over the whole
stop since the delay ended) is *captured* as the bias: the state's bias is set to it,
with the variance of that mean. :attr:`PoseFilter.fidget_bias` and
:attr:`PoseFilter.fidget_count` expose it; capture stops, and the average is discarded,
when the vehicle moves.

Pose validity (``poseValidFlag``)
---------------------------------
:attr:`PoseFilter.pose_valid` is True exactly when all of these hold:

1. a GPS fix has been accepted (the position is initialised);
2. the heading is initialised: from a GPS track at speed >= ``track_min_speed``, from
   :meth:`PoseFilter.initialise`, or from the displacement between GPS fixes once the
   vehicle has moved ``heading_init_distance`` (corrected by half the gyro-integrated
   turn, exact for a circular arc). A stationary vehicle has no observable heading, so
   the flag is False while stationary at start;
3. the heading std is at most ``max_heading_std`` and the position std (larger axis) at
   most ``max_position_std``;
4. no gated measurement (GPS position, GPS track, IMU yaw) was rejected, and no GPS reset
   happened, within the last ``invalid_hold`` seconds of filter time.

Sources checked: seed §3.2.4, Tables 20, 21, A.8 (behaviour, names, defaults); ROS REP 103
(ENU/NED and yaw conventions); docs/geometry.md (vehicle frame, antenna and wheel
geometry); Moore & Stouch 2014, robot_localization (gated EKF fusion of GPS, IMU,
odometry); chi-square quantiles for 1 and 2 degrees of freedom have closed forms (see
:func:`chi2_quantile`); the tests check them against scipy.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist
from typing import Final, Literal

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "IX_EAST",
    "IX_NORTH",
    "IX_YAW",
    "IX_SPEED",
    "IX_YAW_RATE",
    "IX_BIAS",
    "STATE_SIZE",
    "PoseEstimate",
    "PoseFilter",
    "PoseFilterTuning",
    "PoseUnavailableError",
    "RAW_EXTRAPOLATION_LIMIT",
    "RawPose",
    "chi2_quantile",
    "compass_from_enu_yaw",
    "ctrv_transition",
    "enu_attitude_from_ned",
    "enu_yaw_from_compass",
    "homogeneous_transform",
    "wrap_angle",
]

FloatArray = NDArray[np.float64]

IX_EAST: Final = 0
IX_NORTH: Final = 1
IX_YAW: Final = 2
IX_SPEED: Final = 3
IX_YAW_RATE: Final = 4
IX_BIAS: Final = 5
STATE_SIZE: Final = 6

_TWO_PI: Final = 2.0 * math.pi
#: Below this turn angle per step (rad) the arc is integrated by its series expansion
#: (error below v dt 1e-8; avoids the cancellation in v / w (sin - sin)).
_STRAIGHT_TURN: Final = 1e-4
#: Below this predicted antenna speed (m/s) the GPS track is not fused (no direction).
_MIN_TRACK_MODEL_SPEED: Final = 0.05


class PoseUnavailableError(RuntimeError):
    """No pose yet: the filter has not accepted a GPS fix."""


# --- angles and frames ------------------------------------------------------------------

def wrap_angle(angle: float) -> float:
    """Wrap an angle in radians to [-pi, pi)."""
    return (angle + math.pi) % _TWO_PI - math.pi


def enu_yaw_from_compass(heading: float) -> float:
    """ENU yaw (counter-clockwise from east, [-pi, pi)) from a compass heading.

    ``heading`` is in radians, clockwise from north (GPS track, NED yaw).
    """
    return wrap_angle(0.5 * math.pi - heading)


def compass_from_enu_yaw(yaw: float) -> float:
    """Compass heading (clockwise from north, radians in [0, 2 pi)) from an ENU yaw."""
    return (0.5 * math.pi - yaw) % _TWO_PI


def enu_attitude_from_ned(roll: float, pitch: float, yaw: float) -> tuple[float, float, float]:
    """Convert Euler angles of a NED-style body frame (x forward, y right, z down, as the
    3DM-GX1 reports them) to the ENU / vehicle (x forward, y left, z up) convention.

    Both use R = Rz(yaw) Ry(pitch) Rx(roll). Returns (roll, pitch, yaw) with yaw wrapped
    to [-pi, pi).
    """
    return roll, -pitch, wrap_angle(0.5 * math.pi - yaw)


def homogeneous_transform(east: float, north: float, up: float, yaw: float,
                          pitch: float = 0.0, roll: float = 0.0) -> FloatArray:
    """The 4x4 transform [R t; 0 1] with R = Rz(yaw) Ry(pitch) Rx(roll), t = (e, n, u)."""
    cy, sy = math.cos(yaw), math.sin(yaw)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cr, sr = math.cos(roll), math.sin(roll)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr, east],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr, north],
        [-sp, cp * sr, cp * cr, up],
        [0.0, 0.0, 0.0, 1.0],
    ])


def turned_lever(offset: Sequence[float], yaw: float, pitch: float,
                 roll: float) -> FloatArray:
    """A body-frame lever arm (the GPS antenna's offset from the vehicle reference)
    turned by Rz(yaw) Ry(pitch) Rx(roll): on a 13° slope an antenna 1.75 m up leans
    0.39 m downhill of the axle."""
    rotation = homogeneous_transform(0.0, 0.0, 0.0, yaw, pitch, roll)[:3, :3]
    lever: FloatArray = rotation @ np.asarray(offset, dtype=np.float64)
    return lever


def chi2_quantile(probability: float, dof: int) -> float:
    """Chi-square quantile for 1 or 2 degrees of freedom (the gates this filter uses).

    dof 2: -2 ln(1 - p) (the chi-square with 2 dof is exponential with mean 2);
    dof 1: the squared standard-normal quantile at (1 + p) / 2.

    Raises:
        ValueError: ``probability`` not in (0, 1) or ``dof`` not 1 or 2.
    """
    if not 0.0 < probability < 1.0:
        raise ValueError(f"probability must be in (0, 1), got {probability}")
    if dof == 1:
        return NormalDist().inv_cdf(0.5 * (1.0 + probability)) ** 2
    if dof == 2:
        return -2.0 * math.log1p(-probability)
    raise ValueError(f"only 1 or 2 degrees of freedom are supported, got {dof}")


def ctrv_transition(state: FloatArray, dt: float) -> tuple[FloatArray, FloatArray]:
    """Propagate ``state`` by ``dt`` seconds along a constant-speed, constant-turn arc.

    Returns the new state and the Jacobian F = d(new state)/d(state). Speed, yaw rate and
    bias are constant; the yaw is wrapped.
    """
    east, north, yaw, v, w = (float(state[i]) for i in range(5))
    s0, c0 = math.sin(yaw), math.cos(yaw)
    yaw1 = yaw + w * dt
    s1, c1 = math.sin(yaw1), math.cos(yaw1)
    jac = np.eye(STATE_SIZE)
    if abs(w * dt) > _STRAIGHT_TURN:
        de = v / w * (s1 - s0)
        dn = v / w * (c0 - c1)
        jac[IX_EAST, IX_YAW] = v / w * (c1 - c0)
        jac[IX_NORTH, IX_YAW] = v / w * (s1 - s0)
        jac[IX_EAST, IX_SPEED] = (s1 - s0) / w
        jac[IX_NORTH, IX_SPEED] = (c0 - c1) / w
        jac[IX_EAST, IX_YAW_RATE] = v * dt * c1 / w - de / w
        jac[IX_NORTH, IX_YAW_RATE] = v * dt * s1 / w - dn / w
    else:
        # Second-order limit of the arc: keeps the yaw-rate column non-zero.
        de = v * dt * c0 - 0.5 * v * w * dt * dt * s0
        dn = v * dt * s0 + 0.5 * v * w * dt * dt * c0
        jac[IX_EAST, IX_YAW] = -v * dt * s0
        jac[IX_NORTH, IX_YAW] = v * dt * c0
        jac[IX_EAST, IX_SPEED] = dt * c0
        jac[IX_NORTH, IX_SPEED] = dt * s0
        jac[IX_EAST, IX_YAW_RATE] = -0.5 * v * dt * dt * s0
        jac[IX_NORTH, IX_YAW_RATE] = 0.5 * v * dt * dt * c0
    jac[IX_YAW, IX_YAW_RATE] = dt
    new = np.array(state, dtype=float, copy=True)
    new[IX_EAST] = east + de
    new[IX_NORTH] = north + dn
    new[IX_YAW] = wrap_angle(yaw1)
    return new, jac


# --- tuning and outputs -----------------------------------------------------------------

@dataclass(frozen=True, slots=True)
class PoseFilterTuning:
    """Noise model, gates and thresholds of :class:`PoseFilter` (SI units, radians).

    ``fidget_delay`` and ``fidget_period`` are Table A.8's FidgetDelay and FidgetPeriod
    (seconds). Geometry defaults are docs/geometry.md's Raptor (wheelbase 1.9 m, track
    1.3 m); the antenna lever arm defaults to zero (the model server passes the
    ``GpsAntenna:PhaseCenter`` position in ``Raptor:RearAxleCenter``).

    Raises:
        ValueError: a standard deviation, PSD, period or geometry value is not positive
            (or negative where zero is allowed), or a probability is not in (0, 1).
    """

    fidget_delay: float = 20.0
    """s stationary before bias capture starts (Table A.8 FidgetDelay)."""
    fidget_period: float = 300.0
    """s between bias captures while stationary (Table A.8 FidgetPeriod)."""
    accel_psd: float = 0.5
    """m^2/s^3: white longitudinal acceleration (speed random walk)."""
    yaw_accel_psd: float = 0.1
    """rad^2/s^3: white yaw acceleration (yaw-rate random walk)."""
    position_psd: float = 0.01
    """m^2/s per axis: side slip and unmodelled motion."""
    yaw_psd: float = 1e-5
    """rad^2/s: heading model error."""
    bias_psd: float = 1e-8
    """rad^2/s^3: gyro bias random walk."""
    max_predict_step: float = 0.1
    """s: longer predictions are split into steps no longer than this."""
    initial_speed_std: float = 1.0
    """m/s: speed std before any speed measurement."""
    initial_yaw_rate_std: float = 0.5
    """rad/s: yaw-rate std before any rate measurement."""
    initial_bias_std: float = 0.035
    """rad/s: turn-on gyro bias std (2 deg/s)."""
    gate_probability: float = 0.999
    """Chi-square gate probability for GPS position, track, IMU yaw and odometry."""
    max_consecutive_rejections: int = 8
    """GPS fixes rejected in a row before the position is reset to the next one."""
    gps_velocity_std: float = 0.1
    """m/s: std of each GPS velocity component (Doppler); sets speed and track noise."""
    track_min_speed: float = 1.0
    """m/s: the GPS track is a heading measurement only at or above this speed."""
    heading_init_distance: float = 5.0
    """m: GPS displacement that initialises the heading when no track is usable."""
    heading_init_max_turn: float = 0.5
    """rad: gyro-integrated turn beyond which the displacement baseline restarts."""
    antenna_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """m: GPS antenna phase centre in the vehicle frame (x forward, y left, z up)."""
    gyro_rate_std: float = 0.01
    """rad/s: std of one gyro yaw-rate sample."""
    imu_yaw_std: float = math.radians(10.0)
    """rad: std of the IMU's absolute (magnetometer) yaw."""
    imu_yaw_offset: float = 0.0
    """rad: added to the IMU yaw (declination, mounting) before fusing."""
    wheelbase: float = 1.9
    """m: rear axle to front axle."""
    track_width: float = 1.3
    """m: between the front wheels' contact points."""
    wheel_speed_std: float = 0.05
    """m/s: std of one wheel's mean speed between odometry reports ..."""
    wheel_speed_scale_std: float = 0.02
    """... plus this fraction of the wheel speed (slip, tyre radius)."""
    stationary_speed: float = 0.02
    """m/s: both wheels below this: stationary."""
    stationary_gps_speed: float = 0.25
    """m/s: GPS speed below this: stationary (and GPS speed is not fused)."""
    stationary_radius: float = 1.0
    """m: GPS-only stationary detection: fixes within this radius of the stop ..."""
    stationary_gps_time: float = 5.0
    """s: ... for at least this long."""
    zupt_speed_std: float = 0.01
    """m/s: zero-velocity update while stationary."""
    zupt_yaw_rate_std: float = 0.001
    """rad/s: zero-yaw-rate update while stationary."""
    max_heading_std: float = math.radians(5.0)
    """rad: pose_valid needs the heading std at most this."""
    max_position_std: float = 2.0
    """m: pose_valid needs the position std (worse axis) at most this."""
    invalid_hold: float = 1.0
    """s: pose_valid stays False this long after a rejection or reset."""

    def __post_init__(self) -> None:
        positive = ("fidget_period", "accel_psd", "yaw_accel_psd", "position_psd", "yaw_psd",
                    "bias_psd", "max_predict_step", "initial_speed_std",
                    "initial_yaw_rate_std", "initial_bias_std", "gps_velocity_std",
                    "heading_init_distance", "heading_init_max_turn", "gyro_rate_std",
                    "imu_yaw_std", "wheelbase", "track_width", "wheel_speed_std",
                    "stationary_speed", "stationary_gps_speed", "stationary_radius",
                    "stationary_gps_time",
                    "zupt_speed_std", "zupt_yaw_rate_std", "max_heading_std",
                    "max_position_std")
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")
        for name in ("fidget_delay", "track_min_speed", "wheel_speed_scale_std",
                     "invalid_hold"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be finite and >= 0, got {value}")
        if not 0.0 < self.gate_probability < 1.0:
            raise ValueError(f"gate_probability must be in (0, 1), got "
                             f"{self.gate_probability}")
        if self.max_consecutive_rejections < 0:
            raise ValueError("max_consecutive_rejections must be >= 0")
        if len(self.antenna_offset) != 3 or not all(map(math.isfinite, self.antenna_offset)):
            raise ValueError(f"antenna_offset must be 3 finite numbers, got "
                             f"{self.antenna_offset}")
        if not math.isfinite(self.imu_yaw_offset):
            raise ValueError("imu_yaw_offset must be finite")


@dataclass(frozen=True, slots=True)
class PoseEstimate:
    """A snapshot of the filter: absolute position (UTM metres), ENU yaw, rates, validity.

    ``covariance`` is the 6x6 state covariance in the order east, north, yaw, speed,
    yaw rate, gyro bias (a copy; the caller may keep it).
    """

    time: float
    east: float
    north: float
    heading: float
    speed: float
    yaw_rate: float
    gyro_bias: float
    covariance: FloatArray
    pose_valid: bool
    stationary: bool

    @property
    def compass_heading(self) -> float:
        """Heading clockwise from north, radians in [0, 2 pi)."""
        return compass_from_enu_yaw(self.heading)

    @property
    def position_std(self) -> float:
        """Standard deviation of the position along its worse axis, metres."""
        block = self.covariance[:2, :2]
        return math.sqrt(max(float(np.linalg.eigvalsh(block)[-1]), 0.0))

    @property
    def heading_std(self) -> float:
        """Standard deviation of the heading, radians."""
        return math.sqrt(max(float(self.covariance[IX_YAW, IX_YAW]), 0.0))


def _finite(name: str, *values: float) -> None:
    for value in values:
        if not math.isfinite(value):
            raise ValueError(f"{name} must be finite, got {value}")


def _transform_from(initial_utm: Sequence[float], east: float, north: float,
                    elevation: float | None, antenna_z: float, yaw: float,
                    pitch: float, roll: float) -> FloatArray:
    if len(initial_utm) != 3:
        raise ValueError(f"initial_utm must be (easting, northing, elevation), got "
                         f"{initial_utm!r}")
    e0, n0, u0 = (float(v) for v in initial_utm)
    _finite("initial_utm", e0, n0, u0)
    up = 0.0 if elevation is None else elevation - antenna_z - u0
    return homogeneous_transform(east - e0, north - n0, up, yaw, pitch, roll)


# --- the filter -------------------------------------------------------------------------

class PoseFilter:
    """Planar EKF over [east, north, yaw, speed, yaw rate, gyro bias].

    Feed it events in time order through :meth:`update_gps`, :meth:`update_imu` and
    :meth:`update_odometry` (each predicts to its time first); read :meth:`estimate`,
    :meth:`transform` and :attr:`pose_valid`. Times are seconds on any monotonic scale.
    A measurement older than the filter time is applied at the filter time (no
    prediction backwards) and counted in :attr:`late_measurements`.
    """

    def __init__(self, tuning: PoseFilterTuning | None = None) -> None:
        self.tuning = tuning or PoseFilterTuning()
        t = self.tuning
        self._x: FloatArray = np.zeros(STATE_SIZE)
        self._p: FloatArray = np.diag([1e6, 1e6, math.pi ** 2, t.initial_speed_std ** 2,
                                       t.initial_yaw_rate_std ** 2,
                                       t.initial_bias_std ** 2])
        self._time: float | None = None
        self._origin: tuple[float, float] | None = None
        self._heading_known = False
        self._gate2 = chi2_quantile(t.gate_probability, 2)
        self._gate1 = chi2_quantile(t.gate_probability, 1)
        # GPS bookkeeping
        self._consecutive_rejections = 0
        self._last_invalidating: float | None = None
        self._anchor: tuple[float, float, float] | None = None  # e, n (local), yaw
        self._elevation: float | None = None
        # IMU attitude pass-through
        self._roll = 0.0
        self._pitch = 0.0
        # odometry
        self._odometry: tuple[float, float, float] | None = None
        # stationary / fidget
        self._speed_source_seen = False
        self._motion_reports: dict[str, bool] = {}
        self._stationary = False
        self._stationary_since: float | None = None
        self._stop_anchor: tuple[float, float, int, float] | None = None  # e, n, count, t0
        self._fidget_start: float | None = None
        self._fidget_next = 0.0
        self._fidget_sum = 0.0
        self._fidget_sum_sq = 0.0
        self._fidget_n = 0
        self.fidget_bias: float | None = None
        """The last captured gyro bias (rad/s), None before the first capture."""
        self.fidget_count = 0
        """Number of bias captures so far."""
        self.gps_rejections = 0
        """GPS fixes rejected by the position gate."""
        self.gps_resets = 0
        """Position resets after a burst of more than max_consecutive_rejections."""
        self.track_rejections = 0
        """GPS track (heading) measurements rejected by the gate."""
        self.imu_yaw_rejections = 0
        """IMU absolute yaw measurements rejected by the gate."""
        self.odometry_rejections = 0
        """Odometry wheel-speed measurements rejected by the gate (wheel slip)."""
        self.late_measurements = 0
        """Measurements older than the filter time (applied without prediction)."""

    # -- read-out -----------------------------------------------------------------------

    @property
    def time(self) -> float | None:
        """Time of the state, seconds; None before the first call."""
        return self._time

    @property
    def position_known(self) -> bool:
        """True once a GPS fix has initialised the position."""
        return self._origin is not None

    @property
    def heading_known(self) -> bool:
        """True once the heading has been initialised from motion (track or displacement)."""
        return self._heading_known

    @property
    def stationary(self) -> bool:
        """True while the speed sources say the vehicle stands still."""
        return self._stationary

    @property
    def east(self) -> float:
        """Absolute easting of the vehicle reference, m (0 before the first fix)."""
        return float(self._x[IX_EAST]) + (self._origin[0] if self._origin else 0.0)

    @property
    def north(self) -> float:
        """Absolute northing of the vehicle reference, m (0 before the first fix)."""
        return float(self._x[IX_NORTH]) + (self._origin[1] if self._origin else 0.0)

    @property
    def heading(self) -> float:
        """ENU yaw, radians counter-clockwise from east, [-pi, pi)."""
        return float(self._x[IX_YAW])

    @property
    def speed(self) -> float:
        """Speed of the rear axle centre along the heading, m/s (negative reversing)."""
        return float(self._x[IX_SPEED])

    @property
    def yaw_rate(self) -> float:
        """Yaw rate, rad/s, counter-clockwise positive (bias removed)."""
        return float(self._x[IX_YAW_RATE])

    @property
    def gyro_bias(self) -> float:
        """Estimated gyro bias, rad/s (measured rate = true rate + bias)."""
        return float(self._x[IX_BIAS])

    @property
    def covariance(self) -> FloatArray:
        """A copy of the 6x6 state covariance."""
        return self._p.copy()

    @property
    def pose_valid(self) -> bool:
        """The poseValidFlag; the rule is in the module docstring."""
        t = self.tuning
        if self._origin is None or not self._heading_known or self._time is None:
            return False
        if math.sqrt(max(self._p[IX_YAW, IX_YAW], 0.0)) > t.max_heading_std:
            return False
        position_var = float(np.linalg.eigvalsh(self._p[:2, :2])[-1])
        if math.sqrt(max(position_var, 0.0)) > t.max_position_std:
            return False
        return (self._last_invalidating is None
                or self._time - self._last_invalidating >= t.invalid_hold)

    def estimate(self) -> PoseEstimate:
        """A snapshot of the current state (see :class:`PoseEstimate`)."""
        return PoseEstimate(
            time=self._time if self._time is not None else 0.0, east=self.east,
            north=self.north, heading=self.heading, speed=self.speed,
            yaw_rate=self.yaw_rate, gyro_bias=self.gyro_bias, covariance=self.covariance,
            pose_valid=self.pose_valid, stationary=self._stationary)

    def transform(self, initial_utm: Sequence[float]) -> FloatArray:
        """^W T_V: the vehicle reference pose, translation measured from ``initial_utm``.

        ``initial_utm`` is (easting, northing, elevation) (Table 21). The rotation is
        Rz(heading) Ry(pitch) Rx(roll) with roll and pitch the last IMU values (vehicle
        convention; zero if none); z is the last GPS elevation minus the antenna height
        minus the initial elevation (0 if no elevation was given).

        Raises:
            PoseUnavailableError: no GPS fix accepted yet.
            ValueError: ``initial_utm`` is not three finite numbers.
        """
        if self._origin is None:
            raise PoseUnavailableError("the pose filter has no GPS fix yet")
        return _transform_from(initial_utm, self.east, self.north, self._elevation,
                               self._levelled_lever()[2], self.heading, self._pitch,
                               self._roll)

    # -- explicit initialisation ------------------------------------------------------------

    def initialise(self, t: float, east: float, north: float, heading: float,
                   position_std: float, heading_std: float) -> None:
        """Set position and heading directly (e.g. a surveyed start), keeping the rest.

        Raises:
            ValueError: a value is not finite, or a std is not positive.
        """
        _finite("initialise arguments", t, east, north, heading)
        if not (position_std > 0.0 and heading_std > 0.0):
            raise ValueError("position_std and heading_std must be > 0")
        self.predict(t)
        self._set_position(east, north, position_std ** 2)
        self._set_heading(heading, heading_std ** 2)

    # -- prediction -----------------------------------------------------------------------

    def predict(self, t: float) -> None:
        """Propagate the state to time ``t`` (no-op if ``t`` is not after the filter time).

        Raises:
            ValueError: ``t`` is not finite.
        """
        _finite("t", t)
        if self._time is None:
            self._time = t
            return
        dt = t - self._time
        if dt < 0.0:
            self.late_measurements += 1
            return
        if dt == 0.0:
            return
        steps = max(1, math.ceil(dt / self.tuning.max_predict_step - 1e-9))
        h = dt / steps
        for _ in range(steps):
            self._predict_step(h)
        self._time = t

    def _predict_step(self, h: float) -> None:
        t = self.tuning
        x_new, jac = ctrv_transition(self._x, h)
        yaw, v = float(self._x[IX_YAW]), float(self._x[IX_SPEED])
        q = np.zeros((STATE_SIZE, STATE_SIZE))
        if not self._heading_known:
            # Unknown heading: the position is a random walk of step |v| h instead of
            # being pushed along a heading that is still arbitrary.
            x_new[IX_EAST], x_new[IX_NORTH] = self._x[IX_EAST], self._x[IX_NORTH]
            jac[:2, :] = 0.0
            jac[0, 0] = jac[1, 1] = 1.0
            walk = (abs(v) + 3.0 * math.sqrt(self._p[IX_SPEED, IX_SPEED])) * h
            q[0, 0] = q[1, 1] = walk * walk
        c, s = math.cos(yaw), math.sin(yaw)
        # white acceleration along the heading drives speed and position
        g = np.array([c, s])
        qa = t.accel_psd
        q[:2, :2] += qa * h ** 3 / 3.0 * np.outer(g, g)
        q[:2, IX_SPEED] += qa * h ** 2 / 2.0 * g
        q[IX_SPEED, :2] += qa * h ** 2 / 2.0 * g
        q[IX_SPEED, IX_SPEED] += qa * h
        # white yaw acceleration drives yaw rate and yaw
        qw = t.yaw_accel_psd
        q[IX_YAW, IX_YAW] += qw * h ** 3 / 3.0 + t.yaw_psd * h
        q[IX_YAW, IX_YAW_RATE] += qw * h ** 2 / 2.0
        q[IX_YAW_RATE, IX_YAW] += qw * h ** 2 / 2.0
        q[IX_YAW_RATE, IX_YAW_RATE] += qw * h
        q[0, 0] += t.position_psd * h
        q[1, 1] += t.position_psd * h
        q[IX_BIAS, IX_BIAS] += t.bias_psd * h
        self._x = x_new
        p = jac @ self._p @ jac.T + q
        self._p = 0.5 * (p + p.T)

    # -- generic update -------------------------------------------------------------------

    def _update(self, innovation: FloatArray, hm: FloatArray, r: FloatArray,
                gate: float | None) -> bool:
        """Kalman update with innovation y, Jacobian H, noise R; False if gated out."""
        s = hm @ self._p @ hm.T + r
        nis = float(innovation @ np.linalg.solve(s, innovation))
        if gate is not None and not nis <= gate:
            return False
        k = np.linalg.solve(s, hm @ self._p).T  # P H^T S^-1 (S symmetric)
        self._x = self._x + k @ innovation
        self._x[IX_YAW] = wrap_angle(float(self._x[IX_YAW]))
        i_kh = np.eye(STATE_SIZE) - k @ hm
        p = i_kh @ self._p @ i_kh.T + k @ r @ k.T  # Joseph form: stays positive
        self._p = 0.5 * (p + p.T)
        return True

    def _set_position(self, east: float, north: float, variance: float) -> None:
        if self._origin is None:
            self._origin = (east, north)
        self._x[IX_EAST] = east - self._origin[0]
        self._x[IX_NORTH] = north - self._origin[1]
        for i in (IX_EAST, IX_NORTH):
            self._p[i, :] = 0.0
            self._p[:, i] = 0.0
            self._p[i, i] = variance

    def _set_heading(self, yaw: float, variance: float) -> None:
        self._x[IX_YAW] = wrap_angle(yaw)
        self._p[IX_YAW, :] = 0.0
        self._p[:, IX_YAW] = 0.0
        self._p[IX_YAW, IX_YAW] = variance
        self._heading_known = True
        self._anchor = None

    # -- stationary tracking and fidget --------------------------------------------------

    def _report_motion(self, t: float, source: str, stationary: bool) -> None:
        """Record one source's verdict; stationary only while every source agrees."""
        if source != "position":
            self._motion_reports.pop("position", None)  # a real speed source supersedes
        self._motion_reports[source] = stationary
        now = all(self._motion_reports.values())
        if now and not self._stationary:
            self._stationary = True
            self._stationary_since = t
        elif not now and self._stationary:
            self._stationary = False
            self._stationary_since = None
            self._fidget_start = None

    def _fidget(self, t: float, measured_rate: float) -> None:
        tu = self.tuning
        since = self._stationary_since
        if not self._stationary or since is None or t - since < tu.fidget_delay:
            return
        if self._fidget_start is None:
            self._fidget_start = t
            self._fidget_next = t + tu.fidget_period
            self._fidget_sum = self._fidget_sum_sq = 0.0
            self._fidget_n = 0
        self._fidget_sum += measured_rate
        self._fidget_sum_sq += measured_rate * measured_rate
        self._fidget_n += 1
        if t >= self._fidget_next and self._fidget_n >= 2:
            # The mean over the whole stop so far: the longer the stop, the better.
            n = self._fidget_n
            mean = self._fidget_sum / n
            sample_var = max(self._fidget_sum_sq - n * mean * mean, 0.0) / (n - 1)
            variance = max(sample_var, tu.gyro_rate_std ** 2) / n
            self.fidget_bias = mean
            self.fidget_count += 1
            # Capture: the true rate is zero, so the mean is the bias (seed §3.2.4).
            self._x[IX_BIAS] = mean
            self._p[IX_BIAS, :] = 0.0
            self._p[:, IX_BIAS] = 0.0
            self._p[IX_BIAS, IX_BIAS] = variance
            self._fidget_next += tu.fidget_period

    def _zero_velocity_update(self) -> None:
        tu = self.tuning
        hm = np.zeros((2, STATE_SIZE))
        hm[0, IX_SPEED] = 1.0
        hm[1, IX_YAW_RATE] = 1.0
        y = -self._x[[IX_SPEED, IX_YAW_RATE]]
        self._update(y, hm, np.diag([tu.zupt_speed_std ** 2, tu.zupt_yaw_rate_std ** 2]),
                     None)

    # -- GPS ------------------------------------------------------------------------------

    def update_gps(self, t: float, east: float, north: float, std_m: float,
                   speed: float | None = None, track: float | None = None,
                   elevation: float | None = None) -> bool:
        """Fuse a GPS fix of the antenna: UTM ``east``, ``north`` (m) with std ``std_m``.

        ``speed`` is the speed over ground (m/s, >= 0) and ``track`` the track over ground
        in radians clockwise from north (``math.radians(GpsIDL.track)``); the track is
        used only when ``speed`` >= ``track_min_speed``. ``elevation`` (m) is kept for the
        transform's z. Returns True if the position was used (accepted or a reset), False
        if the gate rejected it (then speed and track are ignored too).

        Raises:
            ValueError: a value is not finite, ``std_m`` <= 0 or ``speed`` < 0.
        """
        _finite("GPS fix", t, east, north, std_m)
        if not std_m > 0.0:
            raise ValueError(f"std_m must be > 0, got {std_m}")
        if speed is not None:
            _finite("speed", speed)
            if speed < 0.0:
                raise ValueError(f"speed over ground must be >= 0, got {speed}")
        if track is not None:
            _finite("track", track)
        if elevation is not None:
            _finite("elevation", elevation)
        tu = self.tuning
        self.predict(t)
        variance = std_m * std_m
        ax, ay, _ = self._levelled_lever()

        if self._origin is None:
            # First fix: the reference is within one lever arm of the antenna.
            yaw = self.heading if self._heading_known else 0.0
            ce, se = math.cos(yaw), math.sin(yaw)
            known = self._heading_known
            e_ref = east - (ce * ax - se * ay if known else 0.0)
            n_ref = north - (se * ax + ce * ay if known else 0.0)
            lever = math.hypot(ax, ay)
            self._set_position(e_ref, n_ref, variance + (0.0 if known else lever * lever))
            accepted = True
        else:
            accepted = self._gps_position_update(t, east, north, variance, ax, ay)
        if not accepted:
            return False
        if elevation is not None:
            self._elevation = elevation

        if speed is not None:
            self._speed_source_seen = True
            self._report_motion(t, "gps", speed < tu.stationary_gps_speed)
        elif not self._speed_source_seen:
            self._position_motion(t, east, north, std_m)

        if speed is not None and speed >= tu.stationary_gps_speed:
            self._gps_speed_update(speed)
            if track is not None and speed >= tu.track_min_speed:
                self._track_update(t, track, speed)
        if not self._heading_known:
            self._heading_from_displacement(variance)
        return True

    def _gps_position_update(self, t: float, east: float, north: float, variance: float,
                             ax: float, ay: float) -> bool:
        """The fix of the antenna at (ax, ay) from the reference, levelled (heading
        not yet applied)."""
        tu = self.tuning
        assert self._origin is not None
        lever = math.hypot(ax, ay)
        yaw = float(self._x[IX_YAW])
        c, s = math.cos(yaw), math.sin(yaw)
        hm = np.zeros((2, STATE_SIZE))
        hm[0, IX_EAST] = hm[1, IX_NORTH] = 1.0
        r = np.eye(2) * variance
        if self._heading_known:
            predicted = (self._x[IX_EAST] + c * ax - s * ay,
                         self._x[IX_NORTH] + s * ax + c * ay)
            hm[0, IX_YAW] = -s * ax - c * ay
            hm[1, IX_YAW] = c * ax - s * ay
        else:
            predicted = (self._x[IX_EAST], self._x[IX_NORTH])
            r += np.eye(2) * lever * lever
        y = np.array([east - self._origin[0] - predicted[0],
                      north - self._origin[1] - predicted[1]])
        if self._update(y, hm, r, self._gate2):
            self._consecutive_rejections = 0
            return True
        self.gps_rejections += 1
        self._consecutive_rejections += 1
        self._last_invalidating = t
        if self._consecutive_rejections > tu.max_consecutive_rejections:
            # A burst this long is the GPS moving, not an outlier: believe it.
            e_ref = east - (c * ax - s * ay if self._heading_known else 0.0)
            n_ref = north - (s * ax + c * ay if self._heading_known else 0.0)
            self._set_position(e_ref, n_ref,
                               variance + (0.0 if self._heading_known else lever * lever))
            self.gps_resets += 1
            self._consecutive_rejections = 0
            self._anchor = None
            self._stop_anchor = None
            return True
        return False

    def _levelled_lever(self) -> tuple[float, float, float]:
        """The antenna lever arm turned by the IMU's pitch and roll (:func:`turned_lever`;
        the heading is the state's, turned in the measurement model)."""
        x, y, z = turned_lever(self.tuning.antenna_offset, 0.0, self._pitch, self._roll)
        return float(x), float(y), float(z)

    def _antenna_velocity(self) -> tuple[float, float]:
        """Antenna velocity in the vehicle frame: (v - w a_y, w a_x) (lever arm a)."""
        ax, ay, _ = self.tuning.antenna_offset
        v, w = float(self._x[IX_SPEED]), float(self._x[IX_YAW_RATE])
        return v - w * ay, w * ax

    def _gps_speed_update(self, speed: float) -> None:
        """Speed over ground of the antenna, |(v - w a_y, w a_x)| for lever arm a.

        The across part w a_x is stripped (w from the state) so the measurement is
        linear: along = v - w a_y. GPS speed has no sign: forward is assumed unless the
        state says the vehicle is reversing (odometry carries the sign).
        """
        ax, ay, _ = self.tuning.antenna_offset
        across = float(self._x[IX_YAW_RATE]) * ax
        along = math.sqrt(max(speed * speed - across * across, 0.0))
        if self._x[IX_SPEED] < -0.2:
            along = -along
        hm = np.zeros((1, STATE_SIZE))
        hm[0, IX_SPEED] = 1.0
        hm[0, IX_YAW_RATE] = -ay
        self._update(np.array([along - float(hm[0] @ self._x)]), hm,
                     np.array([[self.tuning.gps_velocity_std ** 2]]), self._gate1)

    def _track_update(self, t: float, track: float, speed: float) -> None:
        """GPS track = heading + the antenna's drift angle atan2(w a_x, v - w a_y).

        Reversing needs no special case: the drift angle is then near pi.
        """
        tu = self.tuning
        ax, ay, _ = tu.antenna_offset
        yaw_meas = enu_yaw_from_compass(track)
        std = math.atan2(tu.gps_velocity_std, speed)
        along, across = self._antenna_velocity()
        if not self._heading_known:
            w = float(self._x[IX_YAW_RATE])
            along = (-speed if self._x[IX_SPEED] < -0.2 else speed) - w * ay
            self._set_heading(yaw_meas - math.atan2(w * ax, along), std * std)
            return
        norm2 = along * along + across * across
        if norm2 < _MIN_TRACK_MODEL_SPEED ** 2:
            return  # the state says (nearly) stopped: the speed update fixes that first
        hm = np.zeros((1, STATE_SIZE))
        hm[0, IX_YAW] = 1.0
        hm[0, IX_SPEED] = -across / norm2
        hm[0, IX_YAW_RATE] = (along * ax + across * ay) / norm2
        predicted = float(self._x[IX_YAW]) + math.atan2(across, along)
        y = np.array([wrap_angle(yaw_meas - predicted)])
        if not self._update(y, hm, np.array([[std * std]]), self._gate1):
            self.track_rejections += 1
            self._last_invalidating = t

    def _heading_from_displacement(self, variance: float) -> None:
        tu = self.tuning
        e, n, yaw = (float(self._x[i]) for i in (IX_EAST, IX_NORTH, IX_YAW))
        if self._anchor is None:
            self._anchor = (e, n, yaw)
            return
        e0, n0, yaw0 = self._anchor
        turned = wrap_angle(yaw - yaw0)
        if abs(turned) > tu.heading_init_max_turn:
            self._anchor = (e, n, yaw)
            return
        distance = math.hypot(e - e0, n - n0)
        if distance < tu.heading_init_distance:
            return
        chord = math.atan2(n - n0, e - e0)
        if self._x[IX_SPEED] < -0.2:
            chord += math.pi
        # On an arc the chord points half-way between the start and end headings.
        std = 2.0 * math.sqrt(variance) / distance
        self._set_heading(chord + 0.5 * turned, std * std)

    def _position_motion(self, t: float, east: float, north: float, std_m: float) -> None:
        """Stationary detection from raw GPS fixes alone (no speed source seen).

        Stationary once the fixes have stayed for ``stationary_gps_time`` within
        max(``stationary_radius``, 4.5 std) of their mean since the stop began (a
        4.5-sigma miss has probability 4e-5 per fix); a fix outside restarts the mean
        there and reports motion.
        """
        tu = self.tuning
        anchor = self._stop_anchor
        if anchor is None:
            self._stop_anchor = (east, north, 1, t)
            self._report_motion(t, "position", False)
            return
        me, mn, count, start = anchor
        if math.hypot(east - me, north - mn) <= max(tu.stationary_radius, 4.5 * std_m):
            count += 1
            self._stop_anchor = (me + (east - me) / count, mn + (north - mn) / count, count,
                                 start)
            self._report_motion(t, "position", t - start >= tu.stationary_gps_time)
        else:
            self._stop_anchor = (east, north, 1, t)
            self._report_motion(t, "position", False)

    # -- IMU ------------------------------------------------------------------------------

    def update_imu(self, t: float, yaw_rate_measured: float, yaw: float | None = None,
                   roll: float | None = None, pitch: float | None = None) -> None:
        """Fuse a gyro yaw rate (rad/s, CCW positive, bias included) and optional attitude.

        ``yaw`` is an absolute ENU yaw (radians; :func:`enu_attitude_from_ned` converts
        the 3DM-GX1's), fused through a gate once the heading is known; ``roll`` and
        ``pitch`` (vehicle convention) are passed through to :meth:`transform`.

        Raises:
            ValueError: a value is not finite.
        """
        _finite("IMU sample", t, yaw_rate_measured)
        for name, value in (("yaw", yaw), ("roll", roll), ("pitch", pitch)):
            if value is not None:
                _finite(name, value)
        tu = self.tuning
        self.predict(t)
        if roll is not None:
            self._roll = roll
        if pitch is not None:
            self._pitch = pitch
        self._fidget(t, yaw_rate_measured)
        hm = np.zeros((1, STATE_SIZE))
        hm[0, IX_YAW_RATE] = hm[0, IX_BIAS] = 1.0
        y = np.array([yaw_rate_measured - self._x[IX_YAW_RATE] - self._x[IX_BIAS]])
        self._update(y, hm, np.array([[tu.gyro_rate_std ** 2]]), None)
        if self._stationary and self._speed_source_seen:
            # Not on GPS positions alone: a 1 m radius cannot tell a crawl from a stop.
            self._zero_velocity_update()
        if yaw is not None and self._heading_known:
            hm = np.zeros((1, STATE_SIZE))
            hm[0, IX_YAW] = 1.0
            y = np.array([wrap_angle(yaw + tu.imu_yaw_offset - self._x[IX_YAW])])
            if not self._update(y, hm, np.array([[tu.imu_yaw_std ** 2]]), self._gate1):
                self.imu_yaw_rejections += 1
                self._last_invalidating = t

    # -- odometry -------------------------------------------------------------------------

    def update_odometry(self, t: float, left_distance_m: float,
                        right_distance_m: float) -> bool:
        """Fuse cumulative front-wheel distances (m, forward positive).

        The first call only stores the distances; each later call uses the mean wheel
        speeds since the previous call. Returns False if nothing was fused (first call,
        time not advancing, or the gate rejected the wheel speeds).

        Raises:
            ValueError: a value is not finite.
        """
        _finite("odometry", t, left_distance_m, right_distance_m)
        tu = self.tuning
        previous = self._odometry
        if previous is not None and t <= previous[0]:
            return False
        self._odometry = (t, left_distance_m, right_distance_m)
        self.predict(t)
        if previous is None:
            return False
        dt = t - previous[0]
        sl = (left_distance_m - previous[1]) / dt
        sr = (right_distance_m - previous[2]) / dt
        self._speed_source_seen = True
        self._report_motion(t, "odometry", max(abs(sl), abs(sr)) < tu.stationary_speed)
        # A front wheel at (wheelbase, +-track/2) rolls at hypot(v -+ w track/2,
        # w wheelbase); strip the across part (w from the state, well known from the
        # gyro) so the measurement is linear in (v, w): along = v -+ w track/2.
        across = float(self._x[IX_YAW_RATE]) * tu.wheelbase
        along = np.array([math.copysign(math.sqrt(max(sl * sl - across * across, 0.0)), sl),
                          math.copysign(math.sqrt(max(sr * sr - across * across, 0.0)), sr)])
        half = 0.5 * tu.track_width
        hm = np.zeros((2, STATE_SIZE))
        hm[:, IX_SPEED] = 1.0
        hm[0, IX_YAW_RATE] = -half
        hm[1, IX_YAW_RATE] = half
        y = along - hm @ self._x
        r = np.diag([(tu.wheel_speed_std + tu.wheel_speed_scale_std * abs(sl)) ** 2,
                     (tu.wheel_speed_std + tu.wheel_speed_scale_std * abs(sr)) ** 2])
        if self._update(y, hm, r, self._gate2):
            return True
        self.odometry_rejections += 1
        return False


# --- raw pose (UseRawPose) ----------------------------------------------------------------

#: Longest time (s) a raw GPS fix is moved along its velocity to a pose's time stamp: two
#: of the receiver's 0.25 s epochs; past it (fixes lost) the position is held there.
RAW_EXTRAPOLATION_LIMIT = 0.5


class RawPose:
    """The unfiltered GPS/IMU solution for ``UseRawPose`` (seed §3.2.4, Table A.8).

    Position is the latest GPS fix (minus the antenna lever arm once a heading exists);
    heading comes from ``heading_source``: ``"gps"`` takes the GPS track whenever the
    speed is at least ``track_min_speed`` and holds the last one otherwise; ``"imu"``
    takes the IMU's absolute yaw. Roll and pitch pass through from the IMU.

    ``pose_valid`` is True with a fix and a heading, and, for the GPS source, only while
    the latest fix carried a usable track (stationary GPS heading is erratic: the seed's
    reason for the flag).

    **Time.** A fix is the position at its own time, and the receiver sends one every
    0.25 s while the pose is published on every IMU sample too (and stamped then).
    :meth:`transform` with ``at`` moves the fix along the receiver's own velocity (the
    speed and track of the same epoch) to time ``at``, by at most
    :data:`RAW_EXTRAPOLATION_LIMIT` seconds: without it a pose stamped 0.2 s after its
    fix placed the vehicle 0.3 m behind itself at 1.5 m/s, and every scan fused with
    such a pose landed that far behind the truth (decision 0025).

    Raises:
        ValueError: ``heading_source`` is not "gps" or "imu", or ``track_min_speed`` < 0.
    """

    def __init__(self, heading_source: Literal["gps", "imu"] = "gps",
                 track_min_speed: float = 1.0,
                 antenna_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        if heading_source not in ("gps", "imu"):
            raise ValueError(f"heading_source must be 'gps' or 'imu', got {heading_source!r}")
        if not (math.isfinite(track_min_speed) and track_min_speed >= 0.0):
            raise ValueError(f"track_min_speed must be >= 0, got {track_min_speed}")
        self.heading_source = heading_source
        self.track_min_speed = track_min_speed
        self.antenna_offset = antenna_offset
        self.time: float | None = None
        self._fix: tuple[float, float] | None = None
        self._fix_time: float | None = None
        self._fix_velocity = (0.0, 0.0)  # east, north m/s of the fix's epoch
        self._elevation: float | None = None
        self.heading: float | None = None
        """ENU yaw, radians, or None before the first heading."""
        self.speed = 0.0
        self._roll = 0.0
        self._pitch = 0.0
        self._fresh_heading = False

    def update_gps(self, t: float, east: float, north: float, speed: float | None = None,
                   track: float | None = None, elevation: float | None = None) -> None:
        """Take a GPS fix (UTM metres; speed m/s; track radians clockwise from north).

        Raises:
            ValueError: a value is not finite.
        """
        _finite("GPS fix", t, east, north)
        for value in (speed, track, elevation):
            if value is not None:
                _finite("GPS value", value)
        self.time = t
        self._fix = (east, north)
        self._fix_time = t
        if speed is not None and track is not None:
            self._fix_velocity = (speed * math.sin(track), speed * math.cos(track))
        else:
            self._fix_velocity = (0.0, 0.0)  # no velocity: the fix is held, not moved
        if elevation is not None:
            self._elevation = elevation
        if speed is not None:
            self.speed = speed
        if self.heading_source == "gps":
            self._fresh_heading = (track is not None and speed is not None
                                   and speed >= self.track_min_speed)
            if self._fresh_heading and track is not None:
                self.heading = enu_yaw_from_compass(track)

    def update_imu(self, t: float, yaw: float | None = None, roll: float | None = None,
                   pitch: float | None = None) -> None:
        """Take IMU attitude (vehicle/ENU convention, radians).

        Raises:
            ValueError: a value is not finite.
        """
        _finite("IMU time", t)
        for value in (yaw, roll, pitch):
            if value is not None:
                _finite("IMU angle", value)
        self.time = t
        if roll is not None:
            self._roll = roll
        if pitch is not None:
            self._pitch = pitch
        if self.heading_source == "imu" and yaw is not None:
            self.heading = wrap_angle(yaw)
            self._fresh_heading = True

    def _reference(self, at: float | None = None) -> tuple[float, float, float]:
        """East, north of the vehicle reference and the antenna's height above it."""
        assert self._fix is not None
        east, north = self._fix
        if at is not None and self._fix_time is not None:
            dt = min(max(at - self._fix_time, 0.0), RAW_EXTRAPOLATION_LIMIT)
            east += self._fix_velocity[0] * dt
            north += self._fix_velocity[1] * dt
        if self.heading is None:
            return east, north, self.antenna_offset[2]
        lever = self._lever()
        return east - lever[0], north - lever[1], float(lever[2])

    def _lever(self) -> FloatArray:
        """The antenna's offset from the vehicle reference in the world frame: the body
        offset turned by heading, pitch and roll (:func:`turned_lever`)."""
        return turned_lever(self.antenna_offset, self.heading or 0.0, self._pitch,
                            self._roll)

    @property
    def east(self) -> float:
        """Easting of the vehicle reference, m.

        Raises:
            PoseUnavailableError: no fix yet.
        """
        if self._fix is None:
            raise PoseUnavailableError("no GPS fix yet")
        return self._reference()[0]

    @property
    def north(self) -> float:
        """Northing of the vehicle reference, m.

        Raises:
            PoseUnavailableError: no fix yet.
        """
        if self._fix is None:
            raise PoseUnavailableError("no GPS fix yet")
        return self._reference()[1]

    @property
    def pose_valid(self) -> bool:
        """The poseValidFlag of the raw solution (rule in the class docstring)."""
        return self._fix is not None and self.heading is not None and self._fresh_heading

    def transform(self, initial_utm: Sequence[float], at: float | None = None) -> FloatArray:
        """^W T_V from the raw solution, translation measured from ``initial_utm``.

        With ``at`` (a time on the scale of the updates' ``t``) the position is the fix
        moved along its epoch's GPS velocity from the fix's time to ``at`` (not
        backwards, at most :data:`RAW_EXTRAPOLATION_LIMIT` s); without it, the fix.

        Raises:
            PoseUnavailableError: no GPS fix yet.
            ValueError: ``initial_utm`` is not three finite numbers, or ``at`` is not
                finite.
        """
        if self._fix is None:
            raise PoseUnavailableError("no GPS fix yet")
        if at is not None:
            _finite("at", at)
        east, north, height = self._reference(at)
        return _transform_from(initial_utm, east, north, self._elevation, height,
                               self.heading or 0.0, self._pitch, self._roll)

