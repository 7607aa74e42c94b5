"""Plane textures: brightness resampled onto a regular grid in the plane's own 2D frame.

A texture is an image whose pixel ``(row j, column i)`` is the point
``ref + (i0 + i) * nu * u + (j0 + j) * nu * v`` of the plane, where ``ref`` is a reference point
on the plane, ``(u, v)`` orthonormal in-plane axes and ``nu`` the pixel size (the paper's nu,
eq. 3). Grids are anchored at integer multiples of ``nu`` from ``ref`` (``index0 = (i0, j0)``), so
two textures with the same ``ref`` and axes share one lattice and a shift of ``k`` pixels is a
shift of ``k * nu`` metres.

Brightness is sampled from the camera image by projecting each grid point (inverse mapping, so
every texture pixel gets a value and none is splatted twice), from the image-pyramid level whose
pixel footprint best matches ``nu`` (no aliasing when the plane is close). Validity: the grid
point projects inside the image, in front of the camera, and onto a pixel that belongs to this
plane (registered RGB-D: the segmentation labels; range sensor + separately calibrated camera:
inside the plane's outline polygon, and not hidden behind a nearer range point).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError
from navkit.geometry.fitting import Plane
from navkit.geometry.linalg import rows_matmul
from navkit.geometry.polygons import points_in_polygon
from navkit.planes.segments import PlaneSegment, plane_frame
from navkit.sensors import PinholeCamera

__all__ = ["PlaneTexture", "gray_levels", "texture_from_camera", "texture_from_rgbd", "to_gray"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PlaneTexture:
    """Brightness of one plane on a regular in-plane grid.

    Attributes
    ----------
    image : (h, w) float32 array
        Brightness in ``[0, 1]``; NaN where not valid.
    mask : (h, w) bool array
        Valid texture pixels (the paper's ``c_ij``, eq. 4).
    ref : (3,) array
        Reference point on the plane (sensor frame), metres.
    axes : (2, 3) array
        In-plane unit axes ``u`` (columns) and ``v`` (rows), ``u x v`` = plane normal.
    index0 : (2,) int array
        Lattice index ``(i0, j0)`` of pixel ``(0, 0)``.
    nu : float
        Pixel size, metres.
    plane : Plane
        The plane the texture lies on.
    """

    image: NDArray[np.float32]
    mask: NDArray[np.bool_]
    ref: NDArray[np.float64]
    axes: NDArray[np.float64]
    index0: NDArray[np.int64]
    nu: float
    plane: Plane

    @property
    def valid_count(self) -> int:
        return int(self.mask.sum())

    def contrast(self) -> float:
        """Standard deviation of the valid brightness (0 for a uniform texture)."""
        v = self.image[self.mask]
        return float(np.std(v)) if len(v) > 1 else 0.0

    def points(self) -> NDArray[np.float64]:
        """``(h, w, 3)`` sensor-frame positions of the pixel centres."""
        h, w = self.image.shape
        i = (self.index0[0] + np.arange(w)) * self.nu
        j = (self.index0[1] + np.arange(h)) * self.nu
        return self.ref + i[None, :, None] * self.axes[0] + j[:, None, None] * self.axes[1]


def to_gray(color: ArrayLike) -> NDArray[np.float32]:
    """``(H, W)`` float32 brightness in ``[0, 1]`` of an RGB uint8 (or gray) image (BT.601)."""
    c = np.asarray(color)
    if c.ndim == 2:
        with np.errstate(over="ignore"):
            g = c.astype(np.float32)
    elif c.ndim == 3 and c.shape[2] == 3:
        with np.errstate(over="ignore"):  # values beyond float32 are not an image: inf
            cf = c.astype(np.float32)
        g = 0.299 * cf[..., 0] + 0.587 * cf[..., 1] + 0.114 * cf[..., 2]
    else:
        raise InputError(
            f"has shape {c.shape}", field="color", expected="(H, W, 3) RGB or (H, W) gray"
        )
    return g / (255.0 if c.dtype == np.uint8 else (65535.0 if c.dtype == np.uint16 else 1.0))


_EXTENT_POINTS = 4000
"""Inliers (a regular subsample) the texture window's extent is measured on: the 1st and 99th
percentiles of 4000 points are within about 0.3 % of the plane's extent of the whole set's
(binomial standard error), under one 1 cm texture pixel for planes up to 3 m across."""


def _grid(P: NDArray[np.float64], inliers, ref, axes, nu, margin: int, max_pixels: int):
    """Lattice window ``(lo (2,), size (2,))`` covering the inliers ``P[inliers]`` (1-99
    percentiles of at most about :data:`_EXTENT_POINTS` of them), at most ``max_pixels`` per
    side (centred on the inliers' median when cropped)."""
    step = max(1, len(inliers) // _EXTENT_POINTS)
    uv = rows_matmul(P[inliers[::step]] - ref, axes.T)
    uv = uv[np.all(np.isfinite(uv), axis=1)]
    if len(uv) == 0:
        raise InputError(
            "plane has no finite inliers", field="segment", expected="a non-empty plane"
        )
    if len(uv) > 200:
        a, b = np.percentile(uv, [1, 99], axis=0)
    else:
        a, b = uv.min(axis=0), uv.max(axis=0)
    lo = np.floor(a / nu).astype(np.int64) - margin
    hi = np.ceil(b / nu).astype(np.int64) + margin
    mid = np.rint(np.median(uv, axis=0) / nu).astype(np.int64)
    half = max_pixels // 2
    lo = np.maximum(lo, mid - half)
    hi = np.minimum(hi, mid + half)
    return lo, np.maximum(hi - lo + 1, 1)


def gray_levels(gray: ArrayLike) -> list[NDArray[np.float32]]:
    """The start of a brightness pyramid for :func:`texture_from_rgbd`'s ``levels``: level 0
    only; the sampler appends the ``cv2.pyrDown`` levels it needs."""
    return [np.ascontiguousarray(gray, dtype=np.float32)]


def _sample(
    gray,
    camera: PinholeCamera,
    pts_cam: NDArray[np.float64],
    nu: float,
    levels: list[NDArray[np.float32]] | None = None,
):
    """Bilinear brightness at camera-frame points ``(h, w, 3)`` from the matching pyramid level
    (``levels``: a pyramid shared between calls, :func:`gray_levels`, extended here).

    Returns brightness ``(h, w)`` float32, pixel coordinates ``(h, w, 2)`` at level 0 and the
    in-front mask.
    """
    h, w = pts_cam.shape[:2]
    z = pts_cam[..., 2]
    front = z > 1e-6
    with np.errstate(divide="ignore", invalid="ignore"):
        u = camera.fx * pts_cam[..., 0] / z + camera.cx
        v = camera.fy * pts_cam[..., 1] / z + camera.cy
    zf = z[front]
    level = 0
    if len(zf):
        ratio = nu * camera.fx / float(np.median(zf))  # image pixels per texture pixel
        level = int(np.clip(np.floor(np.log2(max(ratio, 1.0))), 0, 4))
    pyr = gray_levels(gray) if levels is None else levels
    while len(pyr) <= level:
        pyr.append(np.asarray(cv2.pyrDown(pyr[-1]), dtype=np.float32))
    img = pyr[level]
    # cv2.pyrDown centres its 5-tap kernel on source pixel 2x: level-0 pixel u sits at u / 2 on
    # level 1 (not the area convention (u + 0.5) / 2 - 0.5, which shifted every level-1 texture
    # by half a camera pixel: 4-6 mm at 2 m, seen as a bias of textures fused at 2 cm)
    scale = 0.5**level
    mx = np.where(front, u * scale, -1e6).astype(np.float32)
    my = np.where(front, v * scale, -1e6).astype(np.float32)
    val = cv2.remap(
        img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=np.nan
    )
    inside = front & (u >= 0) & (v >= 0) & (u <= camera.width - 1) & (v <= camera.height - 1)
    return val.reshape(h, w), np.stack([u, v], axis=-1), inside


def _texture(val, mask, ref, axes, lo, nu, plane) -> PlaneTexture:
    mask = mask & np.isfinite(val)
    img = np.where(mask, val, np.nan).astype(np.float32)
    return PlaneTexture(
        image=img,
        mask=mask,
        ref=np.asarray(ref, float),
        axes=np.asarray(axes, float),
        index0=lo,
        nu=float(nu),
        plane=plane,
    )


def _frame_args(segment: PlaneSegment, axes, ref):
    o, b = plane_frame(segment.plane)
    axes = b if axes is None else np.asarray(axes, dtype=np.float64)
    ref = o if ref is None else np.asarray(ref, dtype=np.float64)
    if axes.shape != (2, 3):
        raise InputError(f"has shape {axes.shape}", field="axes", expected="(2, 3) in-plane axes")
    return axes, ref


def texture_from_rgbd(
    gray: ArrayLike,
    points: ArrayLike,
    labels: ArrayLike,
    label: int,
    segment: PlaneSegment,
    camera: PinholeCamera,
    nu: float = 0.01,
    *,
    axes: ArrayLike | None = None,
    ref: ArrayLike | None = None,
    margin: int = 1,
    max_pixels: int = 400,
    levels: list[NDArray[np.float32]] | None = None,
) -> PlaneTexture:
    """Texture of a plane seen by a registered RGB-D camera.

    Parameters
    ----------
    gray : (H, W) array
        Brightness (see :func:`to_gray`), registered with the depth.
    points : (H, W, 3) array
        Back-projected depth, camera frame, metres (used for the grid's extent).
    labels : (H, W) int array
        Segment index per pixel (:class:`~navkit.planes.segments.ExtractionResult` ``.labels``).
    label : int
        This segment's index.
    segment : PlaneSegment
    camera : PinholeCamera
    nu : float
        Texture pixel size, metres.
    axes, ref : optional
        In-plane axes ``(2, 3)`` and reference point ``(3,)`` (default: the plane's own frame).
    margin : int
        Extra texture pixels around the inliers' extent.
    max_pixels : int
        Largest texture side, pixels (a bigger plane is cropped around its inliers' median).
    levels : list of arrays, optional
        The brightness pyramid shared by the calls on one frame (:func:`gray_levels` of
        ``gray``; extended as needed), so each frame is reduced once.

    Returns
    -------
    PlaneTexture
    """
    axes_, ref_ = _frame_args(segment, axes, ref)
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    lab = np.asarray(labels)
    lo, size = _grid(P, segment.inliers, ref_, axes_, nu, margin, max_pixels)
    i = (lo[0] + np.arange(size[0])) * nu
    j = (lo[1] + np.arange(size[1])) * nu
    pts = ref_ + i[None, :, None] * axes_[0] + j[:, None, None] * axes_[1]
    val, uv, inside = _sample(gray, camera, pts, nu, levels)
    ui = np.clip(np.rint(uv[..., 0]), 0, camera.width - 1).astype(np.int64)
    vi = np.clip(np.rint(uv[..., 1]), 0, camera.height - 1).astype(np.int64)
    ok = inside & (lab[vi, ui] == label)
    return _texture(val, ok, ref_, axes_, lo, nu, segment.plane)


def texture_from_camera(
    gray: ArrayLike,
    camera: PinholeCamera,
    T_camera_sensor: ArrayLike,
    segment: PlaneSegment,
    points: ArrayLike,
    nu: float = 0.01,
    *,
    axes: ArrayLike | None = None,
    ref: ArrayLike | None = None,
    margin: int = 1,
    max_pixels: int = 400,
    occlusion_tolerance: float = 0.05,
) -> PlaneTexture:
    """Texture of a plane from a range sensor and a separately calibrated camera.

    Parameters
    ----------
    gray : (H, W) array
        Camera brightness (undistorted).
    camera : PinholeCamera
        Camera intrinsics.
    T_camera_sensor : (4, 4) array
        Extrinsics: maps range-sensor points into the camera frame (OpenCV optical axes).
    segment : PlaneSegment
        The plane, in the range sensor's frame.
    points : (N, 3) or (H', W', 3) array
        All range points (sensor frame): the segment's inliers give the extent; all of them are
        projected into the camera as a z-buffer, so texture pixels hidden behind a nearer point
        (by more than ``occlusion_tolerance`` metres) are invalid.
    nu, axes, ref, margin, max_pixels
        As in :func:`texture_from_rgbd`.

    Returns
    -------
    PlaneTexture
        Valid where the grid point lies inside the plane's outline, projects into the image and
        is not occluded.
    """
    axes_, ref_ = _frame_args(segment, axes, ref)
    T = np.asarray(T_camera_sensor, dtype=np.float64)
    if T.shape != (4, 4):
        raise InputError(
            f"has shape {T.shape}", field="T_camera_sensor", expected="(4, 4) transform"
        )
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    lo, size = _grid(P, segment.inliers, ref_, axes_, nu, margin, max_pixels)
    i = (lo[0] + np.arange(size[0])) * nu
    j = (lo[1] + np.arange(size[1])) * nu
    pts = ref_ + i[None, :, None] * axes_[0] + j[:, None, None] * axes_[1]
    pc = rows_matmul(pts, T[:3, :3].T) + T[:3, 3]
    val, uv, inside = _sample(gray, camera, pc, nu)
    # inside the outline polygon (outline is in the plane's own frame)
    o, b = plane_frame(segment.plane)
    own = rows_matmul(pts.reshape(-1, 3) - o, b.T)
    ok = inside.ravel()
    if len(segment.outline) >= 3:
        ok &= points_in_polygon(own, segment.outline, tolerance=nu)
    # z-buffer of all range points in the camera: hidden grid points are invalid
    Pc = rows_matmul(P[np.all(np.isfinite(P), axis=1)], T[:3, :3].T) + T[:3, 3]
    Pc = Pc[Pc[:, 2] > 1e-6]
    zbuf = np.full((camera.height, camera.width), np.inf)
    pu = np.rint(camera.fx * Pc[:, 0] / Pc[:, 2] + camera.cx).astype(np.int64)
    pv = np.rint(camera.fy * Pc[:, 1] / Pc[:, 2] + camera.cy).astype(np.int64)
    inn = (pu >= 0) & (pv >= 0) & (pu < camera.width) & (pv < camera.height)
    np.minimum.at(zbuf, (pv[inn], pu[inn]), Pc[inn, 2])
    ui = np.clip(np.rint(uv[..., 0]), 0, camera.width - 1).astype(np.int64).ravel()
    vi = np.clip(np.rint(uv[..., 1]), 0, camera.height - 1).astype(np.int64).ravel()
    ok &= ~(zbuf[vi, ui] < pc[..., 2].ravel() - occlusion_tolerance)
    return _texture(val, ok.reshape(size[1], size[0]), ref_, axes_, lo, nu, segment.plane)
