"""Traversability Map parameters: seed Table A.7, section ``TraverseMap``.

The seed prints ``StepOn``, ``SlopeOn`` and ``StepPercent`` as ``1``/``0``: they are
integer switches (0 or 1), not Miro booleans, so the file keeps the seed's spelling.
``GlobalMap`` and ``EgoMap`` are booleans (``true``/``false``).

The four map descriptions are nested structures (``<parameter name="...">`` with named
children). As in Miro, a description in the file changes only the members it names;
the others keep that description's default (so an ``EgoTravMapDescription`` giving only
``Gridsize`` keeps Depth and Width 16000, not MapDescription's 32000).

Units: ``-`` marks names and flags, ``1`` a dimensionless number.
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import Field, model_validator

from afa.config.parameters import Parameters, check_grid, param

__all__ = ["TraversabilityMapParameters", "MapDescription"]

Switch = Annotated[int, Field(ge=0, le=1)]


class MapDescription(Parameters):
    """Extent, cell size and event name of one map (Table A.7's nested descriptions)."""

    Depth: Annotated[int, Field(gt=0)] = param(32000, unit="mm", description="Depth (mm) of map")
    Width: Annotated[int, Field(gt=0)] = param(32000, unit="mm", description="Width (mm) of map")
    Gridsize: Annotated[int, Field(gt=0)] = param(500, unit="mm",
                                                  description="Size of map cells (mm)")
    EventName: str = param("Traverse", unit="-", description="Event name")

    @model_validator(mode="after")
    def _whole_cells(self) -> MapDescription:
        check_grid(self, ("Depth", "Width"))
        return self


class TraversabilityMapParameters(Parameters):
    """Step and slope hazards from the terrain maps (seed Table A.7)."""

    StepOn: Switch = param(1, unit="-", description="Turn the Step Hazard calculation on/off")
    SlopeOn: Switch = param(1, unit="-",
                            description="Turn the Slope Hazard calculation on/off")
    StepPercent: Switch = param(0, unit="-",
                                description="Calculate Step Hazard as a percentage")
    Stepheight: Annotated[float, Field(gt=0)] = param(
        300.0, unit="mm",
        description="Step hazard height (mm); with StepPercent 1 the step hazard is graded "
                    "as a percentage of it, min(1, step / Stepheight), instead of 0 or 1")
    Maxslope: Annotated[float, Field(gt=0, lt=90)] = param(
        20.0, unit="deg", description="Slope hazard angle")
    ChannelName: str = param("EventChannel", unit="-", description="EventChannel name")
    GlobalMap: bool = param(True, unit="-",
                            description="Turn the Global Traversability Map on/off")
    EgoMap: bool = param(True, unit="-", description="Turn the Ego Traversability Map on/off")
    Farfield: Annotated[float, Field(ge=0)] = param(
        8000.0, unit="mm", description="Distance (mm) of the farzone")
    Farfieldscale: Annotated[float, Field(gt=0)] = param(
        1.5, unit="1", description="Step hazard scaling factor for the farfield area")
    Farfieldslopescale: Annotated[float, Field(gt=0)] = param(
        1.5, unit="1", description="Slope hazard scaling factor for the far-field area")
    MapEventInterval: Annotated[float, Field(gt=0)] = param(
        1.0, unit="s", description="Rate (seconds) at which events are produces")
    MapUpdateTime: Annotated[float, Field(ge=0)] = param(
        7.0, unit="s",
        description="Delay (seconds) between events after a clear map has been issued")
    GlobalTravMapDescription: MapDescription = param(
        MapDescription(Depth=32000, Width=32000, Gridsize=500, EventName="Traverse"),
        unit="-", description="Description of the Global Traversability Map")
    EgoTravMapDescription: MapDescription = param(
        MapDescription(Depth=16000, Width=16000, Gridsize=500, EventName="Traverse"),
        unit="-", description="Description of the Ego Traversability Map")
    TerrainMapDescription: MapDescription = param(
        MapDescription(Depth=32000, Width=32000, Gridsize=200, EventName="Terrain"),
        unit="-", description="Description of the Global Terrain Map events subscribed to")
    EgoTerrainMapDescription: MapDescription = param(
        MapDescription(Depth=16000, Width=16000, Gridsize=200, EventName="Terrain"),
        unit="-", description="Description of the Ego Terrain Map events subscribed to")

    @model_validator(mode="before")
    @classmethod
    def _members_over_defaults(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        merged = dict(data)
        for name, info in cls.model_fields.items():
            value = merged.get(name)
            if isinstance(value, dict) and isinstance(info.default, MapDescription):
                merged[name] = {**info.default.model_dump(), **value}
        return merged
