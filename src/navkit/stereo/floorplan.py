"""From a stereo point cloud to the 2D wall points of a floor plan.

Paper 3 builds its room map from the wall points of the stereo cloud, in the world's horizontal
plane (the camera turns about the vertical and moves in x, y). navkit keeps the points whose
height above the floor lies in a band (``min_height .. max_height``: above the floor and low
furniture, below the ceiling), drops far points (stereo depth error grows as ``z^2``), and
projects them on the floor. :func:`wall_points_world` gives the points in the world (for map
building with known poses), :func:`wall_points_body` in the robot's body frame (x forward,
y left: the fragment to localize).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.domains import POSITIVE, Domain, domain_field
from navkit.errors import ConfigError, InputError
from navkit.geometry import R_BODY_FROM_OPTICAL, se3_apply
from navkit.geometry._validate import check_settings
from navkit.sensors import StereoRig
from navkit.stereo.disparity import DisparitySettings, compute_disparity
from navkit.stereo.triangulation import disparity_to_points

__all__ = [
    "FloorplanSettings",
    "default_num_disparities",
    "stereo_wall_points",
    "thin_points",
    "usable_depth",
    "wall_points_body",
    "wall_points_world",
]


#: A height above the floor (z = 0), metres; negative below it (a floor lower than the
#: reference, a camera looking down a step).
_HEIGHT = Domain(note="metres above the floor, negative below it")


@dataclass(frozen=True)
class FloorplanSettings:
    """Which stereo points are wall points.

    Attributes
    ----------
    min_height, max_height : float
        Metres above the floor (``z = 0`` in the world).
    max_depth : float
        Metres; farther points are dropped (the depth error ``z^2 / (b f) * sigma_d`` grows fast).
    cell : float
        Metres; the projected points are thinned to one per ``cell`` square.
    max_depth_error : float
        Metres; :func:`stereo_wall_points` also drops points whose predicted depth error
        ``z^2 / (b f) * disparity_sigma`` exceeds this (so the usable range follows the rig).
    disparity_sigma : float
        Pixels; the matcher's disparity noise assumed for that prediction.
    min_depth : float
        Metres; without explicit matcher settings the disparity search range is ``b f / min_depth``.
    max_disparity_step : float
        Pixels; :func:`stereo_wall_points` drops pixels whose 5 x 5 neighbourhood spans a larger
        disparity range (depth edges, where matchers smear foreground into background).
    subpixel : {"lk", "parabola"}
        Sub-pixel step of the default matcher of :func:`stereo_wall_points` (see
        :class:`~navkit.stereo.disparity.DisparitySettings`): ``"lk"`` removes the matcher's
        pixel locking, a per-wall depth bias of up to several centimetres.
    """

    min_height: float = domain_field(0.3, _HEIGHT)
    max_height: float = domain_field(2.0, _HEIGHT)
    max_depth: float = domain_field(8.0, POSITIVE)
    cell: float = domain_field(0.02, POSITIVE)
    max_depth_error: float = domain_field(0.25, POSITIVE)
    disparity_sigma: float = domain_field(0.25, Domain(lo=0.0, lo_open=True, note="pixels"))
    max_disparity_step: float = domain_field(1.0, Domain(lo=0.0, note="pixels"))
    min_depth: float = domain_field(0.5, POSITIVE)
    subpixel: Literal["lk", "parabola"] = "lk"

    def __post_init__(self) -> None:
        check_settings(self)
        if not self.max_height > self.min_height:
            raise ConfigError(
                f"{self.min_height} .. {self.max_height}",
                field="min_height/max_height",
                expected="min_height < max_height",
            )


def thin_points(points: ArrayLike, cell: float) -> NDArray[np.float64]:
    """Mean point ``(K, 2)`` of each occupied ``cell`` square (vectorised)."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(P) == 0:
        return P
    keys = np.floor(P / cell).astype(np.int64)
    _, inv, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    out = np.zeros((len(counts), 2))
    np.add.at(out, inv, P)
    return out / counts[:, None]


def _valid(points_cam: ArrayLike) -> NDArray[np.float64]:
    P = np.asarray(points_cam, dtype=np.float64)
    if P.shape[-1] != 3:
        raise InputError(
            f"has shape {P.shape}", field="points", expected="(..., 3) camera-frame points"
        )
    P = P.reshape(-1, 3)
    return P[np.all(np.isfinite(P), axis=1)]


def wall_points_world(
    points_cam: ArrayLike, T_world_camera: ArrayLike, settings: FloorplanSettings | None = None
) -> NDArray[np.float64]:
    """Wall points ``(K, 2)`` in the world plane from camera-frame stereo points ``(..., 3)``."""
    s = settings or FloorplanSettings()
    P = _valid(points_cam)
    P = P[(P[:, 2] > 0) & (P[:, 2] <= s.max_depth)]
    W = se3_apply(np.asarray(T_world_camera, dtype=np.float64), P)
    W = W[(W[:, 2] >= s.min_height) & (W[:, 2] <= s.max_height)]
    return thin_points(W[:, :2], s.cell)


