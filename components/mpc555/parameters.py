"""MPC555 vehicle controller parameters: Wheel Odometry (seed Table A.5, section
``WheelOdometryConfig``) and Vehicle Control (seed Table A.13, section
``RaptorCommandConfig``).

Both components talk to the same MPC555 over one serial link (both tables default to
``/dev/ttyS0``). The seed prints ``N/A`` for the calibration parameters (``LfdParam``,
``RfdParam``, ``SteerParam``, ``PedalParam``, ``SteerPID``); the structures and values
here are afa's choice, documented in each description, for the vehicle described in
``docs/geometry.md`` (wheel radius 0.33 m, wheelbase 1.9 m, maximum steering angle 30
degrees).

Units: ``-`` marks names and flags, ``counts`` raw controller units.
"""

from __future__ import annotations

import math
from typing import Annotated, Any

from pydantic import Field, model_validator

from afa.config.parameters import Parameters, param

__all__ = [
    "WheelOdometryParameters", "VehicleControlParameters", "SteerCalibration",
    "PedalPoint", "PidGains", "WHEEL_DISTANCE_PER_COUNT",
]

#: Wheel travel per encoder count: a 0.33 m radius wheel, a 1024-line encoder decoded
#: in quadrature (4096 counts per revolution): 2*pi*330 mm / 4096 = 0.5062 mm.
WHEEL_DISTANCE_PER_COUNT = round(2 * math.pi * 330.0 / 4096, 4)


class SteerCalibration(Parameters):
    """Steering-angle sensor calibration (afa's choice; the seed prints N/A).

    The steering potentiometer is read by the MPC555's 10-bit QADC (0..1023 counts);
    the angle is ``(counts - Center) * Gain``, positive to the left.
    """

    Center: Annotated[int, Field(ge=0, le=1023)] = param(
        512, unit="counts", description="Sensor reading with the wheels straight ahead")
    Gain: Annotated[float, Field(gt=0)] = param(
        0.075, unit="deg/count", description="Steering angle per sensor count")
    Min: Annotated[int, Field(ge=0, le=1023)] = param(
        112, unit="counts", description="Reading at full right lock (-30 deg)")
    Max: Annotated[int, Field(ge=0, le=1023)] = param(
        912, unit="counts", description="Reading at full left lock (+30 deg)")

    @model_validator(mode="after")
    def _ordered(self) -> SteerCalibration:
        if not self.Min < self.Center < self.Max:
            raise ValueError(f"need Min < Center < Max, got {self.Min}, {self.Center}, "
                             f"{self.Max}")
        return self


class PedalPoint(Parameters):
    """One breakpoint of the pedal (hydrostatic drive) calibration table."""

    Velocity: float = param(description="Translational velocity, forward positive",
                            unit="mm/s")
    Command: Annotated[int, Field(ge=0, le=4095)] = param(
        description="12-bit pedal actuator command producing that velocity on level ground",
        unit="counts")


#: Default pedal table: neutral at 2048, a break-away step out of the hydrostatic
#: dead band, then roughly linear up to MaxTransVelocity (2000 mm/s).
DEFAULT_PEDAL_TABLE = [
    PedalPoint(Velocity=-1000.0, Command=1250),
    PedalPoint(Velocity=0.0, Command=2048),
    PedalPoint(Velocity=200.0, Command=2350),
    PedalPoint(Velocity=1000.0, Command=2750),
    PedalPoint(Velocity=2000.0, Command=3250),
]


class PidGains(Parameters):
    """PID gains of the steering servo loop (afa's choice; the seed prints N/A).

    Error is commanded minus measured steering angle in degrees; the output is the
    steering actuator command in percent of full scale.
    """

    P: Annotated[float, Field(ge=0)] = param(4.0, unit="%/deg", description="Proportional gain")
    I: Annotated[float, Field(ge=0)] = param(  # noqa: E741 - the seed's name
        0.5, unit="%/(deg*s)", description="Integral gain")
    D: Annotated[float, Field(ge=0)] = param(0.1, unit="%*s/deg", description="Derivative gain")


def _wheel_distance(side: str) -> Any:
    return param(WHEEL_DISTANCE_PER_COUNT, unit="mm/count",
                 description=f"{side} wheel distance calibration (afa's choice; the seed "
                             "prints N/A): wheel travel per encoder count, 0.5062 mm for a "
                             "0.33 m radius wheel and a 1024-line encoder in quadrature")


