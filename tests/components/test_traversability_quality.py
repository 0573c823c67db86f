"""Map quality figures (components/traversability_map/quality.py) on hand-made truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from components.terrain_map.grid import GridGeometry
from components.traversability_map.quality import GroundTruth, assess

# truth: 0.1 m samples over [0, 4) x [0, 4); an obstacle square [1.0, 1.5) x [1.0, 1.5)
N = 40
SURFACE = np.zeros((N, N))
OBSTACLE = np.zeros((N, N), dtype=bool)
OBSTACLE[10:15, 10:15] = True  # [j, i]: north rows, east columns
SURFACE[OBSTACLE] = 0.6
TRUTH = GroundTruth(0.0, 0.0, 0.1, SURFACE, OBSTACLE)
TRAV = GridGeometry(0.0, 0.0, 0.5, 8, 8)


def hazard_with(cells: dict[tuple[int, int], float], fill: float = 0.0) -> np.ndarray:
    h = np.full(TRAV.shape, fill)
    for key, value in cells.items():
        h[key] = value
    return h


def test_detection_and_false_hazards() -> None:
    # the obstacle is exactly trav cell [2, 2]; its ring is the don't-care margin
    q = assess(hazard=hazard_with({(2, 2): 1.0, (1, 2): 1.0, (6, 6): 1.0}),
               hazard_geometry=TRAV, truth=TRUTH, track=[[0.0, 0.0]])
    assert (q.obstacle_cells, q.detected_cells, q.detection_fraction) == (1, 1, 1.0)
    assert (q.unobserved_obstacle_cells, q.detection_fraction_in_range) == (0, 1.0)
    assert q.free_observed_cells == 64 - 9
    assert q.false_hazard_cells == 1  # [6, 6]; [1, 2] lies in the margin
    assert q.false_hazard_fraction == pytest.approx(1 / 55)
    assert math.isnan(q.rms_height_error)


def test_unknown_is_neither_detected_nor_free_and_range_limits_targets() -> None:
    h = hazard_with({(2, 2): np.nan, (5, 5): np.nan})
    q = assess(hazard=h, hazard_geometry=TRAV, truth=TRUTH, track=[[1.0, 1.0]])
    assert (q.obstacle_cells, q.detected_cells) == (1, 0)
    # never seen: reported apart, out of the fraction within sensor range
    assert q.unobserved_obstacle_cells == 1 and math.isnan(q.detection_fraction)
    assert q.detection_fraction_in_range == 0.0
    assert q.free_observed_cells == 64 - 9 - 1
    far = assess(hazard=h, hazard_geometry=TRAV, truth=TRUTH, track=[[20.0, 20.0]])
    assert far.obstacle_cells == 0 and math.isnan(far.detection_fraction)
    graded = assess(hazard=hazard_with({(2, 2): 0.99}), hazard_geometry=TRAV, truth=TRUTH,
                    track=[[0.0, 0.0]])
    assert graded.detected_cells == 0  # below the threshold (1: untraversable)


def test_rms_height_error_and_a_rotated_map() -> None:
    terrain = GridGeometry(0.0, 0.0, 0.2, 20, 20)
    elevation = np.full(terrain.shape, 0.01)
    elevation[5:8, 5:8] = 0.5          # the obstacle cells [1.0, 1.6): means of 0.6 and 0
    count = np.ones(terrain.shape, dtype=np.int32)
    count[0, 0] = 0
    q = assess(hazard=hazard_with({}), hazard_geometry=TRAV, truth=TRUTH, track=[[0, 0]],
               terrain_elevation=elevation, terrain_count=count, terrain_geometry=terrain)
    assert q.observed_terrain_cells == 399
    assert q.rms_height_error_ground == pytest.approx(0.01)
    assert q.rms_height_error > 0.01
    assert q.height_offset == pytest.approx(0.01)
    # the whole map 0.25 m higher: the offset takes it, the centred figure does not move
    high = assess(hazard=hazard_with({}), hazard_geometry=TRAV, truth=TRUTH, track=[[0, 0]],
                  terrain_elevation=elevation + 0.25, terrain_count=count,
                  terrain_geometry=terrain)
    assert high.height_offset == pytest.approx(0.26)
    assert high.rms_height_error_ground == pytest.approx(0.26)
    assert high.rms_height_error_centred == pytest.approx(q.rms_height_error_centred)
    # cells over the obstacle: 0.5 where the truth means are 0.6 (inside) or partly 0
    errors = []
    for i in range(20):
        for j in range(20):
            if count[i, j]:
                x = 0.1 * np.arange(2 * i, 2 * i + 2)  # the 0.1 m truth samples in the cell
                y = 0.1 * np.arange(2 * j, 2 * j + 2)
                truth = SURFACE[np.ix_(np.round(y * 10).astype(int),
                                       np.round(x * 10).astype(int))].mean()
                errors.append(elevation[i, j] - truth)
    assert q.rms_height_error == pytest.approx(math.sqrt(np.mean(np.square(errors))))
    assert q.rms_height_error_centred == pytest.approx(
        math.sqrt(np.mean(np.square(np.array(errors) - 0.01))))
    # the same trav grid as an ego map rotated by 90 degrees about (4, 0)
    pose = np.eye(4)
    pose[:2, :2] = [[0.0, -1.0], [1.0, 0.0]]
    pose[:2, 3] = (4.0, 0.0)
    rotated = hazard_with({(2, 5): 1.0})  # map x = north, map y = west of east 4
    q = assess(hazard=rotated, hazard_geometry=TRAV, truth=TRUTH, track=[[0.0, 0.0]],
               map_pose=pose)
    assert (q.obstacle_cells, q.detected_cells) == (1, 1)
    with pytest.raises(ValueError):
        assess(hazard=np.zeros((2, 2)), hazard_geometry=TRAV, truth=TRUTH, track=[[0, 0]])


def test_obstacles_are_counted_whole_over_every_cell_they_touch() -> None:
    """Three obstacles: the square (cell [2, 2]); a thin post (0.2 m, [3.0, 3.2)², no
    cell by half, so no obstacle cell); a square far from the track ([3.5, 4)x[0, 0.5)).
    The track at (0, 0) reaches 8 m, so all three are in range."""
    ids = np.full((N, N), -1, dtype=np.int32)
    ids[OBSTACLE] = 0
    obstacle = OBSTACLE.copy()
    obstacle[30:32, 30:32] = True  # the post, [j, i]
    ids[30:32, 30:32] = 1
    obstacle[0:5, 35:40] = True
    ids[0:5, 35:40] = 2
    truth = GroundTruth(0.0, 0.0, 0.1, np.where(obstacle, 0.6, 0.0), obstacle, ids)
    h = hazard_with({(2, 2): 1.0, (6, 6): 1.0, (7, 0): np.nan})  # [7, 0]: never seen
    q = assess(hazard=h, hazard_geometry=TRAV, truth=truth, track=[[0.0, 0.0]])
    assert (q.obstacles, q.unobserved_obstacles, q.detected_obstacles) == (3, 1, 2)
    assert q.obstacle_detection_fraction == 1.0  # both seen obstacles are detected
    assert q.obstacle_detection_fraction_in_range == pytest.approx(2 / 3)
    assert (q.obstacle_cells, q.detected_cells, q.unobserved_obstacle_cells) == (2, 1, 1)
    missed = assess(hazard=hazard_with({(7, 0): np.nan}), hazard_geometry=TRAV, truth=truth,
                    track=[[0.0, 0.0]])
    assert (missed.obstacles, missed.detected_obstacles) == (3, 0)
    assert missed.obstacle_detection_fraction == 0.0
    near = assess(hazard=h, hazard_geometry=TRAV, truth=truth, track=[[0.0, 0.0]],
                  detection_range=2.0)  # the post's cell centre (3.25, 3.25) lies 4.6 m
    assert (near.obstacles, near.detected_obstacles) == (1, 1)  # off, the far one's 3.8 m
    no_ids = assess(hazard=h, hazard_geometry=TRAV, truth=TRUTH, track=[[0.0, 0.0]])
    assert no_ids.obstacles == 0 and math.isnan(no_ids.obstacle_detection_fraction)
