"""One UTM grid for the whole run: a course across a zone boundary or the equator.

A receiver reports each fix in its own standard zone and hemisphere, so crossing a zone
boundary moves the reported easting by hundreds of kilometres and crossing the equator
the northing by 10,000 km. The pose frame is metres from ``initialUTM`` in the first
fix's grid: ModelServer keeps that grid (and turns the IMU's and the receiver's true
headings into it), and waypoints are placed in it. The oracles are textbook formulas,
independent of the Krüger series under test: the length of an arc of a parallel
(N cos φ Δλ) or of a meridian (M Δφ), scaled by the UTM scale factor, and the grid
convergence atan(tan Δλ sin φ).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from afa import System, VirtualClock
from components.gps_sokkia.codec import (
    grid_convergence,
    latlon_to_grid_near,
    latlon_to_utm,
)
from components.model_server import ModelServer, ModelServerParameters
from components.waypoints import to_local
from idl import GpsIDL, ImuIDL, TimeIDL, WaypointIDL

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
A = 6378137.0
F = 1 / 298.257223563
E2 = F * (2 - F)
K0 = 0.9996


def parallel_arc(latitude: float, dlon_deg: float) -> float:
    """Length (m) of an arc of the parallel at ``latitude`` spanning ``dlon_deg``."""
    phi = math.radians(latitude)
    n = A / math.sqrt(1 - E2 * math.sin(phi) ** 2)
    return n * math.cos(phi) * math.radians(dlon_deg)


def meridian_arc(latitude: float, dlat_deg: float) -> float:
    """Length (m) of a short arc of a meridian at ``latitude`` spanning ``dlat_deg``."""
    phi = math.radians(latitude)
    m = A * (1 - E2) / (1 - E2 * math.sin(phi) ** 2) ** 1.5
    return m * math.radians(dlat_deg)


def scale(latitude: float, dlon_deg: float) -> float:
    """UTM point scale factor (spherical approximation, good to 1e-6 here)."""
    b = math.cos(math.radians(latitude)) * math.sin(math.radians(dlon_deg))
    return K0 / math.sqrt(1 - b * b)


def convergence(latitude: float, longitude: float, zone: int) -> float:
    """atan(tan Δλ sin φ), rad: the classical grid convergence."""
    dlon = math.radians(longitude - (zone * 6 - 183))
    return math.atan(math.tan(dlon) * math.sin(math.radians(latitude)))


def test_a_hemisphere_can_be_forced_across_the_equator():
    south = latlon_to_utm(-0.0001, 10.0)
    assert south.hemisphere == "S" and south.northing_m > 9_999_000
    forced = latlon_to_utm(-0.0001, 10.0, hemisphere="N")
    assert forced.northing_m == pytest.approx(south.northing_m - 10_000_000.0, abs=1e-6)
    assert forced.northing_m == pytest.approx(-meridian_arc(0.0, 0.0001) * scale(0.0, 1.0),
                                              rel=1e-5)
    with pytest.raises(ValueError, match="hemisphere"):
        latlon_to_utm(1.0, 10.0, hemisphere="E")


@pytest.mark.parametrize("latitude,longitude,zone", [
    (45.0, -72.0001, 18), (45.0, -77.9, 18), (50.2717, -111.1766, 12), (-33.9, 18.4, 34),
    (0.5, 9.0, 32), (70.0, 179.99, 60),
])
def test_grid_convergence_is_the_textbook_angle(latitude, longitude, zone):
    hemisphere = "N" if latitude >= 0 else "S"
    assert math.degrees(grid_convergence(latitude, longitude, zone, hemisphere)) == \
        pytest.approx(math.degrees(convergence(latitude, longitude, zone)), abs=2e-4)


@pytest.mark.parametrize("origin,point", [
    ((45.0, -72.0002), (45.0, -71.9998)),    # east across the zone 18/19 boundary
    ((45.0, -71.9998), (45.0, -72.0002)),    # and back west
    ((0.0001, 10.0), (-0.0001, 10.0)),       # south across the equator
    ((-0.0001, -72.0001), (0.0002, -71.9997)),  # both at once
    ((78.0, 8.9995), (78.0, 9.0005)),        # Svalbard: zone 31 to 33, two zones apart
    ((78.0, 9.0005), (78.0, 8.9995)),        # and back west
    ((60.5, 2.9995), (60.5, 3.0005)),        # south-western Norway: zone 31 to 32
    ((-17.8, 179.9998), (-17.8, -179.9998)),  # east across the antimeridian
])
def test_a_waypoint_across_a_boundary_is_placed_in_the_vehicles_grid(origin, point):
    start = latlon_to_utm(*origin)  # the first fix: the receiver's own grid
    x, y = to_local(WaypointIDL(latitude=point[0], longitude=point[1]),
                    np.array([start.easting_m, start.northing_m, 0.0]))
    east = parallel_arc(origin[0], (point[1] - origin[1] + 180.0) % 360.0 - 180.0)
    north = meridian_arc(origin[0], point[0] - origin[0])
    k = scale(origin[0], origin[1] - (start.zone_number * 6 - 183))
    gamma = convergence(origin[0], origin[1], start.zone_number)
    # the ground offset, scaled by the grid and turned by its convergence
    assert x == pytest.approx(k * (east * math.cos(gamma) - north * math.sin(gamma)), abs=0.02)
    assert y == pytest.approx(k * (east * math.sin(gamma) + north * math.cos(gamma)), abs=0.02)
    near = latlon_to_grid_near(point[0], point[1], start.easting_m, start.northing_m)
    assert (near.zone_number, near.hemisphere) == (start.zone_number, start.hemisphere)


def fix(t: float, latitude: float, longitude: float, track_deg: float) -> GpsIDL:
    """A receiver's fix: its own standard grid, true track."""
    utm = latlon_to_utm(latitude, longitude)
    return GpsIDL(time=TimeIDL.from_seconds(t), latitude=latitude, longitude=longitude,
                  elevation=100.0, undulation=0.0, easting=utm.easting_m,
                  northing=utm.northing_m, utmZone=utm.zone_number,
                  utmZoneLetter=utm.zone_letter, horizontalSpeed=2.0, track=track_deg,
                  verticalSpeed=0.0, latitudeStd=0.01, longitudeStd=0.01, elevationStd=0.02,
                  differentialAge=1.0, solutionAge=0.0, solutionStatus="SOL_COMPUTED",
                  positionType="RTK_FIXED")


