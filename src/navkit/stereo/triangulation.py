"""3D points from disparity (paper 3, eq. 1) and camera -> world (eq. 2).

Paper 3, fig. 2 / eq. 1: image x-coordinates ``x_L``, ``x_R`` of a point (measured from each
camera's principal point), baseline ``b``, focal length ``f`` (pixels): disparity
``d = x_L - x_R``, depth ``z = b f / d``; with the origin at the *centre* of the pair (midway
between the cameras) ``x = b (x_L + x_R) / (2 d)``, ``y = b y_img / d``. In the left camera's
frame (origin at the left centre) the same point is ``x = b x_L / d`` - the two differ by
``b / 2`` along x. Middlebury's ``doffs`` (principal points differing by ``doffs`` pixels)
enters as ``d + doffs``.

Frames: camera = OpenCV optical (x right, y down, z forward). For the 2D map the camera turns
about the world's vertical and moves in x, y (eq. 2); :func:`camera_to_world` takes any
``T_world_camera``, and :func:`planar_camera_pose` builds the paper's special case.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError
from navkit.geometry import R_BODY_FROM_OPTICAL, se3_apply, se3_from_rt
from navkit.sensors import StereoRig

__all__ = ["camera_to_world", "disparity_to_points", "planar_camera_pose", "triangulate_pixels"]


def triangulate_pixels(
    x_left: ArrayLike,
    x_right: ArrayLike,
    y_img: ArrayLike,
    baseline: float,
    focal: float,
    *,
    origin: Literal["left", "centre"] = "centre",
    doffs: float = 0.0,
    focal_y: float | None = None,
) -> NDArray[np.float64]:
    """Points ``(..., 3)`` from matched image coordinates (paper 3, eq. 1).

    Parameters
    ----------
    x_left, x_right : (...,) arrays
        Image x of the point in the left / right image, pixels from each principal point.
    y_img : (...,) array
        Image y (rows, down), pixels from the principal point.
    baseline : float
        Metres.
    focal : float
        ``f_x``, pixels.
    origin : {"centre", "left"}
        The paper's pair-centre origin, or the left camera.
    doffs : float
        Principal-point offset between the cameras, pixels (Middlebury); ``d -> d + doffs``.
    focal_y : float, optional
        ``f_y`` if pixels are not square.

    Returns
    -------
    (..., 3) array
        ``(x, y, z)`` in metres (OpenCV axes); NaN where ``d + doffs <= 0``.
    """
    xl = np.asarray(x_left, dtype=np.float64)
    xr = np.asarray(x_right, dtype=np.float64)
    yi = np.asarray(y_img, dtype=np.float64)
    d = xl - xr + doffs
    fy = focal if focal_y is None else focal_y
    with np.errstate(divide="ignore", invalid="ignore"):
        z = baseline * focal / d
        # x_R measured from the right camera's own principal point is x_right - doffs
        x = baseline * (xl + xr - doffs) / (2.0 * d) if origin == "centre" else baseline * xl / d
        y = baseline * yi * (focal / fy) / d
    out = np.stack([x, y, z], axis=-1)
    out[~(d > 0)] = np.nan
    return out


def disparity_to_points(
    disparity: ArrayLike, rig: StereoRig, *, origin: Literal["left", "centre"] = "left"
) -> NDArray[np.float64]:
    """Points ``(H, W, 3)`` of a left disparity image (NaN where the disparity is invalid).

    Vectorised eq. 1: pixel ``(u, v)`` has ``x_L = u - c_x``, ``x_R = x_L - d``, ``y_img = v - c_y``.
    """
    d = np.asarray(disparity, dtype=np.float64)
    cam = rig.camera
    if d.shape != (cam.height, cam.width):
        raise InputError(
            f"has shape {d.shape}", field="disparity", expected=f"({cam.height}, {cam.width}) image"
        )
    u = np.arange(cam.width, dtype=np.float64)[None, :] - cam.cx
    v = np.arange(cam.height, dtype=np.float64)[:, None] - cam.cy
    xl = np.broadcast_to(u, d.shape)
    return triangulate_pixels(
        xl,
        xl - d,
        np.broadcast_to(v, d.shape),
        rig.baseline,
        cam.fx,
        origin=origin,
        doffs=rig.doffs,
        focal_y=cam.fy,
    )


def camera_to_world(points: ArrayLike, T_world_camera: ArrayLike) -> NDArray[np.float64]:
    """Points ``(..., 3)`` from the camera frame to the world (``L' = T L``, paper eq. 2); NaN kept."""
    P = np.asarray(points, dtype=np.float64)
    shape = P.shape
    return se3_apply(np.asarray(T_world_camera, dtype=np.float64), P.reshape(-1, 3)).reshape(shape)


def planar_camera_pose(
    x: float, y: float, theta: float, height: float = 0.0
) -> NDArray[np.float64]:
    """``T_world_camera`` of a level camera at ``(x, y, height)`` looking along heading ``theta``.

    The paper's eq. 2 case: the camera only turns about the vertical and moves in x, y. The
    camera's optical axis points along ``(cos theta, sin theta, 0)``; image x is to the right of
    travel, image y down.
    """
    c, s = np.cos(theta), np.sin(theta)
    R_world_body = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return se3_from_rt(R_world_body @ R_BODY_FROM_OPTICAL, np.array([x, y, height]))
