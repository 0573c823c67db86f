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

One exception to "unknown blocks": the *start apron*, a rectangle around where the
arbiter first saw the vehicle on a map: from ``StartApron`` metres behind the rear axle to
the body's front, and ``StartApron`` metres either side of the centre line (at least two
disc radii; decision 0045). The vehicle was put there; a vehicle put down facing an
obstacle closer than it can turn (Obstacle Detection halts it at once) has driven over
nothing yet, and without the apron it would stand there for ever. Turning away takes
more than one back-out, and the later ones swing the tail sideways, so the apron reaches
as far to the sides as behind. Unknown cells in the apron count as ground; hazards there
still block, and so does everything unknown outside it.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from components.arcs import arc_points

__all__ = ["rear_axle", "reverse_clearance", "reverse_candidates"]

#: Arc-length step (m) of the reverse sweep.
SWEEP_STEP = 0.1


def reverse_candidates(curvatures: NDArray[np.float64], preferred: float) -> list[int]:
    """Arc indices in the order a reverse is tried: the arc whose reverse turns the
    vehicle most like ``preferred`` (the mirror curvature, −preferred) first."""
    target = -preferred
    order = sorted(range(len(curvatures)),
                   key=lambda i: (abs(float(curvatures[i]) - target), abs(float(curvatures[i]))))
    return order


def rear_axle(trav: Any, map_offset: float) -> tuple[float, float, float]:
    """The rear axle's (x, y, heading) on ``trav``, whose ``vehiclePosition`` lies
    ``map_offset`` metres ahead of it."""
    heading = float(trav.vehicleHeading)
    return (float(trav.vehiclePosition.x) - map_offset * math.cos(heading),
            float(trav.vehiclePosition.y) - map_offset * math.sin(heading), heading)


def reverse_clearance(trav: Any, curvature: float, distance: float, *, radius: float,
                      offsets: tuple[float, ...], map_offset: float,
                      threshold: float = 1.0,
                      apron: tuple[float, float, float, float, float, float] | None = None
                      ) -> bool:
    """True when reversing ``distance`` metres along ``curvature`` is clear on ``trav``
    (a TravMapArrayEventIDL: world frame, rows along x (east), columns along y (north)),
    whose ``vehiclePosition`` lies ``map_offset`` metres ahead of the rear axle.
    ``apron``: (x, y, heading, behind, ahead, half width) of the start apron (module
    docstring), a rectangle from ``behind`` metres behind (x, y) to ``ahead`` metres
    ahead of it along ``heading``, whose unknown cells count as ground."""
    hazard = np.asarray(trav.hazard, dtype=np.float64)
    g = float(trav.gridsize)
    with np.errstate(invalid="ignore"):
        unknown = np.isnan(hazard)
        if apron is not None:
            ax, ay, ah, behind, ahead, half = apron
            cx = float(trav.originX) + (np.arange(hazard.shape[0])[:, None] + 0.5) * g - ax
            cy = float(trav.originY) + (np.arange(hazard.shape[1])[None, :] + 0.5) * g - ay
            along = cx * math.cos(ah) + cy * math.sin(ah)
            across = -cx * math.sin(ah) + cy * math.cos(ah)
            unknown &= ~((along >= -behind) & (along <= ahead) & (np.abs(across) <= half))
        blocked = np.argwhere((hazard >= threshold) | unknown)
    if len(blocked) == 0:
        return True
    rear_x, rear_y, heading = rear_axle(trav, map_offset)
    c, s = math.cos(heading), math.sin(heading)
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
