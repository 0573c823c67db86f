"""Global Map parameters, section ``GlobalMapConfig``.

The seed gives the Global Map no configuration table (section 3.2.3 describes only its
events and Table 18's planning interface), so every parameter here is an afa addition.
The planning grid's cell is the unit of FindPath's lookahead and tracking tolerance.

Units: ``-`` marks names and flags, ``1`` a dimensionless cost.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from afa.config.parameters import Parameters, check_grid, param

__all__ = ["GlobalMapParameters"]


class GlobalMapParameters(Parameters):
    """Cumulative traversability and the planning interface for FindPath."""

    EventChannelName: str = param("EventChannel", unit="-",
                                  description="afa addition: the event channel's name")
    TraverseEventName: str = param(
        "Traverse", unit="-",
        description="afa addition: subscribed TravMapArrayEventIDL event name")
    PlanMapEventName: str = param(
        "PlanMap", unit="-", description="afa addition: published PlanMapEventIDL event name")
    InterfaceName: str = param(
        "GlobalMap", unit="-",
        description="afa addition: name the Table 18 planning interface is registered under")
    PoseEventName: str = param(
        "Pose", unit="-",
        description="afa addition: subscribed vehicle pose (PoseTransformIDL): a waypoint "
                    "is reached when the rear axle (the point Pure Pursuit and FindPath "
                    "steer) or the traversability maps' vehicle position (the ground under "
                    "the front bumper) comes within its tolerance; empty: the maps' "
                    "position alone")
    Depth: Annotated[int, Field(gt=0)] = param(
        250000, unit="mm",
        description="afa addition: north-south extent of the planning grid, first centred "
                    "on the start position; it moves to keep the mission inside "
                    "(decision 0041)")
    Width: Annotated[int, Field(gt=0)] = param(
        250000, unit="mm",
        description="afa addition: east-west extent of the planning grid, first centred "
                    "on the start position; it moves to keep the mission inside "
                    "(decision 0041)")
    Gridsize: Annotated[int, Field(gt=0)] = param(
        500, unit="mm",
        description="afa addition: planning cell size (500 mm: one global traversability "
                    "cell per planning cell; 500 x 500 cells by default)")
    UnknownCellCost: Annotated[float, Field(ge=1)] = param(
        1.0, unit="1",
        description="afa addition: cost of entering a cell never sensed, relative to a "
                    "fully traversable cell (1: the free-space assumption of D* Lite "
                    "navigation in unknown terrain)")

    @model_validator(mode="after")
    def _whole_cells(self) -> GlobalMapParameters:
        check_grid(self, ("Depth", "Width"))
        return self
