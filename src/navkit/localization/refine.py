"""Final pose refinement: weighted, robust point-to-line least squares against the wall map.

The correlation (paper 3) and the correlative matcher find the right basin; their optimum is the
maximum of a likelihood field blurred by ``sigma`` (0.1 m) and sampled on a grid, so it carries
the field's quantisation and the blur's pull toward nearby clutter. The map, however, is made of
straight walls with total-least-squares lines: the maximum-likelihood pose given the fragment's
points is the one minimising the weighted squared distances of the points to their walls'
*lines* (point-to-line ICP, Censi 2008's PLICP in its Gauss-Newton form)::

    min_{x, y, theta}  sum_i  w_i  rho_H( n_j(i) . (R(theta) p_i + t) - rho_j(i) )

- association: each point to the nearest map segment (distance to the segment, the line
  extended by ``end_margin`` at both ends); points farther than ``max_distance`` are outliers;
- weights: ``w_i = 1 / (sigma_ray_i^2 (n . u_i)^2 + sigma_floor^2)`` - a stereo point's error
  lies along its viewing ray ``u_i`` (the depth error ``sigma_z = z^2 sigma_d / (b f)``, paper 3
  eq. 1 differentiated), so only its component along the wall's normal counts; ``sigma_floor``
  covers the map's own error and wall texture;
- robustness: Huber's weights on the normalised residuals with the scale re-estimated each
  iteration (1.4826 MAD), so stray stereo points and unmodelled clutter do not pull the pose;
- the information matrix ``J^T W J`` gives the covariance of the pose and, for the translation,
  its weakest direction: a fragment of one straight wall constrains only the offset across
  it, and is reported degenerate along the wall instead of returning an arbitrary position.

With a known heading (paper 3's setting: the camera drive's angle sensor) only ``(x, y)`` are
estimated.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.domains import NON_NEGATIVE, POSITIVE, POSITIVE_INT, Domain, domain_field
from navkit.errors import InputError
from navkit.geometry._validate import as_points, check_settings
from navkit.localization.walls import WallSegment

__all__ = [
    "PoseRefinement",
    "RefineSettings",
    "occluded_fraction",
    "refine_pose",
    "stereo_range_sigma",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RefineSettings:
    """Point-to-line refinement settings.

    Attributes
    ----------
    max_distance : float
        Metres; points farther than this from every map segment (at the start pose) are not used.
    end_margin : float
        Metres; a segment is extended by this at both ends for the association (map walls end at
        their extreme supporting points, a little short of the true corners).
    sigma_floor : float
        Metres; error of a point across its wall that does not come from its range (the map's
        own error, wall roughness), added in quadrature.
    huber : float
        Huber's threshold on residuals normalised by their sigma and the robust scale.
    iterations : int
        Most Gauss-Newton iterations (each re-associates the points).
    tolerance : float
        Metres (and radians): stop when the update is smaller.
    max_step : float
        Metres; the refinement moves the start pose at most this far (a larger move means the
        start was in another basin: the result is flagged ``converged=False``).
    degenerate_ratio : float
        The translation is degenerate when the information across its weakest direction is
        below this fraction of that across its strongest (one straight wall: about 0).
    degenerate_sigma : float
        Metres; ... or when the standard error along the weakest direction exceeds this.
    """

    max_distance: float = domain_field(0.3, POSITIVE)
    end_margin: float = domain_field(0.3, NON_NEGATIVE)
    sigma_floor: float = domain_field(0.01, POSITIVE)
    huber: float = domain_field(2.0, POSITIVE)
    iterations: int = domain_field(15, POSITIVE_INT)
    tolerance: float = domain_field(1e-5, POSITIVE)
    max_step: float = domain_field(0.5, POSITIVE)
    degenerate_ratio: float = domain_field(
        0.03, Domain(lo=0.0, hi=1.0, hi_open=True, note="a fraction")
    )
    degenerate_sigma: float = domain_field(0.05, NON_NEGATIVE)

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class PoseRefinement:
    """Result of :func:`refine_pose`.

    Attributes
    ----------
    pose : (3,) array
        Refined ``(x, y, theta)``, metres and radians (theta unchanged with a known heading).
    covariance : (3, 3) array
        m^2 / rad^2; ``s^2 (J^T W J)^-1`` with ``s`` the robust residual scale (the heading row
        and column are zero with a known heading). Infinite entries when degenerate.
    inliers : int
        Points used in the last iteration (associated and not outliers).
    rms : float
        Metres; RMS point-to-line residual of the inliers.
    converged : bool
        The iteration converged within ``max_step`` of the start pose.
    degenerate : bool
        The translation is not determined along ``weak_direction`` (see ``RefineSettings``).
    weak_direction : (2,) array
        World unit vector of the least determined translation direction.
    sigma_weak, sigma_strong : float
        Metres; standard errors of the translation along the weakest / strongest directions.
    information_ratio : float
        Smallest over largest eigenvalue of the translation information (0 = one wall).
    iterations : int
    """

    pose: NDArray[np.float64]
    covariance: NDArray[np.float64]
    inliers: int
    rms: float
    converged: bool
    degenerate: bool
    weak_direction: NDArray[np.float64]
    sigma_weak: float
    sigma_strong: float
    information_ratio: float
    iterations: int


def stereo_range_sigma(
    points: ArrayLike, baseline: float, focal: float, disparity_sigma: float = 0.25
) -> NDArray[np.float64]:
    """Standard error ``(N,)`` of stereo points along their viewing rays, metres.

    ``z = b f / d`` (paper 3, eq. 1) gives ``sigma_z = z^2 sigma_d / (b f)``; along the ray the
    error is ``sigma_z / cos(phi) = r^2 cos(phi) sigma_d / (b f)`` with ``r`` the range and
    ``phi`` the angle off the optical axis. Body-frame points of one view have the camera at the
    origin looking along +x; for fragments of several views (the camera turned on its drive)
    ``cos(phi)`` is not known per point, and ``r^2 sigma_d / (b f)`` (``cos(phi) = 1``, at most
    30 % pessimistic within a 90 deg field of view) is used.

    Parameters
    ----------
    points : (N, 2) array
        Body-frame points, the camera at the origin, metres.
    baseline, focal : float
        Metres and pixels.
    disparity_sigma : float
        Pixels.
    """
    P = as_points(points, 2)
    if not (baseline > 0 and focal > 0 and disparity_sigma > 0):
        raise InputError(
            f"baseline {baseline}, focal {focal}, disparity_sigma {disparity_sigma}",
            field="baseline/focal/disparity_sigma",
            expected="positive numbers",
        )
    r2 = np.einsum("ij,ij->i", P, P)
    return np.asarray(r2 * disparity_sigma / (baseline * focal), dtype=np.float64)


def _segments(walls: Sequence[WallSegment] | ArrayLike) -> NDArray[np.float64]:
    if isinstance(walls, Sequence) and walls and isinstance(walls[0], WallSegment):
        return np.array([[w.start, w.end] for w in walls], dtype=np.float64)  # type: ignore[union-attr]
    S = np.asarray(walls, dtype=np.float64)
    if S.ndim != 3 or S.shape[1:] != (2, 2) or len(S) == 0:
        raise InputError(
            f"has shape {S.shape}",
            field="walls",
            expected="a non-empty list of WallSegment or a (K, 2, 2) array of segments",
        )
    return S


def _associate(
    Q: NDArray[np.float64], A: NDArray[np.float64], B: NDArray[np.float64], margin: float
) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
    """Nearest segment (extended by ``margin``) of each point and the distance to it."""
    d = B - A
    length = np.linalg.norm(d, axis=1)
    u = d / np.maximum(length, 1e-12)[:, None]
    t = np.einsum("nkc,kc->nk", Q[:, None, :] - A[None], u)
    t = np.clip(t, -margin, length + margin)
    foot = A[None] + t[..., None] * u[None]
    dist = np.linalg.norm(Q[:, None, :] - foot, axis=2)
    j = np.argmin(dist, axis=1)
    return j, dist[np.arange(len(Q)), j]


def refine_pose(
    walls: Sequence[WallSegment] | ArrayLike,
    points: ArrayLike,
    pose: ArrayLike,
    *,
    range_sigma: ArrayLike | None = None,
    known_heading: bool = False,
    settings: RefineSettings | None = None,
) -> PoseRefinement:
    """Refine a pose by weighted robust point-to-line least squares (see the module docstring).

    Parameters
    ----------
    walls : list of WallSegment or (K, 2, 2) array
        The map's wall segments, world frame, metres.
    points : (N, 2) array
        The fragment in the body frame (x forward, y left; the sensor at the origin), metres;
        NaN rows dropped.
    pose : (3,) array
        Start ``(x, y, theta)`` (the correlation's or the matcher's fix).
    range_sigma : (N,) array, optional
        Metres; each point's standard error along its ray from the origin (stereo:
        :func:`stereo_range_sigma`). None: every point weighs the same (laser).
    known_heading : bool
        Keep ``theta`` (paper 3: the heading comes from the camera drive's angle sensor); only
        ``(x, y)`` are estimated.
    settings : RefineSettings, optional

    Returns
    -------
    PoseRefinement
    """
    s = settings or RefineSettings()
    seg = _segments(walls)
    P = as_points(points, 2)
    finite = np.all(np.isfinite(P), axis=1)
    if range_sigma is None:
        sig_r = np.zeros(len(P))
    else:
        sig_r = np.asarray(range_sigma, dtype=np.float64).reshape(-1)
        if len(sig_r) != len(P):
            raise InputError(
                f"has {len(sig_r)} values for {len(P)} points",
                field="range_sigma",
                expected="one sigma per point",
            )
        finite &= np.isfinite(sig_r)
    P, sig_r = P[finite], sig_r[finite]
    x0 = np.asarray(pose, dtype=np.float64).reshape(3)
    if len(P) < 3:
        raise InputError(f"has {len(P)} finite points", field="points", expected=">= 3 points")
    A, B = seg[:, 0], seg[:, 1]
    d = B - A
    nrm = (
        np.stack([-d[:, 1], d[:, 0]], axis=1)
        / np.maximum(np.linalg.norm(d, axis=1), 1e-12)[:, None]
    )
    rho_line = np.einsum("kc,kc->k", nrm, A)
    ray = P / np.maximum(np.linalg.norm(P, axis=1), 1e-12)[:, None]
    dof = 2 if known_heading else 3
    x = x0.copy()
    gate = s.max_distance
    converged = False
    it = 0
    H = np.zeros((dof, dof))
    scale = 1.0
    use = np.zeros(len(P), dtype=bool)
    res = np.zeros(0)
    for it in range(1, s.iterations + 1):  # noqa: B007 - the count is reported
        c, sn = np.cos(x[2]), np.sin(x[2])
        R = np.array([[c, -sn], [sn, c]])
        RP = P @ R.T
        Q = RP + x[:2]
        j, dist = _associate(Q, A, B, s.end_margin)
        use = dist <= gate
        if use.sum() < dof + 1:
            break
        n = nrm[j[use]]
        r = np.einsum("nc,nc->n", n, Q[use]) - rho_line[j[use]]
        # a point's error lies along its ray (rotated into the world); its normal part counts
        cos_n = np.einsum("nc,nc->n", n, ray[use] @ R.T)
        sig = np.sqrt((sig_r[use] * cos_n) ** 2 + s.sigma_floor**2)
        e = r / sig
        scale = max(1.4826 * float(np.median(np.abs(e - np.median(e)))), 1e-3)
        a = np.abs(e) / scale
        w = np.where(a <= s.huber, 1.0, s.huber / np.maximum(a, 1e-12)) / sig**2
        Jm = np.empty((len(r), dof))
        Jm[:, :2] = n
        if not known_heading:
            # d/dtheta (R p) = [[-s, -c], [c, -s]] p = perp(R p)
            Jm[:, 2] = n[:, 0] * (-RP[use, 1]) + n[:, 1] * RP[use, 0]
        H = Jm.T @ (w[:, None] * Jm)
        g = Jm.T @ (w * r)
        try:
            step = -np.linalg.lstsq(H, g, rcond=1e-10)[0]
        except np.linalg.LinAlgError:
            break
        x[:dof] += step
        res = r
        # the gate shrinks to the residual spread once the pose is close (3 sigma, >= 5 cm)
        gate = float(np.clip(4.0 * scale * np.median(sig), 0.05, s.max_distance))
        if np.all(np.abs(step) < s.tolerance):
            converged = True
            break
    moved = float(np.linalg.norm(x[:2] - x0[:2]))
    converged = converged and moved <= s.max_step
    # covariance from the information matrix, scaled by the robust residual scale
    evals, evecs = np.linalg.eigh(H[:2, :2]) if H.size else (np.zeros(2), np.eye(2))
    ratio = float(evals[0] / evals[1]) if evals[1] > 0 else 0.0
    cov = np.full((3, 3), np.inf)
    try:
        C = scale**2 * np.linalg.inv(H)
        cov = np.zeros((3, 3))
        cov[:dof, :dof] = C
    except np.linalg.LinAlgError:
        pass
    if np.all(np.isfinite(cov[:2, :2])):
        # the marginal translation covariance (the heading's coupling included)
        cev, cvec = np.linalg.eigh(cov[:2, :2])
        weak = cvec[:, 1]
        sig_w, sig_s = float(np.sqrt(max(cev[1], 0.0))), float(np.sqrt(max(cev[0], 0.0)))
        ratio = float(cev[0] / cev[1]) if cev[1] > 0 else 0.0
    else:
        weak = evecs[:, 0]
        sig_w, sig_s = float("inf"), float("inf")
    degenerate = bool(ratio < s.degenerate_ratio or sig_w > s.degenerate_sigma)
    rms = float(np.sqrt(np.mean(res**2))) if len(res) else float("nan")
    log.debug(
        "refined %s -> %s in %d iterations (%d inliers, rms %.3f m, ratio %.3f)",
        x0,
        x,
        it,
        int(use.sum()),
        rms,
        ratio,
    )
    return PoseRefinement(
        pose=x,
        covariance=cov,
        inliers=int(use.sum()),
        rms=rms,
        converged=bool(converged),
        degenerate=degenerate,
        weak_direction=weak,
        sigma_weak=sig_w,
        sigma_strong=sig_s,
        information_ratio=ratio,
        iterations=it,
    )


def occluded_fraction(
    walls: Sequence[WallSegment] | ArrayLike,
    points: ArrayLike,
    pose: ArrayLike,
    *,
    margin: float | ArrayLike = 0.15,
    end_margin: float = 0.3,
) -> float:
    """Fraction of a fragment's points that the map says the sensor could not have seen.

    A point seen from ``pose`` whose ray crosses a map wall more than ``margin`` metres before
    reaching it was seen *through* that wall: the pose is inconsistent with the map's free space
    (a likelihood field and point-to-line distances are blind to that - a fragment of a
    column's west face also fits its east face). Vectorised over points x walls.

    Parameters
    ----------
    walls : list of WallSegment or (K, 2, 2) array
        World frame, metres.
    points : (N, 2) array
        The fragment in the body frame (the sensor at the origin), metres; NaN rows dropped.
    pose : (3,) array
        ``(x, y, theta)`` of the body in the world.
    margin : float or (N,) array
        Metres; crossings this close to the point are its own wall (noise, map error; give
        about 3 sigma of each stereo point's range error - far points scatter behind their
        wall).
    end_margin : float
        Metres; crossings this close to a wall's end do not count (map walls run a little past
        the true corners - their extreme supporting points - and would block the view past a
        protruding corner).

    Returns
    -------
    float
        In ``[0, 1]`` (0 for an empty fragment).
    """
    seg = _segments(walls)
    P = as_points(points, 2)
    mg = np.broadcast_to(np.asarray(margin, dtype=np.float64), (len(P),))
    keep = np.all(np.isfinite(P), axis=1)
    P, mg = P[keep], mg[keep][:, None]
    if len(P) == 0:
        return 0.0
    x = np.asarray(pose, dtype=np.float64).reshape(3)
    c, sn = np.cos(x[2]), np.sin(x[2])
    Q = P @ np.array([[c, -sn], [sn, c]]).T + x[:2]
    o = x[:2]
    d = Q - o  # (N, 2) rays
    A = seg[:, 0]
    e = seg[:, 1] - A  # (K, 2)
    # o + t d = A + u e  ->  t d - u e = A - o; Cramer's rule per point x wall
    den = d[:, None, 0] * (-e[None, :, 1]) + d[:, None, 1] * e[None, :, 0]
    w = (A - o)[None, :, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * (-e[None, :, 1]) + w[..., 1] * e[None, :, 0]) / den
        u = (d[:, None, 0] * w[..., 1] - d[:, None, 1] * w[..., 0]) / den
    length = np.linalg.norm(d, axis=1)[:, None]
    elen = np.linalg.norm(e, axis=1)[None, :]
    cross = (
        np.isfinite(t)
        & (t > 0)
        & (t * length < length - mg)
        & (u * elen >= end_margin)
        & (u * elen <= elen - end_margin)
    )
    return float(cross.any(axis=1).mean())
