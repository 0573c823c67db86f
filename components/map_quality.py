"""The run summary's ``maps`` section: the maps a simulated run built, scored against the
simulated world's ground truth (issue 11, "Correctness").

:func:`map_summary` takes the System (it finds the Terrain Map, the Global Map and, when
there is no Global Map, the Traversability Map among its components and reads their
latest maps) and the simulation (its world, terrain and the vehicle's actual track) and
returns::

    {"terrain": {"map": "TerrainService", "observed_cells": ..., "rms_height_error_m": ...,
                 "rms_height_error_ground_m": ..., "height_offset_m": ...,
                 "rms_height_error_centred_m": ...},
     "hazards": {"map": "GlobalMapService", "obstacle_cells": ..., "detected_cells": ...,
                 "unobserved_obstacle_cells": ..., "detection_fraction": ...,
                 "detection_fraction_in_range": ..., "obstacles": ...,
                 "unobserved_obstacles": ..., "detected_obstacles": ...,
                 "obstacle_detection_fraction": ...,
                 "obstacle_detection_fraction_in_range": ..., "free_observed_cells": ...,
                 "false_hazard_cells": ..., "false_hazard_fraction": ...},
     "track_points": ..., "detection_range_m": 8.0,
     "targets": {"detection_fraction": 0.95, "obstacle_detection_fraction": 0.95,
                 "false_hazard_fraction": 0.01}}

with the definitions of :mod:`components.traversability_map.quality` (obstacle cells:
traversability cells at least half covered by samples an obstacle raises or lowers by
0.3 m or more, within 8 m of the track; detected: hazard 1; unobserved: obstacle cells
the map holds nothing for, never in any sensor's view, reported apart: the detection
fractions are of the cells *within sensor range*, within 8 m and seen, and the
``…_in_range`` ones count the never seen as missed; obstacles: each obstacle over the
cells holding any of its samples, detected when one of its cells within 8 m is; false
hazards: hazard 1 on an observed cell with no obstacle sample within one cell). The
terrain figures are of the Terrain Map's latest map (32 m around where the vehicle
stopped); the hazard figures of the Global Map's cumulative map (the whole run), or
without one of the Traversability Map's latest map. A map that does not exist or never
published is ``null``; one that cannot be scored (its track lies off the world's
terrain) holds an ``error``.

Frames. The maps are in the pose frame: metres east, north and up of ``initialUTM`` (the
first GPS fix) along the UTM grid. The simulator's truth is in the tangent plane at the
world's origin (true east and north). The two differ by the UTM grid's convergence
(about 0.14 degrees at the shipped worlds: 0.24 m over 100 m), its scale factor and an
offset, so the truth is resampled into the map frame through the exact affine map
between them (:class:`MapFrame`, fitted on three points converted to UTM; the projection
bends from an affine map by well under a millimetre over a few hundred metres).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from components.gps_sokkia.codec import latlon_to_grid_near, latlon_to_utm
from components.terrain_map.grid import GridGeometry
from components.traversability_map.quality import GroundTruth, MapQuality, assess

__all__ = ["map_summary", "MapFrame", "truth_in_map_frame", "registration_world",
           "DETECTION_RANGE", "TARGETS"]

#: Obstacle cells within this distance (m) of the track count (the laser's reach).
DETECTION_RANGE = 8.0
#: Issue 11's targets, reported beside the figures.
TARGETS = {"detection_fraction": 0.95, "obstacle_detection_fraction": 0.95,
           "false_hazard_fraction": 0.01}
#: Truth is resampled this far (m) around the track: beyond the maps' reach.
TRUTH_MARGIN = 25.0

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class MapFrame:
    """The affine map from the simulator's tangent-plane (east, north, up) to a map's
    pose frame: ``(x, y) = A (east, north) + b``, ``z = up + dz``."""

    a: FloatArray
    b: FloatArray
    dz: float

    @classmethod
    def of(cls, origin: Any, initial_utm: ArrayLike) -> MapFrame:
        """For a world ``origin`` (``to_geodetic(east, north)``, ``elevation``) and a
        map's ``initialUTM``."""
        utm0 = np.asarray(initial_utm, dtype=np.float64)
        # the map's grid: the one in which the world's origin lies nearest initialUTM
        latitude0, longitude0 = origin.to_geodetic(0.0, 0.0)
        near = latlon_to_grid_near(latitude0, longitude0, utm0[0], utm0[1])

        def grid(east: float, north: float) -> FloatArray:
            latitude, longitude = origin.to_geodetic(east, north)
            fix = latlon_to_utm(latitude, longitude, zone=near.zone_number,
                                hemisphere=near.hemisphere)
            return np.array([fix.easting_m, fix.northing_m])

        step = 100.0
        p0 = grid(0.0, 0.0)
        a = np.column_stack([(grid(step, 0.0) - p0) / step, (grid(0.0, step) - p0) / step])
        return cls(a, p0 - utm0[:2], float(origin.elevation) - float(utm0[2]))

    def to_map(self, east: ArrayLike, north: ArrayLike) -> tuple[FloatArray, FloatArray]:
        e, n = np.asarray(east, dtype=np.float64), np.asarray(north, dtype=np.float64)
        return (self.a[0, 0] * e + self.a[0, 1] * n + self.b[0],
                self.a[1, 0] * e + self.a[1, 1] * n + self.b[1])

    def to_world(self, x: ArrayLike, y: ArrayLike) -> tuple[FloatArray, FloatArray]:
        inverse = np.linalg.inv(self.a)
        dx = np.asarray(x, dtype=np.float64) - self.b[0]
        dy = np.asarray(y, dtype=np.float64) - self.b[1]
        return (inverse[0, 0] * dx + inverse[0, 1] * dy,
                inverse[1, 0] * dx + inverse[1, 1] * dy)


