"""FindPath's kinematic refinement: a drivable path over the next metres of the D* path.

Why
---
D* Lite plans for a point moving between 8-connected cells, so its path may turn 90°
within one cell: along a wall and into a gate, say. The Raptor drives arcs no tighter
than κ_max (a 3.3 m radius) and its body reaches 3 m ahead of the rear axle. Where the
obstacles leave no room to swing wide, a tracker aiming at a look-ahead point on such a
corner asks for a curvature it cannot drive: it overshoots the opening and circles
(docs/decisions/0024-kinematic-refinement.md).

What
----
:class:`Refiner` searches arcs from the vehicle's pose to a *target pose* on the D* path
a few metres ahead (Hybrid A*, Dolgov et al. 2008: continuous positions, states merged by
cell and heading bin):

- **Motions**: arcs of length ``step`` with curvatures spread evenly over
  [−κ, +κ] (κ a little under the arc set's κ_max, so the tracker keeps some steering in
  hand); with ``reverse_cost`` > 0 the same arcs driven backwards too, each metre
  costing ``reverse_cost`` times as much, each change of direction ``switch_cost`` more,
  and ending only on ``seen`` cells (no sensor looks behind; decision 0046). The vehicle
  is taken to be driving forwards at the start, so a path that starts by backing pays
  one change.
- **Body**: discs of ``radius`` centred ``offsets`` metres ahead of the rear axle (the
  defaults cover the Raptor's 2.85 m × 1.4 m body: √(0.7² + 0.4²) < 0.81 m with discs
  0.8 m apart), checked every quarter motion: a disc is clear when its centre is farther
  than radius + ``slack`` − ``hazard_margin`` from the *centre* of every impassable
  cell. ``slack`` covers the body's travel between checks and the ``resolution`` of the
  distance map; ``hazard_margin`` is how far a mapped hazard cell's centre lies outside
  the obstacle at least: the Traversability Map marks the cells beside a step as hazards
  too, so a hazard cell's centre lies half a cell or more off the obstacle it marks
  (FindPath passes half a cell; 0 treats every hazard cell's centre as obstacle).
  Unknown cells are free (the freespace assumption).
- **Cost**: length times the planning cost of the cell under the rear axle (so the
  margins around obstacles keep their meaning), plus a small charge per change of
  curvature that prefers steady arcs.
- **Heuristic**: the cost-to-target of a point moving between cells (8-connected
  Dijkstra over the same costs, obstacles grown), which knows the walls and so leads the
  search round them rather than into them; it ignores the turning radius, so it never
  overestimates by much.
- **Goal**: within ``position_tolerance`` of the target and, when the target has a
  heading, within ``heading_tolerance`` of it; or, when the target is the waypoint
  (an ``arrival`` region), a pose after the first motion whose rear axle or front point
  (the ground under the bumper, where the Global Map also judges arrival) lies within
  the region: the rear axle cannot stand on a waypoint short of a wall facing it, but
  the bumper can come to it.

The search is confined to a window around start and target and stops after
``max_expansions`` states: it answers ``None`` then, and FindPath tracks the D* path as
before. A typical query expands a few dozen states in the open and a few thousand where it
must swing wide: round the end of a wall, 3,500–5,000 (the budget was 3,000 until
decision 0039; every search that failed there failed for the budget, and the vehicle
backed out and came back to the same place six times). The search loop is compiled
(``_search_jit.py``, decision 0028); the Python loop in :meth:`Refiner.plan` is its
oracle and fallback.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from afa.kernels import compiled
from components.waypoints import reached

__all__ = ["Refiner", "Refined", "Pose", "Arrival", "SEARCH_KERNEL"]

Pose = tuple[float, float, float]  # x, y (m, map frame), heading (rad, from +x)
#: An arrival region: waypoint x, y, radius (m), and the front point's ahead, left (m)
Arrival = tuple[float, float, float, float, float]

#: The compiled search in use (:mod:`components.find_path._search_jit`), None when the
#: Python loop searches (``AFA_KERNELS=numpy``, or no numba).
SEARCH_KERNEL: Any = compiled("components.find_path._search_jit", "search_kernel")


@dataclass(frozen=True)
class Refined:
    """A drivable path: ``poses`` from the start (included) to the target, ``step``
    metres apart; ``expansions`` states expanded to find it."""

    poses: list[Pose]
    curvatures: list[float]  # of each motion, len(poses) - 1
    expansions: int
    step: float  # m, the length of each motion
    #: of each motion: 1 forwards, -1 in reverse (empty: every motion forwards)
    directions: tuple[int, ...] = ()

    def direction(self, k: int) -> int:
        return self.directions[k] if self.directions else 1

    def first_leg(self) -> tuple[int, int]:
        """The direction of the first motion and how many motions in a row share it
        (the path's first leg, up to its first change of direction)."""
        n = len(self.curvatures)
        if n == 0:
            return 1, 0
        first = self.direction(0)
        k = 1
        while k < n and self.direction(k) == first:
            k += 1
        return first, k

    def at(self, distance: float) -> tuple[float, float]:
        """The point ``distance`` metres along the path's first leg (on its arcs; the
        leg's end beyond it: a point past a change of direction would lie behind)."""
        step = self.step
        _, leg = self.first_leg()
        k = int(distance // step) if step > 0 else 0
        if k >= leg:
            return self.poses[leg][0], self.poses[leg][1]
        x, y, h = self.poses[k]
        ax, ay = _arc(self.curvatures[k], self.direction(k) * (distance - k * step))
        return (x + ax * math.cos(h) - ay * math.sin(h),
                y + ax * math.sin(h) + ay * math.cos(h))


class Refiner:
    """Hybrid A* over arcs, forwards and (with ``reverse_cost``) backwards (module
    docstring). Lengths in metres."""

    def __init__(self, max_curvature: float, offsets: tuple[float, ...], radius: float,
                 *, hazard_margin: float = 0.0, resolution: float = 0.1,
                 slack: float = 0.1, motions: int = 7, step: float = 0.75, heading_bins: int = 72,
                 max_expansions: int = 12000, window_margin: float | None = None,
                 position_tolerance: float = 0.75, heading_tolerance: float = 0.35,
                 curvature_change_cost: float = 0.5, heuristic_weight: float = 1.0,
                 escape_rate: float = 0.25, reverse_cost: float = 0.0,
                 switch_cost: float = 0.0) -> None:
        if not (max_curvature > 0.0 and motions >= 3 and motions % 2 == 1 and step > 0.0):
            raise ValueError("need max_curvature > 0, an odd motions >= 3 and step > 0")
        self.curvatures = tuple(float(k) for k in np.linspace(max_curvature, -max_curvature,
                                                              motions))
        self.offsets = tuple(float(o) for o in offsets) or (0.0,)
        self.radius = float(radius)
        self.resolution = float(resolution)
        self.slack = float(slack)
        self.hazard_margin = float(hazard_margin)
        #: the clearance a disc centre needs from every impassable cell's centre
        self.need = self.radius + self.slack - self.hazard_margin
        self.step = float(step)
        self.bins = int(heading_bins)
        self.max_expansions = int(max_expansions)
        self.position_tolerance = float(position_tolerance)
        self.heading_tolerance = float(heading_tolerance)
        self.curvature_change_cost = float(curvature_change_cost)
        self.heuristic_weight = float(heuristic_weight)
        self.escape_rate = float(escape_rate)
        self.reverse_cost = float(reverse_cost)
        self.switch_cost = float(switch_cost)
        # room for a U-turn (two turning radii) and the body beyond it, by default
        self.window_margin = float(window_margin) if window_margin is not None else \
            2.0 / max_curvature + max(self.offsets) + self.radius
        # each motion in the frame of its start pose: (end x, y, heading change) and the
        # middle point, for the collision samples
        # (reverse motions: the same arcs driven backwards, when reverse_cost > 0)
        self._motions: list[tuple[float, int, tuple[tuple[float, float, float], ...]]] = []
        for sign in ((1, -1) if self.reverse_cost > 0.0 else (1,)):
            for k in self.curvatures:
                samples = tuple((*_arc(k, sign * s), k * sign * s)
                                for s in (0.25 * self.step, 0.5 * self.step,
                                          0.75 * self.step, self.step))
                self._motions.append((k, sign, samples))
        self._motion_curvatures = np.array([k for k, _, _ in self._motions], dtype=np.float64)
        self._motion_signs = np.array([d for _, d, _ in self._motions], dtype=np.float64)
        self._motion_samples = np.array([samples for _, _, samples in self._motions],
                                        dtype=np.float64)
        #: the compiled search (decision 0014), None for the Python loop (its oracle)
        self.kernel = SEARCH_KERNEL

    def plan(self, blocked: NDArray[np.bool_], cost: NDArray[np.float64],
             origin: tuple[float, float], gridsize: float, start: Pose,
             target: tuple[float, float, float | None],
             curvature: float | None = None, open_cost: float | None = None,
             arrival: Arrival | None = None,
             seen: NDArray[np.bool_] | None = None) -> Refined | None:
        """A drivable path from ``start`` to ``target`` (x, y, heading or None), or None
        when the search finds none within its window and budget.

        ``blocked``: impassable cells (obstacles, off limits); ``cost``: the planning cost
        of every cell (inf where impassable or grown), both indexed [i, j] with x = origin
        + (i + ½)·gridsize; ``curvature``: the one the vehicle steers now, if known, so
        the first motion pays for changing it like every other (a path that starts by
        flicking the steering the other way makes the vehicle weave); ``open_cost``: the
        cost of a cell that ``cost`` closes (inf) but ``blocked`` does not (grown for a
        point, where the discs decide what fits), None to keep it closed;
        ``arrival``: (x, y, radius, ahead, left), a waypoint reached when the rear axle or
        the point ``ahead``, ``left`` of it in the vehicle frame comes within ``radius``
        (tested from the first motion on); ``seen``: the cells a reverse motion may end
        on (None: all; no sensor looks behind the vehicle, so a reverse should keep to
        ground the map has seen). Only the search's window of each array is read.
        """
        g = gridsize
        shape = blocked.shape
        xs = (start[0], target[0])
        ys = (start[1], target[1])
        pad = self.window_margin
        i0 = max(0, int(math.floor((min(xs) - pad - origin[0]) / g)))
        i1 = min(shape[0], int(math.ceil((max(xs) + pad - origin[0]) / g)) + 1)
        j0 = max(0, int(math.floor((min(ys) - pad - origin[1]) / g)))
        j1 = min(shape[1], int(math.ceil((max(ys) + pad - origin[1]) / g)) + 1)
        if i1 - i0 < 2 or j1 - j0 < 2:
            return None
        distances, fine = self._clearance(blocked, gridsize, (i0, i1, j0, j1))
        window_cost = cost[i0:i1, j0:j1]
        if open_cost is not None:
            window_cost = np.where(np.isfinite(window_cost) | blocked[i0:i1, j0:j1],
                                   window_cost, open_cost)
        reversible = (np.ones(window_cost.shape, dtype=np.bool_) if seen is None
                      else np.ascontiguousarray(seen[i0:i1, j0:j1], dtype=np.bool_))
        ox, oy = origin[0] + i0 * g, origin[1] + j0 * g
        ni, nj = window_cost.shape

        def cell(x: float, y: float) -> tuple[int, int] | None:
            i = int(math.floor((x - ox) / g))
            j = int(math.floor((y - oy) / g))
            return (i, j) if 0 <= i < ni and 0 <= j < nj else None

        goal_cell = cell(target[0], target[1])
        start_cell = cell(start[0], start[1])
        if goal_cell is None or start_cell is None:
            return None
        togo = _cost_to(window_cost, goal_cell) * (g * self.heuristic_weight)
        if not math.isfinite(togo[start_cell]):
            return None
        table: Any = distances  # a list of lists for the Python loop, below
        offsets = sorted(self.offsets, reverse=True)  # the front meets obstacles first
        inv = 1.0 / (g / fine)
        mi, mj = distances.shape

        def body_clearance(x: float, y: float, c: float, s: float) -> float:
            least = math.inf
            for o in offsets:
                fi = (x + o * c - ox) * inv
                fj = (y + o * s - oy) * inv
                if not (0.0 <= fi < mi and 0.0 <= fj < mj):
                    return -math.inf
                least = min(least, table[int(fi)][int(fj)])
            return least

        # A vehicle already closer to an obstacle than the discs need (squeezed by a
        # slalom, stopped at a halt) may leave: the clearance asked of it grows from
        # what it has (less 5 cm of noise) by ``escape_rate`` per metre driven until it
        # is the full need.
        need = self.need
        start_clearance = body_clearance(start[0], start[1], math.cos(start[2]),
                                         math.sin(start[2]))
        escape_from = min(need, start_clearance)
        escape_rate = self.escape_rate

        if self.kernel is not None:
            return self._search_compiled(distances, fine, window_cost, togo, (ox, oy), g,
                                         start, target, curvature, float(escape_from),
                                         arrival, reversible)
        table = distances.tolist()  # plain floats index faster than an array
        tx, ty, th = target
        tol2 = self.position_tolerance ** 2
        bin_width = 2.0 * math.pi / self.bins

        def key(x: float, y: float, h: float) -> tuple[int, int, int]:
            return (int(math.floor((x - ox) / g)), int(math.floor((y - oy) / g)),
                    int(round(h / bin_width)) % self.bins)

        poses: list[Pose] = [start]
        parents: list[int] = [-1]
        kappas: list[float] = [math.nan if curvature is None else float(curvature)]
        signs: list[int] = [1]  # the vehicle is taken to be driving forwards
        costs: list[float] = [0.0]
        travel: list[float] = [0.0]
        best: dict[tuple[int, int, int], float] = {key(*start): 0.0}
        closed: set[tuple[int, int, int]] = set()
        frontier: list[tuple[float, int]] = [(float(togo[start_cell]), 0)]
        expansions = 0
        while frontier and expansions < self.max_expansions:
            _, n = heapq.heappop(frontier)
            x, y, h = poses[n]
            k_n = key(x, y, h)
            if k_n in closed:
                continue
            closed.add(k_n)
            expansions += 1
            c, s = math.cos(h), math.sin(h)
            if (x - tx) ** 2 + (y - ty) ** 2 <= tol2 and (
                    th is None or abs(_wrap(h - th)) <= self.heading_tolerance) or (
                    n > 0 and arrival is not None and reached(
                        x, y, c, s, arrival[3:], arrival[0], arrival[1], arrival[2])):
                return self._path(poses, parents, kappas, signs if self.reverse_cost > 0.0
                                  else None, n, expansions, self.step)
            required = min(need, escape_from - 0.05 + escape_rate * travel[n])
            for kappa, sign, samples in self._motions:
                ok = True
                for ax, ay, turn in samples:
                    if body_clearance(x + ax * c - ay * s, y + ax * s + ay * c,
                                      math.cos(h + turn), math.sin(h + turn)) <= required:
                        ok = False
                        break
                if not ok:
                    continue
                ex, ey, turn = samples[-1]
                nx, ny, nh = x + ex * c - ey * s, y + ex * s + ey * c, _wrap(h + turn)
                here = cell(nx, ny)
                if here is None:
                    continue
                remaining = togo[here]
                if not math.isfinite(remaining) or (sign < 0 and not reversible[here]):
                    continue
                step_cost = self.step * float(window_cost[here])
                if not math.isfinite(step_cost):
                    continue
                if sign < 0:
                    step_cost *= self.reverse_cost
                if sign != signs[n]:
                    step_cost += self.switch_cost
                previous = kappas[n]
                if not math.isnan(previous):
                    step_cost += self.curvature_change_cost * abs(kappa - previous) / \
                        max(abs(self.curvatures[0]), 1e-9)
                total = costs[n] + step_cost
                k_new = key(nx, ny, nh)
                if k_new in closed or total >= best.get(k_new, math.inf):
                    continue
                best[k_new] = total
                poses.append((nx, ny, nh))
                parents.append(n)
                kappas.append(kappa)
                signs.append(sign)
                costs.append(total)
                travel.append(travel[n] + self.step)
                heapq.heappush(frontier, (total + float(remaining), len(poses) - 1))
        return None

    def _search_compiled(self, distances: NDArray[np.float64], fine: int,
                         window_cost: NDArray[np.float64], togo: NDArray[np.float64],
                         corner: tuple[float, float], g: float, start: Pose,
                         target: tuple[float, float, float | None], curvature: float | None,
                         escape_from: float, arrival: Arrival | None,
                         reversible: NDArray[np.bool_]) -> Refined | None:
        """:meth:`plan`'s search by the compiled kernel (``components/find_path/
        _search_jit.py``): the same states in the same order, the same path."""
        capacity = self.max_expansions * len(self._motions) + 1
        poses = np.empty((capacity, 3))
        parents = np.empty(capacity, dtype=np.int64)
        kappas = np.empty(capacity)
        signs = np.empty(capacity)
        th = target[2]
        found, expansions, _ = self.kernel(
            np.ascontiguousarray(distances, dtype=np.float64), 1.0 / (g / fine),
            np.ascontiguousarray(window_cost, dtype=np.float64),
            np.ascontiguousarray(togo, dtype=np.float64), corner[0], corner[1], float(g),
            np.array(sorted(self.offsets, reverse=True), dtype=np.float64),
            self._motion_curvatures, self._motion_signs, self._motion_samples, reversible,
            np.array([start[0], start[1], start[2],
                      math.nan if curvature is None else float(curvature), self.need,
                      escape_from, self.escape_rate]),
            np.array([target[0], target[1], 0.0 if th is None else th,
                      0.0 if th is None else 1.0,
                      *((arrival[0], arrival[1], arrival[2] * arrival[2], arrival[3],
                         arrival[4])
                        if arrival is not None else (0.0, 0.0, -1.0, 0.0, 0.0))]),
            self.curvatures[0], self.position_tolerance ** 2, self.heading_tolerance,
            self.curvature_change_cost, self.reverse_cost, self.switch_cost, self.step,
            self.bins, self.max_expansions, poses, parents, kappas, signs)
        if found < 0:
            return None
        chain: list[int] = []
        n = int(found)
        while n >= 0:
            chain.append(n)
            n = int(parents[n])
        chain.reverse()
        return Refined([(float(poses[m, 0]), float(poses[m, 1]), float(poses[m, 2]))
                        for m in chain], [float(kappas[m]) for m in chain[1:]],
                       int(expansions), self.step,
                       tuple(int(signs[m]) for m in chain[1:]) if self.reverse_cost > 0.0
                       else ())

    def _clearance(self, blocked: NDArray[np.bool_], gridsize: float,
                   window: tuple[int, int, int, int]) -> tuple[NDArray[np.float64], int]:
        """The distance (m, capped a little beyond what a disc needs) from each sub-cell
        of the window, ``fine`` per cell, to the centre of the nearest impassable cell
        (looking beyond the window's edge as far as that matters)."""
        i0, i1, j0, j1 = window
        fine = max(1, int(round(gridsize / self.resolution)))
        if fine % 2 == 0:
            fine += 1  # an odd count puts a sub-cell's centre on the cell's centre
        step = gridsize / fine
        need = self.need
        reach = int(math.ceil(need / gridsize)) + 1
        a0, b0 = max(0, i0 - reach), max(0, j0 - reach)
        a1, b1 = min(blocked.shape[0], i1 + reach), min(blocked.shape[1], j1 + reach)
        region = blocked[a0:a1, b0:b1]
        shape = ((i1 - i0) * fine, (j1 - j0) * fine)
        if not region.any():
            return np.full(shape, need + gridsize), fine
        free = np.ones((region.shape[0] * fine, region.shape[1] * fine), dtype=bool)
        free[fine // 2::fine, fine // 2::fine] = ~region
        distance = ndimage.distance_transform_edt(free) * step
        di, dj = (i0 - a0) * fine, (j0 - b0) * fine
        return np.minimum(distance[di:di + shape[0], dj:dj + shape[1]], need + gridsize), fine

    @staticmethod
    def _path(poses: list[Pose], parents: list[int], kappas: list[float],
              signs: list[int] | None, n: int, expansions: int, step: float) -> Refined:
        chain: list[int] = []
        while n >= 0:
            chain.append(n)
            n = parents[n]
        chain.reverse()
        return Refined([poses[m] for m in chain], [kappas[m] for m in chain[1:]], expansions,
                       step, () if signs is None else tuple(signs[m] for m in chain[1:]))


def _arc(kappa: float, s: float) -> tuple[float, float]:
    """The point after arc length ``s`` on the arc of curvature ``kappa`` from the origin
    heading along +x (left positive)."""
    if abs(kappa) < 1e-12:
        return (s, 0.0)
    return (math.sin(kappa * s) / kappa, (1.0 - math.cos(kappa * s)) / kappa)


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def _cost_to(cost: NDArray[np.float64], goal: tuple[int, int]) -> NDArray[np.float64]:
    """Cost (in cells) from every cell to ``goal`` for a point moving between
    8-connected cells, each move its length times the mean of the two cells' costs;
    inf where unreachable."""
    ni, nj = cost.shape
    index = np.arange(ni * nj).reshape(ni, nj)
    passable = np.isfinite(cost)
    rows, cols, weights = [], [], []
    for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1)):
        a = index[max(0, -di):ni - max(0, di), max(0, -dj):nj - max(0, dj)]
        b = index[max(0, di):ni - max(0, -di), max(0, dj):nj - max(0, -dj)]
        ca = cost.ravel()[a.ravel()]
        cb = cost.ravel()[b.ravel()]
        ok = passable.ravel()[a.ravel()] & passable.ravel()[b.ravel()]
        w = math.hypot(di, dj) * 0.5 * (ca + cb)
        rows += [a.ravel()[ok], b.ravel()[ok]]
        cols += [b.ravel()[ok], a.ravel()[ok]]
        weights += [w[ok], w[ok]]
    graph = csr_matrix((np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(ni * nj, ni * nj))
    togo = dijkstra(graph, directed=True, indices=int(index[goal]))
    return np.asarray(togo, dtype=np.float64).reshape(ni, nj)
