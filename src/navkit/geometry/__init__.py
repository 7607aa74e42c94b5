"""Shared maths on arrays: rigid transforms, rotations, plane and line fits, polygons, and the
bounding shapes of obstacles on a 2D map (:mod:`navkit.geometry.shapes`).

Frame conventions (fixed once, for all of navkit): world z up; ``T_a_b`` maps points from frame
*b* to frame *a*; quaternions are scalar-last ``(x, y, z, w)``; angles are radians; the papers'
Euler order is intrinsic Z-X-Y (:data:`EULER_ORDER_PAPER`). Camera frames follow OpenCV (x right,
y down, z forward); range-sensor and robot body frames are x forward, y left, z up
(:data:`T_BODY_FROM_OPTICAL` converts).
"""

import numpy as np

from navkit.geometry.fitting import (
    Line2D,
    Plane,
    canonical_plane,
    fit_line_2d,
    fit_plane,
    intersect_lines_2d,
    intersect_planes,
    line_from_points_2d,
    plane_from_points,
)
from navkit.geometry.polygons import (
    convex_hull_2d,
    ensure_ccw,
    points_in_polygon,
    polygon_area,
    polygon_centroid,
    polygon_perimeter,
    signed_area,
)
from navkit.geometry.rotations import (
    EULER_ORDER_PAPER,
    euler_zxy_to_matrix,
    matrix_to_euler_zxy,
    matrix_to_quat,
    quat_conjugate,
    quat_from_axis_angle,
    quat_multiply,
    quat_rotate,
    quat_to_matrix,
    rotation_angle,
    rotation_between,
)
from navkit.geometry.shapes import (
    SHAPES,
    Circle,
    Ellipse,
    Rectangle,
    Shape,
    compute_shapes,
    min_circle_welzl,
    mvee_khachiyan,
    register_shape,
)
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
    "SHAPES",
    "T_BODY_FROM_OPTICAL",
    "Circle",
    "Ellipse",
    "Line2D",
    "Plane",
    "Rectangle",
    "Shape",
    "canonical_plane",
    "compute_shapes",
    "convex_hull_2d",
    "ensure_ccw",
    "euler_zxy_to_matrix",
    "fit_line_2d",
    "fit_plane",
    "intersect_lines_2d",
    "intersect_planes",
    "line_from_points_2d",
    "matrix_to_euler_zxy",
    "matrix_to_quat",
    "min_circle_welzl",
    "mvee_khachiyan",
    "plane_from_points",
    "points_in_polygon",
    "polygon_area",
    "polygon_centroid",
    "polygon_perimeter",
    "quat_conjugate",
    "quat_from_axis_angle",
    "quat_multiply",
    "quat_rotate",
    "quat_to_matrix",
    "register_shape",
    "rotation_angle",
    "rotation_between",
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
    "signed_area",
    "wrap_angle",
]
