"""Paper 1: isolated-obstacle detection from range data, and the 2D obstacle map.

The eight stages (Pavlovsky 2016), vectorised over the scan grid::

    scan grid -> 3D points (1) -> triangle mesh (2) -> normals (3) -> H_s, C_d (4)
              -> rules P1-P5: ground 0 / unreliable -1 / obstacle -2 / side shadow -3 /
                 shadow behind -4 (5) -> separate obstacles, shadows to their owner (6)
              -> boundary vertices (7) -> bounding shapes A1-A7 on the 2D map (8)

The online object: :class:`ObstacleMapper` fuses detections into a 2D obstacle map.
Entry points: :func:`detect_obstacles` (a :class:`~navkit.sensors.RangeScan`),
:func:`detect_obstacles_grid` (an organised grid of body-frame points),
:func:`detect_obstacles_in_grid` (a :class:`ScanGrid` recovered by :func:`cloud_to_grid` from a
spinning-lidar cloud, by :func:`organized_to_grid` or :func:`depth_to_grid`). Thresholds live in
:class:`ObstacleSettings`; the sensor's mounting in :class:`Mounting`. The bounding shapes are the
registry of :mod:`navkit.geometry.shapes` (re-exported here).
"""

from navkit.geometry.shapes import (
    SHAPES,
    Circle,
    Ellipse,
    Rectangle,
    circle_a2,
    circle_a3,
    compute_shapes,
    ellipse_a4,
    ellipse_a5,
    ellipse_a6,
    hull_points,
    min_circle_welzl,
    mvee_khachiyan,
    rect_a1,
    register_shape,
)
from navkit.obstacles.detector import (
    Obstacle,
    ObstacleDetection,
    detect_obstacles,
    detect_obstacles_grid,
    detect_obstacles_in_grid,
    unsort_vertex_array,
)
from navkit.obstacles.evaluate import (
    GroundScores,
    ground_scores,
    score_obstacle_map,
    shape_contains,
)
from navkit.obstacles.grids import ScanGrid, cloud_to_grid, depth_to_grid, organized_to_grid
from navkit.obstacles.mapper import MappedObstacle, MapperSettings, ObstacleGrid, ObstacleMapper
from navkit.obstacles.mounting import Mounting, level_rotation_from_gravity
from navkit.obstacles.rules import GROUND, OBSTACLE, SHADOW_BEHIND, SIDE_SHADOW, UNRELIABLE
from navkit.obstacles.settings import DEFAULT_SHAPES, ObstacleSettings

__all__ = [
    "DEFAULT_SHAPES",
    "GROUND",
    "OBSTACLE",
    "SHADOW_BEHIND",
    "SHAPES",
    "SIDE_SHADOW",
    "UNRELIABLE",
    "Circle",
    "Ellipse",
    "GroundScores",
    "MappedObstacle",
    "MapperSettings",
    "Mounting",
    "Obstacle",
    "ObstacleDetection",
    "ObstacleGrid",
    "ObstacleMapper",
    "ObstacleSettings",
    "Rectangle",
    "ScanGrid",
    "circle_a2",
    "circle_a3",
    "cloud_to_grid",
    "compute_shapes",
    "depth_to_grid",
    "detect_obstacles",
    "detect_obstacles_grid",
    "detect_obstacles_in_grid",
    "ellipse_a4",
    "ellipse_a5",
    "ellipse_a6",
    "ground_scores",
    "hull_points",
    "level_rotation_from_gravity",
    "min_circle_welzl",
    "mvee_khachiyan",
    "organized_to_grid",
    "rect_a1",
    "register_shape",
    "score_obstacle_map",
    "shape_contains",
    "unsort_vertex_array",
]
