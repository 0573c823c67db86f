"""Nodding Laser (seed §3.1.1): SICK LMS 211 on a nodding mount, over TCP.

:class:`NodLaser` is the driver component (``component.py``); the fake controller
used by tests and the simulator is ``components.nodding_laser.fake.FakeNodLaser``.
"""

from components.nodding_laser.component import NodLaser
from components.nodding_laser.parameters import NodLaserParameters

__all__ = ["NodLaser", "NodLaserParameters"]
