"""The simulated Digiclops: depth images ray-cast from the camera, turned into disparity.

Registered as the ``Stereo`` emulator (entry point group ``afa.emulators``).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from afa.sim.raycast import depth_image
from afa.transport import DeviceFactory
from components.simulation import SimulatedWorld
from components.stereo.backends import DIGICLOPS_MODEL, SyntheticBackend, serve_camera
from components.stereo.component import Stereo

__all__ = ["emulate", "CAMERA_FRAME", "STEREO_SUBSAMPLE"]

CAMERA_FRAME = "Digiclops:ImagePlane"
#: The emulator ray-casts one depth sample per STEREO_SUBSAMPLE^2 pixels.
STEREO_SUBSAMPLE = 4


def emulate(component: Stereo, sim: SimulatedWorld) -> DeviceFactory:
    """A synthetic camera backend rendering the simulated world."""
    backend = SyntheticBackend(sim.clock, render=_renderer(component, sim), rng=sim.rng())
    return serve_camera(backend)  # type: ignore[return-value]


def _renderer(component: Stereo, sim: SimulatedWorld) -> Callable[[float], np.ndarray]:
    """Depth images ``STEREO_SUBSAMPLE`` times coarser than the 320x240 disparity image,
    repeated to full size (a 76,800-ray image costs ~0.1 s; the coarse one ~6 ms, and the
    component still sees 320x240)."""
    max_range = component.parameters.MaxRange / 1000.0 * 1.25
    model, k = DIGICLOPS_MODEL, STEREO_SUBSAMPLE
    fov = math.degrees(2 * math.atan(0.5 * model.width / model.focal_px))

    def render(t: float) -> np.ndarray:
        pose = sim.frame_pose(CAMERA_FRAME)
        coarse = depth_image(sim.terrain, pose[:3, 3], pose[:3, :3], model.width // k,
                             model.height // k, fov, max_range)
        h, w = coarse.shape
        return np.broadcast_to(coarse[:, None, :, None], (h, k, w, k)).reshape(h * k, w * k)

    return render
