"""IMU: Microstrain 3DM-GX1 over serial (seed §3.1.3)."""

from components.imu.component import Imu
from components.imu.parameters import ImuParameters

__all__ = ["Imu", "ImuParameters"]
