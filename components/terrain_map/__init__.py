"""Terrain Map (seed §3.2.1): fuses range points into 2.5-D grids."""

from afa.registry import not_implemented
from components.terrain_map.parameters import TerrainMapParameters

TerrainMap = not_implemented("TerrainMap", TerrainMapParameters, "Terrain Map: the maps capability")

__all__ = ["TerrainMap", "TerrainMapParameters"]
