"""Where the Terrain Map puts the vehicle (components.terrain_map.stabiliser): the
position predicted from the wheels' distance and pulled towards the GPS's with a time
constant, so that the GPS's wander does not move scans taken seconds apart.

Expected values follow from the definitions: a straight drive at a known speed, a GPS
error added by hand, the first-order pull ``dt / (tau + dt)`` per pose.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from components.terrain_map.stabiliser import (
    JUMP,
    PLANE_TIME,
    STALE,
    OdometryTrack,
    PoseStabiliser,
)

DT = 0.1


def pose(x: float, y: float, z: float = 0.5, yaw: float = 0.0,
         pitch: float = 0.0) -> np.ndarray:
    """Vehicle pose: heading ``yaw`` (rad from east), nose up by ``pitch``."""
    cy, sy, cp, sp = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, -sp], [0, 1, 0], [sp, 0, cp]])  # x axis tilted up
    t = np.eye(4)
    t[:3, :3] = rz @ ry
    t[:3, 3] = (x, y, z)
    return t


def wheels(track: OdometryTrack, t: float, distance: float, speed: float,
           steering: float = 0.0) -> None:
    track.add(t, distance, distance, speed, speed, steering)


def test_the_track_interpolates_extrapolates_briefly_and_then_says_nothing():
    track = OdometryTrack()
    assert track.at(0.0) is None
    wheels(track, 1.0, 10.0, 2.0)  # the first report is the zero of the track
    wheels(track, 1.2, 10.4, 2.0)
    assert track.at(1.1) == pytest.approx(0.2)
    assert track.at(1.2 + STALE) == pytest.approx(0.4 + 2.0 * STALE)  # by the last speed
    assert track.at(1.2 + STALE + 0.01) is None  # stale
    assert track.at(0.5) is None  # before the track


def test_in_a_turn_the_rear_axle_rolls_the_front_wheels_distance_times_cos_steering():
    track = OdometryTrack()
    steer = math.radians(25)
    wheels(track, 0.0, 0.0, 1.0, steer)
    wheels(track, 0.2, 0.2, 1.0, steer)
    assert track.at(0.2) == pytest.approx(0.2 * math.cos(steer))


def test_a_counter_restart_continues_the_track_instead_of_jumping():
    track = OdometryTrack()
    wheels(track, 0.0, 100.0, 1.0)
    wheels(track, 0.2, 100.2, 1.0)
    wheels(track, 0.4, 0.0, 1.0)  # the controller restarted: -100 m in 0.2 s
    assert track.restarts == 1
    wheels(track, 0.6, 0.2, 1.0)
    assert track.at(0.6) == pytest.approx(0.4)  # 0.2 before the restart, 0.2 after
    assert JUMP < 100


def test_a_gps_jump_moves_the_placement_only_as_fast_as_the_pull():
    """Driving east at 1 m/s with odometry, the GPS fix jumps 0.3 m north at t = 5 s:
    the placement follows the wheels exactly along the track and takes the jump in
    with the time constant, ``1 - prod(1 - dt / (tau + dt))`` of it after n poses."""
    s = PoseStabiliser()
    placed = []
    for k in range(101):
        t = k * DT
        wheels(s.odometry, t, t * 1.0, 1.0)
        error = 0.3 if t >= 5.0 else 0.0
        placed.append(s(t, pose(t, error)))
    after = 50  # poses after the jump, included
    pull = DT / (PLANE_TIME + DT)
    expected_north = 0.3 * (1 - (1 - pull) ** (after + 1))
    assert placed[-1][1, 3] == pytest.approx(expected_north, abs=1e-9)
    assert placed[-1][0, 3] == pytest.approx(10.0, abs=1e-9)  # the wheels: exact
    # one second after the jump the placement moved 3 cm, not 30
    assert placed[60][1, 3] == pytest.approx(0.3 * (1 - (1 - pull) ** 11), abs=1e-9)
    assert placed[60][1, 3] < 0.035
    assert placed[-1][:3, :3] == pytest.approx(pose(10.0, 0.3)[:3, :3])  # attitude kept


def test_climbing_follows_the_wheels_along_the_tilted_axis():
    """On a 10 degree ramp the rolled distance moves the vehicle up by sin(10) of it,
    whatever the GPS height says in the meantime (pulled in over 600 s)."""
    s = PoseStabiliser()
    pitch = math.radians(10)
    for k in range(21):
        t = k * DT
        wheels(s.odometry, t, t * 2.0, 2.0)
        rolled = 2.0 * t
        noisy_z = 0.5 + rolled * math.sin(pitch) + (0.4 if k % 2 else -0.4)
        out = s(t, pose(rolled * math.cos(pitch), 0.0, noisy_z, pitch=pitch))
    assert out[0, 3] == pytest.approx(4.0 * math.cos(pitch), abs=0.01)
    assert out[2, 3] == pytest.approx(0.5 - 0.4 + 4.0 * math.sin(pitch), abs=0.02)


def test_reversing_moves_the_placement_backwards():
    s = PoseStabiliser()
    for k in range(11):
        t = k * DT
        wheels(s.odometry, t, -t, -1.0)
        out = s(t, pose(-t, 0.0))
    assert out[0, 3] == pytest.approx(-1.0, abs=1e-9)


def test_without_odometry_the_placement_is_the_gps_position():
    """No wheel reports (or stale ones): horizontally the measured position, as before
    decision 0033; the height still follows the forward motion times the slope."""
    s = PoseStabiliser()
    for k in range(30):
        t = k * DT
        out = s(t, pose(t, 0.3 if k >= 10 else 0.0))
    assert out[1, 3] == pytest.approx(0.3, abs=1e-12)
    assert s.counts == {"odometry": 0, "no_odometry": 29}
    wheels(s.odometry, 3.0, 0.0, 1.0)
    s(3.0, pose(3.0, 0.3))  # the interval began before the first report: measured
    wheels(s.odometry, 3.2, 0.2, 1.0)
    s(3.2, pose(3.2, 0.3))  # both ends on the track: the wheels
    s(3.2 + STALE + 0.1, pose(3.8, 0.3))  # the wheels went silent: measured again
    assert s.counts == {"odometry": 1, "no_odometry": 31}


def test_a_second_pose_at_the_same_stamp_continues_the_filter():
    s = PoseStabiliser(height_tau=2.0)
    assert s(10.0, pose(0, 0, 0.0))[2, 3] == 0.0
    assert s(11.0, pose(0, 0, 0.3))[2, 3] == pytest.approx(0.1)  # 1 / (2 + 1) of the way
    assert s(11.0, pose(0, 0, 0.9))[2, 3] == pytest.approx(0.1)  # same stamp: held
    assert s(12.0, pose(0, 0, 0.4))[2, 3] == pytest.approx(0.2)  # pulled on from 0.1
    assert s(5.0, pose(0, 0, 0.7))[2, 3] == 0.7  # back in time: starts again
