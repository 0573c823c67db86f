"""Traversability Map (seed §3.2.2): step and slope hazards, goodness."""

from afa.registry import not_implemented
from components.traversability_map.parameters import TraversabilityMapParameters

TraversabilityMap = not_implemented("TraversabilityMap", TraversabilityMapParameters,
                                    "Traversability Map: the maps capability")

__all__ = ["TraversabilityMap", "TraversabilityMapParameters"]
