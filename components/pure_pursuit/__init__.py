"""Pure Pursuit (seed §3.3.3): waypoint following with Gaussian arc votes."""

from afa.registry import not_implemented
from components.pure_pursuit.parameters import PurePursuitParameters

PurePursuit = not_implemented("PurePursuit", PurePursuitParameters,
                              "Pure Pursuit: the planning capability")

__all__ = ["PurePursuit", "PurePursuitParameters"]
