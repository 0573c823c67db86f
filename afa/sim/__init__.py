"""The simulated world: world files, the terrain heightfield, the Raptor's motion model
and ray casting for the sensor emulators. Pure numpy/lxml, no asyncio (docs/worlds.md).

- :mod:`afa.sim.world` — world files (:func:`load_world`) and geodetic conversion
- :mod:`afa.sim.terrain` — :class:`Terrain`, the 2.5-D heightfield with obstacles
- :mod:`afa.sim.vehicle` — :class:`Vehicle`, the kinematic bicycle with collisions
- :mod:`afa.sim.raycast` — :func:`laser_scan`, :func:`depth_image`, :func:`cast_rays`
"""

from afa.sim.raycast import camera_directions, cast_rays, depth_image, laser_directions, laser_scan
from afa.sim.terrain import Terrain
from afa.sim.vehicle import (
    GRAVITY,
    Collision,
    DriveResult,
    Vehicle,
    VehicleParameters,
    VehicleState,
    run_drive,
)
from afa.sim.world import (
    DriveCommand,
    Mission,
    Obstacle,
    Origin,
    TerrainSpec,
    VehicleStart,
    Waypoint,
    World,
    load_world,
    parse_world,
)

__all__ = [
    "World", "Origin", "TerrainSpec", "Obstacle", "VehicleStart", "Waypoint", "Mission",
    "DriveCommand", "load_world", "parse_world",
    "Terrain",
    "Vehicle", "VehicleParameters", "VehicleState", "Collision", "DriveResult", "run_drive",
    "GRAVITY",
    "cast_rays", "laser_scan", "laser_directions", "camera_directions", "depth_image",
]
