"""Traversability Map (seed §3.2.2): step and slope hazards, far field, goodness."""

from components.traversability_map.component import TraversabilityMap
from components.traversability_map.parameters import TraversabilityMapParameters

__all__ = ["TraversabilityMap", "TraversabilityMapParameters"]
