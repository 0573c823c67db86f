"""Mission waypoints in the pose frame: the one conversion Pure Pursuit, the Global Map
and FindPath share.

A :class:`~idl.planning.WaypointIDL` holds WGS84 latitude/longitude (and, if the operator
gave them, UTM easting/northing). The pose frame (``Pose`` events, seed Table 21) is
metres east and north of ``initialUTM``. A waypoint's UTM coordinates come from its
latitude/longitude in its own zone (``components.gps_sokkia.codec.latlon_to_utm``, a
millimetre-accurate Krüger series) unless easting and northing are given; a mission is
expected to lie in the vehicle's UTM zone (a course across a zone boundary would need the
zone of ``initialUTM``, which the pose does not carry).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from components.gps_sokkia.codec import latlon_to_utm
from idl import WaypointIDL

__all__ = ["to_local", "all_to_local"]


def to_local(waypoint: WaypointIDL, initial_utm: Sequence[float] | np.ndarray) -> tuple[float,
                                                                                        float]:
    """(x east, y north) of ``waypoint`` in metres from ``initial_utm``."""
    if waypoint.easting is not None and waypoint.northing is not None:
        easting, northing = waypoint.easting, waypoint.northing
    else:
        utm = latlon_to_utm(waypoint.latitude, waypoint.longitude)
        easting, northing = utm.easting_m, utm.northing_m
    return float(easting - initial_utm[0]), float(northing - initial_utm[1])


def all_to_local(waypoints: Sequence[WaypointIDL],
                 initial_utm: Sequence[float] | np.ndarray) -> list[tuple[float, float]]:
    return [to_local(w, initial_utm) for w in waypoints]