def _steer_param() -> Any:
    return param(SteerCalibration(), unit="-",
                 description="Steering calibration parameters (afa's choice; the seed prints "
                             "N/A): {Center, Gain, Min, Max} of the steering sensor")


class WheelOdometryParameters(Parameters):
    """Wheel odometry from the MPC555's front wheel encoders (seed Table A.5)."""

    Device: str = param("/dev/ttyS0", unit="-", description="Serial port")
    LfdParam: Annotated[float, Field(gt=0)] = _wheel_distance("Left")
    RfdParam: Annotated[float, Field(gt=0)] = _wheel_distance("Right")
    SteerParam: SteerCalibration = _steer_param()
    SpeedRepTime: Annotated[int, Field(gt=0)] = param(
        1000, unit="ms", description="Speed report interval (ms)")
    WheelDistRepTime: Annotated[int, Field(gt=0)] = param(
        200, unit="ms",
        description="Wheel distance report interval (ms) (Table 9 prints '250 ms "
                    "(configurable)'; Table A.5's 200 is used)")
    RaptorOdometryEvent: str = param("RaptorOdometry", unit="-",
                                     description="Name of published Events")
    Baudrate: Annotated[int, Field(gt=0)] = param(
        115200, unit="baud", description="afa addition: serial bit rate of the MPC555 link")


class VehicleControlParameters(Parameters):
    """Commands to the MPC555: velocity, steering, start/stop (seed Table A.13)."""

    RaptorMotionEvent: str = param(
        "RaptorMotion", unit="-",
        description="Event name to publish under (also the name the Table 26 interface is "
                    "registered under)")
    Device: str = param("/dev/ttyS0", unit="-", description="Serial device to write to")
    MaxSteeringAngle: Annotated[float, Field(gt=0, le=90)] = param(
        30.0, unit="deg", description="Maximum allowable steering angle (degrees)")
    MaxRotVelocity: Annotated[float, Field(gt=0)] = param(
        1.0, unit="rad/s", description="Maximum allowable rotational velocity (Rad/s)")
    MaxTransVelocity: Annotated[float, Field(gt=0)] = param(
        2000.0, unit="mm/s", description="Maximum allowable translational velocity (mm/s)")
    RfdParam: Annotated[float, Field(gt=0)] = _wheel_distance("Right")
    LfdParam: Annotated[float, Field(gt=0)] = _wheel_distance("Left")
    PedalParam: list[PedalPoint] = param(
        DEFAULT_PEDAL_TABLE, unit="-",
        description="Pedal calibration parameter (afa's choice; the seed prints N/A): "
                    "breakpoints {Velocity, Command} of a piecewise-linear map from "
                    "velocity to pedal actuator command, velocities strictly increasing "
                    "and including 0")
    SteerParam: SteerCalibration = _steer_param()
    SteerPID: PidGains = param(
        PidGains(), unit="-",
        description="Steering PID parameters (afa's choice; the seed prints N/A): {P, I, D}")
    Baudrate: Annotated[int, Field(gt=0)] = param(
        115200, unit="baud", description="afa addition: serial bit rate of the MPC555 link")
    CommandWatchdog: Annotated[float, Field(gt=0)] = param(
        0.5, unit="s",
        description="afa addition: stop the vehicle when no velocity command arrives "
                    "within this interval")
    Wheelbase: Annotated[float, Field(gt=0)] = param(
        1.9, unit="m",
        description="afa addition: front to rear axle distance, turning a rotational "
                    "velocity into a steering angle (atan(Wheelbase * w / v))")

    @model_validator(mode="after")
    def _pedal_table(self) -> VehicleControlParameters:
        velocities = [point.Velocity for point in self.PedalParam]
        if len(velocities) < 2:
            raise ValueError("PedalParam needs at least two breakpoints")
        if any(b <= a for a, b in zip(velocities, velocities[1:], strict=False)):
            raise ValueError(f"PedalParam velocities must increase strictly, got {velocities}")
        if 0.0 not in velocities:
            raise ValueError("PedalParam must contain a breakpoint at velocity 0 (neutral)")
        return self
