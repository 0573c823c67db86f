"""ModelServer as a component: Platform polls over the shipped geometry, Pose events."""

import math
from pathlib import Path

import numpy as np
import pytest

from afa import EOutOfBounds, ETimeOut, System, VirtualClock
from components.gps_sokkia.codec import latlon_to_utm
from components.model_server import ModelServer, ModelServerParameters
from idl import GpsIDL, ImuIDL, Platform, TimeIDL

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def make_system(clock, **parameters):
    server = ModelServer("modelServer", ModelServerParameters(**parameters))
    return server, System([server], clock=clock, base_dir=CONFIGS)


async def test_platform_answers_table_19_from_the_shipped_model():
    clock = VirtualClock()
    server, system = make_system(clock)
    async with system:
        platform = await system.resolve(Platform, "ModelService", timeout=1.0)
        bodies = (await platform.getBodyList()).values
        assert "Raptor" in bodies and "Digiclops" in bodies
        frames = (await platform.getBodyFrameList("Digiclops")).values
        assert "ImagePlane" in frames or "Digiclops:ImagePlane" in frames
        laser = await platform.getTransformation("Raptor: Front-BumperCenter",
                                                 "FrontNoddingSICKLeft: AxleCenterFreeEnd")
        back = await platform.getTransformation("FrontNoddingSICKLeft: AxleCenterFreeEnd",
                                                "Raptor: Front-BumperCenter")
        assert np.allclose(laser.HTransform @ back.HTransform, np.eye(4), atol=1e-12)
        assert laser.poseValidFlag and not laser.initialUTM.any()
        ground = await platform.getTransformation("Raptor:Ground",
                                                  "FrontNoddingSICKLeft:AxleCenterFreeEnd")
        assert ground.HTransform[2, 3] == pytest.approx(2.0, abs=1e-9)  # laser axle 2 m up
        with pytest.raises(EOutOfBounds):
            await platform.getTransformation("Raptor:Nowhere", "Raptor:Ground")
        with pytest.raises(EOutOfBounds):
            await platform.getBodyFrameList("Tank")
        with pytest.raises(ETimeOut):
            await platform.getWaitPose()  # no GPS yet: no pose


def circle_truth(t, radius=15.0, speed=2.0):
    """A counter-clockwise circle about (0, 0): position, ENU yaw, yaw rate."""
    w = speed / radius
    angle = w * t
    return radius * math.cos(angle), radius * math.sin(angle), angle + math.pi / 2, w


async def drive(system, clock, duration, rng, lat0=50.2717, lon0=-111.1766, gps_std=0.3):
    utm = latlon_to_utm(lat0, lon0)
    e0, n0, zone, letter = utm.easting_m, utm.northing_m, utm.zone_number, utm.zone_letter
    truth = []
    start = clock.now()
    step = 0
    while clock.now() - start < duration:
        t = clock.now() - start
        east, north, yaw, rate = circle_truth(t)
        if step % 10 == 0:  # IMU at 10 Hz, z-down sensor rate (negated), with a bias
            system.channel.publish("Raptor", "Imu", ImuIDL(
                time=TimeIDL.from_seconds(clock.now()), roll=0.0, pitch=0.0,
                yaw=math.pi / 2 - yaw, accelX=0.0, accelY=0.0, accelZ=-9.81, rateX=0.0,
                rateY=0.0, rateZ=-(rate + 0.01) + rng.normal(0, 0.005)))
        if step % 25 == 0:  # GPS at 4 Hz, antenna 0.9 m ahead of the rear axle
            ax, an = east + 0.9 * math.cos(yaw), north + 0.9 * math.sin(yaw)
            # the antenna moves at (v, w * 0.9) in the vehicle frame: its own track and speed
            antenna_yaw = yaw + math.atan2(rate * 0.9, 2.0)
            antenna_speed = math.hypot(2.0, rate * 0.9)
            system.channel.publish("Raptor", "Gps", GpsIDL(
                time=TimeIDL.from_seconds(clock.now()), latitude=lat0, longitude=lon0,
                elevation=750.0, undulation=0.0,
                easting=e0 + ax + rng.normal(0, gps_std),
                northing=n0 + an + rng.normal(0, gps_std),
                utmZone=zone, utmZoneLetter=letter, horizontalSpeed=antenna_speed,
                track=math.degrees(math.pi / 2 - antenna_yaw) % 360.0, verticalSpeed=0.0,
                latitudeStd=0.3, longitudeStd=0.3, elevationStd=0.5, differentialAge=1.0,
                solutionAge=0.0, solutionStatus="SOL_COMPUTED", positionType="PSRDIFF"))
            truth.append((clock.now(), e0 + east, n0 + north, yaw))
        step += 1
        await clock.sleep(0.01)
    return truth


