"""GPS Sokkia GSR2600 (seed §3.1.4): NovAtel OEM4 logs and NMEA over serial."""

from afa.registry import not_implemented
from components.gps_sokkia.parameters import GpsSokkiaParameters

GpsSokkia = not_implemented("GpsSokkia", GpsSokkiaParameters, "GPS Sokkia driver: device drivers")

__all__ = ["GpsSokkia", "GpsSokkiaParameters"]
