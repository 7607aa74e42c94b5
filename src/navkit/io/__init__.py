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

See ``docs/formats.md`` for every format's conventions.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

_EXPORTS = {
    "arrays": ["read_npy", "read_npz"],
    "atomic": [
        "atomic_path",
        "atomic_write",
        "write_json",
        "write_text",
    ],
    "pointcloud": [
        "PointCloud",
        "lzf_compress",
        "lzf_decompress",
        "read_kitti_bin",
        "read_kitti_labels",
        "read_pcd",
        "read_ply",
        "read_pointcloud",
        "write_kitti_bin",
        "write_kitti_labels",
        "write_pcd",
        "write_ply",
    ],
    "trajectory": [
        "Trajectory",
        "read_euroc",
        "read_kitti_poses",
        "read_odometry_log",
        "read_trajectory",
        "read_tum",
        "write_kitti_poses",
        "write_tum",
    ],
    "images": [
        "read_depth",
        "read_image",
        "read_pfm",
        "write_depth",
        "write_image",
        "write_pfm",
    ],
    "maps": [
        "OccupancyGrid",
        "line_geometry",
        "point_geometry",
        "polygon_geometry",
        "read_occupancy_grid",
        "write_geojson",
        "write_occupancy_grid",
    ],
    "rosbag": [
        "BagMessage",
        "iter_images",
        "iter_pointclouds",
        "list_topics",
    ],
}
_WHERE = {name: module for module, names in _EXPORTS.items() for name in names}

__all__ = [
    "BagMessage",
    "OccupancyGrid",
    "PointCloud",
    "Trajectory",
    "atomic_path",
    "atomic_write",
    "iter_images",
    "iter_pointclouds",
    "line_geometry",
    "list_topics",
    "lzf_compress",
    "lzf_decompress",
    "point_geometry",
    "polygon_geometry",
    "read_depth",
    "read_euroc",
    "read_image",
    "read_kitti_bin",
    "read_kitti_labels",
    "read_kitti_poses",
    "read_npy",
    "read_npz",
    "read_occupancy_grid",
    "read_odometry_log",
    "read_pcd",
    "read_pfm",
    "read_ply",
    "read_pointcloud",
    "read_trajectory",
    "read_tum",
    "write_depth",
    "write_geojson",
    "write_image",
    "write_json",
    "write_kitti_bin",
    "write_kitti_labels",
    "write_kitti_poses",
    "write_occupancy_grid",
    "write_pcd",
    "write_pfm",
    "write_ply",
    "write_text",
    "write_tum",
]

if TYPE_CHECKING:  # for type checkers and IDEs; at run time names load on first use
    from navkit.io.arrays import read_npy, read_npz
    from navkit.io.atomic import atomic_path, atomic_write, write_json, write_text
    from navkit.io.images import (
        read_depth,
        read_image,
        read_pfm,
        write_depth,
        write_image,
        write_pfm,
    )
    from navkit.io.maps import (
        OccupancyGrid,
        line_geometry,
        point_geometry,
        polygon_geometry,
        read_occupancy_grid,
        write_geojson,
        write_occupancy_grid,
    )
    from navkit.io.pointcloud import (
        PointCloud,
        lzf_compress,
        lzf_decompress,
        read_kitti_bin,
        read_kitti_labels,
        read_pcd,
        read_ply,
        read_pointcloud,
        write_kitti_bin,
        write_kitti_labels,
        write_pcd,
        write_ply,
    )
    from navkit.io.rosbag import BagMessage, iter_images, iter_pointclouds, list_topics
    from navkit.io.trajectory import (
        Trajectory,
        read_euroc,
        read_kitti_poses,
        read_odometry_log,
        read_trajectory,
        read_tum,
        write_kitti_poses,
        write_tum,
    )


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'navkit.io' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"navkit.io.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