async def test_filtered_pose_follows_a_circular_drive():
    clock = VirtualClock()
    server, system = make_system(clock, UseRawPose=False)
    rng = np.random.default_rng(5)
    async with system:
        poses = system.channel.subscribe("Raptor", "Pose", maxsize=100_000)
        truth = await drive(system, clock, 60.0, rng)
        await clock.settle()
    events = []
    while (event := poses.get_nowait()) is not None:
        events.append(event)
    assert server.inputs["gps"] == len(truth) and server.inputs["imu"] > 500
    inputs = server.inputs["gps"] + server.inputs["imu"]
    assert inputs - 1 <= len(events) <= inputs  # one per input event once a fix exists
    by_time = {e.time: e.body for e in events}
    errors, heading_errors = [], []
    for t, east, north, yaw in truth[len(truth) // 3:]:  # after convergence
        pose = by_time[t]
        initial = pose.initialUTM
        errors.append(math.hypot(pose.HTransform[0, 3] + initial[0] - east,
                                 pose.HTransform[1, 3] + initial[1] - north))
        estimated = math.atan2(pose.HTransform[1, 0], pose.HTransform[0, 0])
        heading_errors.append(math.degrees(math.remainder(estimated - yaw, 2 * math.pi)))
        assert pose.poseValidFlag
    assert np.sqrt(np.mean(np.square(errors))) < 0.3
    assert np.sqrt(np.mean(np.square(heading_errors))) < 2.0


async def test_timed_updates_and_raw_pose():
    clock = VirtualClock()
    server, system = make_system(clock, UseRawPose=True, UpdatePeriod=200)
    rng = np.random.default_rng(1)
    async with system:
        poses = system.channel.subscribe("Raptor", "Pose", maxsize=1000)
        platform = await system.resolve(Platform, "ModelService")
        await drive(system, clock, 10.0, rng)
        latest = await platform.getPose()
    count = poses.statistics().queued
    assert 48 <= count <= 51  # every 200 ms once the first fix arrived
    assert latest.initialUTM[2] == 750.0


async def test_a_raw_pose_is_where_the_vehicle_is_at_its_stamp():
    # GPS at 4 Hz, IMU at 10 Hz, a pose on each: most poses are stamped up to 0.24 s
    # after the fix they carry. Each must place the vehicle where it is at its stamp,
    # not where it was at the fix (0.48 m behind at 2 m/s): the map fuses scans with
    # the pose at their stamp.
    clock = VirtualClock()
    server, system = make_system(clock, UseRawPose=True, UpdatePeriod=0)
    rng = np.random.default_rng(2)
    utm = latlon_to_utm(50.2717, -111.1766)
    async with system:
        poses = system.channel.subscribe("Raptor", "Pose", maxsize=100_000)
        start = clock.now()
        await drive(system, clock, 20.0, rng, gps_std=0.0)
        await clock.settle()
    errors, ages = [], []
    while (event := poses.get_nowait()) is not None:
        pose = event.body
        if not pose.poseValidFlag:
            continue  # the first fix, before any heading: no lever-arm correction
        t = pose.time.to_seconds() - start
        east, north, _, _ = circle_truth(t)
        initial = pose.initialUTM
        errors.append(math.hypot(pose.HTransform[0, 3] + initial[0] - utm.easting_m - east,
                                 pose.HTransform[1, 3] + initial[1] - utm.northing_m - north))
        ages.append(t - 0.25 * math.floor(t / 0.25 + 1e-6))  # since the last fix
    errors_arr = np.array(errors)
    assert len(errors) > 100 and max(ages) > 0.2  # poses well after their fix
    assert errors_arr.max() < 0.03  # the arc's chord against the tangent: under 1 cm