def truth_in_map_frame(terrain: Any, frame: MapFrame, x_range: tuple[float, float],
                       y_range: tuple[float, float]) -> GroundTruth:
    """The simulator's truth (:meth:`GroundTruth.from_terrain`: surface heights and
    obstacle samples) resampled at the terrain's resolution on a regular grid of the
    map frame over ``x_range`` × ``y_range`` (clipped to the terrain), nearest sample,
    heights in the map frame."""
    world = GroundTruth.from_terrain(terrain)
    res = world.resolution
    ny, nx = world.surface.shape
    e0, e1 = world.east0, world.east0 + res * (nx - 1)
    n0, n1 = world.north0, world.north0 + res * (ny - 1)
    # the largest map-frame box inside the terrain's (slightly rotated) rectangle
    west_x, _ = frame.to_map([e0, e0], [n0, n1])
    east_x, _ = frame.to_map([e1, e1], [n0, n1])
    _, south_y = frame.to_map([e0, e1], [n0, n0])
    _, north_y = frame.to_map([e0, e1], [n1, n1])
    x0, x1 = max(x_range[0], float(west_x.max())), min(x_range[1], float(east_x.min()))
    y0, y1 = max(y_range[0], float(south_y.max())), min(y_range[1], float(north_y.min()))
    if x1 <= x0 or y1 <= y0:
        raise ValueError("the map region does not overlap the world's terrain")
    x = x0 + res * np.arange(int((x1 - x0) / res) + 1)
    y = y0 + res * np.arange(int((y1 - y0) / res) + 1)
    east, north = frame.to_world(x[None, :], y[:, None])
    i = np.clip(np.rint((east - world.east0) / res).astype(np.intp), 0, nx - 1)
    j = np.clip(np.rint((north - world.north0) / res).astype(np.intp), 0, ny - 1)
    surface = world.surface[j, i].astype(np.float64) + frame.dz
    ids = None if world.ids is None else world.ids[j, i]
    return GroundTruth(float(x[0]), float(y[0]), res, surface, world.obstacle[j, i], ids)


def registration_world(heading: float, start_east: float, speed: float,
                       seconds: float) -> bytes:
    """The world map registration is measured on (decision 0025): flat, noise-free ground,
    a 0.6 m box (east -0.5..0.5, north 2..6) north of the line north = 0 and a 0.8 m deep
    ditch (east 5..7, north -6..-3) south of it, and a straight scripted drive along the
    line from ``start_east`` at ``heading`` (deg), ``speed`` (m/s) for ``seconds``."""
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<world name="registration">
  <origin latitude="50.2717" longitude="-111.1766" elevation="750.0"/>
  <terrain width="90" depth="40" resolution="0.1" roughness="0.0" seed="1">
    <slope east="0.0" north="0.0"/>
  </terrain>
  <obstacle type="box" east="0" north="4" length="4" width="1" height="0.6" heading="0"/>
  <obstacle type="ditch" east="6" north="-4.5" length="3" width="2" depth="0.8" heading="0"/>
  <vehicle east="{start_east}" north="0" heading="{heading}"/>
  <drive>
    <command time="0" speed="{speed}" steering="0"/>
    <command time="{seconds:.2f}" speed="0" steering="0"/>
  </drive>
