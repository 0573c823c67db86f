"""IMU: Microstrain 3DM-GX1 over serial (seed §3.1.3)."""

from afa.registry import not_implemented
from components.imu.parameters import ImuParameters

Imu = not_implemented("Imu", ImuParameters, "IMU driver: device drivers")

__all__ = ["Imu", "ImuParameters"]
