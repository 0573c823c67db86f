"""Backing out of a dead end (afa addition to the Arc Arbiter). Pure numpy: no asyncio.

Every candidate arc runs forwards, so a vehicle that drove into a corner (a cul-de-sac's
end, a trunk on either side of the bumper) can find every arc vetoed and would stand
there for ever. The arbiter then *backs out*: once every arc has been vetoed for
``RecoverAfter`` seconds, it reverses ``RecoverDistance`` metres at ``RecoverSpeed`` with
the steering that turns the vehicle towards the arc the behaviours would prefer were
nothing vetoed (reversing with the wheels turned right swings the nose left: the second
leg of a three-point turn). Then it hands back to the votes, which now look at the
obstacle from further off and at another angle.

Behind the vehicle no sensor looks, so the reverse sweep is checked on the latest global
Traversability map (north-up, world frame; it holds the ground the vehicle drove over,
seen on the way in): discs of ``VehicleRadius`` at ``DiscOffsets`` along the body are
swept backwards along each candidate arc, and an arc is clear when no hazard cell
(hazard 1) or unknown cell comes within a disc's radius: the ground the vehicle backs
over must be ground the map has seen (it came over it), never the unseen edge of the
world. A cell the body already overlaps (the vehicle stands there and has not collided:
a map cell is coarser than the body) blocks only if the sweep brings it closer still.
Candidates are tried from the steering
that turns most towards the preferred arc; when none is clear the vehicle keeps standing.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from components.arcs import arc_points

__all__ = ["reverse_clearance", "reverse_candidates"]

#: Arc-length step (m) of the reverse sweep.
SWEEP_STEP = 0.1


def reverse_candidates(curvatures: NDArray[np.float64], preferred: float) -> list[int]:
    """Arc indices in the order a reverse is tried: the arc whose reverse turns the
    vehicle most like ``preferred`` (the mirror curvature, −preferred) first."""
    target = -preferred
    order = sorted(range(len(curvatures)),
                   key=lambda i: (abs(float(curvatures[i]) - target), abs(float(curvatures[i]))))
    return order


def reverse_clearance(trav: Any, curvature: float, distance: float, *, radius: float,
                      offsets: tuple[float, ...], map_offset: float,
                      threshold: float = 1.0) -> bool:
    """True when reversing ``distance`` metres along ``curvature`` is clear on ``trav``
    (a TravMapArrayEventIDL: world frame, rows along x (east), columns along y (north)),
    whose ``vehiclePosition`` lies ``map_offset`` metres ahead of the rear axle."""
    hazard = np.asarray(trav.hazard, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        blocked = np.argwhere((hazard >= threshold) | np.isnan(hazard))  # unknown too
    if len(blocked) == 0:
        return True
    g = float(trav.gridsize)
    heading = float(trav.vehicleHeading)
    c, s = math.cos(heading), math.sin(heading)
    rear_x = float(trav.vehiclePosition.x) - map_offset * c
    rear_y = float(trav.vehiclePosition.y) - map_offset * s
    steps = max(1, math.ceil(distance / SWEEP_STEP - 1e-9))
    travel = -np.linspace(0.0, distance, steps + 1)
    xs, ys = [], []
    for a in offsets:
        x, y, _ = arc_points(travel, curvature, a)
        xs.append(rear_x + x * c - y * s)
        ys.append(rear_y + x * s + y * c)
    px = np.stack(xs)  # (offsets, steps + 1)
    py = np.stack(ys)
    x0 = float(trav.originX) + blocked[:, 0] * g  # cell rectangles
    y0 = float(trav.originY) + blocked[:, 1] * g
    # distance from every disc centre to every hazard cell's rectangle
    dx = np.maximum(np.maximum(x0[:, None, None] - px, px - (x0[:, None, None] + g)), 0.0)
    dy = np.maximum(np.maximum(y0[:, None, None] - py, py - (y0[:, None, None] + g)), 0.0)
    d = np.hypot(dx, dy).min(axis=1)  # (cells, steps + 1): nearest disc of the body
    start = d[:, 0]
    allowed = np.minimum(radius, start - 1e-9)  # inside already: no closer
    return bool(np.all(d[:, 1:] >= allowed[:, None]))
