"""File formats at the edge of navkit: point clouds, trajectories, images, maps, ROS bags.

Readers validate what they read and raise :class:`navkit.errors.FormatError` naming the file,
the field and what was expected; writers are atomic (:mod:`navkit.io.atomic`). Names are
imported lazily, so ``import navkit.io`` stays cheap:

- :mod:`navkit.io.pointcloud` - KITTI ``.bin``/``.label``, PCD v0.7 (ascii, binary,
  binary_compressed), PLY; :class:`PointCloud` (one module per format: ``kitti``, ``pcd``,
  ``ply``, ``lzf``, ``cloud``; ``pointcloud`` re-exports them).
- :mod:`navkit.io.trajectory` - TUM, KITTI poses, EuRoC CSV, ``time v omega`` odometry logs;
  :class:`Trajectory`.
- :mod:`navkit.io.images` - PNG/JPG/PGM/PPM images (RGB), depth images, PFM.
- :mod:`navkit.io.maps` - ROS map_server occupancy grids (PGM + YAML), GeoJSON.
- :mod:`navkit.io.rosbag` - PointCloud2 / Image messages from ROS1 bags and ROS2 folders
  (optional extra ``rosbag``).
- :mod:`navkit.io.atomic` - atomic writes and output transactions.
- :mod:`navkit.io.arrays` - ``.npy`` / ``.npz`` with declared sizes checked first.
- :mod:`navkit.io.textfiles` - JSON / TOML / text user files, one error per failure.

The package exports the format-independent readers and their containers
(:func:`read_pointcloud`, :func:`read_trajectory`, :func:`read_image`, :func:`read_depth`,
:func:`read_occupancy_grid`); the per-format readers and writers are imported from their modules.
See ``docs/formats.md`` for every format's conventions.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

_EXPORTS = {
    "images": ["read_depth", "read_image"],
    "maps": ["OccupancyGrid", "read_occupancy_grid"],
    "pointcloud": ["PointCloud", "read_pointcloud"],
    "trajectory": ["Trajectory", "read_trajectory"],
}
_WHERE = {name: module for module, names in _EXPORTS.items() for name in names}

__all__ = [
    "OccupancyGrid",
    "PointCloud",
    "Trajectory",
    "read_depth",
    "read_image",
    "read_occupancy_grid",
    "read_pointcloud",
    "read_trajectory",
]

if TYPE_CHECKING:  # for type checkers and IDEs; at run time names load on first use
    from navkit.io.images import read_depth, read_image
    from navkit.io.maps import OccupancyGrid, read_occupancy_grid
    from navkit.io.pointcloud import PointCloud, read_pointcloud
    from navkit.io.trajectory import Trajectory, read_trajectory


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'navkit.io' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"navkit.io.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
