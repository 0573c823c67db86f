"""How good a map is, against simulated ground truth: the figures behind a run
summary's ``maps`` section. Pure numpy: no asyncio, no afa (a simulator's
:class:`afa.sim.terrain.Terrain` is read by duck typing, so the run-time packages do not
depend on the simulator).

Use::

    truth = GroundTruth.from_terrain(terrain)          # obstacles: |relief| >= 0.3 m
    quality = assess(hazard=trav.hazard, hazard_geometry=trav.geometry, truth=truth,
                     track=vehicle_xy,                 # (n, 2) world positions driven
                     terrain_elevation=layers.elevation, terrain_count=layers.count,
                     terrain_geometry=layers.geometry)
    summary["maps"] = quality.as_dict()

Definitions (grids may be rotated and translated by ``map_pose``, ^W T_M, default
identity, as a map event's ``mapPose``):

- Truth samples are binned into a map's cells by floor semantics (a cell owns the
  samples inside it). A traversability cell's *obstacle coverage* is the fraction of
  its samples that belong to an obstacle (``GroundTruth.obstacle``).
- **Obstacle cells**: coverage ≥ ``obstacle_coverage`` (0.5: cells mostly obstacle)
  and centre within ``detection_range`` (8 m, the laser's reach) of some point of
  the track. **Detected**: hazard ≥ ``hazard_threshold`` (1: untraversable).
  **Unobserved** (never seen): obstacle cells the map holds nothing for (NaN): within
  reach of the track but never in any sensor's view (behind the start, in another
  obstacle's shadow). An obstacle cell is *within sensor range* when it is within
  reach of the track **and** seen: ``detection_fraction`` is detected / (obstacle cells
  − unobserved), the issue's figure; ``detection_fraction_in_range`` counts the never
  seen cells as missed too. (Seen means the map holds a reading: points fell in the
  cell, or it was inferred a hole from points around it.)
- **Obstacles** (with ``GroundTruth.ids``): each obstacle over every cell holding any
  of its samples (a 0.3 m post covers no cell by half, yet it is an obstacle). An
  obstacle is *in range* when one of those cells has its centre within
  ``detection_range`` of the track, *seen* when one of its in-range cells is observed,
  and *detected* when one of its in-range cells is a hazard:
  ``obstacle_detection_fraction`` is detected / seen obstacles,
  ``obstacle_detection_fraction_in_range`` detected / in-range obstacles.
- **Free observed cells**: observed (``observed``, default: hazard not NaN) and no
  obstacle sample in the cell or within ``margin_cells`` cells of it. The margin is a
  don't-care band: the step rule marks both sides of a face, so the ground cell
  against a rock is a hazard by design, not a false one. **False hazard**: a free
  observed cell with hazard ≥ ``hazard_threshold``.
- **RMS height error**: over observed terrain cells (count > 0) holding truth samples,
  ``elevation - mean(truth surface samples in the cell)``; ``…_ground`` restricts it to
  cells clear of obstacles by the margin (faces make cell means depend on where the
  beams happened to land). ``height_offset`` is the mean error over those ground
  cells: the level at which the whole map sits above the truth (a map stitched with
  a vehicle height from GPS floats by decimetres; hazards, which are height
  differences, do not see it), and ``rms_height_error_centred`` the RMS over all
  observed cells of the error less that offset: the error in the map's shape.

Fractions are NaN when their denominator is 0.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from components.terrain_map.grid import GridGeometry

__all__ = ["GroundTruth", "MapQuality", "assess"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class GroundTruth:
    """Truth on a regular sample grid, the simulator's layout: sample ``[j, i]`` at
    east ``east0 + i·resolution``, north ``north0 + j·resolution``; ``surface`` heights
    (m, obstacles included) and ``obstacle`` flags, both ``(ny, nx)``."""

    east0: float
    north0: float
    resolution: float
    surface: NDArray[np.floating[Any]]
    obstacle: NDArray[np.bool_]
    #: the index of the obstacle each sample belongs to (-1 where ``obstacle`` is
    #: false); None when unknown (no per-obstacle figures then)
    ids: NDArray[np.integer[Any]] | None = None

    @classmethod
    def from_terrain(cls, terrain: Any, *, min_height: float = 0.3, min_depth: float = 0.3,
                     only: Iterable[int] | None = None) -> GroundTruth:
        """From a simulator ``Terrain`` (``surface``, ``ground``, ``ids``, ``east0``,
        ``north0``, ``resolution``): obstacle samples are those an obstacle raises by at
        least ``min_height`` or lowers by at least ``min_depth`` (default: the seed's
        300 mm ``Stepheight``), optionally only obstacles with the given indices."""
        relief = np.asarray(terrain.surface, dtype=np.float64) - terrain.ground
        ids = np.asarray(terrain.ids)
        significant = (ids >= 0) & ((relief >= min_height) | (relief <= -min_depth))
        if only is not None:
            significant &= np.isin(ids, list(only))
        return cls(float(terrain.east0), float(terrain.north0), float(terrain.resolution),
                   np.asarray(terrain.surface), significant,
                   np.where(significant, ids, -1).astype(np.int32))

    def coordinates(self) -> tuple[FloatArray, FloatArray]:
        """World (east, north) of every sample, flattened in ``[j, i]`` order."""
        ny, nx = self.surface.shape
        east = self.east0 + self.resolution * np.arange(nx, dtype=np.float64)
        north = self.north0 + self.resolution * np.arange(ny, dtype=np.float64)
        e, n = np.meshgrid(east, north)
        return e.ravel(), n.ravel()


@dataclass(frozen=True)
class MapQuality:
    """Map figures against ground truth (see the module doc)."""

    observed_terrain_cells: int
    rms_height_error: float
    rms_height_error_ground: float
    height_offset: float
    rms_height_error_centred: float
    obstacle_cells: int
    detected_cells: int
    unobserved_obstacle_cells: int
    detection_fraction: float
    detection_fraction_in_range: float
    obstacles: int
    unobserved_obstacles: int
    detected_obstacles: int
    obstacle_detection_fraction: float
    obstacle_detection_fraction_in_range: float
    free_observed_cells: int
    false_hazard_cells: int
    false_hazard_fraction: float

    def as_dict(self) -> dict[str, float | int]:
        """The figures as a plain dict (NaN kept), for a run summary."""
        return asdict(self)


def _bins(truth: GroundTruth, geometry: GridGeometry, map_pose: ArrayLike | None
          ) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
    """Flat cell index of every truth sample, and which samples fall inside."""
    east, north = truth.coordinates()
    if map_pose is not None:
        pose = np.asarray(map_pose, dtype=np.float64)
        de, dn = east - pose[0, 3], north - pose[1, 3]
        east = pose[0, 0] * de + pose[1, 0] * dn  # Rᵀ (p - t), rotation about z
        north = pose[0, 1] * de + pose[1, 1] * dn
    fi = np.floor((east - geometry.origin_x) / geometry.gridsize)
    fj = np.floor((north - geometry.origin_y) / geometry.gridsize)
    inside = (fi >= 0) & (fi < geometry.rows) & (fj >= 0) & (fj < geometry.cols)
    flat = np.where(inside, fi * geometry.cols + fj, 0).astype(np.intp)
    return flat, inside


def _clear_of_obstacles(obstacle_samples: NDArray[np.int64], margin: int) -> NDArray[np.bool_]:
    """Cells with no obstacle sample within ``margin`` cells (Chebyshev)."""
    hit = obstacle_samples > 0
    rows, cols = hit.shape
    padded = np.zeros((rows + 2 * margin, cols + 2 * margin), dtype=bool)
    padded[margin:margin + rows, margin:margin + cols] = hit
    near = np.zeros_like(hit)
    for di in range(-margin, margin + 1):
        for dj in range(-margin, margin + 1):
            near |= padded[margin + di:margin + di + rows, margin + dj:margin + dj + cols]
    result: NDArray[np.bool_] = ~near
    return result


def _fraction(part: int, whole: int) -> float:
    return part / whole if whole else math.nan


def _near_track(cells: NDArray[np.intp], geometry: GridGeometry, map_pose: ArrayLike | None,
                path: FloatArray, reach: float) -> NDArray[np.bool_]:
    """Which of the cells ``(n, 2)`` have their centre within ``reach`` of the track."""
    near = np.zeros(len(cells), dtype=bool)
    if not len(cells):
        return near
    cx, cy = geometry.cell_center(cells[:, 0], cells[:, 1])
    if map_pose is not None:
        pose = np.asarray(map_pose, dtype=np.float64)
        cx, cy = (pose[0, 0] * cx + pose[0, 1] * cy + pose[0, 3],
                  pose[1, 0] * cx + pose[1, 1] * cy + pose[1, 3])
    for start in range(0, len(cells), 1024):  # (1024, track) distances at a time
        block = slice(start, start + 1024)
        d2 = ((cx[block, None] - path[None, :, 0]) ** 2
              + (cy[block, None] - path[None, :, 1]) ** 2)
        near[block] = d2.min(axis=1) <= reach ** 2
    return near


def _per_obstacle(truth: GroundTruth, flat: NDArray[np.intp], inside: NDArray[np.bool_],
                  geometry: GridGeometry, map_pose: ArrayLike | None, path: FloatArray,
                  reach: float, seen: NDArray[np.bool_], hazardous: NDArray[np.bool_]
                  ) -> tuple[int, int, int]:
    """(obstacles in range, of them never seen, of them detected): see the module doc."""
    if truth.ids is None:
        return 0, 0, 0
    ids = truth.ids.ravel()
    mine = inside & (ids >= 0)
    pairs = np.unique(np.column_stack([ids[mine], flat[mine]]), axis=0)  # (obstacle, cell)
    cells = np.column_stack(np.unravel_index(pairs[:, 1], geometry.shape))
    near = _near_track(cells, geometry, map_pose, path, reach)
    obstacle, cell = pairs[near, 0], pairs[near, 1]
    in_range = np.unique(obstacle)
    seen_ones = np.unique(obstacle[seen.ravel()[cell]])
    detected = np.unique(obstacle[hazardous.ravel()[cell]])
    return len(in_range), len(in_range) - len(seen_ones), len(detected)


def assess(*, hazard: ArrayLike, hazard_geometry: GridGeometry, truth: GroundTruth,
           track: ArrayLike, terrain_elevation: ArrayLike | None = None,
           terrain_count: ArrayLike | None = None,
           terrain_geometry: GridGeometry | None = None,
           observed: ArrayLike | None = None, map_pose: ArrayLike | None = None,
           terrain_map_pose: ArrayLike | None = None, detection_range: float = 8.0,
           hazard_threshold: float = 1.0, obstacle_coverage: float = 0.5,
           margin_cells: int = 1) -> MapQuality:
    """Score a traversability grid (and optionally its terrain grid) against truth.

    ``hazard``: (rows, cols) 0..1 or NaN on ``hazard_geometry`` placed by ``map_pose``;
    ``track``: (n, 2) world (east, north) positions of the vehicle; the terrain grid
    (``terrain_elevation``, ``terrain_count``, ``terrain_geometry``, placed by
    ``terrain_map_pose``) is optional, without it the RMS figures are NaN;
    ``observed``: which traversability cells count as observed (default: hazard not
    NaN). Raises ValueError for mismatched shapes or an empty track.
    """
    h = np.asarray(hazard, dtype=np.float64)
    if h.shape != hazard_geometry.shape:
        raise ValueError(f"hazard {h.shape} does not match its geometry "
                         f"{hazard_geometry.shape}")
    path = np.asarray(track, dtype=np.float64).reshape(-1, 2)
    if not len(path):
        raise ValueError("assess needs at least one track position")
    seen = ~np.isnan(h) if observed is None else np.asarray(observed, dtype=bool)

    flat, inside = _bins(truth, hazard_geometry, map_pose)
    n = hazard_geometry.size
    samples = np.bincount(flat[inside], minlength=n).reshape(h.shape)
    obstacle = np.bincount(flat[inside], weights=truth.obstacle.ravel()[inside],
                           minlength=n).round().astype(np.int64).reshape(h.shape)
    with np.errstate(invalid="ignore", divide="ignore"):
        coverage = np.where(samples > 0, obstacle / samples, 0.0)
    candidates = np.argwhere(coverage >= obstacle_coverage)
    targets = candidates[_near_track(candidates, hazard_geometry, map_pose, path,
                                     detection_range)]
    with np.errstate(invalid="ignore"):
        hazardous = h >= hazard_threshold
    detected = int(np.count_nonzero(hazardous[targets[:, 0], targets[:, 1]]))
    unobserved = int(np.count_nonzero(~seen[targets[:, 0], targets[:, 1]]))
    obstacles, unseen_obstacles, detected_obstacles = _per_obstacle(
        truth, flat, inside, hazard_geometry, map_pose, path, detection_range, seen, hazardous)
    free = seen & (samples > 0) & _clear_of_obstacles(obstacle, margin_cells)
    false = int(np.count_nonzero(free & hazardous))
    n_free = int(np.count_nonzero(free))

    rms = rms_ground = offset = rms_centred = math.nan
    n_observed = 0
    if terrain_elevation is not None and terrain_count is not None \
            and terrain_geometry is not None:
        elevation = np.asarray(terrain_elevation, dtype=np.float64)
        count = np.asarray(terrain_count)
        tflat, tin = _bins(truth, terrain_geometry, terrain_map_pose)
        m = terrain_geometry.size
        tsamples = np.bincount(tflat[tin], minlength=m).reshape(elevation.shape)
        tsum = np.bincount(tflat[tin], weights=truth.surface.ravel()[tin].astype(np.float64),
                           minlength=m).reshape(elevation.shape)
        tobstacle = np.bincount(tflat[tin], weights=truth.obstacle.ravel()[tin],
                                minlength=m).round().astype(np.int64).reshape(elevation.shape)
        cells = (count > 0) & (tsamples > 0)
        n_observed = int(np.count_nonzero(count > 0))
        error = elevation[cells] - tsum[cells] / tsamples[cells]
        if len(error):
            rms = float(np.sqrt(np.mean(error ** 2)))
        ground = cells & _clear_of_obstacles(tobstacle, margin_cells)
        error_ground = elevation[ground] - tsum[ground] / tsamples[ground]
        if len(error_ground):
            rms_ground = float(np.sqrt(np.mean(error_ground ** 2)))
            offset = float(np.mean(error_ground))
            rms_centred = float(np.sqrt(np.mean((error - offset) ** 2)))

    return MapQuality(
        observed_terrain_cells=n_observed, rms_height_error=rms,
        rms_height_error_ground=rms_ground, height_offset=offset,
        rms_height_error_centred=rms_centred, obstacle_cells=len(targets),
        detected_cells=detected, unobserved_obstacle_cells=unobserved,
        detection_fraction=_fraction(detected, len(targets) - unobserved),
        detection_fraction_in_range=_fraction(detected, len(targets)),
        obstacles=obstacles, unobserved_obstacles=unseen_obstacles,
        detected_obstacles=detected_obstacles,
        obstacle_detection_fraction=_fraction(detected_obstacles,
                                              obstacles - unseen_obstacles),
        obstacle_detection_fraction_in_range=_fraction(detected_obstacles, obstacles),
        free_observed_cells=n_free, false_hazard_cells=false,
        false_hazard_fraction=_fraction(false, n_free))
