"""2.5-D grid maps: terrain (Table 11), traversability (Table 15) and plan maps (§3.2.3).

Every map carries the same header and grid convention:

- ``frame`` names the map frame M: ``World`` for global maps (x east, y north, z up,
  origin at ``initialUTM``), or the vehicle frame an egocentric map is attached to
  (e.g. ``Raptor:Front-BumperCenter``, heading-aligned, gravity-aligned).
- ``mapPose`` is ^W T_M, the map frame in the world frame at ``time``: identity
  rotation for global maps; the vehicle's yaw (only) for ego maps. M is always
  gravity-aligned, so its rotation is about z alone.
- Cell ``[i, j]`` (row i, column j) covers map-frame x in
  ``[originX + i·g, originX + (i+1)·g)`` and y in ``[originY + j·g, originY + (j+1)·g)``
  with ``g = gridsize``: rows run along +x (east for global maps, ahead for ego
  maps), columns along +y (north for global maps, left for ego maps).
- Layers are ``(rows, cols)`` arrays; heights are map-frame z in metres.

"Array" maps (the seed's static arrays) hold every cell; "Seq" maps (CORBA sequences)
hold only the known cells as parallel ``(n,)`` arrays of row, column and values.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, ClassVar

import numpy as np
from pydantic import model_validator

from idl._base import Array, field
from idl.common import HTransform4x4, Position3DIDL, TimeIDL, Vector3, _Struct, check_homogeneous
from idl.planning import PlanningBoundaryIDL

__all__ = [
    "MapArrayEventIDL",
    "MapSeqEventIDL",
    "EgoMapArrayEventIDL",
    "EgoMapSeqEventIDL",
    "TravMapArrayEventIDL",
    "EtravMapArrayEventIDL",
    "PlanMapEventIDL",
]

Grid32 = Annotated[np.ndarray, Array("float32", (None, None))]
GridCount = Annotated[np.ndarray, Array("int32", (None, None))]
Cells32 = Annotated[np.ndarray, Array("float32", (None,))]
CellIndex = Annotated[np.ndarray, Array("int32", (None,))]


class _MapHeader(_Struct):
    """Time, placement and geometry of a grid map."""

    time: TimeIDL = field(unit="", description="time stamp of the map")
    frame: str = field(unit="", description="the map frame: World, or the vehicle frame "
                                            "of an ego map")
    mapPose: HTransform4x4 = field(unit="m", description="^W T_M: the map frame in the "
                                                         "world frame (rotation about z only)")
    initialUTM: Vector3 = field(unit="m", description="UTM (easting, northing, elevation) of "
                                                      "the world frame's origin")
    gridsize: float = field(unit="m", gt=0.0, allow_inf_nan=False, description="cell edge")
    originX: float = field(unit="m", allow_inf_nan=False,
                           description="map-frame x of the outer edge of row 0")
    originY: float = field(unit="m", allow_inf_nan=False,
                           description="map-frame y of the outer edge of column 0")
    rows: int = field(unit="1", ge=1, description="cells along map x")
    cols: int = field(unit="1", ge=1, description="cells along map y")

    def _check_header(self) -> None:
        name = type(self).__name__
        check_homogeneous(self.mapPose, f"{name}.mapPose")
        rotation = self.mapPose[:3, :3]
        if not (np.allclose(rotation[2], [0.0, 0.0, 1.0], atol=1e-6)
                and np.allclose(rotation[:, 2], [0.0, 0.0, 1.0], atol=1e-6)):
            raise ValueError(f"{name}.mapPose must rotate about z only (gravity-aligned map)")
        if not np.all(np.isfinite(self.initialUTM)):
            raise ValueError(f"{name}.initialUTM has non-finite entries")

    def _check_grid(self, **layers: np.ndarray) -> None:
        for layer, values in layers.items():
            if values.shape != (self.rows, self.cols):
                raise ValueError(f"{type(self).__name__}.{layer} has shape {values.shape}, "
                                 f"expected (rows, cols) = ({self.rows}, {self.cols})")

    def cell_center(self, i: float, j: float) -> tuple[float, float]:
        """Map-frame (x, y) of the centre of cell [i, j], metres."""
        return (self.originX + (i + 0.5) * self.gridsize,
                self.originY + (j + 0.5) * self.gridsize)

    def cell_index(self, x: float, y: float) -> tuple[int, int]:
        """The cell [i, j] containing map-frame (x, y); may lie outside the grid."""
        return (math.floor((x - self.originX) / self.gridsize),
                math.floor((y - self.originY) / self.gridsize))

    def contains(self, i: int, j: int) -> bool:
        """True if cell [i, j] is inside the grid."""
        return 0 <= i < self.rows and 0 <= j < self.cols


# --- terrain maps ----------------------------------------------------------------------


class _TerrainArray(_MapHeader):
    """Terrain layers over every cell; NaN (count 0) marks unknown cells."""

    _seq_type: ClassVar[type[_TerrainSeq]]

    elevation: Grid32 = field(unit="m", description="mean height of the cell's points; "
                                                    "NaN = unknown")
    minHeight: Grid32 = field(unit="m", description="lowest point height; NaN = unknown")
    maxHeight: Grid32 = field(unit="m", description="highest point height; NaN = unknown")
    pointCount: GridCount = field(unit="1", description="points fused into the cell (≥ 0)")
    variance: Grid32 = field(unit="m^2", description="variance of point heights; NaN = "
                                                     "unknown")

    @model_validator(mode="after")
    def _check(self) -> _TerrainArray:
        self._check_header()
        self._check_grid(elevation=self.elevation, minHeight=self.minHeight,
                         maxHeight=self.maxHeight, pointCount=self.pointCount,
                         variance=self.variance)
        if np.any(self.pointCount < 0):
            raise ValueError(f"{type(self).__name__}.pointCount must be ≥ 0")
        if np.any(self.variance < 0):  # NaN compares false: unknown cells pass
            raise ValueError(f"{type(self).__name__}.variance must be ≥ 0")
        return self

    def known(self) -> np.ndarray:
        """(rows, cols) mask of cells with an elevation."""
        return ~np.isnan(self.elevation)

    def to_seq(self) -> _TerrainSeq:
        """The sequence form: the known cells in row-major order."""
        i, j = np.nonzero(self.known())
        header = {name: getattr(self, name) for name in _MapHeader.model_fields}
        return self._seq_type(
            **header, cellRow=i.astype(np.int32), cellCol=j.astype(np.int32),
            elevation=self.elevation[i, j], minHeight=self.minHeight[i, j],
            maxHeight=self.maxHeight[i, j], pointCount=self.pointCount[i, j],
            variance=self.variance[i, j])


class _TerrainSeq(_MapHeader):
    """Terrain layers of the known cells only, as parallel (n,) arrays."""

    _array_type: ClassVar[type[_TerrainArray]]

    cellRow: CellIndex = field(unit="1", description="(n,) row index i of each cell")
    cellCol: CellIndex = field(unit="1", description="(n,) column index j of each cell")
    elevation: Cells32 = field(unit="m", description="(n,) mean height (finite)")
    minHeight: Cells32 = field(unit="m", description="(n,) lowest point height")
    maxHeight: Cells32 = field(unit="m", description="(n,) highest point height")
    pointCount: CellIndex = field(unit="1", description="(n,) points fused (≥ 0)")
    variance: Cells32 = field(unit="m^2", description="(n,) variance of point heights")

    @model_validator(mode="after")
    def _check(self) -> _TerrainSeq:
        name = type(self).__name__
        self._check_header()
        n = self.cellRow.shape[0]
        for layer in ("cellCol", "elevation", "minHeight", "maxHeight", "pointCount",
                      "variance"):
            if getattr(self, layer).shape[0] != n:
                raise ValueError(f"{name}.{layer} has {getattr(self, layer).shape[0]} "
                                 f"entries, cellRow has {n}")
        inside = ((self.cellRow >= 0) & (self.cellRow < self.rows)
                  & (self.cellCol >= 0) & (self.cellCol < self.cols))
        if not np.all(inside):
            raise ValueError(f"{name}: cell indices outside the {self.rows}x{self.cols} grid")
        flat = self.cellRow.astype(np.int64) * self.cols + self.cellCol
        if np.unique(flat).shape[0] != n:
            raise ValueError(f"{name}: a cell appears more than once")
        if not np.all(np.isfinite(self.elevation)):
            raise ValueError(f"{name}.elevation: a sequence holds only known cells")
        if np.any(self.pointCount < 0) or np.any(self.variance < 0):
            raise ValueError(f"{name}: pointCount and variance must be ≥ 0")
        return self

    def to_array(self) -> _TerrainArray:
        """The static-array form: unknown cells NaN with count 0."""
        shape = (self.rows, self.cols)
        layers: dict[str, Any] = {}
        for layer in ("elevation", "minHeight", "maxHeight", "variance"):
            grid = np.full(shape, np.nan, dtype=np.float32)
            grid[self.cellRow, self.cellCol] = getattr(self, layer)
            layers[layer] = grid
        count = np.zeros(shape, dtype=np.int32)
        count[self.cellRow, self.cellCol] = self.pointCount
        header = {name: getattr(self, name) for name in _MapHeader.model_fields}
        return self._array_type(**header, pointCount=count, **layers)


class MapArrayEventIDL(_TerrainArray):
    """Global terrain map, static array form (Table 11); frame ``World``."""


class MapSeqEventIDL(_TerrainSeq):
    """Global terrain map, sequence form (Table 11): known cells only."""


class EgoMapArrayEventIDL(_TerrainArray):
    """Egocentric terrain map, static array form (Table 11): vehicle-centred,
    heading-aligned (rows ahead, columns to the left)."""


class EgoMapSeqEventIDL(_TerrainSeq):
    """Egocentric terrain map, sequence form (Table 11): known cells only."""


MapArrayEventIDL._seq_type = MapSeqEventIDL
MapSeqEventIDL._array_type = MapArrayEventIDL
EgoMapArrayEventIDL._seq_type = EgoMapSeqEventIDL
EgoMapSeqEventIDL._array_type = EgoMapArrayEventIDL


# --- traversability and plan maps ------------------------------------------------------


def _check_unit_interval(values: np.ndarray, what: str, *, nan_ok: bool) -> None:
    inside = (values >= 0.0) & (values <= 1.0)
    if nan_ok:
        inside |= np.isnan(values)
    if not np.all(inside):
        raise ValueError(f"{what} must lie in 0..1{' or be NaN' if nan_ok else ''}")


class _TravArray(_MapHeader):
    """Traversability layers and the vehicle position the map was made at."""

    hazard: Grid32 = field(unit="1", description="0 = easy, 1 = untraversable; NaN = "
                                                 "unknown")
    goodness: Grid32 = field(unit="1", description="accuracy of the data behind hazard, "
                                                   "0 (none) .. 1")
    vehiclePosition: Position3DIDL = field(unit="m", description="vehicle reference point "
                                                                 "in the world frame")
    vehicleHeading: float = field(0.0, unit="rad", allow_inf_nan=False,
                                  description="vehicle yaw in the world frame, "
                                              "counter-clockwise from east")

    def _check_trav(self) -> None:
        name = type(self).__name__
        self._check_header()
        self._check_grid(hazard=self.hazard, goodness=self.goodness)
        _check_unit_interval(self.hazard, f"{name}.hazard", nan_ok=True)
        _check_unit_interval(self.goodness, f"{name}.goodness", nan_ok=False)

    @model_validator(mode="after")
    def _check(self) -> _TravArray:
        self._check_trav()
        return self


class TravMapArrayEventIDL(_TravArray):
    """Global traversability map (Tables 15, 16); frame ``World``."""


class EtravMapArrayEventIDL(_TravArray):
    """Egocentric traversability map (Table 16; Table 15 prints it as EgoMapArrayEventIDL)."""


class PlanMapEventIDL(_TravArray):
    """The Global Map's cumulative planning map (§3.2.3), published for display.

    The accumulated traversability, plus the planning costs the Table 18 interface
    serves: planning node (x, y) is cell [x, y] (see :mod:`idl.planning`).
    """

    aPrioriCost: Grid32 = field(unit="1", description="a priori cost per cell, ≥ 1 or inf")
    sensedCost: Grid32 = field(unit="1", description="sensed cost per cell, ≥ 1 or inf")
    planningBoundary: PlanningBoundaryIDL = field(unit="", description="the searchable "
                                                                       "part of the grid")
    revision: int = field(0, unit="1", ge=0,
                          description="the Global Map's revision these layers show (it "
                                      "counts changes); see GlobalMap.getPlanMapChanges")
    fullRows: int = field(0, unit="1", ge=0,
                          description="rows of the whole planning grid (0: this is the "
                                      "whole grid); a window's row i is grid row "
                                      "i + (originX - gridOriginX) / gridsize")
    fullCols: int = field(0, unit="1", ge=0,
                          description="columns of the whole planning grid (0: whole grid)")

    def planning_cost(self) -> np.ndarray:
        """The cost a planner uses per cell: the sensed cost where the cell was sensed
        (hazard known), else the a priori cost (``PlanPointIDL.cost``)."""
        return np.where(np.isnan(self.hazard), self.aPrioriCost, self.sensedCost)

    @model_validator(mode="after")
    def _check_costs(self) -> PlanMapEventIDL:
        self._check_grid(aPrioriCost=self.aPrioriCost, sensedCost=self.sensedCost)
        for name in ("aPrioriCost", "sensedCost"):
            if not np.all(getattr(self, name) >= 1.0):  # NaN fails too
                raise ValueError(f"PlanMapEventIDL.{name} must be ≥ 1 or inf")
        return self
