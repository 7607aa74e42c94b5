"""Paper 3's front end: rectified stereo -> dense disparity -> 3D points -> 2D wall points.

- :mod:`~navkit.stereo.disparity` - OpenCV SGBM / BM with an explicit left-right consistency
  check (the right disparity by forward warping, or a second matcher run) and 1/16-pixel
  sub-pixel disparities; Middlebury's bad-pixel figure;
- :mod:`~navkit.stereo.triangulation` - ``z = b f / d`` and the paper's ``x, y`` (eq. 1), camera
  -> world (eq. 2);
- :mod:`~navkit.stereo.floorplan` - wall points of the floor plan (height band, projection).

The package exports the settings, the disparity result and the three entry functions
(:func:`compute_disparity`, :func:`disparity_to_points`, :func:`stereo_wall_points`); the stage
helpers are imported from their modules. Room maps and localization from these points live in
:mod:`navkit.localization`.
"""

from navkit.stereo.disparity import DisparityResult, DisparitySettings, compute_disparity
from navkit.stereo.floorplan import FloorplanSettings, stereo_wall_points
from navkit.stereo.triangulation import disparity_to_points

__all__ = [
    "DisparityResult",
    "DisparitySettings",
    "FloorplanSettings",
    "compute_disparity",
    "disparity_to_points",
    "stereo_wall_points",
]
