"""Stereo Vision (seed §3.1.2): Digiclops disparity to 3-D points."""

from components.stereo.backends import (
    CameraBackend,
    CameraModel,
    CameraSpec,
    DisparityFrame,
    RecordedBackend,
    SyntheticBackend,
    write_recording,
)
from components.stereo.component import Stereo
from components.stereo.parameters import StereoParameters

__all__ = ["Stereo", "StereoParameters", "CameraBackend", "CameraModel", "CameraSpec",
           "DisparityFrame", "RecordedBackend", "SyntheticBackend", "write_recording"]
