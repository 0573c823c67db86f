"""GPS Sokkia GSR2600 (seed §3.1.4): NovAtel OEM4 logs and NMEA over serial."""

from components.gps_sokkia.component import GpsSokkia
from components.gps_sokkia.parameters import GpsSokkiaParameters

__all__ = ["GpsSokkia", "GpsSokkiaParameters"]
