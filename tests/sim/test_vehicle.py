"""Vehicle model: exact arcs, wheel odometry, limits, lags, terrain attitude, collisions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from afa.sim import (
    GRAVITY,
    Obstacle,
    Terrain,
    TerrainSpec,
    Vehicle,
    VehicleParameters,
    VehicleState,
)

L, W = 1.9, 1.3
FLAT = TerrainSpec(width=60, depth=40, resolution=0.1)


def arc_end(e0: float, n0: float, heading_deg: float, v: float, steer_deg: float,
            t: float) -> tuple[float, float, float]:
    """Closed-form end of a constant-curvature drive, by hand: (east, north, yaw)."""
    yaw0 = math.radians(90 - heading_deg)
    radius = L / math.tan(math.radians(steer_deg))  # signed: + = centre to the left
    ce = e0 - radius * math.sin(yaw0)
    cn = n0 + radius * math.cos(yaw0)
    yaw = yaw0 + v * t / radius
    return ce + radius * math.sin(yaw), cn - radius * math.cos(yaw), yaw


@pytest.mark.parametrize(("steer", "speed"), [(10.0, 1.5), (-25.0, 2.0), (30.0, 0.7), (12.0, -0.8)])
def test_constant_command_drives_the_exact_arc(steer: float, speed: float) -> None:
    vehicle = Vehicle()
    vehicle.reset(3.0, -2.0, 30.0, speed=speed, steering_deg=steer)
    for _ in range(100):
        vehicle.step(0.05, speed, steer)
    e, n, yaw = arc_end(3.0, -2.0, 30.0, speed, steer, 5.0)
    s = vehicle.state
    assert s.time == pytest.approx(5.0, abs=1e-12)
    assert s.east == pytest.approx(e, abs=1e-9)
    assert s.north == pytest.approx(n, abs=1e-9)
    assert math.cos(s.yaw - yaw) == pytest.approx(1.0, abs=1e-15)
    assert s.heading_deg == pytest.approx((90 - math.degrees(yaw)) % 360, abs=1e-7)
    assert s.yaw_rate == pytest.approx(speed * math.tan(math.radians(steer)) / L, abs=1e-9)
    assert s.distance == pytest.approx(speed * 5.0, abs=1e-9)


def test_straight_line() -> None:
    vehicle = Vehicle()
    vehicle.reset(0.0, 0.0, 45.0, speed=2.0)
    for _ in range(10):
        vehicle.step(0.5, 2.0, 0.0)
    d = 10.0 / math.sqrt(2)
    assert (vehicle.state.east, vehicle.state.north) == pytest.approx((d, d), abs=1e-9)
    s = vehicle.state
    assert s.front_left_distance == pytest.approx(10.0, abs=1e-9)
    assert s.rear_right_distance == pytest.approx(10.0, abs=1e-9)


def test_backing_counts_down_the_odometer_but_adds_to_the_distance_driven() -> None:
    # 10 s forwards at 1 m/s, then as long backwards: the encoders' signed distance
    # returns to about 0, the distance driven (what a mission's path ratio counts) is
    # about 20 m
    vehicle = Vehicle()
    vehicle.reset(0.0, 0.0, 90.0)
    for speed in (1.0, -1.0):
        for _ in range(200):
            vehicle.step(0.05, speed, 0.0)
        for _ in range(100):  # come to rest
            vehicle.step(0.05, 0.0, 0.0)
    s = vehicle.state
    assert abs(s.east) < 0.05 and s.speed == 0.0
    assert abs(s.distance) < 0.05
    assert s.travelled == pytest.approx(20.0, rel=0.02)


def test_wheel_distances_on_an_arc() -> None:
    steer, v, t = 20.0, 1.5, 4.0
    vehicle = Vehicle()
    vehicle.reset(0.0, 0.0, 0.0, speed=v, steering_deg=steer)
    for _ in range(80):
        vehicle.step(0.05, v, steer)
    r = L / math.tan(math.radians(steer))
    turned = v * t / r
    # each wheel's radius about the turn centre, by hand (left turn: left wheels inside)
    s = vehicle.state
    assert s.rear_left_distance == pytest.approx(turned * (r - W / 2), abs=1e-9)
    assert s.rear_right_distance == pytest.approx(turned * (r + W / 2), abs=1e-9)
    assert s.front_left_distance == pytest.approx(turned * math.hypot(L, r - W / 2), abs=1e-9)
    assert s.front_right_distance == pytest.approx(turned * math.hypot(L, r + W / 2), abs=1e-9)


def test_steering_and_speed_limits() -> None:
    vehicle = Vehicle()
    vehicle.reset(0.0, 0.0, 0.0)
    for _ in range(400):
        vehicle.step(0.05, 5.0, 45.0)
    s = vehicle.state
    assert s.speed == pytest.approx(2.0, abs=1e-6)
    assert s.steering_deg == pytest.approx(30.0, abs=1e-6)
    assert s.yaw_rate == pytest.approx(2.0 * math.tan(math.radians(30)) / L, abs=1e-5)
    for _ in range(400):
        vehicle.step(0.05, -5.0, -45.0)
    assert vehicle.state.speed == pytest.approx(-1.0, abs=1e-6)  # max reverse speed
    assert vehicle.state.steering_deg == pytest.approx(-30.0, abs=1e-6)


def test_acceleration_limit() -> None:
    vehicle = Vehicle()
    vehicle.reset(0.0, 0.0, 0.0)
    speeds = []
    for _ in range(10):
        speeds.append(vehicle.step(0.05, 2.0, 0.0).speed)
    # 1 m/s^2 from rest: 0.05 m/s per step while the lag asks for more
    np.testing.assert_allclose(speeds, 0.05 * np.arange(1, 11), atol=1e-12)
    assert vehicle.state.longitudinal_acceleration == pytest.approx(1.0)


def test_first_order_lags() -> None:
    fast = VehicleParameters(max_acceleration=100.0, max_deceleration=100.0)
    vehicle = Vehicle(fast)
    vehicle.reset(0.0, 0.0, 0.0)
    for _ in range(10):
        vehicle.step(0.05, 1.0, 20.0)
    s = vehicle.state
    assert s.speed == pytest.approx(1.0 - math.exp(-0.5 / 0.5), abs=1e-12)
    assert s.steering_deg == pytest.approx(20.0 * (1 - math.exp(-0.5 / 0.3)), abs=1e-10)


def test_stopping_comes_to_rest() -> None:
    vehicle = Vehicle()
    vehicle.reset(0.0, 0.0, 0.0, speed=2.0)
    for _ in range(100):
        vehicle.step(0.05, 0.0, 0.0)
    assert vehicle.state.speed == 0.0
    assert vehicle.step(1.0, 0.0, 0.0).north == vehicle.state.north


def test_attitude_follows_the_slope() -> None:
    slope = Terrain.from_spec(TerrainSpec(width=60, depth=40, resolution=0.1, slope_east=0.1))
    vehicle = Vehicle()
    up_east = vehicle.reset(0.0, 0.0, 90.0, terrain=slope)   # facing uphill
    assert up_east.pitch == pytest.approx(-math.atan(0.1), abs=1e-6)  # nose up is negative
    assert up_east.roll == pytest.approx(0.0, abs=1e-9)
    assert up_east.up == pytest.approx(0.33, abs=1e-6)
    north = vehicle.reset(5.0, 0.0, 0.0, terrain=slope)      # facing north: west is left
    assert north.roll == pytest.approx(-math.atan(0.1), abs=1e-6)  # left side down
    assert north.pitch == pytest.approx(0.0, abs=1e-9)
    assert north.up == pytest.approx(0.5 + 0.33, abs=1e-6)
    # an accelerometer at rest facing uphill reads +g sin(theta) forward
    force = up_east.specific_force_body()
    sin_t = 0.1 / math.sqrt(1.01)
    assert force == pytest.approx([GRAVITY * sin_t, 0.0, GRAVITY * math.sqrt(1 - sin_t**2)],
                                  abs=1e-6)
    # the body x axis points up the slope
    forward = up_east.rotation() @ np.array([1.0, 0.0, 0.0])
    assert forward == pytest.approx([1 / math.sqrt(1.01), 0.0, 0.1 / math.sqrt(1.01)], abs=1e-6)


def test_level_rest_reads_gravity_and_no_rotation() -> None:
    state = Vehicle().reset(0.0, 0.0, 123.0, terrain=Terrain.from_spec(FLAT))
    assert state.specific_force_body() == pytest.approx([0, 0, GRAVITY])
    assert state.angular_velocity_body() == pytest.approx([0, 0, 0])
    assert state.transform()[:3, 3] == pytest.approx([0, 0, 0.33])


def drive_until_stopped(vehicle: Vehicle, terrain: Terrain, seconds: float) -> None:
    for _ in range(int(seconds / 0.05)):
        vehicle.step(0.05, 1.5, 0.0, terrain)


def test_collision_with_a_box_stops_the_vehicle() -> None:
    # heading 90: 1 m along east, so the west face is at east = 9.5
    box = Obstacle("box", east=10, north=0, length=1, width=4, height=1.0, heading=90)
    terrain = Terrain.from_spec(FLAT, [box])
    vehicle = Vehicle()
    vehicle.reset(0.0, 0.0, 90.0, speed=1.5, terrain=terrain)
    drive_until_stopped(vehicle, terrain, 10.0)
    hit = vehicle.collision
    assert hit is not None and hit.kind == "obstacle" and hit.obstacle == 0
    # the front bumper (2.45 m ahead of the rear axle) touched the face at 9.5
    assert vehicle.state.east == pytest.approx(9.5 - 2.45, abs=0.1 + terrain.resolution)
    assert hit.east == pytest.approx(9.5, abs=terrain.resolution)
    assert hit.time == pytest.approx((9.5 - 2.45) / 1.5, abs=0.1)
    stopped = vehicle.state
    assert stopped.speed == 0.0
    vehicle.step(1.0, 1.5, 0.0, terrain)  # further motion is refused
    assert (vehicle.state.east, vehicle.state.speed) == (stopped.east, 0.0)
    assert vehicle.state.time == pytest.approx(stopped.time + 1.0)
    vehicle.reset(0.0, 0.0, 270.0, terrain=terrain)  # a reset clears it
    assert vehicle.collision is None
    vehicle.step(1.0, 1.5, 0.0, terrain)
    assert vehicle.state.east < 0


def test_low_step_is_climbed() -> None:
    step = Obstacle("box", east=10, north=0, length=2, width=4, height=0.2, heading=90)
    terrain = Terrain.from_spec(FLAT, [step])
    vehicle = Vehicle()
    vehicle.reset(0.0, 0.0, 90.0, speed=1.5, terrain=terrain)
    pitches = []
    for _ in range(200):
        pitches.append(vehicle.step(0.05, 1.5, 0.0, terrain).pitch)
    assert vehicle.collision is None
    assert vehicle.state.east > 14
    assert min(pitches) < -0.05  # nose up while the front wheels are on the step


def test_collision_with_a_ditch() -> None:
    # heading 0: 10 m along north, 1.5 m wide across the vehicle's path; west edge 9.25
    ditch = Obstacle("ditch", east=10, north=0, length=10, width=1.5, depth=0.8, heading=0)
    terrain = Terrain.from_spec(FLAT, [ditch])
    vehicle = Vehicle()
    vehicle.reset(0.0, 0.0, 90.0, speed=1.5, terrain=terrain)
    drive_until_stopped(vehicle, terrain, 10.0)
    hit = vehicle.collision
    assert hit is not None and hit.kind == "ditch" and hit.obstacle == 0
    # the front wheels (1.9 m ahead) went over the edge at 9.25
    assert vehicle.state.east == pytest.approx(9.25 - 1.9, abs=0.1 + terrain.resolution)


def test_shallow_ditch_is_crossed() -> None:
    ditch = Obstacle("ditch", east=10, north=0, length=10, width=1.5, depth=0.2, heading=0)
    terrain = Terrain.from_spec(FLAT, [ditch])
    vehicle = Vehicle()
    vehicle.reset(0.0, 0.0, 90.0, speed=1.5, terrain=terrain)
    drive_until_stopped(vehicle, terrain, 10.0)
    assert vehicle.collision is None and vehicle.state.east > 14


def test_boundary() -> None:
    terrain = Terrain.from_spec(FLAT)
    vehicle = Vehicle()
    vehicle.reset(20.0, 0.0, 90.0, speed=1.5, terrain=terrain)
    drive_until_stopped(vehicle, terrain, 10.0)
    hit = vehicle.collision
    assert hit is not None and hit.kind == "boundary" and hit.obstacle == -1
    assert hit.east == pytest.approx(30.0, abs=0.1)


def test_large_steps_do_not_tunnel_through_thin_posts() -> None:
    post = Obstacle("cylinder", east=10, north=0, radius=0.1, height=1.0)
    terrain = Terrain.from_spec(FLAT, [post])
    vehicle = Vehicle()
    vehicle.reset(0.0, 0.0, 90.0, speed=2.0, terrain=terrain)
    vehicle.step(10.0, 2.0, 0.0, terrain)  # one call, 20 m of travel
    assert vehicle.collision is not None and vehicle.collision.obstacle == 0


def test_bad_step_arguments() -> None:
    vehicle = Vehicle()
    with pytest.raises(ValueError):
        vehicle.step(-0.1, 1.0, 0.0)
    with pytest.raises(ValueError):
        vehicle.step(0.1, math.nan, 0.0)
    with pytest.raises(ValueError):
        VehicleParameters(wheelbase=0.0)


def test_transform_is_rotation_and_position_bit_for_bit() -> None:
    # transform() writes rotation()'s expressions out in one array (decision 0030): the
    # same bits as the rotation and the position set into an identity
    rng = np.random.default_rng(4)
    for _ in range(500):
        state = VehicleState(east=rng.uniform(-500, 500), north=rng.uniform(-500, 500),
                             up=rng.uniform(-5, 5), yaw=rng.uniform(-4, 4),
                             roll=rng.uniform(-0.5, 0.5), pitch=rng.uniform(-0.5, 0.5))
        expected = np.eye(4)
        expected[:3, :3] = state.rotation()
        expected[:3, 3] = state.position
        transform = state.transform()
        assert transform.dtype == np.float64 and transform.shape == (4, 4)
        assert transform.tobytes() == expected.tobytes()
