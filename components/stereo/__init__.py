"""Stereo Vision (seed §3.1.2): Digiclops disparity to 3-D points."""

from afa.registry import not_implemented
from components.stereo.parameters import StereoParameters

Stereo = not_implemented("Stereo", StereoParameters, "Stereo Vision: device drivers")

__all__ = ["Stereo", "StereoParameters"]
