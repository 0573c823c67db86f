"""Where the Terrain Map puts the vehicle when it stitches scans: the pose *stabilised*
against the GPS's wander. Pure Python and numpy: no asyncio, no afa.

A 2.5-D map stitches scans taken seconds apart, each placed with the pose of its own
instant, so what matters to the map is that the pose is *consistent over seconds*, more
than that it is right to the centimetre. The raw pose is not: its position is the GPS
fix (the RT-20: 0.17 m per axis horizontally, twice that vertically), whose error
wanders by about 0.1 m in one second and 0.17 m in three (measured on the
alternating-ditches mission, decision 0033). The same ditch edge seen one second and
three seconds before it is reached lands in cells a decimetre or two apart: the map
smears it over a second cell, misses the ditch's near strip and marks its far lip.

:class:`PoseStabiliser` replaces the pose's position by one *predicted from the
vehicle's own motion* and pulled towards the measured position with a time constant:

- the motion between two poses is the distance the rear axle rolled
  (:class:`OdometryTrack`: the front wheels' mean distance, times the cosine of the
  steering angle for the rear axle's shorter path in a turn) along the vehicle's x axis
  (from the IMU's attitude, the mean of the two poses' axes), in three dimensions;
- without odometry (none configured, none recorded, or none for :data:`STALE`
  seconds) the horizontal motion is the measured one and the vertical is the forward
  part of it times the x axis's slope;
- the horizontal position is pulled towards the measured one with
  :data:`PLANE_TIME` (10 s), the height with :data:`HEIGHT_TIME` (600 s): heights are
  locally consistent and follow the ground, their absolute level drifts slowly
  (irrelevant to hazards, which are differences); horizontally the map keeps the
  GPS's placement averaged over seconds instead of its instant wander.

With the RT-20's error model and exact odometry this takes the change of the placement
error over three seconds from 0.17 m to about 0.04 m RMS. Real wheels slip: a few per
cent of the distance rolled in ten seconds, also slowly varying, so still consistent
over the seconds a map is stitched from. The stabilised position differs from the raw
pose by 0.15 m RMS; the ego map is placed with it. The Terrain Map feeds it wheel
reports when its ``OdometryEventName`` names them; the shipped configuration does not
(decision 0033: every world's figures either way).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["PoseStabiliser", "OdometryTrack", "HEIGHT_TIME", "PLANE_TIME", "STALE"]

#: Time constant (s) with which the stabilised height follows the pose's.
HEIGHT_TIME = 600.0
#: Time constant (s) with which the stabilised horizontal position follows the pose's.
PLANE_TIME = 10.0
#: Odometry this much older than a pose (s) is not extrapolated to it.
STALE = 0.5
#: Odometry samples kept (5 a second: 6 s).
TRACK_LENGTH = 32
#: A report whose distance jumped by more than this beyond what its speed allows (m)
#: starts the track again (the controller restarted its counters).
JUMP = 0.5


class OdometryTrack:
    """The rear axle's rolled distance over time, from wheel reports: interpolated
    between reports and extrapolated by the last speed for at most :data:`STALE`
    seconds after the last one."""

    def __init__(self, length: int = TRACK_LENGTH) -> None:
        self._samples: deque[tuple[float, float, float]] = deque(maxlen=length)
        self._front: float | None = None  # the previous report's front-wheel mean
        self.rolled = 0.0  # rear-axle distance since the track started (m)
        self.restarts = 0

    def add(self, time: float, left: float, right: float, left_speed: float,
            right_speed: float, steering: float) -> None:
        """A wheel report: cumulative front-wheel distances (m), speeds (m/s), steering
        angle (rad). Reports older than the newest are ignored."""
        if self._samples and time <= self._samples[-1][0]:
            return
        front = 0.5 * (left + right)
        rear = math.cos(steering)
        speed = 0.5 * (left_speed + right_speed) * rear
        if self._front is not None and self._samples:
            step = front - self._front
            dt = time - self._samples[-1][0]
            if abs(step) > abs(speed) * dt + JUMP:
                self._samples.clear()  # counters restarted: continue from here
                self.restarts += 1
            else:
                self.rolled += step * rear
        self._front = front
        self._samples.append((time, self.rolled, speed))

    def at(self, time: float) -> float | None:
        """Rolled distance at ``time``, or None when the track does not reach it."""
        samples = self._samples
        if not samples:
            return None
        t1, s1, v1 = samples[-1]
        if time >= t1:
            return s1 + v1 * (time - t1) if time - t1 <= STALE else None
        if time < samples[0][0]:
            return None
        for k in range(len(samples) - 2, -1, -1):
            t0, s0, _ = samples[k]
            if t0 <= time:
                t1, s1, _ = samples[k + 1]
                return s0 + (s1 - s0) * (time - t0) / (t1 - t0)
        return None  # pragma: no cover - time >= samples[0][0] ends the loop

    def clear(self) -> None:
        self._samples.clear()
        self._front = None


class PoseStabiliser:
    """The vehicle's position for stitching scans (module doc). Call it with each pose
    in time order; feed wheel reports to :attr:`odometry`."""

    def __init__(self, height_tau: float = HEIGHT_TIME,
                 plane_tau: float = PLANE_TIME) -> None:
        self.height_tau = height_tau
        self.plane_tau = plane_tau
        self.odometry = OdometryTrack()
        self._last: tuple[float, NDArray[np.float64], float | None] | None = None
        self.position = np.zeros(3)
        self._offset = np.zeros(2)  # horizontal: stabilised less measured
        #: poses placed with odometry, and without (no odometry for them)
        self.counts = {"odometry": 0, "no_odometry": 0}

    def reset(self) -> None:
        self._last = None
        self.odometry.clear()

    def __call__(self, time: float, world_from_vehicle: ArrayLike) -> NDArray[np.float64]:
        """``world_from_vehicle`` with its position replaced by the stabilised one."""
        pose = np.array(world_from_vehicle, dtype=np.float64)
        measured = pose[:3, 3].copy()
        rolled = self.odometry.at(time)
        # a second pose at the same stamp (a GPS fix and an IMU sample of one instant)
        # continues the filter with dt = 0; only time going back starts it again
        if self._last is None or time < self._last[0]:
            self.position = measured
            self._offset = np.zeros(2)
        else:
            t0, previous, rolled0 = self._last
            dt = time - t0
            plane = dt / (self.plane_tau + dt)
            height = dt / (self.height_tau + dt)
            if rolled is not None and rolled0 is not None:
                axis = previous[:3, 0] + pose[:3, 0]  # the x axis over the interval
                norm = float(np.linalg.norm(axis))
                axis = axis / norm if norm > 1e-9 else pose[:3, 0]
                predicted = self.position + (rolled - rolled0) * axis
                self.position = predicted + np.array((plane, plane, height)) \
                    * (measured - predicted)
                self._offset = self.position[:2] - measured[:2]
                self.counts["odometry"] += 1
            else:
                # the GPS's motion: horizontally the measured position (less what is
                # left of an offset the wheels built up), the height by the forward
                # part of the motion times the slope
                axis = pose[:3, 0]
                level = math.hypot(axis[0], axis[1])
                moved = pose[:2, 3] - previous[:2, 3]
                forward = float(moved @ axis[:2]) / level if level > 1e-9 else 0.0
                z = self.position[2] + forward * float(axis[2]) / max(level, 1e-9)
                self._offset = self._offset * (1.0 - plane)
                self.position = np.array((measured[0] + self._offset[0],
                                          measured[1] + self._offset[1],
                                          z + height * (measured[2] - z)))
                self.counts["no_odometry"] += 1
        self._last = (time, pose.copy(), rolled)
        pose[:3, 3] = self.position
        return pose
