"""Obstacle Detection (seed §3.3.4): the laser safety catch."""

from components.obstacle_detection.component import ObstacleDetection
from components.obstacle_detection.parameters import ObstacleDetectionParameters

__all__ = ["ObstacleDetection", "ObstacleDetectionParameters"]
