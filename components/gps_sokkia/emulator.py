"""The simulated GSR2600: NovAtel logs of the simulated antenna's position and velocity.

Registered as the ``GpsSokkia`` emulator (entry point group ``afa.emulators``); the
simulation (:mod:`components.simulation`) calls :func:`emulate` for each GPS component.
"""

from __future__ import annotations

import math

import numpy as np

from afa.transport import DeviceFactory
from components.gps_sokkia.codec import PositionType
from components.gps_sokkia.component import GpsSokkia
from components.gps_sokkia.fake import FakeGps, GpsNoise, GpsTruth
from components.simulation import SimulatedWorld

__all__ = ["emulate", "GPS_NOISE", "ANTENNA_FRAME"]

ANTENNA_FRAME = "GpsAntenna:PhaseCenter"
#: The Raptor's GSR2600 took RTCA corrections from a Pacific Crest radio: NovAtel's RT-20
#: carrier-phase differential mode, 0.20 m CEP (OEM4 specification), i.e. about 0.17 m
#: per axis; errors correlated over ~10 s as the receiver's noise model says.
GPS_NOISE = GpsNoise(horizontal=0.17, vertical=0.34)


def emulate(component: GpsSokkia, sim: SimulatedWorld) -> DeviceFactory:
    """A fake receiver reporting the antenna's truth with RT-20 noise."""
    antenna = sim.mount(ANTENNA_FRAME)[:3, 3]

    def truth(t: float) -> GpsTruth:
        state = sim.state
        rotation = state.rotation()
        position = state.position + rotation @ antenna
        omega = rotation @ state.angular_velocity_body()
        velocity = state.velocity() + np.cross(omega, rotation @ antenna)
        lat, lon, _height = sim.world.origin.enu_to_geodetic(*position)
        speed = float(math.hypot(velocity[0], velocity[1]))
        track = math.degrees(math.atan2(velocity[0], velocity[1])) % 360.0 if speed > 1e-6 \
            else state.heading_deg
        return GpsTruth(lat=lat, lon=lon, height=sim.world.origin.elevation + position[2],
                        speed=speed, track=track, vertical_speed=float(velocity[2]),
                        position_type=PositionType.L1_FLOAT)

    return sim.adopt(component, FakeGps(sim.clock, truth, sim.rng(), noise=GPS_NOISE))
