"""Obstacle Detection (seed §3.3.4): the laser safety catch."""

from afa.registry import not_implemented
from components.obstacle_detection.parameters import ObstacleDetectionParameters

ObstacleDetection = not_implemented("ObstacleDetection", ObstacleDetectionParameters,
                                    "Obstacle Detection: the planning capability")

__all__ = ["ObstacleDetection", "ObstacleDetectionParameters"]
