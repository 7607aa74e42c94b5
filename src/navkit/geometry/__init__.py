"""Shared maths on arrays: rigid transforms, rotations, plane and line fits, polygons, and the
bounding shapes of obstacles on a 2D map.

Frame conventions (fixed once, for all of navkit): world z up; ``T_a_b`` maps points from frame
*b* to frame *a*; quaternions are scalar-last ``(x, y, z, w)``; angles are radians; the papers'
Euler order is intrinsic Z-X-Y (:data:`EULER_ORDER_PAPER`). Camera frames follow OpenCV (x right,
y down, z forward); range-sensor and robot body frames are x forward, y left, z up
(:data:`T_BODY_FROM_OPTICAL` converts).

The package exports the frame conventions and the SE(2) / SE(3) transforms. Rotations and
quaternions are imported from :mod:`~navkit.geometry.rotations`, plane and line fits from
:mod:`~navkit.geometry.fitting`, polygons from :mod:`~navkit.geometry.polygons` and the bounding
shapes from :mod:`~navkit.geometry.shapes`.
"""

import numpy as np

from navkit.geometry.rotations import EULER_ORDER_PAPER
from navkit.geometry.transforms import (
    se2_apply,
    se2_compose,
    se2_from_xytheta,
    se2_inverse,
    se2_to_xytheta,
    se3_apply,
    se3_compose,
    se3_from_rt,
    se3_from_xyz_quat,
    se3_inverse,
    se3_to_rt,
    se3_to_xyz_quat,
    wrap_angle,
)

R_BODY_FROM_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
"""Rotation taking OpenCV optical axes (x right, y down, z forward) to body axes (x forward,
y left, z up): ``p_body = R_BODY_FROM_OPTICAL @ p_optical``."""

T_BODY_FROM_OPTICAL = se3_from_rt(R_BODY_FROM_OPTICAL, np.zeros(3))
"""The same as a ``(4, 4)`` transform ``T_body_optical``."""

__all__ = [
    "EULER_ORDER_PAPER",
    "R_BODY_FROM_OPTICAL",
    "T_BODY_FROM_OPTICAL",
    "se2_apply",
    "se2_compose",
    "se2_from_xytheta",
    "se2_inverse",
    "se2_to_xytheta",
    "se3_apply",
    "se3_compose",
    "se3_from_rt",
    "se3_from_xyz_quat",
    "se3_inverse",
    "se3_to_rt",
    "se3_to_xyz_quat",
    "wrap_angle",
]
