"""Pure Pursuit (seed §3.3.3): waypoint following with Gaussian arc votes."""

from components.pure_pursuit.component import PurePursuit
from components.pure_pursuit.parameters import PurePursuitParameters

__all__ = ["PurePursuit", "PurePursuitParameters"]
