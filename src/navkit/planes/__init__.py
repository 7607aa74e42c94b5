"""Paper 2: planar objects from range images, 6-DoF motion from 1, 2 or >= 3 textured planes,
and the merged plane map.

Pipeline (one module per stage)::

    extract  -> planes of a range image / cloud           (extract.py, segments.py)
    texture  -> brightness on a grid in each plane        (texture.py)
    associate-> the same planes in two frames              (associate.py)
    solve    -> >= 3 closed form | 2: eq. 7 | 1: eqs. 3-4, 8-11  (solve.py, align.py, quaternion.py)
    odometry -> trajectory, frame-to-map tracking          (odometry.py)
    map      -> merged, textured plane map                 (plane_map.py)

Everything works on NumPy arrays; readers for files are in :mod:`navkit.io.rgbd` and
:mod:`navkit.io.pointcloud`. The package exports the online object (:class:`PlaneOdometry`), the
settings and results, and the entry functions (extraction, observation, two-frame motion); the
stage functions (association, solvers, texture, dense alignment) are imported from their modules.
"""

from navkit.planes.extract import (
    CloudExtractionSettings,
    ExtractionSettings,
    extract_planes_cloud,
    extract_planes_organized,
)
from navkit.planes.frame import PlaneObservation, observe_points, observe_rgbd
from navkit.planes.motion import MotionPrior, MotionSettings, estimate_motion
from navkit.planes.odometry import FrameMotion, OdometrySettings, PlaneOdometry
from navkit.planes.plane_map import MapPlane, PlaneMap
from navkit.planes.segments import ExtractionResult, PlaneSegment
from navkit.planes.solve import MotionEstimate, MotionFailure

__all__ = [
    "CloudExtractionSettings",
    "ExtractionResult",
    "ExtractionSettings",
    "FrameMotion",
    "MapPlane",
    "MotionEstimate",
    "MotionFailure",
    "MotionPrior",
    "MotionSettings",
    "OdometrySettings",
    "PlaneMap",
    "PlaneObservation",
    "PlaneOdometry",
    "PlaneSegment",
    "estimate_motion",
    "extract_planes_cloud",
    "extract_planes_organized",
    "observe_points",
    "observe_rgbd",
]