def wall_points_body(
    points_cam: ArrayLike, camera_height: float, settings: FloorplanSettings | None = None
) -> NDArray[np.float64]:
    """Wall points ``(K, 2)`` in the body frame (x forward, y left) of a level camera.

    The camera sits ``camera_height`` metres above the floor, level (the paper's 2D case);
    ``p_body = R_BODY_FROM_OPTICAL p_cam`` with the height band applied to ``z_body + height``.
    """
    s = settings or FloorplanSettings()
    P = _valid(points_cam)
    P = P[(P[:, 2] > 0) & (P[:, 2] <= s.max_depth)]
    B = P @ R_BODY_FROM_OPTICAL.T
    h = B[:, 2] + camera_height
    B = B[(h >= s.min_height) & (h <= s.max_height)]
    return thin_points(B[:, :2], s.cell)


def default_num_disparities(rig: StereoRig, settings: FloorplanSettings | None = None) -> int:
    """The disparity search range :func:`stereo_wall_points` uses without matcher settings.

    ``b f / min_depth`` (the nearest depth of interest) rounded up to a multiple of 16 (OpenCV),
    at least 16 and at most half the image width (the left-right check needs both halves).
    """
    s = settings or FloorplanSettings()
    nd = int(16 * np.ceil(rig.baseline * rig.camera.fx / s.min_depth / 16))
    return max(16, min(nd, 16 * ((rig.camera.width - 1) // 32)))


def usable_depth(rig: StereoRig, settings: FloorplanSettings | None = None) -> float:
    """Farthest depth :func:`stereo_wall_points` keeps, metres.

    ``max_depth``, or nearer where the predicted depth error ``z^2 sigma_d / (b f)`` (paper 3,
    eq. 1 differentiated) reaches ``max_depth_error``.
    """
    s = settings or FloorplanSettings()
    bf = rig.baseline * rig.camera.fx
    return min(s.max_depth, float(np.sqrt(s.max_depth_error * bf / s.disparity_sigma)))


def stereo_wall_points(
    left: ArrayLike,
    right: ArrayLike,
    rig: StereoRig,
    *,
    T_world_camera: ArrayLike | None = None,
    camera_height: float | None = None,
    disparity: DisparitySettings | None = None,
    settings: FloorplanSettings | None = None,
) -> NDArray[np.float64]:
    """The whole front end for one rectified pair: disparity -> points -> 2D wall points.

    Give ``T_world_camera`` for world-frame points (map building with known poses), or
    ``camera_height`` for body-frame points of a level camera (the fragment to localize).

    Without ``disparity`` settings the matcher checks left against right by a second run on the
    mirrored pair (``lr_method="rematch"``), not by the faster forward warp that is
    :class:`~navkit.stereo.disparity.DisparitySettings`' default: wall maps and fixes are metric,
    and the re-match also rejects isolated mismatches (Middlebury: 3.07 % instead of 3.51 % of
    the kept pixels off by more than 2 px); with the warp one of the four fixes of
    ``tests/stereo/test_cli_stereo.py::test_locate_refines_stereo_fixes_against_the_walls`` was
    no longer refined against the walls.
    """
    if (T_world_camera is None) == (camera_height is None):
        raise InputError(
            "give exactly one of T_world_camera / camera_height",
            field="T_world_camera",
            expected="a (4, 4) pose for world points, or a height for body points",
        )
    import cv2

    s = settings or FloorplanSettings()
    if disparity is None:
        disparity = DisparitySettings(
            num_disparities=default_num_disparities(rig, s),
            subpixel=s.subpixel,
            lr_method="rematch",
        )
    d = compute_disparity(left, right, disparity).disparity
    # Stage: drop depth edges (a large disparity range in the 5 x 5 neighbourhood).
    k = np.ones((5, 5), np.uint8)
    hi = cv2.dilate(np.where(np.isfinite(d), d, -1e6).astype(np.float32), k)
    lo = cv2.erode(np.where(np.isfinite(d), d, 1e6).astype(np.float32), k)
    d = np.where((hi - lo) <= s.max_disparity_step, d, np.nan)
    # Stage: drop points whose predicted depth error exceeds the budget.
    bf = rig.baseline * rig.camera.fx
    d = np.where(d + rig.doffs >= bf / usable_depth(rig, s), d, np.nan)
    P = disparity_to_points(d, rig)
    settings = s
    if T_world_camera is not None:
        return wall_points_world(P, T_world_camera, settings)
    return wall_points_body(P, float(camera_height), settings)  # type: ignore[arg-type]
