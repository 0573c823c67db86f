"""Ground-truth references for judging a simulated mission.

- :class:`HazardField`: where the world's obstacles and ditches are (the rules of
  :mod:`afa.sim.vehicle`: relief above the climbable step or below the crossable depth),
  and the distance from any point to the nearest one (for the least clearance of a run).
- :func:`shortest_course`: the shortest collision-free course through a mission's
  waypoints on the *fully known* world, for the rear axle centre: Dijkstra on a
  16-connected grid of the hazards grown by the vehicle's half width (and kept that far
  inside the terrain). Sixteen neighbours bring the grid path within about 3 % of the true
  shortest length (eight would allow 8 %); the vehicle's turning radius is not modelled,
  which makes the reference shorter, never longer, than what any vehicle can drive.

Computed with scipy (``scipy.ndimage`` distance transforms, ``scipy.sparse.csgraph``),
independently of the planner under test.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from afa.sim.terrain import Terrain
from afa.sim.vehicle import VehicleParameters
from afa.sim.world import World

__all__ = ["HazardField", "Course", "shortest_course", "ORACLE_RESOLUTION", "ORACLE_MAX_CELLS"]

#: Grid spacing of the course oracle (m).
ORACLE_RESOLUTION = 0.25
#: Cells of the oracle's grid at most (each costs ~1 kB while the graph is built): a
#: larger terrain is planned at a coarser spacing (the shipped worlds, at most 200 m
#: square, are planned at ORACLE_RESOLUTION; a 5 km terrain at 0.25 m was 4e8 cells and
#: exhausted memory at the end of every run).
ORACLE_MAX_CELLS = 1_000_000
_MOVES = [(1, 0), (0, 1), (-1, 0), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1),
          (1, 2), (2, 1), (-1, 2), (-2, 1), (1, -2), (2, -1), (-1, -2), (-2, -1)]


class HazardField:
    """The hazard samples of a terrain and the distance (m) of every sample to the
    nearest one."""

    def __init__(self, terrain: Terrain, parameters: VehicleParameters | None = None) -> None:
        p = parameters or VehicleParameters()
        relief = terrain.surface.astype(np.float64) - terrain.ground
        self.terrain = terrain
        self.hazard: NDArray[np.bool_] = (relief > p.step_height) | (relief < -p.ditch_depth)
        if self.hazard.any():
            self.distance = ndimage.distance_transform_edt(~self.hazard) * terrain.resolution
        else:
            self.distance = np.full(self.hazard.shape, np.inf)

    def clearance(self, east: NDArray[np.float64], north: NDArray[np.float64]) -> float:
        """The least distance (m) from the points to a hazard sample (less half a sample:
        the samples stand for the cells around them)."""
        t = self.terrain
        # (ufuncs rather than np.clip, whose wrapper costs more than the work: the
        # simulation asks for the body's outline every physics step)
        fi = np.rint((east - t.east0) / t.resolution)
        fj = np.rint((north - t.north0) / t.resolution)
        i = np.minimum(np.maximum(fi, 0, out=fi), t.nx - 1, out=fi).astype(np.intp)
        j = np.minimum(np.maximum(fj, 0, out=fj), t.ny - 1, out=fj).astype(np.intp)
        return max(0.0, float(self.distance.ravel().take(j * t.nx + i).min())
                   - 0.5 * t.resolution)

    @property
    def sample_jump(self) -> float:
        """How much farther apart two points' samples can be than the points: half a
        diagonal each (the nearest sample, clamped onto the grid), and a nanometre for
        rounding. The distance field is 1-Lipschitz between samples, so a point's
        :meth:`clearance` changes by at most its move plus this."""
        return math.sqrt(2.0) * self.terrain.resolution + 1e-9


@dataclass(frozen=True)
class Course:
    """The reference course: total length and each leg's (m); ``None`` if a leg has no
    collision-free route."""

    length: float | None
    legs: tuple[float | None, ...]


def shortest_course(world: World, field: HazardField, *, half_width: float | None = None,
                    resolution: float = ORACLE_RESOLUTION) -> Course:
    """Shortest collision-free course from the vehicle's start through every mission
    waypoint in order (once; patrol missions are judged on one lap), on a grid of
    ``resolution`` spacing, or coarser where the terrain needs more than
    :data:`ORACLE_MAX_CELLS` cells. Raises ValueError for a world without waypoints."""
    waypoints = world.mission.waypoints
    if not waypoints:
        raise ValueError(f"world {world.name!r} has no mission waypoints")
    half = (half_width if half_width is not None
            else VehicleParameters().body_width / 2.0)
    t = field.terrain
    east0, east1, north0, north1 = t.extent
    resolution = max(resolution, math.sqrt((east1 - east0) * (north1 - north0)
                                           / ORACLE_MAX_CELLS))
    nx = int(math.floor((east1 - east0) / resolution)) + 1
    ny = int(math.floor((north1 - north0) / resolution)) + 1
    ge = east0 + resolution * np.arange(nx)
    gn = north0 + resolution * np.arange(ny)
    fi = np.clip(np.rint((ge - t.east0) / t.resolution), 0, t.nx - 1).astype(np.intp)
    fj = np.clip(np.rint((gn - t.north0) / t.resolution), 0, t.ny - 1).astype(np.intp)
    free = field.distance[np.ix_(fj, fi)] > half
    inside_e = (ge >= east0 + half) & (ge <= east1 - half)
    inside_n = (gn >= north0 + half) & (gn <= north1 - half)
    free &= inside_n[:, None] & inside_e[None, :]
    graph = _graph(free, resolution)
    points = [(world.vehicle.east, world.vehicle.north)] + [(w.east, w.north) for w in waypoints]
    nodes = [_nearest_free(free, (e - east0) / resolution, (n - north0) / resolution)
             for e, n in points]
    legs: list[float | None] = []
    for (a, b), (pa, pb) in zip(zip(nodes, nodes[1:], strict=False),
                                zip(points, points[1:], strict=False), strict=True):
        if a is None or b is None:
            legs.append(None)
            continue
        # a detour longer than this is not a course a mission would be judged on
        limit = 4.0 * math.dist(pa, pb) + 100.0
        cost = float(dijkstra(graph, indices=a, limit=limit)[b])
        legs.append(cost if math.isfinite(cost) else None)
    total = None if any(leg is None for leg in legs) else float(sum(legs))  # type: ignore[arg-type]
    return Course(total, tuple(legs))


def _graph(free: NDArray[np.bool_], resolution: float) -> csr_matrix:
    ny, nx = free.shape
    index = np.arange(ny * nx).reshape(ny, nx)
    rows, cols, weights = [], [], []
    for di, dj in _MOVES:
        src = free.copy()
        shifted = np.zeros_like(free)
        j0, j1 = max(0, -dj), ny - max(0, dj)
        i0, i1 = max(0, -di), nx - max(0, di)
        shifted[j0:j1, i0:i1] = free[j0 + dj:j1 + dj, i0 + di:i1 + di]
        ok = src & shifted
        # no corner cutting: the cells a move passes beside must be free as well
        for pi, pj in _passed(di, dj):
            passed = np.zeros_like(free)
            a0, a1 = max(0, -pj), ny - max(0, pj)
            b0, b1 = max(0, -pi), nx - max(0, pi)
            passed[a0:a1, b0:b1] = free[a0 + pj:a1 + pj, b0 + pi:b1 + pi]
            ok &= passed
        j, i = np.nonzero(ok)
        rows.append(index[j, i])
        cols.append(index[j + dj, i + di])
        weights.append(np.full(j.size, math.hypot(di, dj) * resolution))
    return csr_matrix((np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(ny * nx, ny * nx))


def _passed(di: int, dj: int) -> list[tuple[int, int]]:
    """The cells (offsets) a move brushes past besides its end."""
    if abs(di) + abs(dj) == 1:
        return []
    if abs(di) == 1 and abs(dj) == 1:
        return [(di, 0), (0, dj)]
    if abs(di) == 2:  # (±2, ±1)
        return [(di // 2, 0), (di // 2, dj)]
    return [(0, dj // 2), (di, dj // 2)]  # (±1, ±2)


def _nearest_free(free: NDArray[np.bool_], fx: float, fy: float,
                  search: int = 20) -> int | None:
    """The free node nearest (fx, fy) within ``search`` nodes, as a flat index."""
    ny, nx = free.shape
    i, j = int(round(fx)), int(round(fy))
    best: tuple[float, int] | None = None
    for dj in range(-search, search + 1):
        for di in range(-search, search + 1):
            a, b = j + dj, i + di
            if 0 <= a < ny and 0 <= b < nx and free[a, b]:
                d = math.hypot(b - fx, a - fy)
                if best is None or d < best[0]:
                    best = (d, a * nx + b)
    return None if best is None else best[1]
