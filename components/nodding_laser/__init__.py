"""Nodding Laser (seed §3.1.1): SICK LMS 211 on a nodding mount, over TCP."""

from afa.registry import not_implemented
from components.nodding_laser.parameters import NodLaserParameters

NodLaser = not_implemented("NodLaser", NodLaserParameters, "Nodding Laser driver: device drivers")

__all__ = ["NodLaser", "NodLaserParameters"]
