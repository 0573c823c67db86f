"""Mission waypoints in the pose frame: the one conversion Pure Pursuit, the Global Map
and FindPath share.

A :class:`~idl.planning.WaypointIDL` holds WGS84 latitude/longitude (and, if the operator
gave them, UTM easting/northing). The pose frame (``Pose`` events, seed Table 21) is
metres east and north of ``initialUTM`` in its UTM grid (the zone and hemisphere of the
first GPS fix, which ModelServer keeps for the whole run). A waypoint's UTM coordinates
come from its latitude/longitude (``components.gps_sokkia.codec``, a millimetre-accurate
Krüger series) in that grid, unless easting and northing are given. The pose does not
carry the grid, so the grid is the one in which the waypoint lies nearest
``initialUTM`` (:func:`~components.gps_sokkia.codec.latlon_to_grid_near`): its own zone
and hemisphere, or, for a course across a zone boundary or the equator, the vehicle's.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from components.gps_sokkia.codec import latlon_to_grid_near
from idl import WaypointIDL

__all__ = ["to_local", "all_to_local"]


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
