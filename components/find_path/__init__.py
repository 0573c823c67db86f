"""FindPath (seed §3.3.1): D* Lite planning over the Global Map."""

from afa.registry import not_implemented
from components.find_path.parameters import FindPathParameters

FindPath = not_implemented("FindPath", FindPathParameters, "FindPath: the planning capability")

__all__ = ["FindPath", "FindPathParameters"]
