"""One sensor frame as the plane pipeline sees it: its planes and how to texture them."""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError
from navkit.geometry.linalg import rows_matmul
from navkit.planes.extract import (
    CloudExtractionSettings,
    ExtractionSettings,
    extract_planes_cloud,
    extract_planes_organized,
)
from navkit.planes.segments import ExtractionResult, PlaneSegment
from navkit.planes.texture import (
    PlaneTexture,
    gray_levels,
    texture_from_camera,
    texture_from_rgbd,
    to_gray,
)
from navkit.sensors import PinholeCamera, RGBDFrame

__all__ = ["PlaneObservation", "observe_points", "observe_rgbd", "reproject_rgbd"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PlaneObservation:
    """Planes of one frame plus what is needed to texture them.

    Attributes
    ----------
    extraction : ExtractionResult
    points : (H, W, 3) or (N, 3) array
        Sensor-frame points, metres (NaN = none).
    gray : (H, W) float32 array or None
        Camera brightness in ``[0, 1]`` (None = no camera: geometry only).
    camera : PinholeCamera or None
    T_camera_sensor : (4, 4) array or None
        None for a registered RGB-D frame (camera frame = sensor frame, labels index camera
        pixels); the extrinsics of a separately calibrated camera otherwise.
    timestamp : float
    """

    extraction: ExtractionResult
    points: NDArray[np.float64]
    gray: NDArray[np.float32] | None = None
    camera: PinholeCamera | None = None
    T_camera_sensor: NDArray[np.float64] | None = None
    timestamp: float = float("nan")

    @property
    def segments(self) -> tuple[PlaneSegment, ...]:
        return self.extraction.segments

    @functools.cached_property
    def _gray_levels(self) -> list[NDArray[np.float32]]:
        """The brightness pyramid the frame's textures share (built on demand)."""
        assert self.gray is not None
        return gray_levels(self.gray)

    @property
    def has_texture(self) -> bool:
        return self.gray is not None and self.camera is not None

    def texture(
        self, k: int, axes: ArrayLike | None = None, ref: ArrayLike | None = None, nu: float = 0.01
    ) -> PlaneTexture:
        """Texture of plane ``k`` (default frame: the plane's own; see :mod:`navkit.planes.texture`)."""
        if self.gray is None or self.camera is None:
            raise InputError(
                "this frame has no camera image",
                field="gray",
                expected="an RGB-D frame or a range scan with a calibrated camera",
            )
        seg = self.segments[k]
        if self.T_camera_sensor is None:
            return texture_from_rgbd(
                self.gray,
                self.points,
                self.extraction.labels,
                k,
                seg,
                self.camera,
                nu,
                axes=axes,
                ref=ref,
                levels=self._gray_levels,
            )
        return texture_from_camera(
            self.gray, self.camera, self.T_camera_sensor, seg, self.points, nu, axes=axes, ref=ref
        )


def observe_rgbd(frame: RGBDFrame, settings: ExtractionSettings | None = None) -> PlaneObservation:
    """Extract the planes of a registered RGB-D frame (organised, CAPE-like)."""
    pts = frame.points()
    ext = extract_planes_organized(pts, settings)
    return PlaneObservation(ext, pts, to_gray(frame.color), frame.camera, None, frame.timestamp)


def observe_points(
    points: ArrayLike,
    *,
    gray: ArrayLike | None = None,
    camera: PinholeCamera | None = None,
    T_camera_sensor: ArrayLike | None = None,
    organized_settings: ExtractionSettings | None = None,
    cloud_settings: CloudExtractionSettings | None = None,
    timestamp: float = float("nan"),
) -> PlaneObservation:
    """Extract planes of a range image ``(H, W, 3)`` or a cloud ``(N, 3)``, optionally with a
    separately calibrated camera (``gray``, ``camera``, ``T_camera_sensor``) for textures."""
    P = np.asarray(points, dtype=np.float64)
    if P.ndim == 3 and P.shape[2] == 3:
        ext = extract_planes_organized(P, organized_settings)
    elif P.ndim == 2 and P.shape[1] == 3:
        ext = extract_planes_cloud(P, cloud_settings)
    else:
        raise InputError(f"has shape {P.shape}", field="points", expected="(H, W, 3) or (N, 3)")
    g = None if gray is None else to_gray(gray)
    T = None
    if g is not None:
        if camera is None:
            raise InputError(
                "a camera image needs its intrinsics", field="camera", expected="a PinholeCamera"
            )
        T = np.eye(4) if T_camera_sensor is None else np.asarray(T_camera_sensor, dtype=np.float64)
    return PlaneObservation(ext, P, g, camera, T, timestamp)


def reproject_rgbd(
    points: ArrayLike, color: ArrayLike, camera: PinholeCamera, T_new_old: ArrayLike, splat: int = 2
) -> RGBDFrame:
    """View synthesis: coloured points seen from a moved pinhole camera (z-buffered splats).

    Used to give a real RGB-D frame a *known* motion (evaluation on recorded frames that have no
    second view): every valid point is moved by ``T_new_old`` and drawn as a ``splat x splat``
    pixel square, nearest point wins. Pixels no point reaches have NaN depth.

    Parameters
    ----------
    points : (H, W, 3) or (N, 3) array
        Points in the old frame, metres (NaN = none).
    color : (H, W, 3) or (N, 3) uint8 array
        Their RGB colours.
    camera : PinholeCamera
        The new view's intrinsics (its size is the output size).
    T_new_old : (4, 4) array
        Maps old-frame points into the new camera frame.
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    C = np.asarray(color, dtype=np.uint8).reshape(-1, 3)
    T = np.asarray(T_new_old, dtype=np.float64)
    ok = np.all(np.isfinite(P), axis=1)
    X = rows_matmul(P[ok], T[:3, :3].T) + T[:3, 3]
    C = C[ok]
    front = X[:, 2] > 1e-3
    X, C = X[front], C[front]
    u = camera.fx * X[:, 0] / X[:, 2] + camera.cx
    v = camera.fy * X[:, 1] / X[:, 2] + camera.cy
    H, W = camera.height, camera.width
    depth = np.full(H * W, np.inf)
    owner = -np.ones(H * W, np.int64)
    order = np.argsort(-X[:, 2])  # far first, near points overwrite
    for du in range(splat):
        for dv in range(splat):
            iu = np.floor(u + du - (splat - 1) / 2).astype(np.int64)
            iv = np.floor(v + dv - (splat - 1) / 2).astype(np.int64)
            inside = (iu >= 0) & (iv >= 0) & (iu < W) & (iv < H)
            sel = order[inside[order]]
            pix = iv[sel] * W + iu[sel]
            closer = X[sel, 2] < depth[pix]
            depth[pix[closer]] = X[sel[closer], 2]
            owner[pix[closer]] = sel[closer]
    img = np.zeros((H * W, 3), np.uint8)
    img[owner >= 0] = C[owner[owner >= 0]]
    d = np.where(np.isfinite(depth), depth, np.nan).reshape(H, W)
    return RGBDFrame(img.reshape(H, W, 3), d, camera)
