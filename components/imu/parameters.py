"""IMU (MicroStrain 3DM-GX1) parameters: seed Table A.3, section ``ImuConfig``.

Units: ``-`` marks names and flags.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from afa.config.parameters import Parameters, param

__all__ = ["ImuParameters"]


class ImuParameters(Parameters):
    """The 3DM-GX1 orientation sensor (seed Table A.3)."""

    Device: str = param("/dev/ttyUSB0", unit="-",
                        description="The serial port where the hardware is found")
    ChannelName: str = param("EventChannel", unit="-",
                             description="Name of event channel to publish data")
    Notify: bool = param(True, unit="-",
                         description="Toggles whether or not the component publishes its data")
    EventName: str = param("Imu", unit="-",
                           description="The name of the event on the Event Channel.")
    Baudrate: Annotated[int, Field(gt=0)] = param(
        38400, unit="baud",
        description="afa addition: serial bit rate; 38400 is the 3DM-GX1's factory "
                    "setting (8 data bits, no parity, 1 stop bit)")
