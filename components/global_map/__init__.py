"""Global Map (seed §3.2.3): cumulative traversability, Table 18 planning interface."""

from afa.registry import not_implemented
from components.global_map.parameters import GlobalMapParameters

GlobalMap = not_implemented("GlobalMap", GlobalMapParameters, "Global Map: the maps capability")

__all__ = ["GlobalMap", "GlobalMapParameters"]