</world>""".encode()


def _figures(quality: MapQuality, *, terrain: bool) -> dict[str, Any]:
    def number(value: float, digits: int = 4) -> float | None:
        return None if math.isnan(value) else round(value, digits)

    if terrain:
        return {"observed_cells": quality.observed_terrain_cells,
                "rms_height_error_m": number(quality.rms_height_error),
                "rms_height_error_ground_m": number(quality.rms_height_error_ground),
                "height_offset_m": number(quality.height_offset),
                "rms_height_error_centred_m": number(quality.rms_height_error_centred)}
    return {"obstacle_cells": quality.obstacle_cells,
            "detected_cells": quality.detected_cells,
            "unobserved_obstacle_cells": quality.unobserved_obstacle_cells,
            "detection_fraction": number(quality.detection_fraction),
            "detection_fraction_in_range": number(quality.detection_fraction_in_range),
            "obstacles": quality.obstacles,
            "unobserved_obstacles": quality.unobserved_obstacles,
            "detected_obstacles": quality.detected_obstacles,
            "obstacle_detection_fraction": number(quality.obstacle_detection_fraction),
            "obstacle_detection_fraction_in_range":
                number(quality.obstacle_detection_fraction_in_range),
            "free_observed_cells": quality.free_observed_cells,
            "false_hazard_cells": quality.false_hazard_cells,
            "false_hazard_fraction": number(quality.false_hazard_fraction, 5)}


def _latest(slot: Any) -> Any:
    return slot.get() if slot is not None and slot.version else None


def map_summary(system: Any, simulation: Any) -> dict[str, Any]:
    """The ``maps`` section of a simulated run's summary (see the module doc)."""
    from components.global_map.component import GlobalMap
    from components.terrain_map.component import TerrainMap
    from components.traversability_map.component import TraversabilityMap

    components = list(system.components.values())
    track = np.array(list(simulation.track), dtype=np.float64).reshape(-1, 2)
    if not len(track):
        state = simulation.state
        track = np.array([[state.east, state.north]])
    summary: dict[str, Any] = {"terrain": None, "hazards": None, "track_points": len(track),
                               "detection_range_m": DETECTION_RANGE, "targets": TARGETS}
    origin = simulation.world.origin
    empty = np.zeros((1, 1))

    def region(frame: MapFrame) -> tuple[tuple[float, float], tuple[float, float],
                                         FloatArray]:
        x, y = frame.to_map(track[:, 0], track[:, 1])
        return ((float(x.min()) - TRUTH_MARGIN, float(x.max()) + TRUTH_MARGIN),
                (float(y.min()) - TRUTH_MARGIN, float(y.max()) + TRUTH_MARGIN),
                np.column_stack([x, y]))

    for component in components:
        if isinstance(component, TerrainMap):
            terrain_map = _latest(getattr(component, "latest_map", None))
            if terrain_map is None:
                break
            frame = MapFrame.of(origin, terrain_map.initialUTM)
            xs, ys, path = region(frame)
            geometry = GridGeometry(terrain_map.originX, terrain_map.originY,
                                    terrain_map.gridsize, terrain_map.rows, terrain_map.cols)
            try:
                truth = truth_in_map_frame(simulation.terrain, frame, xs, ys)
            except ValueError as exc:  # the track lies off the world's terrain
                summary["terrain"] = {"map": component.name, "error": str(exc)}
                break
            quality = assess(hazard=empty, hazard_geometry=GridGeometry(0, 0, 1, 1, 1),
                             truth=truth, track=path, terrain_elevation=terrain_map.elevation,
                             terrain_count=terrain_map.pointCount, terrain_geometry=geometry)
            summary["terrain"] = {"map": component.name, **_figures(quality, terrain=True)}
            break

    hazard: tuple[str, NDArray[Any], GridGeometry, ArrayLike] | None = None
    for component in components:
        if isinstance(component, GlobalMap) and component.initial_utm is not None:
            hazard = (component.name, component.grid.hazard, component.grid.geometry,
                      component.initial_utm)
            break
    else:
        for component in components:
            if isinstance(component, TraversabilityMap):
                trav = _latest(getattr(component, "latest_map", None))
                if trav is not None:
                    hazard = (component.name, trav.hazard,
                              GridGeometry(trav.originX, trav.originY, trav.gridsize,
                                           trav.rows, trav.cols), trav.initialUTM)
                break
    if hazard is not None:
        name, layer, geometry, initial_utm = hazard
        frame = MapFrame.of(origin, initial_utm)
        xs, ys, path = region(frame)
        try:
            truth = truth_in_map_frame(simulation.terrain, frame, xs, ys)
        except ValueError as exc:
            summary["hazards"] = {"map": name, "error": str(exc)}
        else:
            quality = assess(hazard=layer, hazard_geometry=geometry, truth=truth, track=path,
                             detection_range=DETECTION_RANGE)
            summary["hazards"] = {"map": name, **_figures(quality, terrain=False)}
    return summary
