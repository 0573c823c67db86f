"""FindPath (seed §3.3.1): D* Lite over the Global Map, tracked by arc votes."""

from components.find_path.component import FindPath
from components.find_path.parameters import FindPathParameters

__all__ = ["FindPath", "FindPathParameters"]
