"""The simulated MPC555 controller: its commands drive the simulated vehicle, its reports
carry the front wheels' distances and speeds.

Registered as the emulator of both ``WheelOdometry`` and ``VehicleControl`` (one
controller serves the two components on one serial link, as on the Raptor).
"""

from __future__ import annotations

from typing import Any

from afa.component import Component
from afa.transport import DeviceFactory
from components.mpc555.fake import DriveCommand, FakeMpc555, WheelTruth, front_wheel_speeds
from components.simulation import SimulatedWorld

__all__ = ["emulate"]


def emulate(component: Component[Any], sim: SimulatedWorld) -> DeviceFactory:
    """The one fake controller of this simulation (made on first use)."""

    def plant(t: float, command: DriveCommand) -> WheelTruth:
        sim.command(command.translation, command.steering, command.brake)
        state = sim.state
        parameters = sim.vehicle.parameters
        left, right = front_wheel_speeds(state.speed, state.yaw_rate, parameters.wheelbase,
                                         parameters.track)
        return WheelTruth(time=t, left_distance=state.front_left_distance,
                          right_distance=state.front_right_distance, left_speed=left,
                          right_speed=right, speed=state.speed, steering=state.steering,
                          yaw_rate=state.yaw_rate)

    fake = sim.shared("mpc555", lambda: FakeMpc555(sim.clock, plant=plant))
    return sim.adopt(component, fake)
