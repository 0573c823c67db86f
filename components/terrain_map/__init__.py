"""Terrain Map (seed §3.2.1): fuses range points into 2.5-D grids."""

from components.terrain_map.component import TerrainMap
from components.terrain_map.parameters import TerrainMapParameters

__all__ = ["TerrainMap", "TerrainMapParameters"]
