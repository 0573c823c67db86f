"""Mission waypoints in the pose frame: the one conversion Pure Pursuit, the Global Map
and FindPath share, and the one arrival rule (decision 0042).

A :class:`~idl.planning.WaypointIDL` holds WGS84 latitude/longitude (and, if the operator
gave them, UTM easting/northing). The pose frame (``Pose`` events, seed Table 21) is
metres east and north of ``initialUTM`` in its UTM grid (the zone and hemisphere of the
first GPS fix, which ModelServer keeps for the whole run). A waypoint's UTM coordinates
come from its latitude/longitude (``components.gps_sokkia.codec``, a millimetre-accurate
Krüger series) in that grid, unless easting and northing are given. The pose does not
carry the grid, so the grid is the one in which the waypoint lies nearest
``initialUTM`` (:func:`~components.gps_sokkia.codec.latlon_to_grid_near`): its own zone
and hemisphere, or, for a course across a zone boundary or the equator, the vehicle's.

A waypoint is reached when the rear axle (the pose's point, the one the arcs steer) or
the ground under the front bumper (``GroundFrame``, whose place on the vehicle
:func:`ground_point` asks ModelServer) comes within its tolerance: :func:`reached`.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Literal

import numpy as np

from afa import EOutOfBounds
from afa.errors import AfaError
from components.gps_sokkia.codec import latlon_to_grid_near
from idl import Platform, WaypointIDL

__all__ = ["to_local", "all_to_local", "reached", "ground_point", "VEHICLE_FRAME"]

#: The frame of the pose ModelServer publishes: the rear axle's centre (the one name
#: every component uses; afa/ keeps its own copies, as it may not import components).
VEHICLE_FRAME = "Raptor:RearAxleCenter"


def to_local(waypoint: WaypointIDL, initial_utm: Sequence[float] | np.ndarray) -> tuple[float,
                                                                                        float]:
    """(x east, y north) of ``waypoint`` in metres from ``initial_utm``."""
    if waypoint.easting is not None and waypoint.northing is not None:
        easting, northing = waypoint.easting, waypoint.northing
    else:
        utm = latlon_to_grid_near(waypoint.latitude, waypoint.longitude,
                                  float(initial_utm[0]), float(initial_utm[1]))
        easting, northing = utm.easting_m, utm.northing_m
    return float(easting - initial_utm[0]), float(northing - initial_utm[1])


def all_to_local(waypoints: Sequence[WaypointIDL],
                 initial_utm: Sequence[float] | np.ndarray) -> list[tuple[float, float]]:
    return [to_local(w, initial_utm) for w in waypoints]


def reached(x: float, y: float, c: float, s: float, front: tuple[float, float],
            wx: float, wy: float, radius: float) -> bool:
    """Whether a vehicle whose rear axle is at (x, y), heading (cos, sin) = (c, s), has
    reached (wx, wy): the rear axle, or the point ``front`` = (ahead, left) of it in the
    vehicle frame, within ``radius``. Squared distances, compared as FindPath's compiled
    search compares them (``components/find_path/_search_jit.py``)."""
    r2 = radius * radius
    ahead, left = front
    return ((x - wx) ** 2 + (y - wy) ** 2 <= r2
            or (x + ahead * c - left * s - wx) ** 2 + (y + ahead * s + left * c - wy) ** 2
            <= r2)


async def ground_point(platform: Platform, frame: str, log: logging.Logger
                       ) -> tuple[float, float] | Literal[False] | None:
    """Where ``frame`` (the ground under the front bumper) lies on the vehicle: (ahead,
    left) of the rear axle, m, from ModelServer's ``getTransformation``; False, logged as
    a warning, when ModelServer does not know the frame (arrival is then judged by the
    rear axle alone); None while ModelServer is not reachable (ask again later)."""
    try:
        transform = await platform.getTransformation(VEHICLE_FRAME, frame)
    except EOutOfBounds as exc:
        log.warning("ModelServer does not know the frame %r (%s): waypoints are reached by "
                    "the rear axle only", frame, exc)
        return False
    except AfaError:
        return None
    h = np.asarray(transform.HTransform, dtype=np.float64)
    return float(h[0, 3]), float(h[1, 3])
