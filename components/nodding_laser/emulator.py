"""The simulated nodding SICK LMS 211: each scan line ray-cast against the heightfield at
the beam bearings and the nod angle the controller reports.

Registered as the ``NodLaser`` emulator (entry point group ``afa.emulators``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from afa.sim.raycast import cast_rays
from afa.transport import DeviceFactory
from components.nodding_laser.component import NodLaser, laser_frame
from components.nodding_laser.fake import FakeNodLaser
from components.simulation import SimulatedWorld

__all__ = ["emulate", "MAX_RANGE"]

#: The LMS's longest reading (8191 mm less the no-return codes), metres.
MAX_RANGE = 8.183


def emulate(component: NodLaser, sim: SimulatedWorld) -> DeviceFactory:
    """A fake nodding controller whose scans are ray-cast from the laser's mounting."""
    fake = FakeNodLaser(sim.clock, source=_source(laser_frame(component.parameters.LaserID), sim),
                        offset_deg=component.parameters.LaserOffsetAngle, rng=sim.rng())
    return sim.adopt(component, fake, kind="tcp")


def _source(frame: str, sim: SimulatedWorld) -> Callable[..., np.ndarray]:
    beams: list[np.ndarray] = []  # the last bearings seen, their sines and -cosines

    def source(t: float, nod_deg: np.ndarray, bearings_deg: np.ndarray) -> np.ndarray:
        # the line is cast from where the laser was at its first beam, the time the
        # driver stamps it with (the fake asks at the line's end, a physics step later)
        pose = sim.frame_pose_at(frame, t)
        if not beams or beams[0] is not bearings_deg:  # the fake reuses one array
            b = np.deg2rad(bearings_deg)
            beams[:] = [bearings_deg, np.sin(b), -np.cos(b)]
        _, sin_b, minus_cos_b = beams
        n = np.deg2rad(nod_deg)
        local = np.empty((sin_b.size, 3))
        np.multiply(sin_b, np.cos(n), out=local[:, 0])
        local[:, 1] = minus_cos_b
        np.multiply(sin_b, np.sin(n), out=local[:, 2])
        # NaN (nothing within range) is a no-return for the fake, as inf would be
        return cast_rays(sim.terrain, pose[:3, 3], local @ pose[:3, :3].T, MAX_RANGE)

    return source
