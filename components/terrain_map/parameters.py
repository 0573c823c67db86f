"""Terrain Map parameters: seed Table A.6, section ``MapConfig``.

Frame names are ``Body:Frame`` names in the ModelServer geometry model
(``docs/geometry.md``); whitespace around the colon is not significant, so the seed's
``Raptor: Front-BumperCenter`` is kept exactly as printed.

Units: ``-`` marks names and flags. Map extents are integer millimetres, as in the
original, and must be whole multiples of the grid size.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from afa.config.parameters import Parameters, check_grid, param

__all__ = ["TerrainMapParameters"]


class TerrainMapParameters(Parameters):
    """Fusion of laser and stereo ranges into global and egocentric grids (Table A.6)."""

    EventChannelName: str = param("EventChannel", unit="-",
                                  description="The event channel's name")
    EventName: str = param("Terrain", unit="-", description="Name of event published")
    Depth: Annotated[int, Field(gt=0)] = param(32000, unit="mm", description="Map depth in mm")
    Width: Annotated[int, Field(gt=0)] = param(32000, unit="mm", description="Map width in mm")
    Gridsize: Annotated[int, Field(gt=0)] = param(200, unit="mm",
                                                  description="Map Grid size in mm")
    notify: bool = param(True, unit="-", description="Published events enabled, True/False")
    RangeEventName1: str = param("Laser11", unit="-", description="Subscribed Range Event")
    RangeEventName2: str = param("Laser12", unit="-", description="Subscribed Range Event")
    RangeEventName3: str = param("Stereo", unit="-", description="Subscribed Range Event")
    PoseEventName: str = param("Pose", unit="-", description="Subscribed Pose Event")
    OdometryEventName: str = param(
        "", unit="-",
        description="afa addition: subscribed wheel odometry event (e.g. RaptorOdometry); "
                    "the distance rolled between poses keeps the map's placement of the "
                    "vehicle consistent over seconds where the GPS wanders (decision 0033); "
                    "empty (the default): the GPS position")
    MapEventInterval: Annotated[float, Field(gt=0)] = param(
        0.25, unit="s", description="Create map events on a timed interval, sec.")
    MapUpdateTime: Annotated[float, Field(ge=0)] = param(
        7.0, unit="s", description="Time required to fill map with data, sec.")
    PlatformEvent: str = param(
        "ModelService", unit="-",
        description="Polled Object for geometry (the name ModelServer offers its Platform "
                    "interface under, Table A.8 OfferedNames)")
    GroundFrame: str = param("Raptor: Front-BumperCenter", unit="-", description="Map Frame")
    SickLaserFrame1: str = param("FrontNoddingSICKLeft: AxleCenterFreeEnd", unit="-",
                                 description="Left SICK Laser Frame")
    SickLaser1_ID: Annotated[int, Field(ge=0)] = param(11, unit="1",
                                                       description="Left Laser I.D.")
    SickLaserFrame2: str = param("FrontNoddingSICKRight: AxleCenterFreeEnd", unit="-",
                                 description="Right SICK Laser Frame")
    SickLaser2_ID: Annotated[int, Field(ge=0)] = param(12, unit="1",
                                                       description="Right Laser I.D.")
    DigiclopsFrame: str = param("Digiclops:ImagePlane", unit="-", description="Digiclop Frame")
    BumperHeight: float = param(
        -500.0, unit="mm",
        description="Ground to bumper Ht., mm (the ground lies this far along z from the "
                    "GroundFrame: -500 = 0.5 m below the bumper frame)")
    MaxVelocity: Annotated[float, Field(gt=0)] = param(
        6000.0, unit="mm/s", description="Max vehicle velocity, mm/sec.")
    PoseInterval: Annotated[float, Field(gt=0)] = param(
        0.1, unit="s",
        description="Pose update interval, sec. Used with MaxVelocity to audit position "
                    "changes")
    OrientationDevError: Annotated[float, Field(ge=0)] = param(
        2.0, unit="deg", description="Estimate Orientation Error, deg.")
    StereoPeriod: Annotated[float, Field(gt=0)] = param(
        0.5, unit="s",
        description="Stereo Event Rate, sec. Used to equal Stereo and Laser data densities")
    EgoDepth: Annotated[int, Field(gt=0)] = param(
        16000, unit="mm",
        description="afa addition: depth of the egocentric map ahead of the GroundFrame, mm "
                    "(Table A.7's EgoTerrainMapDescription)")
    EgoWidth: Annotated[int, Field(gt=0)] = param(
        16000, unit="mm",
        description="afa addition: width of the egocentric map, mm, centred left-right")

    @model_validator(mode="after")
    def _whole_cells(self) -> TerrainMapParameters:
        check_grid(self, ("Depth", "Width"), ("EgoDepth", "EgoWidth"))
        return self
