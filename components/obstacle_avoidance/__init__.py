"""Obstacle Avoidance (seed §3.3.2): candidate arcs scored on the traversability map."""

from components.obstacle_avoidance.component import ObstacleAvoidance
from components.obstacle_avoidance.parameters import ObstacleAvoidanceParameters

__all__ = ["ObstacleAvoidance", "ObstacleAvoidanceParameters"]
