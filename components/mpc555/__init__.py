"""The MPC555 vehicle controller link (seed §3.1.5, §3.5): Wheel Odometry and Vehicle Control."""

from afa.registry import not_implemented
from components.mpc555.parameters import VehicleControlParameters, WheelOdometryParameters

WheelOdometry = not_implemented("WheelOdometry", WheelOdometryParameters,
                                "Wheel Odometry driver: device drivers")
VehicleControl = not_implemented("VehicleControl", VehicleControlParameters,
                                 "Vehicle Control driver: device drivers")

__all__ = ["WheelOdometry", "VehicleControl", "WheelOdometryParameters",
           "VehicleControlParameters"]
