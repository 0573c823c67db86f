"""Stereo Vision (Digiclops) parameters: seed Table A.2, section ``StereoConfig``.

Units: ``-`` marks names and flags.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from afa.config.parameters import Parameters, param

__all__ = ["StereoParameters"]


class StereoParameters(Parameters):
    """The Digiclops stereo camera (seed Table A.2)."""

    EventChannelName: str = param("EventChannel", unit="-",
                                  description="The event channel's name")
    EventName: str = param("Stereo", unit="-", description="Name of event published")
    MaxRange: Annotated[int, Field(gt=0, le=100_000)] = param(
        8000, unit="mm", description="Maximum depth range in mm (at most 100 m: a stereo "
                                     "pair's depth error grows with the square of range)")
    frameRate: Annotated[float, Field(gt=0, le=30.0)] = param(
        2.0, unit="frames/s",
        description="The Event Publication rate in frames/sec. (Table 3 prints 'default "
                    "2 sec.'; Table A.6's StereoPeriod 0.5 s agrees with 2 frames/s); at "
                    "most 30, the camera's video rate")
