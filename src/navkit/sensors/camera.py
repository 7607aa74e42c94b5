"""Pinhole camera, RGB-D frames and rectified stereo rigs.

Camera frames follow OpenCV: x right, y down, z forward (optical axis); pixel ``(u, v)`` =
(column, row) with the centre of the top-left pixel at ``(0, 0)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError

__all__ = ["PinholeCamera", "RGBDFrame", "StereoPair", "StereoRig"]


@dataclass(frozen=True)
class PinholeCamera:
    """Pinhole intrinsics (no distortion: images are assumed undistorted / rectified).

    Attributes
    ----------
    fx, fy : float
        Focal lengths, pixels.
    cx, cy : float
        Principal point, pixels.
    width, height : int
        Image size, pixels.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        for name in ("fx", "fy"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise InputError(
                    f"is {v}", field=name, expected="a positive focal length in pixels"
                )
        for name in ("width", "height"):
            if int(getattr(self, name)) <= 0:
                raise InputError(
                    f"is {getattr(self, name)}", field=name, expected="a positive pixel count"
                )

    @classmethod
    def from_fov(cls, width: int, height: int, hfov_deg: float) -> PinholeCamera:
        """Square-pixel camera with the given horizontal field of view, centred principal point."""
        f = 0.5 * width / np.tan(np.radians(hfov_deg) / 2.0)
        return cls(f, f, (width - 1) / 2.0, (height - 1) / 2.0, int(width), int(height))

    @property
    def K(self) -> NDArray[np.float64]:
        """``(3, 3)`` intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    def pixel_rays(self) -> NDArray[np.float64]:
        """``(H, W, 3)`` ray directions with ``z = 1`` (multiply by depth to get points)."""
        u, v = np.meshgrid(np.arange(self.width), np.arange(self.height))
        return np.stack(
            [(u - self.cx) / self.fx, (v - self.cy) / self.fy, np.ones(u.shape)], axis=-1
        )

    def backproject(self, depth: ArrayLike) -> NDArray[np.float64]:
        """Points ``(H, W, 3)`` in the camera frame from a depth image (metres along z; NaN kept)."""
        d = np.asarray(depth, dtype=np.float64)
        if d.shape != (self.height, self.width):
            raise InputError(
                f"has shape {d.shape}",
                field="depth",
                expected=f"({self.height}, {self.width}) image",
            )
        # pixel_rays() * depth by coordinate, the rays as a row / column broadcast: the same
        # products bit for bit, ~20x faster than multiplying a (H, W, 3) ray image
        out = np.empty((self.height, self.width, 3))
        np.multiply(((np.arange(self.width) - self.cx) / self.fx)[None, :], d, out=out[..., 0])
        np.multiply(((np.arange(self.height) - self.cy) / self.fy)[:, None], d, out=out[..., 1])
        out[..., 2] = d
        return out

    def project(self, points: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Pixels ``(N, 2)`` and depths ``(N,)`` of camera-frame points ``(N, 3)``.

        Points at or behind the camera (``z <= 0``) get NaN pixels.
        """
        P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        z = P[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = np.stack(
                [self.fx * P[:, 0] / z + self.cx, self.fy * P[:, 1] / z + self.cy], axis=1
            )
        uv[z <= 0] = np.nan
        return uv, z


@dataclass(frozen=True)
class RGBDFrame:
    """A registered colour + depth frame.

    Attributes
    ----------
    color : (H, W, 3) uint8 array
        RGB colour (not OpenCV's BGR).
    depth : (H, W) float64 array
        Depth along the optical axis, metres; NaN = invalid.
    camera : PinholeCamera
        Intrinsics shared by colour and depth.
    timestamp : float
        Seconds, NaN if unknown.
    """

    color: NDArray[np.uint8]
    depth: NDArray[np.float64]
    camera: PinholeCamera
    timestamp: float = float("nan")

    def __post_init__(self) -> None:
        shape = (self.camera.height, self.camera.width)
        depth = np.asarray(self.depth, dtype=np.float64)
        if depth.shape != shape:
            raise InputError(f"has shape {depth.shape}", field="depth", expected=f"{shape}")
        color = np.asarray(self.color)
        if color.shape != (*shape, 3):
            raise InputError(f"has shape {color.shape}", field="color", expected=f"{(*shape, 3)}")
        depth = depth.copy()
        depth[~(depth > 0)] = np.nan
        object.__setattr__(self, "depth", depth)
        object.__setattr__(self, "color", color.astype(np.uint8, copy=False))

    @property
    def gray(self) -> NDArray[np.float64]:
        """``(H, W)`` brightness in ``[0, 1]`` (ITU-R BT.601 weights)."""
        return (self.color.astype(np.float64) @ np.array([0.299, 0.587, 0.114])) / 255.0

    def points(self) -> NDArray[np.float64]:
        """``(H, W, 3)`` camera-frame points (NaN where depth is invalid)."""
        return self.camera.backproject(self.depth)


@dataclass(frozen=True)
class StereoRig:
    """A rectified stereo pair of identical pinhole cameras.

    The right camera sits ``baseline`` metres along the left camera's +x axis. Disparity
    ``d = u_left - u_right`` (pixels, > 0); depth ``z = baseline * fx / (d + doffs)`` (``doffs``:
    Middlebury's principal-point offset between the two cameras, 0 for an ideal rig).
    """

    camera: PinholeCamera
    baseline: float
    doffs: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.baseline) and self.baseline > 0):
            raise InputError(f"is {self.baseline}", field="baseline", expected="positive metres")

    def depth_from_disparity(self, disparity: ArrayLike) -> NDArray[np.float64]:
        """Depth (metres) from disparity (pixels); non-positive or NaN disparity -> NaN."""
        d = np.asarray(disparity, dtype=np.float64) + self.doffs
        with np.errstate(divide="ignore", invalid="ignore"):
            z = self.baseline * self.camera.fx / d
        z[~(d > 0)] = np.nan
        return z

    def disparity_from_depth(self, depth: ArrayLike) -> NDArray[np.float64]:
        """Disparity (pixels) of points at the given depth (metres)."""
        z = np.asarray(depth, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.baseline * self.camera.fx / z - self.doffs

    def triangulate(self, disparity: ArrayLike) -> NDArray[np.float64]:
        """Points ``(H, W, 3)`` in the left camera frame from a left disparity image (NaN kept)."""
        return self.camera.backproject(self.depth_from_disparity(disparity))


@dataclass(frozen=True)
class StereoPair:
    """Left and right rectified images (``(H, W)`` gray or ``(H, W, 3)`` RGB uint8) and their rig."""

    left: NDArray[np.uint8]
    right: NDArray[np.uint8]
    rig: StereoRig
    timestamp: float = float("nan")

    def __post_init__(self) -> None:
        left, right = np.asarray(self.left), np.asarray(self.right)
        if left.shape != right.shape:
            raise InputError(
                f"left {left.shape} and right {right.shape} differ",
                field="right",
                expected="images of the same shape",
            )
        if left.shape[:2] != (self.rig.camera.height, self.rig.camera.width):
            raise InputError(
                f"has shape {left.shape}",
                field="left",
                expected=f"({self.rig.camera.height}, {self.rig.camera.width}) image",
            )
