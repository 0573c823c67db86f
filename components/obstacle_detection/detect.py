"""Obstacle Detection's core (seed §3.3.4, Table A.11): the laser safety catch.

Pure Python + numpy: no asyncio, no framework. The component transforms each
``Range3dLaserIDL`` scan's valid points into the frame below, calls
:meth:`ObstacleDetector.update`, and publishes the votes it returns (if any).

The frame: *laser-level vehicle frame*
--------------------------------------
Points (n, 3) are expected with vehicle-aligned axes (x forward along the vehicle's
centre line, y left, z up; not the laser's own toed-out, nodding axes), with the origin on
the centre line, at the laser's x and at the laser's height. The seed checks the 3-D
returns "adjusting for the height at which the sensor is mounted above the wheels": the
ground plane is z = −``LaserHeight`` (2 m, docs/geometry.md), so a return's height above
the ground is h = z + LaserHeight. The ground plane is the vehicle's own (it tilts with
the vehicle, as the seed's does: a safety catch, not a terrain model). The component
gets this frame from ModelServer as ^RearAxle T_laser with the rear-axle-frame offset
(x_laser, 0, z_laser) subtracted.

Ranges: returns at or beyond ``MaxLaserRange`` (mm; 8191 is the LMS's "no echo" value)
are ignored, as are points with a NaN coordinate. Ranges are the points' distance from
the origin unless the component passes the measured ranges (the laser sits 0.35 m off
the centre line, so the two differ slightly).

The check
---------
A return is *in the corridor* when 0 ≤ x ≤ ``SafetyDist`` and
|y| ≤ min(``VehicleWidth``/2, ``DefaultYMax``). In the corridor it is a *positive* hit
when h > ``SafetyHeight`` (if ``CheckPosObs``) and a *negative* hit when
h < −``SafetyDepth`` (if ``CheckNegObs``). Table A.11's ``VehicleWidth`` 1 m is narrower
than the Raptor's 1.4 m body: configure 1.4 (or more) for the Raptor.

States, and what the arbiter sees
---------------------------------
- *armed*: each scan is checked. ``NumHitsTolerance`` hits or more (positive and
  negative together) → a **halt** vote (every arc vetoed, :meth:`ArcVotes.halt`) and the
  detector *holds*. Fewer (noise, a blade of grass) → a **clear** vote: no vetoes, votes
  0, certainty 0, maxSpeed ``max_speed`` on every arc. It weighs nothing in the
  arbiter's sum (certainty 0), does not limit speed below the vehicle's top speed, and
  keeps the catch visibly alive; it also replaces an earlier halt once rechecking finds
  the way clear.
- *holding*: the next ``ResetCounter`` scans are not checked and **nothing** is
  published (``votes`` is None). The halt stays the detector's latest vote, so it keeps
  the vehicle stopped until the arbiter finds it stale (``StaleVoteTime``, 1.5 s); the
  other behaviours may then move the vehicle away from what stopped it, and the catch
  rechecks after the hold (200 scans ≈ 5.3 s at 26.6 ms). This is the seed's
  "how many laser scans to wait after a halt before rechecking".
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from components.arcs import ArcSet, ArcVotes
from components.obstacle_detection.parameters import ObstacleDetectionParameters

__all__ = ["ObstacleDetector", "DetectionResult", "HitCount", "count_hits", "DetectorState"]

DetectorState = Literal["armed", "holding"]


@dataclass(frozen=True)
class HitCount:
    """Returns of one scan beyond the safety height (``positive``) or depth
    (``negative``) inside the corridor; ``considered`` returns were in the corridor."""

    positive: int
    negative: int
    considered: int

    @property
    def total(self) -> int:
        return self.positive + self.negative


def count_hits(points: ArrayLike, parameters: ObstacleDetectionParameters,
               ranges: ArrayLike | None = None) -> HitCount:
    """Count one scan's hits (module docstring); ``points`` (n, 3) in the laser-level
    vehicle frame (m), ``ranges`` (n,) optional measured ranges (m).

    Raises ValueError if ``points`` is not (n, 3) or ``ranges`` not (n,).
    """
    p = parameters
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must be (n, 3), got {pts.shape}")
    if ranges is None:
        rng = np.sqrt(np.einsum("ij,ij->i", pts, pts))
    else:
        rng = np.asarray(ranges, dtype=np.float64)
        if rng.shape != (pts.shape[0],):
            raise ValueError(f"ranges must be ({pts.shape[0]},), got {rng.shape}")
    x, y, z = pts[:, 0], pts[:, 1], pts[:, 2]
    half_width = min(p.VehicleWidth / 2.0, p.DefaultYMax)
    # NaN fails every comparison below, so NaN points and ranges drop out.
    inside = ((x >= 0.0) & (x <= p.SafetyDist) & (np.abs(y) <= half_width)
              & (rng < p.MaxLaserRange / 1000.0))
    height = z[inside] + p.LaserHeight
    positive = int(np.count_nonzero(height > p.SafetyHeight)) if p.CheckPosObs else 0
    negative = int(np.count_nonzero(height < -p.SafetyDepth)) if p.CheckNegObs else 0
    return HitCount(positive, negative, int(np.count_nonzero(inside)))


@dataclass(frozen=True, eq=False)
class DetectionResult:
    """One scan's outcome: the votes to publish (None while holding), whether this scan
    halted, the hits counted (None while holding) and the scans left before rechecking."""

    votes: ArcVotes | None
    halt: bool
    hits: HitCount | None
    state: DetectorState
    scans_to_recheck: int


class ObstacleDetector:
    """The stateful safety catch (module docstring).

    ``max_speed`` (m/s, finite, > 0) is the speed the clear vote allows, the vehicle's
    top speed (Table A.13's MaxTransVelocity 2000 mm/s). Raises ValueError otherwise.
    """

    def __init__(self, parameters: ObstacleDetectionParameters, arcs: ArcSet, *,
                 max_speed: float = 2.0) -> None:
        if not (math.isfinite(max_speed) and max_speed > 0.0):
            raise ValueError(f"max_speed must be finite and > 0, got {max_speed}")
        self.parameters = parameters
        self.arcs = arcs
        n = len(arcs)
        self._halt = ArcVotes.halt(n)
        self._clear = ArcVotes(np.zeros(n, dtype=bool), np.zeros(n), np.zeros(n),
                               np.full(n, float(max_speed)))
        self._hold = 0

    @property
    def state(self) -> DetectorState:
        return "holding" if self._hold > 0 else "armed"

    @property
    def clear_votes(self) -> ArcVotes:
        """The vote published for a scan below tolerance."""
        return self._clear

    def reset(self) -> None:
        """Re-arm at once (e.g. when the component restarts)."""
        self._hold = 0

    def update(self, points: NDArray[np.float64] | ArrayLike,
               ranges: ArrayLike | None = None) -> DetectionResult:
        """Process one scan (see :func:`count_hits` for the arguments and errors)."""
        if self._hold > 0:
            self._hold -= 1
            return DetectionResult(None, False, None, "holding", self._hold)
        hits = count_hits(points, self.parameters, ranges)
        if hits.total >= self.parameters.NumHitsTolerance:
            self._hold = self.parameters.ResetCounter
            return DetectionResult(self._halt, True, hits, self.state, self._hold)
        return DetectionResult(self._clear, False, hits, "armed", 0)
