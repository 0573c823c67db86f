"""The simulated 3DM-GX1: attitude, rates and specific force of the simulated sensor.

Registered as the ``Imu`` emulator (entry point group ``afa.emulators``).
"""

from __future__ import annotations

import math

from afa.sim.vehicle import VehicleState
from afa.transport import DeviceFactory
from components.imu.component import Imu
from components.imu.fake import FakeImu, ImuTruth
from components.simulation import SimulatedWorld

__all__ = ["emulate", "IMU_FRAME"]

IMU_FRAME = "Imu:SensorCenter"


def emulate(component: Imu, sim: SimulatedWorld) -> DeviceFactory:
    """A fake IMU sampling the vehicle's motion at the sensor's mounting."""
    to_sensor = sim.mount(IMU_FRAME)[:3, :3].T  # sensor-from-vehicle
    cache: list[tuple[VehicleState, ImuTruth]] = []

    def truth(t: float) -> ImuTruth:
        state = sim.state
        if cache and cache[0][0] is state:  # the unit samples twice per physics step
            return cache[0][1]
        # The 3DM-GX1's angles are NED-style (x forward, y right, z down).
        yaw = math.remainder(math.pi / 2 - state.yaw, 2 * math.pi)
        sample = ImuTruth(roll=state.roll, pitch=-state.pitch, yaw=yaw,
                          accel=tuple((to_sensor @ state.specific_force_body()).tolist()),
                          rates=tuple((to_sensor @ state.angular_velocity_body()).tolist()))
        cache[:] = [(state, sample)]
        return sample

    return sim.adopt(component, FakeImu(sim.clock, truth, rng=sim.rng()))
