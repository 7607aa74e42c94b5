"""Paper 3's localization: slide the observed wall fragment along the map, known heading.

The robot sees a fragment ``phi_2`` of a wall; the maximum over offsets of the correlation
between the map ``phi_1`` and the shifted fragment gives the fragment's place on the map; with
the heading ``theta`` known (the camera drive's angle sensor) the robot position follows from the
fragment's world and camera coordinates.

- :func:`correlate_profiles` is the paper's discrete form, ``R_i = sum_{j=i}^{i+M-1}
  phi_1(A_j) phi_2(B_{j-i+1})``, ``i = 1 .. N - M + 1`` (or, by default, its normalised version,
  the correlation coefficient the paper names: raw products favour bright / dense stretches).
- :func:`robot_position` is the paper's position formula in navkit's frames.
- :func:`locate_known_heading` applies the method to 2D points: the fragment, turned by the known
  heading, is correlated over every 2D offset with the map's likelihood field (by FFT), the
  maximum is refined to sub-cell by a parabola, and the robot position follows from
  :func:`robot_position`.

Decision (the paper's eq. 2 prints ``R = [[-sin t, cos t], [cos t, sin t]]``, a reflection with
determinant -1 that bakes in its camera axes): navkit uses the body frame (x forward, y left) and
the proper rotation ``R(theta)``; the position formula is then ``t = p_w - R(theta) p_c``, i.e.
``dx = x_w - x_c cos(theta) + y_c sin(theta)``, ``dy = y_w - x_c sin(theta) - y_c cos(theta)``.
The paper's printed ``dx = x_w + x_c sin(theta) - y_c cos(theta)`` is the same formula for its
axes (camera x to the left of travel, y forward, heading measured from world y).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.signal import fftconvolve

from navkit.domains import POSITIVE, Domain, domain_field
from navkit.errors import InputError
from navkit.geometry._validate import as_points, check_settings
from navkit.geometry.polygons import points_in_polygon
from navkit.localization.field import LikelihoodField
from navkit.localization.refine import (
    PoseRefinement,
    RefineSettings,
    occluded_fraction,
    refine_pose,
)
from navkit.localization.visibility import ViewModel, VisibilityCheck, check_visibility
from navkit.localization.walls import WallSegment

__all__ = [
    "KnownHeadingFix",
    "KnownHeadingSettings",
    "correlate_profiles",
    "locate_known_heading",
    "robot_position",
]

log = logging.getLogger(__name__)


def correlate_profiles(
    map_profile: ArrayLike, fragment: ArrayLike, *, normalized: bool = True
) -> NDArray[np.float64]:
    """Correlation of a fragment slid along a map profile (paper 3, discrete form).

    Parameters
    ----------
    map_profile : (N,) array
        ``phi_1(A_1 .. A_N)``, the map sampled at equal steps.
    fragment : (M,) array
        ``phi_2(B_1 .. B_M)``, the observed fragment at the same step, ``M <= N``.
    normalized : bool
        True: the correlation coefficient of each window (Pearson; 0 for a constant window);
        False: the paper's raw sum of products.

    Returns
    -------
    (N - M + 1,) array
        ``R_i`` for offsets ``i = 0 .. N - M``; ``argmax`` is the fragment's place.
    """
    A = np.asarray(map_profile, dtype=np.float64).reshape(-1)
    B = np.asarray(fragment, dtype=np.float64).reshape(-1)
    if len(B) == 0 or len(B) > len(A):
        raise InputError(
            f"has {len(B)} samples for a map of {len(A)}",
            field="fragment",
            expected="1 <= M <= N samples",
        )
    if not (np.isfinite(A).all() and np.isfinite(B).all()):
        raise InputError(
            "contains NaN or inf", field="map_profile / fragment", expected="finite samples"
        )
    windows = np.lib.stride_tricks.sliding_window_view(A, len(B))  # (N - M + 1, M)
    if not normalized:
        return windows @ B
    Wc = windows - windows.mean(axis=1, keepdims=True)
    Bc = B - B.mean()
    den = np.linalg.norm(Wc, axis=1) * np.linalg.norm(Bc)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = (Wc @ Bc) / den
    return np.where(den > 0, r, 0.0)


def robot_position(
    fragment_world: ArrayLike, fragment_body: ArrayLike, theta: float | ArrayLike
) -> NDArray[np.float64]:
    """Robot position from a point seen in the body frame and found in the world (paper 3).

    ``t = p_w - R(theta) p_c`` with ``R(theta)`` the rotation by the heading (body x forward,
    y left): ``dx = x_w - x_c cos(theta) + y_c sin(theta)``,
    ``dy = y_w - x_c sin(theta) - y_c cos(theta)``.

    Parameters
    ----------
    fragment_world, fragment_body : (..., 2) arrays
        The same point in the world and in the body frame, metres.
    theta : float or (...,) array
        Heading, radians.

    Returns
    -------
    (..., 2) array
        Robot position ``(dx, dy)``, metres.
    """
    w = np.asarray(fragment_world, dtype=np.float64)
    c = np.asarray(fragment_body, dtype=np.float64)
    th = np.asarray(theta, dtype=np.float64)
    ct, st = np.cos(th), np.sin(th)
    dx = w[..., 0] - c[..., 0] * ct + c[..., 1] * st
    dy = w[..., 1] - c[..., 0] * st - c[..., 1] * ct
    return np.stack([dx, dy], axis=-1)


#: A share of the fragment (occluded, unseen) above which a fix is refused; >= 1 = off.
_SHARE = Domain(lo=0.0, note="a fraction, >= 1 = off")


@dataclass(frozen=True)
class KnownHeadingSettings:
    """Ambiguity rules and refinement of :func:`locate_known_heading`.

    Attributes
    ----------
    peak_tolerance : float
        Offsets scoring within this fraction of the best belong to the peak.
    ambiguity_extent : float
        Metres; a peak (its connected near-optimal set) longer than this along its major axis is
        ambiguous (the fragment slides along a straight wall).
    second_peak_ratio : float
        A distinct second peak (outside ``exclusion_radius`` of the best) scoring at least this
        fraction of the best makes the fix ambiguous (a twin corner, a repeated wall).
    exclusion_radius : float
        Metres; offsets nearer than this to the best belong to the same peak.
    min_score : float
        Fixes scoring below this fail.
    max_occluded : float
        With walls: a fix from which more than this fraction of the fragment would have been
        seen through a map wall is inconsistent (reason ``"occluded"``; see
        :func:`~navkit.localization.refine.occluded_fraction`).
    max_unseen : float
        With walls and a ``view``: a fix from which the map predicts a near wall, but the
        fragment has no point at or before it, over more than this fraction of the view's
        bearings is inconsistent (reason ``"unseen wall"``; see
        :func:`~navkit.localization.visibility.check_visibility`). Decision: 0.15 (about 9 deg
        of the 62 deg a 320-pixel, 90 deg stereo camera with 64 disparities returns). A correct
        fix leaves nearly nothing unseen: the pose error (a few cm) and the map's wall
        directions (< 0.5 deg, < 5 cm at 5 m) are far below the 0.15 m range margin, and the
        front end's depth-edge filter removes 2 pixels (0.7 deg) on each side of an edge,
        inside the check's one-bearing-step tolerance; 0.15 leaves room for several such bands
        and untextured patches, and a wall missing over a sixth of the view is no such gap.
    refine : RefineSettings
        The final point-to-line refinement (when the map's walls are given).
    """

    peak_tolerance: float = domain_field(
        0.05, Domain(lo=0.0, hi=1.0, lo_open=True, hi_open=True, note="a fraction of the best")
    )
    ambiguity_extent: float = domain_field(0.5, POSITIVE)
    second_peak_ratio: float = domain_field(0.9, Domain(lo=0.0, hi=1.0, lo_open=True))
    exclusion_radius: float = domain_field(1.0, POSITIVE)
    min_score: float = domain_field(0.3, Domain(lo=0.0, hi=1.0, note="a score, 0 = accept all"))
    max_occluded: float = domain_field(0.05, _SHARE)
    max_unseen: float = domain_field(0.15, _SHARE)
    refine: RefineSettings = field(default_factory=RefineSettings)

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class KnownHeadingFix:
    """Result of :func:`locate_known_heading`.

    Attributes
    ----------
    position : (2,) array
        Robot ``(x, y)``, metres (after the point-to-line refinement when walls were given).
    fragment_world : (2,) array
        Where the fragment's centroid lies on the map (the correlation's peak).
    score : float
        Peak correlation divided by the number of fragment cells, ``[0, 1]``.
    correlation : (H, W) array
        ``R(dx, dy)`` over the searched offsets (row = y).
    peak_extent : float
        Metres; length of the peak (the connected set of offsets within ``peak_tolerance`` of
        the best) along its major axis (large = ambiguous, e.g. a straight wall).
    peak_direction : (2,) array
        World unit vector of that axis (along the wall for a straight wall).
    ok : bool
        A confident fix: score above ``min_score`` and not ambiguous.
    ambiguous : bool
        The fragment fits along a line (elongated peak, or a degenerate refinement) or in two
        distinct places (second peak).
    reason : str
        ``""``, ``"elongated peak"``, ``"second peak"``, ``"degenerate"``, ``"occluded"`` (the
        fragment would have been seen through a map wall from there), ``"unseen wall"`` (the
        map predicts a near wall over part of the view where the fragment has nothing), joined
        by ``" and "``.
    second_score : float
        Best correlation outside the peak's neighbourhood, same units as ``score`` (NaN when the
        correlation has no offset there).
    second_position : (2,) array
        Robot position of that second peak, metres.
    correlation_position : (2,) array
        The robot position from the correlation peak alone (the paper's method, before the
        refinement).
    refinement : PoseRefinement or None
        The point-to-line refinement (None without walls).
    visibility : VisibilityCheck or None
        The negative-information check at the final position (None without walls and view).
    """

    position: NDArray[np.float64]
    fragment_world: NDArray[np.float64]
    score: float
    correlation: NDArray[np.float64]
    peak_extent: float
    peak_direction: NDArray[np.float64]
    ok: bool = True
    ambiguous: bool = False
    reason: str = ""
    second_score: float = float("nan")
    second_position: NDArray[np.float64] = field(default_factory=lambda: np.full(2, np.nan))
    correlation_position: NDArray[np.float64] = field(default_factory=lambda: np.full(2, np.nan))
    refinement: PoseRefinement | None = None
    visibility: VisibilityCheck | None = None

    @property
    def unseen_fraction(self) -> float:
        """Part of the view where the map predicts a near wall the fragment lacks (NaN: not
        checked)."""
        return float("nan") if self.visibility is None else self.visibility.unseen_fraction


def _peak_shape(
    R: NDArray[np.float64], y: int, x: int, r: float, tolerance: float
) -> tuple[NDArray[np.float64], float, NDArray[np.bool_]]:
    """Major direction, extent (metres) and mask of the connected near-optimal set at (y, x)."""
    from scipy import ndimage

    near = R >= (1.0 - tolerance) * R[y, x]
    labels, _ = ndimage.label(near)
    comp = labels == labels[y, x]
    yy, xx = np.nonzero(comp)
    T = np.stack([xx, yy], axis=1) * r
    if len(T) > 1:
        _, V = np.linalg.eigh(np.cov(T.T))
        d = V[:, 1]
        proj = T @ d
        return d, float(proj.max() - proj.min()) + r, comp
    return np.array([1.0, 0.0]), r, comp


def locate_known_heading(
    fld: LikelihoodField,
    points: ArrayLike,
    theta: float,
    *,
    walls: Sequence[WallSegment] | ArrayLike | None = None,
    range_sigma: ArrayLike | None = None,
    region: ArrayLike | None = None,
    view: ViewModel | None = None,
    settings: KnownHeadingSettings | None = None,
) -> KnownHeadingFix:
    """Paper 3's correlation localization in 2D with a known heading.

    Stages: (1) turn the fragment's body-frame points by ``theta`` (paper eq. 2); (2) rasterise
    them on the field's grid, relative to their centroid; (3) correlate with the map over every
    offset (``R(dx, dy) = sum phi_1 phi_2``, by FFT); (4) the maximum, refined by a parabola per
    axis, places the fragment's centroid in the world; (5) the robot position from
    :func:`robot_position`; (6) the ambiguity report: the shape of the peak (its connected
    near-optimal set: a straight wall makes it long, along the wall) and the best distinct
    second peak; (7) with the map's ``walls``, the position is refined by weighted point-to-line
    least squares (:func:`navkit.localization.refine.refine_pose`, heading kept), whose
    information matrix also flags a fragment of one straight wall as degenerate, and the fix
    is checked against the map's free space (no fragment point seen through a wall) and, with a
    ``view``, against negative information (no near wall predicted where the fragment is empty).

    Parameters
    ----------
    fld : LikelihoodField
        The map ``phi_1``.
    points : (N, 2) array
        Fragment points in the body frame, metres (NaN rows dropped).
    theta : float
        Known heading, radians.
    walls : list of WallSegment or (K, 2, 2) array, optional
        The map's walls, for the final refinement (stage 7).
    range_sigma : (N,) array, optional
        Metres; each point's error along its ray (stereo:
        :func:`~navkit.localization.refine.stereo_range_sigma`), weights of the refinement.
    region : (P, 2) array, optional
        A polygon the robot is known to be in (e.g. the map's room outline,
        ``WallMap.outline``): offsets that would put the robot outside are no candidates (their
        correlation is set to -1). Without it a wall fragment also fits the far side of a wall,
        seen from outside the room.
    view : ViewModel, optional
        The sensor's usable bearings and depth (stereo: :meth:`ViewModel.from_stereo`); with
        ``walls``, the fix is checked for walls the map predicts in view that the fragment
        lacks (:func:`~navkit.localization.visibility.check_visibility`).
    settings : KnownHeadingSettings, optional

    Returns
    -------
    KnownHeadingFix
    """
    s = settings or KnownHeadingSettings()
    P = as_points(points, 2)
    finite = np.all(np.isfinite(P), axis=1)
    P = P[finite]
    if len(P) < 2:
        raise InputError(
            f"has {len(P)} finite points", field="points", expected="at least 2 points"
        )
    r = fld.resolution
    c, sn = np.cos(theta), np.sin(theta)
    Q = P @ np.array([[c, -sn], [sn, c]]).T
    centroid_body = P.mean(axis=0)
    q0 = Q.mean(axis=0)
    rel = Q - q0
    ij = np.round(rel / r).astype(np.intp)
    lo = ij.min(axis=0)
    ij -= lo
    kw, kh = (ij.max(axis=0) + 1).tolist()
    kernel = np.zeros((kh, kw))
    np.add.at(kernel, (ij[:, 1], ij[:, 0]), 1.0)
    # correlation = convolution with the flipped kernel; 'full' then keep offsets where the
    # kernel's cell (0, 0) lands on a map cell
    R = fftconvolve(fld.values.astype(np.float64), kernel[::-1, ::-1], mode="full")
    R = R[kh - 1 :, kw - 1 :]  # R[y, x]: kernel cell (0, 0) on map cell (y, x)
    R = R / len(P)
    if region is not None:
        # the robot position of each offset: cell centre - lo r - R(theta) c_body
        poly = as_points(region, 2, "region")
        gy, gx = np.mgrid[0 : R.shape[0], 0 : R.shape[1]]
        cells = np.stack([gx.ravel(), gy.ravel()], axis=1) + 0.5
        robot = robot_position(fld.origin + cells * r - lo * r, centroid_body, theta)
        inside = points_in_polygon(robot, poly).reshape(R.shape)
        if not inside.any():
            raise InputError(
                "no offset places the robot inside it",
                field="region",
                expected="a polygon overlapping the map",
            )
        R = np.where(inside, R, -1.0)
    y, x = np.unravel_index(int(np.argmax(R)), R.shape)

    def parabola(a: float, b: float, cc: float) -> float:
        den = a - 2 * b + cc
        return 0.0 if den >= 0 else float(np.clip(0.5 * (a - cc) / den, -0.5, 0.5))

    dx = parabola(R[y, x - 1], R[y, x], R[y, x + 1]) if 0 < x < R.shape[1] - 1 else 0.0
    dy = parabola(R[y - 1, x], R[y, x], R[y + 1, x]) if 0 < y < R.shape[0] - 1 else 0.0

    def to_world(yx: NDArray[np.float64]) -> NDArray[np.float64]:
        # map cell (y, x) has centre origin + (x + 0.5, y + 0.5) r; the kernel cell (0, 0)
        # holds points at rel = lo * r, so the centroid sits at that centre - lo * r
        return fld.origin + (yx[::-1] + 0.5) * r - lo * r

    frag_world = to_world(np.array([y + dy, x + dx]))
    pos = robot_position(frag_world, centroid_body, theta)
    # Stage 6: the peak's shape and a distinct second peak.
    d, extent, comp = _peak_shape(R, int(y), int(x), r, s.peak_tolerance)
    yy, xx = np.mgrid[0 : R.shape[0], 0 : R.shape[1]]
    # the second peak lies outside the peak's own near-optimal set and the exclusion radius
    away = ~comp & (np.hypot(yy - y, xx - x) * r >= s.exclusion_radius)
    second, second_pos = float("nan"), np.full(2, np.nan)
    if away.any():
        k = int(np.argmax(np.where(away, R, -np.inf)))
        y2, x2 = np.unravel_index(k, R.shape)
        second = float(R[y2, x2])
        second_pos = robot_position(to_world(np.array([y2, x2], float)), centroid_body, theta)
    score = float(R[y, x])
    reasons = []
    if extent > s.ambiguity_extent:
        reasons.append("elongated peak")
    if np.isfinite(second) and second >= s.second_peak_ratio * score:
        reasons.append("second peak")
    # Stage 7: point-to-line refinement against the walls (heading kept).
    refinement = None
    visibility = None
    correlation_position = pos.copy()
    if walls is not None:
        sig = None
        if range_sigma is not None:
            sig = np.asarray(range_sigma, dtype=np.float64).reshape(-1)
            if len(sig) != len(finite):
                raise InputError(
                    f"has {len(sig)} values for {len(finite)} points",
                    field="range_sigma",
                    expected="one sigma per point",
                )
            sig = sig[finite]
        refinement = refine_pose(
            walls,
            P,
            np.array([pos[0], pos[1], theta]),
            range_sigma=sig,
            known_heading=True,
            settings=s.refine,
        )
        if refinement.converged:
            pos = refinement.pose[:2].copy()
        if refinement.degenerate:
            reasons.append("degenerate")
            if "elongated peak" not in reasons:
                d = refinement.weak_direction
        # a point may lie up to 3 sigma of its range error behind its own wall
        margin = 0.15 if sig is None else np.maximum(0.15, 3.0 * sig)
        occluded = occluded_fraction(walls, P, np.array([pos[0], pos[1], theta]), margin=margin)
        if occluded > s.max_occluded:
            reasons.append("occluded")
        if view is not None:
            # negative information: walls the map puts in view that the fragment lacks
            visibility = check_visibility(walls, P, np.array([pos[0], pos[1], theta]), view)
            if visibility.unseen_fraction > s.max_unseen:
                reasons.append("unseen wall")
    ambiguous = bool(reasons)
    log.debug("known-heading fix %s score %.3f %s", pos, score, " and ".join(reasons))
    return KnownHeadingFix(
        position=pos,
        fragment_world=frag_world,
        score=score,
        correlation=R,
        peak_extent=extent,
        peak_direction=d,
        ok=bool(score >= s.min_score and not ambiguous),
        ambiguous=ambiguous,
        reason=" and ".join(reasons),
        second_score=second,
        second_position=second_pos,
        correlation_position=correlation_position,
        refinement=refinement,
        visibility=visibility,
    )
