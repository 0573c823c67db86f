"""Global Map (seed §3.2.3): the cumulative planning map and Table 18's interface."""

from components.global_map.component import GlobalMap
from components.global_map.parameters import GlobalMapParameters

__all__ = ["GlobalMap", "GlobalMapParameters"]
