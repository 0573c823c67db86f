"""The MPC555 vehicle controller link (seed §3.1.5, §3.5): Wheel Odometry and Vehicle Control.

Both components talk to the one controller over one serial port
(``docs/protocols/mpc555.md``); :class:`~components.mpc555.fake.FakeMpc555` plays the
controller in tests and in the simulator.
"""

from components.mpc555.control import VehicleControl
from components.mpc555.odometry import WheelOdometry
from components.mpc555.parameters import VehicleControlParameters, WheelOdometryParameters

__all__ = ["WheelOdometry", "VehicleControl", "WheelOdometryParameters",
           "VehicleControlParameters"]
