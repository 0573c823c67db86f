"""Proprioceptive sensor events: IMU (Table 5), GPS (Table 7), wheel odometry (Table 9).

All values are SI: metres, seconds, radians, except GPS latitude, longitude and track,
which stay in degrees as the receiver and the waypoint lists give them.
"""

from __future__ import annotations

from pydantic import model_validator

from idl._base import field
from idl.common import TimeIDL, _Struct

__all__ = ["ImuIDL", "GpsIDL", "WheelDataIDL", "WheelEventIDL", "UTM_ZONE_LETTERS"]

#: Latitude band letters of UTM zones (C..X without I and O).
UTM_ZONE_LETTERS = "CDEFGHJKLMNPQRSTUVWX"


def _finite(description: str, unit: str, default: float = 0.0, **kwargs: object) -> float:
    return field(default, unit=unit, allow_inf_nan=False, description=description, **kwargs)


class ImuIDL(_Struct):
    """Orientation, acceleration and angular rate from the 3DM-GX1 (seed Table 5).

    Values are in the sensor frame ``frame`` (default ``Imu:SensorCenter``, the
    device's own x forward, y right, z down frame; see docs/geometry.md). Euler angles
    are the device's gyro-stabilised roll, pitch, yaw (applied yaw, then pitch, then
    roll), in radians.
    """

    time: TimeIDL = field(unit="", description="time stamp of the sample")
    roll: float = _finite("roll about the sensor x axis", "rad")
    pitch: float = _finite("pitch about the sensor y axis", "rad")
    yaw: float = _finite("yaw (heading) about the sensor z axis", "rad")
    accelX: float = _finite("acceleration along sensor x (gravity included)", "m/s^2")
    accelY: float = _finite("acceleration along sensor y (gravity included)", "m/s^2")
    accelZ: float = _finite("acceleration along sensor z (gravity included)", "m/s^2")
    rateX: float = _finite("angular rate about sensor x", "rad/s")
    rateY: float = _finite("angular rate about sensor y", "rad/s")
    rateZ: float = _finite("angular rate about sensor z", "rad/s")
    frame: str = field("Imu:SensorCenter", unit="",
                       description="Body:Frame the values are expressed in")


class GpsIDL(_Struct):
    """A GPS fix from the Sokkia GSR2600 (NovAtel OEM4 BESTPOS, BESTVEL, BESTUTM).

    ``solutionStatus`` and ``positionType`` carry NovAtel's enumeration names
    (``SOL_COMPUTED``, ``INSUFFICIENT_OBS`` …; ``NONE``, ``SINGLE``, ``PSRDIFF``,
    ``NARROW_INT`` …), see docs/idl.md for the numeric codes of binary logs. A fix
    without a solution still validates: its position fields are whatever the receiver
    reported (usually 0), and :attr:`has_fix` is false.
    """

    time: TimeIDL = field(unit="", description="time stamp of the fix")
    latitude: float = _finite("geodetic latitude, WGS84, north positive", "deg", ge=-90.0,
                              le=90.0)
    longitude: float = _finite("geodetic longitude, WGS84, east positive", "deg",
                               ge=-180.0, le=180.0)
    elevation: float = _finite("height above mean sea level", "m")
    undulation: float = _finite("geoid undulation (ellipsoid height = elevation + "
                                "undulation)", "m")
    easting: float = _finite("UTM easting (false easting 500 km included)", "m")
    northing: float = _finite("UTM northing (10,000 km false northing south of the "
                              "equator)", "m")
    utmZone: int = field(0, unit="1", ge=0, le=60, description="UTM zone number 1..60; 0 "
                                                               "if unknown")
    utmZoneLetter: str = field("", unit="", max_length=1,
                               description="UTM latitude band letter C..X; empty if unknown")
    satellitesTracked: int = field(0, unit="1", ge=0, description="satellites tracked")
    satellitesUsed: int = field(0, unit="1", ge=0, description="satellites used in the "
                                                               "solution")
    horizontalSpeed: float = _finite("speed over ground", "m/s", ge=0.0)
    track: float = _finite("track over ground, clockwise from true north, 0..360", "deg",
                           ge=0.0, lt=360.0)
    verticalSpeed: float = _finite("vertical speed, up positive", "m/s")
    solutionStatus: str = field("INSUFFICIENT_OBS", unit="",
                                description="NovAtel solution status name")
    positionType: str = field("NONE", unit="", description="NovAtel position type name")
    latitudeStd: float = _finite("standard deviation of latitude", "m", ge=0.0)
    longitudeStd: float = _finite("standard deviation of longitude", "m", ge=0.0)
    elevationStd: float = _finite("standard deviation of elevation", "m", ge=0.0)
    differentialAge: float = _finite("age of the differential corrections", "s", ge=0.0)
    solutionAge: float = _finite("age of the solution", "s", ge=0.0)
    baseStationId: str = field("", unit="", description="differential base station id")

    @model_validator(mode="after")
    def _check(self) -> GpsIDL:
        if self.utmZoneLetter and self.utmZoneLetter not in UTM_ZONE_LETTERS:
            raise ValueError(f"utmZoneLetter must be one of {UTM_ZONE_LETTERS} or empty, "
                             f"got {self.utmZoneLetter!r}")
        return self

    @property
    def has_fix(self) -> bool:
        """True if the receiver computed a position (SOL_COMPUTED, type not NONE)."""
        return self.solutionStatus == "SOL_COMPUTED" and self.positionType != "NONE"


class WheelDataIDL(_Struct):
    """Wheel odometry from the MPC555 (seed Tables 9, 10): the two front wheels.

    Distances are cumulative since the controller started (they only grow when
    driving forward and shrink when reversing). The steering angle is the front-wheel
    (Ackermann bicycle-model) angle, positive turning left.
    """

    time: TimeIDL = field(unit="", description="time stamp of the report")
    leftDistance: float = _finite("cumulative distance rolled by the left front wheel", "m")
    rightDistance: float = _finite("cumulative distance rolled by the right front wheel",
                                   "m")
    leftSpeed: float = _finite("left front wheel speed, forward positive", "m/s")
    rightSpeed: float = _finite("right front wheel speed, forward positive", "m/s")
    steeringAngle: float = _finite("front wheel steering angle, left positive", "rad")

    @property
    def distance(self) -> float:
        """Mean cumulative distance of the two wheels, metres."""
        return 0.5 * (self.leftDistance + self.rightDistance)

    @property
    def speed(self) -> float:
        """Mean speed of the two wheels, m/s."""
        return 0.5 * (self.leftSpeed + self.rightSpeed)


class WheelEventIDL(WheelDataIDL):
    """The odometry event ModelServer subscribes to (seed Table 20).

    A :class:`WheelDataIDL` plus a report counter and the increments since the
    previous report, so a consumer can detect lost reports and integrate without
    keeping state. Being a subclass, it is accepted wherever WheelDataIDL is.
    """

    sequence: int = field(0, unit="1", ge=0, description="report counter, +1 per report")
    leftDelta: float = _finite("left wheel distance since the previous report", "m")
    rightDelta: float = _finite("right wheel distance since the previous report", "m")