@pytest.mark.parametrize("start,heading", [
    ((45.0, -72.0003), "east"),   # across the zone 18/19 boundary, 2.1° of convergence
    ((0.0002, 10.0), "south"),    # across the equator
])
async def test_modelserver_keeps_the_first_fixes_grid(start, heading):
    clock = VirtualClock()
    server = ModelServer("modelServer", ModelServerParameters(UseRawPose=True, UpdatePeriod=0))
    system = System([server], clock=clock, base_dir=CONFIGS)
    speed, seconds = 2.0, 24.0
    enu_yaw = 0.0 if heading == "east" else -math.pi / 2  # true ENU yaw of the course
    async with system:
        poses = system.channel.subscribe("Raptor", "Pose", maxsize=100_000)
        for step in range(int(seconds * 10) + 1):
            t = clock.now()
            s = speed * step * 0.1
            if heading == "east":
                phi = math.radians(start[0])
                n = A / math.sqrt(1 - E2 * math.sin(phi) ** 2)
                latitude, longitude = start[0], start[1] + math.degrees(s / (n * math.cos(phi)))
            else:
                m = A * (1 - E2) / (1 - E2 * math.sin(math.radians(start[0])) ** 2) ** 1.5
                latitude, longitude = start[0] - math.degrees(s / m), start[1]
            system.channel.publish("Raptor", "Imu", ImuIDL(
                time=TimeIDL.from_seconds(t), roll=0.0, pitch=0.0, yaw=math.pi / 2 - enu_yaw,
                accelX=0.0, accelY=0.0, accelZ=-9.81, rateX=0.0, rateY=0.0, rateZ=0.0))
            if step % 2 == 0:
                system.channel.publish("Raptor", "Gps", fix(
                    t, latitude, longitude, math.degrees(math.pi / 2 - enu_yaw) % 360.0))
            await clock.sleep(0.1)
        await clock.settle()
    events = []
    while (event := poses.get_nowait()) is not None:
        events.append(event.body)
    valid = [p for p in events if p.poseValidFlag]
    assert server.gps_regridded > 10  # the receiver did change grid half way
    xy = np.array([[p.HTransform[0, 3], p.HTransform[1, 3]] for p in valid])
    steps = np.hypot(*np.diff(xy, axis=0).T)
    assert steps.max() < 0.25  # 0.2 m per 0.1 s: no jump where the receiver's grid changed
    first = latlon_to_utm(*start)
    zone = first.zone_number
    gamma = convergence(start[0], start[1], zone)
    for pose in valid:
        yaw = math.atan2(pose.HTransform[1, 0], pose.HTransform[0, 0])
        # the grid's heading of the course: the true heading turned by the convergence
        assert math.degrees(math.remainder(yaw - (enu_yaw + gamma), 2 * math.pi)) == \
            pytest.approx(0.0, abs=0.01)
    travelled = math.hypot(*(xy[-1] - xy[0]))
    k = scale(start[0], start[1] - (zone * 6 - 183))
    elapsed = valid[-1].time.to_seconds() - valid[0].time.to_seconds()
    assert travelled == pytest.approx(k * speed * elapsed, rel=1e-3)
