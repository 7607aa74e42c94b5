"""Paper 1: isolated-obstacle detection from range data, and the 2D obstacle map.

The eight stages (Pavlovsky 2016), vectorised over the scan grid::

    scan grid -> 3D points (1) -> triangle mesh (2) -> normals (3) -> H_s, C_d (4)
              -> rules P1-P5: ground 0 / unreliable -1 / obstacle -2 / side shadow -3 /
                 shadow behind -4 (5) -> separate obstacles, shadows to their owner (6)
              -> boundary vertices (7) -> bounding shapes A1-A7 on the 2D map (8)

The online object: :class:`ObstacleMapper` fuses detections into a 2D obstacle map.
Entry points: :func:`detect_obstacles` (a :class:`~navkit.sensors.RangeScan`),
:func:`detect_obstacles_grid` (an organised grid of body-frame points),
:func:`detect_obstacles_in_grid` (a :class:`ScanGrid`, recovered from a spinning-lidar cloud, an
organised cloud or a depth image by :mod:`navkit.obstacles.grids`). Thresholds live in
:class:`ObstacleSettings`; the sensor's mounting in :class:`Mounting`.

Everything else is imported from its module: the label values from :mod:`~navkit.obstacles.rules`,
scoring against truth from :mod:`~navkit.obstacles.evaluate`, the bounding shapes from
:mod:`navkit.geometry.shapes`.
"""

from navkit.obstacles.detector import (
    Obstacle,
    ObstacleDetection,
    detect_obstacles,
    detect_obstacles_grid,
    detect_obstacles_in_grid,
)
from navkit.obstacles.grids import ScanGrid
from navkit.obstacles.mapper import (
    MappedObstacle,
    MapUpdate,
    ObstacleGrid,
    ObstacleMapper,
    ObstacleMapperSettings,
)
from navkit.obstacles.mounting import Mounting
from navkit.obstacles.settings import ObstacleSettings

__all__ = [
    "MapUpdate",
    "MappedObstacle",
    "Mounting",
    "Obstacle",
    "ObstacleDetection",
    "ObstacleGrid",
    "ObstacleMapper",
    "ObstacleMapperSettings",
    "ObstacleSettings",
    "ScanGrid",
    "detect_obstacles",
    "detect_obstacles_grid",
    "detect_obstacles_in_grid",
]
