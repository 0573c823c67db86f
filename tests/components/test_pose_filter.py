"""Tests for ModelServer's pose filter (components/model_server/pose_filter.py).

The synthetic drives compute the truth in closed form (a straight line with a speed
ramp, a circle about a fixed centre, the front wheels on their own circles) and corrupt
it with seeded noise; the filter never sees the truth. Conventions, checked against
scipy: ENU yaw counter-clockwise from east, compass clockwise from north, R = Rz Ry Rx.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from components.model_server.pose_filter import (
    IX_EAST,
    IX_NORTH,
    IX_SPEED,
    IX_YAW,
    IX_YAW_RATE,
    RAW_EXTRAPOLATION_LIMIT,
    PoseFilter,
    PoseFilterTuning,
    PoseUnavailableError,
    RawPose,
    chi2_quantile,
    compass_from_enu_yaw,
    ctrv_transition,
    enu_attitude_from_ned,
    enu_yaw_from_compass,
    homogeneous_transform,
    wrap_angle,
)

# Raptor geometry (docs/geometry.md, configs/bodies/raptor_chassis.xml).
WHEELBASE = 1.9
TRACK = 1.3
E0, N0 = 445_812.0, 5_029_377.0  # a UTM point near Ottawa (zone 18T)
ODO_LEFT0, ODO_RIGHT0 = 1234.5, 1230.25  # cumulative odometer at the start
TICK = 0.002  # odometer resolution, m (a 0.33 m wheel with ~1000 counts per turn)

GPS_STD = 0.3
VEL_STD = 0.05
GYRO_STD = 0.01
BIAS = 0.02

# truth(t) -> east, north, yaw (ENU), speed, yaw rate, left, right wheel distance
Truth = Callable[[float], tuple[float, float, float, float, float, float, float]]


def straight_truth(yaw: float = math.radians(30.0), start: float = 5.0,
                   stop: float | None = None) -> Truth:
    """Stand still until ``start``, accelerate at 1 m/s^2 to 2 m/s, cruise, and stop
    dead at ``stop`` (if given)."""
    c, s = math.cos(yaw), math.sin(yaw)

    def distance(t: float) -> tuple[float, float]:
        if t < start:
            return 0.0, 0.0
        if t < start + 2.0:
            return 0.5 * (t - start) ** 2, t - start
        return 2.0 + 2.0 * (t - start - 2.0), 2.0

    def truth(t: float) -> tuple[float, float, float, float, float, float, float]:
        d, v = distance(min(t, stop) if stop is not None else t)
        if stop is not None and t >= stop:
            v = 0.0
        return E0 + d * c, N0 + d * s, yaw, v, 0.0, ODO_LEFT0 + d, ODO_RIGHT0 + d

    return truth


def circle_truth(radius: float = 20.0, speed: float = 2.0) -> Truth:
    """Rear axle centre on a counter-clockwise circle; front wheels on their own radii."""
    w = speed / radius
    cx, cy = E0 - radius, N0
    r_left = math.hypot(WHEELBASE, radius - TRACK / 2)
    r_right = math.hypot(WHEELBASE, radius + TRACK / 2)

    def truth(t: float) -> tuple[float, float, float, float, float, float, float]:
        phi = w * t
        return (cx + radius * math.cos(phi), cy + radius * math.sin(phi),
                wrap_angle(phi + math.pi / 2), speed, w,
                ODO_LEFT0 + r_left * w * t, ODO_RIGHT0 + r_right * w * t)

    return truth


@dataclass
class Run:
    """What a simulation recorded at every IMU sample (10 Hz)."""

    t: list[float] = field(default_factory=list)
    pos_err: list[float] = field(default_factory=list)
    yaw_err: list[float] = field(default_factory=list)
    valid: list[bool] = field(default_factory=list)
    gps_accepted: dict[int, bool] = field(default_factory=dict)

    def rms_position(self, after: float) -> float:
        e = np.array([p for t, p in zip(self.t, self.pos_err, strict=True) if t > after])
        return float(np.sqrt(np.mean(e ** 2)))

    def rms_heading_deg(self, after: float) -> float:
        e = np.array([y for t, y in zip(self.t, self.yaw_err, strict=True) if t > after])
        return math.degrees(float(np.sqrt(np.mean(e ** 2))))


def simulate(pf: PoseFilter, truth: Truth, duration: float, seed: int, *,
             antenna: tuple[float, float] = (0.0, 0.0), gyro: bool = True,
             odometry: bool = True, gps_speed: bool = True,
             corrupt: Callable[[int, float, float, float], tuple[float, float]] | None = None,
             ) -> Run:
    """Drive ``truth`` for ``duration`` s: GPS 4 Hz, IMU 10 Hz, odometry 5 Hz."""
    rng = np.random.default_rng(seed)
    events: list[tuple[float, str, int]] = []
    events += [(k * 0.25 + 0.013, "gps", k) for k in range(int(duration / 0.25))]
    events += [(k * 0.1 + 0.004, "imu", k) for k in range(int(duration / 0.1))]
    events += [(k * 0.2 + 0.009, "odo", k) for k in range(int(duration / 0.2))]
    events.sort()
    ax, ay = antenna
    run = Run()
    for t, kind, k in events:
        e, n, yaw, v, w, left, right = truth(t)
        c, s = math.cos(yaw), math.sin(yaw)
        if kind == "gps":
            ge = e + c * ax - s * ay + rng.normal(0.0, GPS_STD)
            gn = n + s * ax + c * ay + rng.normal(0.0, GPS_STD)
            if corrupt is not None:
                ge, gn = corrupt(k, t, ge, gn)
            # antenna velocity: v along the heading plus w x (R a), then Doppler noise
            ve = v * c + w * (-s * ax - c * ay) + rng.normal(0.0, VEL_STD)
            vn = v * s + w * (c * ax - s * ay) + rng.normal(0.0, VEL_STD)
            speed = math.hypot(ve, vn)
            track = (math.pi / 2 - math.atan2(vn, ve)) % (2 * math.pi)
            if gps_speed:
                run.gps_accepted[k] = pf.update_gps(t, ge, gn, GPS_STD, speed=speed,
                                                    track=track)
            else:
                run.gps_accepted[k] = pf.update_gps(t, ge, gn, GPS_STD)
        elif kind == "odo" and odometry:
            # encoders count whole ticks: quantise the cumulative distances
            pf.update_odometry(t, math.floor(left / TICK) * TICK,
                               math.floor(right / TICK) * TICK)
        elif kind == "imu":
            if gyro:
                pf.update_imu(t, w + BIAS + rng.normal(0.0, GYRO_STD))
            else:
                pf.predict(t)
            run.t.append(t)
            run.valid.append(pf.pose_valid)
            run.pos_err.append(math.hypot(pf.east - e, pf.north - n)
                               if pf.position_known else math.inf)
            run.yaw_err.append(wrap_angle(pf.heading - yaw))
    return run


# --- conventions and helpers --------------------------------------------------------------

@pytest.mark.parametrize("dof", [1, 2])
@pytest.mark.parametrize("p", [0.9, 0.95, 0.99, 0.999])
def test_chi2_quantile_matches_scipy(p: float, dof: int) -> None:
    assert chi2_quantile(p, dof) == pytest.approx(chi2.ppf(p, dof), rel=1e-9)


def test_chi2_quantile_rejects_bad_arguments() -> None:
    with pytest.raises(ValueError):
        chi2_quantile(1.0, 2)
    with pytest.raises(ValueError):
        chi2_quantile(0.99, 3)


@pytest.mark.parametrize(("compass_deg", "enu_deg"), [
    (0.0, 90.0), (90.0, 0.0), (180.0, -90.0), (270.0, -180.0), (45.0, 45.0), (315.0, 135.0),
])
def test_compass_and_enu_yaw(compass_deg: float, enu_deg: float) -> None:
    yaw = enu_yaw_from_compass(math.radians(compass_deg))
    assert yaw == pytest.approx(math.radians(enu_deg))
    assert -math.pi <= yaw < math.pi
    assert math.degrees(compass_from_enu_yaw(yaw)) == pytest.approx(compass_deg)


def test_ned_attitude_conversion_matches_frame_change() -> None:
    # R_enu<-flu = T_enu<-ned . R_ned<-frd . T_frd<-flu, with the axis swaps by hand.
    t_enu_ned = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    t_frd_flu = np.diag([1.0, -1.0, -1.0])
    for roll, pitch, yaw in [(0.1, 0.2, 0.3), (-0.3, 0.15, 2.5), (0.05, -0.4, -1.2)]:
        r_ned = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
        expected = t_enu_ned @ r_ned @ t_frd_flu
        er, ep, ey = enu_attitude_from_ned(roll, pitch, yaw)
        got = Rotation.from_euler("ZYX", [ey, ep, er]).as_matrix()
        np.testing.assert_allclose(got, expected, atol=1e-12)


def test_homogeneous_transform_matches_scipy() -> None:
    m = homogeneous_transform(1.0, 2.0, 3.0, yaw=0.7, pitch=-0.2, roll=0.1)
    np.testing.assert_allclose(
        m[:3, :3], Rotation.from_euler("ZYX", [0.7, -0.2, 0.1]).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(m[:3, 3], [1.0, 2.0, 3.0])
    np.testing.assert_allclose(m[3], [0.0, 0.0, 0.0, 1.0])


def test_ctrv_follows_the_exact_circle() -> None:
    # Start at (20, 0) heading north (ENU yaw 90 deg), 2 m/s, 0.1 rad/s: centre (0, 0).
    x0 = np.array([20.0, 0.0, math.pi / 2, 2.0, 0.1, 0.0])
    x1, _ = ctrv_transition(x0, 5.0)
    np.testing.assert_allclose(x1[:2], [20.0 * math.cos(0.5), 20.0 * math.sin(0.5)],
                               atol=1e-12)
    assert x1[IX_YAW] == pytest.approx(math.pi / 2 + 0.5)
    straight, _ = ctrv_transition(np.array([0.0, 0.0, 0.0, 2.0, 0.0, 0.0]), 3.0)
    np.testing.assert_allclose(straight[:3], [6.0, 0.0, 0.0], atol=1e-12)


@pytest.mark.parametrize("w", [0.3, 1e-2, 1e-6, 0.0])
def test_ctrv_jacobian_matches_finite_differences(w: float) -> None:
    x0 = np.array([3.0, -2.0, 0.8, 2.5, w, 0.01])
    _, jac = ctrv_transition(x0, 0.1)
    numeric = np.zeros((6, 6))
    eps = 1e-6
    for j in range(6):
        dx = np.zeros(6)
        dx[j] = eps
        plus, _ = ctrv_transition(x0 + dx, 0.1)
        minus, _ = ctrv_transition(x0 - dx, 0.1)
        numeric[:, j] = (plus - minus) / (2 * eps)
    np.testing.assert_allclose(jac, numeric, atol=1e-6)


def test_tuning_rejects_bad_values() -> None:
    with pytest.raises(ValueError):
        PoseFilterTuning(gyro_rate_std=0.0)
    with pytest.raises(ValueError):
        PoseFilterTuning(gate_probability=1.5)
    with pytest.raises(ValueError):
        PoseFilterTuning(fidget_period=-1.0)


def test_bad_measurements_raise() -> None:
    pf = PoseFilter()
    with pytest.raises(ValueError):
        pf.update_gps(0.0, E0, N0, 0.0)
    with pytest.raises(ValueError):
        pf.update_gps(0.0, math.nan, N0, 0.3)
    with pytest.raises(ValueError):
        pf.update_gps(0.0, E0, N0, 0.3, speed=-1.0)
    with pytest.raises(ValueError):
        pf.update_imu(0.0, math.inf)


# --- transform and pose output -------------------------------------------------------------

def test_transform_is_pose_from_initial_utm() -> None:
    pf = PoseFilter()
    with pytest.raises(PoseUnavailableError):
        pf.transform((E0, N0, 70.0))
    pf.initialise(0.0, E0 + 12.0, N0 - 5.0, enu_yaw_from_compass(0.0), 0.1, 0.01)
    pf.update_imu(0.0, 0.0, roll=0.05, pitch=-0.03)
    pf.update_gps(0.0, E0 + 12.0, N0 - 5.0, 0.1, elevation=81.5)
    m = pf.transform((E0, N0, 80.0))
    np.testing.assert_allclose(m[:3, 3], [12.0, -5.0, 1.5], atol=1e-9)
    # heading north: the vehicle's x axis (forward) points north, y (left) west
    np.testing.assert_allclose(
        m[:3, :3], Rotation.from_euler("ZYX", [math.pi / 2, -0.03, 0.05]).as_matrix(),
        atol=1e-9)
    level = homogeneous_transform(0, 0, 0, pf.heading)
    np.testing.assert_allclose(level[:3, 0], [0.0, 1.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(level[:3, 1], [-1.0, 0.0, 0.0], atol=1e-9)
    with pytest.raises(ValueError):
        pf.transform((E0, N0))


def test_late_measurement_is_counted_not_predicted_backwards() -> None:
    pf = PoseFilter()
    pf.initialise(10.0, E0, N0, 0.0, 0.1, 0.01)
    pf.update_imu(9.5, 0.0)
    assert pf.late_measurements == 1
    assert pf.time == 10.0


# --- synthetic drives -------------------------------------------------------------------

def test_straight_drive_accuracy_and_validity() -> None:
    pf = PoseFilter()
    run = simulate(pf, straight_truth(), 70.0, seed=1)
    assert run.rms_position(after=20.0) < 0.3
    assert run.rms_heading_deg(after=20.0) < 2.0
    # before the first fix (t = 0.004) and while standing at the start: not valid
    assert run.t[0] < 0.013 and not run.valid[0]
    assert not any(v for t, v in zip(run.t, run.valid, strict=True) if t < 5.0)
    # valid once the heading is observable from the motion
    late = [v for t, v in zip(run.t, run.valid, strict=True) if t > 15.0]
    assert sum(late) >= 0.95 * len(late)
    assert pf.gyro_bias == pytest.approx(BIAS, abs=0.004)
    assert pf.speed == pytest.approx(2.0, abs=0.1)


@pytest.mark.parametrize("antenna", [(0.0, 0.0), (0.9, 0.0)])
def test_circular_drive_accuracy(antenna: tuple[float, float]) -> None:
    pf = PoseFilter(PoseFilterTuning(antenna_offset=(antenna[0], antenna[1], 0.0)))
    run = simulate(pf, circle_truth(), 90.0, seed=2, antenna=antenna)
    assert run.rms_position(after=20.0) < 0.3
    assert run.rms_heading_deg(after=20.0) < 2.0
    assert pf.yaw_rate == pytest.approx(0.1, abs=0.01)
    assert pf.gyro_bias == pytest.approx(BIAS, abs=0.004)
    assert pf.pose_valid


def test_circle_heading_from_gps_displacement_without_speed_or_track() -> None:
    # No GPS velocity: the heading comes from the displacement between fixes.
    pf = PoseFilter()
    run = simulate(pf, circle_truth(), 60.0, seed=3, gps_speed=False)
    assert pf.heading_known
    assert run.rms_position(after=30.0) < 0.3
    assert run.rms_heading_deg(after=30.0) < 2.0


def test_odometry_difference_gives_yaw_rate_without_gyro() -> None:
    pf = PoseFilter()
    simulate(pf, circle_truth(), 40.0, seed=4, gyro=False)
    assert pf.yaw_rate == pytest.approx(0.1, abs=0.02)
    assert pf.speed == pytest.approx(2.0, abs=0.05)


def test_gps_outliers_are_rejected() -> None:
    jumps = {k: (10.0 * math.cos(k), 10.0 * math.sin(k)) for k in range(100, 280, 30)}

    def corrupt(k: int, t: float, e: float, n: float) -> tuple[float, float]:
        dx, dy = jumps.get(k, (0.0, 0.0))
        return e + dx, n + dy

    pf = PoseFilter()
    run = simulate(pf, straight_truth(), 75.0, seed=5, corrupt=corrupt)
    assert all(not run.gps_accepted[k] for k in jumps)
    assert len(jumps) <= pf.gps_rejections <= len(jumps) + 2
    assert pf.gps_resets == 0
    assert run.rms_position(after=20.0) < 0.3
    # the flag drops right after each rejected fix (next IMU sample)
    for k in jumps:
        t_fix = k * 0.25 + 0.013
        after = next(v for t, v in zip(run.t, run.valid, strict=True) if t > t_fix)
        assert not after


def test_persistent_gps_jump_resets_after_a_rejected_burst() -> None:
    def corrupt(k: int, t: float, e: float, n: float) -> tuple[float, float]:
        return (e + 15.0, n) if t > 40.0 else (e, n)

    pf = PoseFilter(PoseFilterTuning(max_consecutive_rejections=8))
    truth = straight_truth()
    simulate(pf, truth, 60.0, seed=6, corrupt=corrupt)
    assert pf.gps_resets == 1
    assert pf.gps_rejections >= 8
    e, n, *_ = truth(pf.time or 0.0)
    assert math.hypot(pf.east - (e + 15.0), pf.north - n) < 1.0
    assert pf.pose_valid


def test_fidget_captures_the_gyro_bias_while_stationary() -> None:
    pf = PoseFilter(PoseFilterTuning(fidget_delay=20.0, fidget_period=5.0))
    run = simulate(pf, straight_truth(start=1e9), 60.0, seed=7)
    assert pf.stationary
    # delay 20 s then a capture every 5 s until 60 s
    assert 7 <= pf.fidget_count <= 8
    assert pf.fidget_bias is not None
    assert abs(pf.fidget_bias - BIAS) < 0.1 * BIAS
    assert abs(pf.gyro_bias - BIAS) < 0.1 * BIAS
    # erratic GPS tracks of a standing receiver never gave a heading; never valid
    assert not pf.heading_known
    assert not any(run.valid)


def test_fidget_waits_for_the_delay_and_stops_when_moving() -> None:
    pf = PoseFilter(PoseFilterTuning(fidget_delay=20.0, fidget_period=5.0))
    simulate(pf, straight_truth(start=24.0), 24.0, seed=8)
    assert pf.fidget_count == 0  # 20 s delay + 5 s period not reached by 24 s
    pf2 = PoseFilter(PoseFilterTuning(fidget_delay=20.0, fidget_period=5.0))
    simulate(pf2, straight_truth(start=28.0), 60.0, seed=8)
    assert pf2.fidget_count == 1  # one capture at ~25 s, none after moving at 28 s
    assert not pf2.stationary


def test_stop_after_driving_keeps_heading_and_validity() -> None:
    pf = PoseFilter(PoseFilterTuning(fidget_delay=5.0, fidget_period=10.0))
    run = simulate(pf, straight_truth(start=2.0, stop=30.0), 90.0, seed=9)
    assert pf.stationary
    assert pf.fidget_count >= 4
    assert run.rms_heading_deg(after=30.0) < 2.0
    assert run.rms_position(after=30.0) < 0.3
    assert pf.pose_valid
    assert abs(pf.speed) < 0.05


def test_estimate_snapshot() -> None:
    pf = PoseFilter()
    simulate(pf, circle_truth(), 30.0, seed=10)
    est = pf.estimate()
    assert est.east == pf.east and est.north == pf.north
    assert est.covariance.shape == (6, 6)
    np.testing.assert_allclose(est.covariance, est.covariance.T)
    assert np.all(np.linalg.eigvalsh(est.covariance) > 0.0)
    assert est.position_std < 0.3
    assert est.heading_std < math.radians(2.0)
    assert est.compass_heading == pytest.approx(compass_from_enu_yaw(est.heading))
    est.covariance[0, 0] = 99.0
    assert pf.covariance[IX_EAST, IX_EAST] != 99.0
    assert pf.covariance[IX_NORTH, IX_NORTH] < 1.0
    assert pf.covariance[IX_SPEED, IX_SPEED] < 0.1
    assert pf.covariance[IX_YAW_RATE, IX_YAW_RATE] < 0.01


# --- raw pose (UseRawPose) -------------------------------------------------------------------

def test_raw_pose_gps_heading_only_when_moving() -> None:
    raw = RawPose(track_min_speed=1.0, antenna_offset=(0.9, 0.0, 1.75))
    with pytest.raises(PoseUnavailableError):
        raw.transform((E0, N0, 80.0))
    raw.update_gps(0.0, E0 + 10.0, N0 + 20.0, speed=0.05, track=math.radians(123.0),
                   elevation=82.0)
    assert raw.heading is None and not raw.pose_valid
    assert raw.east == E0 + 10.0  # no heading: no lever-arm correction
    raw.update_gps(1.0, E0 + 10.0, N0 + 20.0, speed=2.0, track=math.radians(90.0),
                   elevation=82.0)
    assert raw.pose_valid
    assert raw.heading == pytest.approx(0.0)  # due east
    raw.update_imu(1.0, roll=0.02, pitch=0.01)
    m = raw.transform((E0, N0, 80.0))
    # antenna 0.9 m ahead of and 1.75 m above the reference: the reference is about
    # 0.9 m west of the fix and 1.75 m below it, the lever arm turned by the attitude
    lever = Rotation.from_euler("ZYX", [0.0, 0.01, 0.02]).apply([0.9, 0.0, 1.75])
    np.testing.assert_allclose(m[:3, 3], np.array([10.0, 20.0, 2.0]) - lever, atol=1e-9)
    assert m[0, 3] == pytest.approx(9.1, abs=0.02)
    np.testing.assert_allclose(
        m[:3, :3], Rotation.from_euler("ZYX", [0.0, 0.01, 0.02]).as_matrix(), atol=1e-12)
    raw.update_gps(2.0, E0 + 11.0, N0 + 20.0, speed=0.1, track=math.radians(300.0))
    assert raw.heading == pytest.approx(0.0)  # held, stationary track ignored
    assert not raw.pose_valid


def test_raw_pose_moves_the_fix_to_the_stamp_along_the_gps_velocity() -> None:
    # a fix at t = 10 s, 2 m/s on a track of 30 degrees (clockwise from north)
    raw = RawPose(heading_source="imu")
    raw.update_gps(10.0, E0 + 5.0, N0 - 3.0, speed=2.0, track=math.radians(30.0),
                   elevation=81.0)
    raw.update_imu(10.1, yaw=math.radians(60.0))
    utm = (E0, N0, 80.0)
    np.testing.assert_allclose(raw.transform(utm)[:2, 3], [5.0, -3.0], atol=1e-9)
    np.testing.assert_allclose(raw.transform(utm, at=10.0)[:2, 3], [5.0, -3.0], atol=1e-9)
    # 0.2 s later: 0.4 m along the track, 0.2 m east and 0.3464 m north
    np.testing.assert_allclose(raw.transform(utm, at=10.2)[:2, 3], [5.2, -3.0 + 0.34641],
                               atol=1e-5)
    # not backwards, and held after RAW_EXTRAPOLATION_LIMIT (fixes lost)
    np.testing.assert_allclose(raw.transform(utm, at=9.0)[:2, 3], [5.0, -3.0], atol=1e-9)
    far = [5.0 + 2.0 * 0.5 * RAW_EXTRAPOLATION_LIMIT,
           -3.0 + 2.0 * math.cos(math.radians(30.0)) * RAW_EXTRAPOLATION_LIMIT]
    np.testing.assert_allclose(raw.transform(utm, at=30.0)[:2, 3], far, atol=1e-9)
    # the rotation and height do not depend on the stamp
    np.testing.assert_allclose(raw.transform(utm, at=10.2)[:3, :3],
                               raw.transform(utm)[:3, :3], atol=1e-12)
    assert raw.transform(utm, at=10.2)[2, 3] == pytest.approx(1.0)
    # a fix without velocity is held
    raw.update_gps(11.0, E0, N0)
    np.testing.assert_allclose(raw.transform(utm, at=11.3)[:2, 3], [0.0, 0.0], atol=1e-9)
    with pytest.raises(ValueError):
        raw.transform(utm, at=math.nan)


def test_raw_pose_imu_heading() -> None:
    raw = RawPose(heading_source="imu")
    raw.update_gps(0.0, E0, N0)
    assert not raw.pose_valid
    raw.update_imu(0.1, yaw=1.0)
    assert raw.pose_valid and raw.heading == pytest.approx(1.0)
    bad: Any = "compass"
    with pytest.raises(ValueError):
        RawPose(heading_source=bad)


def test_stationary_from_gps_positions_alone() -> None:
    # No GPS speed, no odometry: fixes staying within stationary_radius mean stopped.
    pf = PoseFilter(PoseFilterTuning(fidget_delay=5.0, fidget_period=5.0))
    run = simulate(pf, straight_truth(start=30.0), 40.0, seed=11, odometry=False,
                   gps_speed=False)
    assert pf.fidget_count >= 3
    assert pf.fidget_bias is not None and abs(pf.fidget_bias - BIAS) < 0.1 * BIAS
    assert not pf.stationary  # moving since 30 s
    assert run.pos_err[-1] < 1.0


@pytest.mark.parametrize("yaw,pitch,roll", [(0.3, 0.0, 0.0), (0.3, math.radians(13.0), 0.0),
                                            (-2.0, math.radians(-9.0), math.radians(7.0)),
                                            (1.2, math.radians(4.0), math.radians(-12.0))])
def test_raw_pose_takes_the_whole_attitude_out_of_the_antenna_lever_arm(yaw, pitch, roll):
    # the antenna 0.9 m ahead of and 1.75 m above the rear axle (the Raptor's); on a
    # slope it leans downhill of the axle: a heading-only lever arm put the pose 0.39 m
    # off on a 13° slope. The oracle is scipy's rotation, intrinsic z-y'-x''.
    offset = np.array([0.9, 0.0, 1.75])
    raw = RawPose("imu", antenna_offset=tuple(offset))
    axle = np.array([500_100.0, 5_500_200.0, 812.0])
    antenna = axle + Rotation.from_euler("ZYX", [yaw, pitch, roll]).apply(offset)
    raw.update_imu(0.0, yaw=yaw, roll=roll, pitch=pitch)
    raw.update_gps(0.0, float(antenna[0]), float(antenna[1]), elevation=float(antenna[2]))
    pose = raw.transform((500_000.0, 5_500_000.0, 800.0))
    assert pose[:3, 3] == pytest.approx(axle - np.array([500_000.0, 5_500_000.0, 800.0]),
                                        abs=1e-9)


@pytest.mark.parametrize("yaw,pitch,roll", [(0.3, math.radians(13.0), 0.0),
                                            (-2.0, math.radians(-9.0), math.radians(7.0))])
def test_the_filter_takes_the_whole_attitude_out_of_the_antenna_lever_arm(yaw, pitch, roll):
    """The EKF (UseRawPose false) on a slope: fixes of the antenna of a vehicle standing
    still with a known heading converge on the rear axle, not on a point 0.39 m uphill
    of it (a level lever arm). The oracle is scipy's rotation, intrinsic z-y'-x''."""
    offset = np.array([0.9, 0.0, 1.75])
    pf = PoseFilter(PoseFilterTuning(antenna_offset=tuple(offset)))
    utm = np.array([500_000.0, 5_500_000.0, 800.0])
    axle = np.array([500_100.0, 5_500_200.0, 812.0])
    antenna = axle + Rotation.from_euler("ZYX", [yaw, pitch, roll]).apply(offset)
    pf.initialise(0.0, float(axle[0]), float(axle[1]), yaw, position_std=1.0,
                  heading_std=0.01)
    for k in range(1, 41):
        t = 0.25 * k
        pf.update_imu(t, 0.0, yaw=yaw, roll=roll, pitch=pitch)
        pf.update_gps(t, float(antenna[0]), float(antenna[1]), 0.05,
                      elevation=float(antenna[2]))
    pose = pf.transform(tuple(utm))
    assert pose[:3, 3] == pytest.approx(axle - utm, abs=0.01)
