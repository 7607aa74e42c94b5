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
:mod:`navkit.io.pointcloud`.
"""

from navkit.planes.associate import AssociationSettings, associate, associate_global
from navkit.planes.dense import DenseFrame, DenseResult, DenseSettings, dense_align
from navkit.planes.extract import (
    CloudExtractionSettings,
    ExtractionSettings,
    extract_planes_cloud,
    extract_planes_organized,
)
from navkit.planes.frame import PlaneObservation, observe_points, observe_rgbd
from navkit.planes.motion import MotionPrior, MotionSettings, estimate_motion
from navkit.planes.odometry import DenseGates, FrameMotion, OdometrySettings, PlaneOdometry
from navkit.planes.plane_map import MapPlane, PlaneMap
from navkit.planes.quaternion import euler_zxy_from_quat
from navkit.planes.segments import ExtractionResult, PlaneSegment, plane_frame
from navkit.planes.solve import (
    MotionEstimate,
    MotionFailure,
    SolverSettings,
    solve_one_plane,
    solve_three_planes,
    solve_two_planes,
)
from navkit.planes.texture import PlaneTexture, texture_from_camera, texture_from_rgbd, to_gray

__all__ = [
    "AssociationSettings",
    "CloudExtractionSettings",
    "DenseFrame",
    "DenseGates",
    "DenseResult",
    "DenseSettings",
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
    "PlaneTexture",
    "SolverSettings",
    "associate",
    "associate_global",
    "dense_align",
    "estimate_motion",
    "euler_zxy_from_quat",
    "extract_planes_cloud",
    "extract_planes_organized",
    "observe_points",
    "observe_rgbd",
    "plane_frame",
    "solve_one_plane",
    "solve_three_planes",
    "solve_two_planes",
    "texture_from_camera",
    "texture_from_rgbd",
    "to_gray",
]
