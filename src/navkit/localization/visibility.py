"""Negative information: does a fix agree with what the sensor should have seen from there?

A correlation (paper 3) or a point-to-line refinement scores only the points that *were* seen:
a fragment of far, noisy points can fit a place from which the map predicts a near wall in part
of the field of view where the fragment has nothing. From the fixed pose the map's segments are
ray-cast over the view's bearings; a bearing whose predicted wall lies well inside the usable
range (its points would survive the sensor's depth cut) but has no fragment point at or before
that wall is *unseen*. A large unseen fraction of the field of view means the fix is not
consistent with the map (the fragment was taken somewhere else).

Decisions (the paper has no such check; the thresholds follow from the sensor, not from a
benchmark):

- a predicted wall is *expected* when ``z + 3 sigma_z(z) <= max_depth`` along the body x axis
  (stereo: ``sigma_z = z^2 sigma_d / (b f)``, paper 3 eq. 1 differentiated; the wall's points
  pass the front end's depth cut with probability >= 99.9 %), the ray meets the wall more than
  ``end_margin`` from the segment's ends (map walls end at their extreme supporting points, and
  doorways / short stray pieces have uncertain extents) and at most ``max_incidence`` off its
  normal (grazing walls foreshorten into few pixels);
- a bearing is *seen* when a fragment point lies within one bearing step of it at a range up to
  the predicted wall plus ``max(0.15 m, 3 sigma_ray)`` (a point in front of the wall is an
  unmapped object that hides it: consistent; a point far behind it is handled by
  :func:`~navkit.localization.refine.occluded_fraction`);
- the unseen fraction is counted over all bearings of the view (not only the expected ones), so
  it reads as "the part of the field of view where a wall is missing".
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import ConfigError, InputError
from navkit.geometry._validate import as_points
from navkit.localization.refine import _segments
from navkit.localization.walls import WallSegment
from navkit.sensors import StereoRig

__all__ = ["ViewModel", "VisibilityCheck", "check_visibility"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ViewModel:
    """What one view of the sensor can see (body frame: x forward, y left, the sensor at 0).

    Attributes
    ----------
    bearing_min, bearing_max : float
        Radians; the bearings the sensor returns points for (for stereo, the image columns
        where the matcher can produce a disparity, not the lens's full field of view).
    max_depth : float
        Metres along the body x axis; points beyond are dropped by the front end.
    depth_sigma_coefficient : float
        ``k`` in ``sigma_z = k z^2`` (1/m; stereo: ``sigma_d / (b f)``; 0 for a laser).
    sigma_floor : float
        Metres; smallest range margin (map error, wall texture), as in the free-space check.
    bearing_step : float
        Radians; the bearings checked (and the tolerance of a point's bearing).
    end_margin : float
        Metres; ray hits this close to a map segment's end are not expected to be seen.
    max_incidence : float
        Radians; walls met at a larger angle from their normal are not expected to be seen.
    """

    bearing_min: float
    bearing_max: float
    max_depth: float
    depth_sigma_coefficient: float = 0.0
    sigma_floor: float = 0.05
    bearing_step: float = float(np.radians(1.0))
    end_margin: float = 0.3
    max_incidence: float = float(np.radians(75.0))

    def __post_init__(self) -> None:
        if not (np.isfinite(self.bearing_min) and self.bearing_min < self.bearing_max < np.pi):
            raise ConfigError(
                f"is {self.bearing_min} .. {self.bearing_max}",
                field="bearing_min/bearing_max",
                expected="-pi < bearing_min < bearing_max < pi radians",
            )
        for name in ("max_depth", "bearing_step", "sigma_floor", "max_incidence"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"is {v}", field=name, expected="a positive number")
        if self.depth_sigma_coefficient < 0 or self.end_margin < 0:
            raise ConfigError(
                f"{self.depth_sigma_coefficient}, {self.end_margin}",
                field="depth_sigma_coefficient/end_margin",
                expected=">= 0",
            )

    @classmethod
    def from_stereo(
        cls,
        rig: StereoRig,
        *,
        max_depth: float,
        num_disparities: int,
        disparity_sigma: float = 0.25,
    ) -> ViewModel:
        """The view of a rectified stereo rig with a left-right checked matcher.

        The left image's first ``num_disparities`` columns have no match in the right image, and
        the left-right check loses the last ``num_disparities`` columns of the right image's
        own disparity map, so columns ``[D, W - D]`` are the ones that return points for every
        depth: bearings ``atan((c_x - u) / f_x)`` (body y to the left = image column to the
        left).
        """
        cam = rig.camera
        D = int(num_disparities)
        if not 0 <= D < cam.width / 2:
            raise InputError(
                f"is {D} for a {cam.width}-pixel image",
                field="num_disparities",
                expected="0 <= D < width / 2",
            )
        b_left = float(np.arctan((cam.cx - D) / cam.fx))
        b_right = float(np.arctan((cam.cx - (cam.width - 1 - D)) / cam.fx))
        return cls(
            bearing_min=b_right,
            bearing_max=b_left,
            max_depth=max_depth,
            depth_sigma_coefficient=disparity_sigma / (rig.baseline * cam.fx),
        )


@dataclass(frozen=True)
class VisibilityCheck:
    """Result of :func:`check_visibility`.

    Attributes
    ----------
    bearings : (M,) array
        Radians, body frame; the checked bearings.
    predicted_range : (M,) array
        Metres to the first map wall along each bearing (NaN: none).
    expected : (M,) bool array
        The map predicts a wall the sensor should return points for.
    seen : (M,) bool array
        The fragment has a point at or before the predicted wall (False where not expected).
    unseen_fraction : float
        ``(expected & ~seen).mean()``: the part of the field of view where a wall is missing.
    expected_fraction : float
        ``expected.mean()``.
    unseen_span : (2,) array
        Radians; the first and last unseen bearing (NaN when none).
    """

    bearings: NDArray[np.float64]
    predicted_range: NDArray[np.float64]
    expected: NDArray[np.bool_]
    seen: NDArray[np.bool_]
    unseen_fraction: float
    expected_fraction: float
    unseen_span: NDArray[np.float64]


def check_visibility(
    walls: Sequence[WallSegment] | ArrayLike,
    points: ArrayLike,
    pose: ArrayLike,
    view: ViewModel,
) -> VisibilityCheck:
    """Ray-cast the map from ``pose`` over the view's bearings and compare with the fragment.

    Parameters
    ----------
    walls : list of WallSegment or (K, 2, 2) array
        The map's walls, world frame, metres.
    points : (N, 2) array
        The fragment in the body frame (the sensor at the origin), metres; NaN rows dropped.
    pose : (3,) array
        ``(x, y, theta)`` of the body in the world (the fix to check).
    view : ViewModel

    Returns
    -------
    VisibilityCheck
    """
    seg = _segments(walls)
    P = as_points(points, 2)
    P = P[np.all(np.isfinite(P), axis=1)]
    x = np.asarray(pose, dtype=np.float64).reshape(3)
    if not np.all(np.isfinite(x)):
        raise InputError(f"is {x}", field="pose", expected="a finite (x, y, theta)")
    step = view.bearing_step
    n = max(1, int(np.floor((view.bearing_max - view.bearing_min) / step)) + 1)
    b = np.asarray(view.bearing_min + step * np.arange(n), dtype=np.float64)
    # Ray-cast: o + t d = A + u e for every bearing x segment (Cramer's rule).
    d = np.stack([np.cos(x[2] + b), np.sin(x[2] + b)], axis=1)  # (M, 2)
    A = seg[:, 0]
    e = seg[:, 1] - A  # (K, 2)
    elen = np.linalg.norm(e, axis=1)
    den = d[:, None, 0] * (-e[None, :, 1]) + d[:, None, 1] * e[None, :, 0]
    w = (A - x[:2])[None, :, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * (-e[None, :, 1]) + w[..., 1] * e[None, :, 0]) / den
        u = (d[:, None, 0] * w[..., 1] - d[:, None, 1] * w[..., 0]) / den
    hit = np.isfinite(t) & (t > 0) & (u >= 0) & (u <= 1)
    tt = np.where(hit, t, np.inf)
    k = np.argmin(tt, axis=1)
    rows = np.arange(n)
    r_pred = tt[rows, k]
    has = np.isfinite(r_pred)
    # the first wall's hit: far from its ends, not grazing, inside the usable depth
    u_m = u[rows, k] * elen[k]
    inner = (u_m >= view.end_margin) & (u_m <= elen[k] - view.end_margin)
    normal = np.stack([-e[k, 1], e[k, 0]], axis=1) / np.maximum(elen[k], 1e-12)[:, None]
    cos_inc = np.abs(np.einsum("mc,mc->m", normal, d))
    z = np.where(has, r_pred, np.inf) * np.cos(b)
    sig_z = view.depth_sigma_coefficient * z**2
    expected = has & inner & (cos_inc >= np.cos(view.max_incidence))
    expected &= z + 3.0 * sig_z <= view.max_depth
    # Seen: the nearest fragment point within one step of each bearing.
    seen = np.zeros(n, dtype=bool)
    if len(P):
        pb = np.arctan2(P[:, 1], P[:, 0])
        pr = np.hypot(P[:, 0], P[:, 1])
        j = np.round((pb - view.bearing_min) / step).astype(np.intp)
        inside = (j >= -1) & (j <= n)
        nearest = np.full(n + 2, np.inf)
        np.minimum.at(nearest, j[inside] + 1, pr[inside])
        # a point counts for its own bearing and both neighbours (bearing quantisation)
        near3 = np.minimum(np.minimum(nearest[:-2], nearest[1:-1]), nearest[2:])
        sig_ray = sig_z / np.maximum(np.cos(b), 1e-6)
        margin = np.maximum(np.maximum(0.15, view.sigma_floor), 3.0 * sig_ray)
        seen = expected & (near3 <= r_pred + margin)
    unseen = expected & ~seen
    span = np.array([b[unseen].min(), b[unseen].max()]) if unseen.any() else np.full(2, np.nan)
    res = VisibilityCheck(
        bearings=b,
        predicted_range=np.where(has, r_pred, np.nan),
        expected=expected,
        seen=seen,
        unseen_fraction=float(unseen.mean()),
        expected_fraction=float(expected.mean()),
        unseen_span=span,
    )
    log.debug(
        "visibility from %s: %.0f %% of the view expects a wall, %.0f %% unseen",
        x,
        100 * res.expected_fraction,
        100 * res.unseen_fraction,
    )
    return res
