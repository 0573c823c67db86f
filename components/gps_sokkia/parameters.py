"""GPS Sokkia (GSR2600, NovAtel OEM4 firmware) parameters: seed Table A.4, section
``GpsSokkiaConfig``.

Units: ``-`` marks names and flags.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from afa.config.parameters import Parameters, param

__all__ = ["GpsSokkiaParameters"]


class GpsSokkiaParameters(Parameters):
    """The Sokkia GSR2600 receiver (seed Table A.4)."""

    Device: str = param("/dev/ttyUSB0", unit="-",
                        description="The serial port where the hardware is found")
    ChannelName: str = param("EventChannel", unit="-",
                             description="Name of event channel to publish data")
    Notify: bool = param(True, unit="-",
                         description="Toggles whether or not the component publishes its data")
    EventName: str = param("Gps", unit="-",
                           description="The name of the event on the Event Channel.")
    Baudrate: Annotated[int, Field(gt=0)] = param(
        57600, unit="baud",
        description="afa addition: serial bit rate. The OEM4 COM ports start at 9600; "
                    "BESTPOSA + BESTVELA + BESTUTMA at 4 Hz (about 3 kB/s) need a faster "
                    "port, set on the receiver with the COM command")
