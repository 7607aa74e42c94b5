"""Paper 3's front end: rectified stereo -> dense disparity -> 3D points -> 2D wall points.

- :mod:`~navkit.stereo.disparity` - OpenCV SGBM / BM with an explicit left-right consistency
  check (the right disparity by forward warping, or a second matcher run) and 1/16-pixel
  sub-pixel disparities; Middlebury's bad-pixel figure;
- :mod:`~navkit.stereo.triangulation` - ``z = b f / d`` and the paper's ``x, y`` (eq. 1), camera
  -> world (eq. 2);
- :mod:`~navkit.stereo.floorplan` - wall points of the floor plan (height band, projection).

Room maps and localization from these points live in :mod:`navkit.localization`.
"""

from navkit.stereo.disparity import (
    DisparityResult,
    DisparitySettings,
    bad_pixel_rate,
    compute_disparity,
    lr_consistency,
    warp_right_disparity,
)
from navkit.stereo.floorplan import (
    FloorplanSettings,
    stereo_wall_points,
    thin_points,
    wall_points_body,
    wall_points_world,
)
from navkit.stereo.triangulation import (
    camera_to_world,
    disparity_to_points,
    planar_camera_pose,
    triangulate_pixels,
)

__all__ = [
    "DisparityResult",
    "DisparitySettings",
    "FloorplanSettings",
    "bad_pixel_rate",
    "camera_to_world",
    "compute_disparity",
    "disparity_to_points",
    "lr_consistency",
    "planar_camera_pose",
    "stereo_wall_points",
    "thin_points",
    "triangulate_pixels",
    "wall_points_body",
    "wall_points_world",
    "warp_right_disparity",
]
