"""Obstacle Avoidance (seed §3.3.2): candidate arcs scored on the traversability map."""

from afa.registry import not_implemented
from components.obstacle_avoidance.parameters import ObstacleAvoidanceParameters

ObstacleAvoidance = not_implemented("ObstacleAvoidance", ObstacleAvoidanceParameters,
                                    "Obstacle Avoidance: the planning capability")

__all__ = ["ObstacleAvoidance", "ObstacleAvoidanceParameters"]
