"""Motion between two frames from planes: association, then the solver the geometry allows.

An optional :class:`MotionPrior` (a measured motion with its uncertainty) gates the association,
starts the texture searches and fills the degrees of freedom nothing else fixes; texture
solutions are checked against the rest of the scene (:func:`depth_consistency`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.domains import NON_NEGATIVE_INT, Domain, domain_field
from navkit.geometry import se3_from_rt
from navkit.geometry._validate import check_settings
from navkit.geometry.fitting import Plane, canonical_plane
from navkit.geometry.linalg import cross3, rows_matmul
from navkit.planes.associate import AssociationSettings, associate, associate_global
from navkit.planes.frame import PlaneObservation
from navkit.planes.quaternion import q1_normal_alignment
from navkit.planes.solve import (
    MotionEstimate,
    MotionFailure,
    SolverSettings,
    _residuals,
    normal_rank,
    solve_one_plane,
    solve_three_planes,
    solve_two_planes,
)

__all__ = [
    "DepthCheck",
    "MotionPrior",
    "MotionSettings",
    "depth_consistency",
    "estimate_motion",
    "matched_pairs",
    "point_fit",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MotionSettings:
    """Association and solver settings together."""

    association: AssociationSettings = field(default_factory=AssociationSettings)
    solver: SolverSettings = field(default_factory=SolverSettings)
    min_plane_points: int = domain_field(2000, NON_NEGATIVE_INT)
    """Smallest plane (points) used for motion in an organised frame (depth image, scan grid)."""
    min_cloud_plane_points: int = domain_field(500, NON_NEGATIVE_INT)
    """The same for unorganised clouds (``points`` of shape ``(N, 3)``). Their extraction
    works on a voxel grid, so a wall far from the scanner keeps few points: the one wall that
    fixes the third direction between the PCL room scans has about 700."""
    global_search: bool = True
    """Without a prior, also try :func:`~navkit.planes.associate.associate_global` (large
    motions); its >= 3-plane solution replaces the gated one when it puts more of frame 2's
    points onto frame 1's (:func:`point_fit`)."""
    texture: bool = True
    """Run the texture searches of the 1- and 2-plane cases (paper 2, eqs. 3-11). False: the
    degrees of freedom the planes leave free are taken from the prior or the prediction
    (``MotionEstimate.prior_dof``), or the frame fails without either.
    :class:`~navkit.planes.odometry.PlaneOdometry` turns it off for a frame its dense step will
    measure."""
    max_depth_violation: float = domain_field(0.35, Domain(lo=0.0, hi=1.0, note="a fraction"))
    """A motion whose degrees of freedom came from texture (1 or 2 plane directions) is rejected
    (:class:`MotionFailure` naming them) when more than this fraction of the tested off-plane
    points of frame 2 land in frame 1's free space (:func:`depth_consistency`). Measured on the
    real slambook pairs: 0.12-0.16 under the reference poses (Kinect noise, mixed pixels at
    depth edges, reference error), 0.54-0.97 for wrong motions (13 cm to 1.1 m off); a random
    misplacement of the scene puts about half of the points in front of the visible surface."""
    min_depth_points: int = domain_field(500, NON_NEGATIVE_INT)
    """Fewest off-plane points needed for the depth check to decide (otherwise it is skipped:
    a scene of only the matched planes has nothing else to check)."""

    def __post_init__(self) -> None:
        check_settings(self)


NORMAL_SCATTER_DEG = 3.0
"""Allowance for the planes' own normal error in the prior's association gate, degrees (far
Kinect walls: 1-2 deg between frames on slambook, see docs/benchmarks/planes.md)."""
RHO_SCATTER = 0.05
"""Allowance for the planes' own distance error in the prior's association gate, metres
(Kinect depth noise ``0.0025 d^2`` is 4 cm at 4 m)."""


@dataclass(frozen=True)
class MotionPrior:
    """A predicted motion ``T_1_2`` with its uncertainty (visual odometry, wheel odometry, IMU).

    The prior is used three ways by :func:`estimate_motion` (decisions: the paper has no prior):

    1. **association gate**: normals must agree within ``3 sigma_rotation_deg + 3`` deg and
       distances within ``3 sigma_translation + 0.05`` m after the prior (the additive terms are
       the planes' own scatter, :data:`NORMAL_SCATTER_DEG`, :data:`RHO_SCATTER`);
    2. **start of the texture search**: frame 2's planes are moved by the prior before solving,
       so ``mu = eta = lambda = 0`` is the prior; the 1-plane search covers turns within
       ``3 sigma_rotation_deg + 5`` deg and shifts within ``3 sigma_translation + 0.15`` m
       (never more than :class:`~navkit.planes.solve.SolverSettings`' ranges); the 2-plane
       search keeps its full range (a narrow window makes ``D(mu)`` look flat), centred on
       the prior;
    3. **degrees of freedom neither geometry nor texture fix** (uniform or missing texture,
       texture rejected by the depth check) are taken from the prior; the result is then a
       :class:`~navkit.planes.solve.MotionEstimate` whose ``prior_dof`` names them (never
       silently). With no plane matched at all the result stays a
       :class:`~navkit.planes.solve.MotionFailure` (nothing was measured).

    Attributes
    ----------
    T : (4, 4) array
        Predicted ``T_1_2`` (frame 2 -> frame 1, ``X1 = R X2 + t``).
    sigma_rotation_deg : float
        1-sigma rotation uncertainty, degrees.
    sigma_translation : float
        1-sigma translation uncertainty, metres.
    """

    T: NDArray[np.float64]
    sigma_rotation_deg: float = 2.0
    sigma_translation: float = 0.05

    def association(self, base: AssociationSettings) -> AssociationSettings:
        """Association gates from the prior's uncertainty (see the class docstring)."""
        return replace(
            base,
            max_angle_deg=3.0 * self.sigma_rotation_deg + NORMAL_SCATTER_DEG,
            max_distance=3.0 * self.sigma_translation + RHO_SCATTER,
        )

    def one_plane_solver(self, base: SolverSettings) -> SolverSettings:
        """1-plane texture search ranges from the prior's uncertainty."""
        return replace(
            base,
            max_turn_deg=min(base.max_turn_deg, 3.0 * self.sigma_rotation_deg + 5.0),
            max_shift=min(base.max_shift, 3.0 * self.sigma_translation + 0.15),
        )


def as_prior(prior: ArrayLike | MotionPrior) -> MotionPrior:
    """A :class:`MotionPrior` (a bare ``(4, 4)`` array gets the default uncertainty)."""
    if isinstance(prior, MotionPrior):
        return prior
    return MotionPrior(np.asarray(prior, dtype=np.float64).reshape(4, 4))


def _rank(segs, pairs, s: MotionSettings) -> int:
    if not pairs:
        return 0
    return normal_rank(np.array([segs[i].normal for i, _ in pairs]), s.solver.parallel_deg)[0]


def estimate_motion(
    obs1: PlaneObservation,
    obs2: PlaneObservation,
    T_1_2_prior: ArrayLike | MotionPrior | None = None,
    settings: MotionSettings | None = None,
) -> MotionEstimate | MotionFailure:
    """Motion ``T_1_2`` between two frames from their planes (paper 2).

    Stages: associate planes (gated by the prior), count the independent normal directions of
    the matches, then the closed form (>= 3), rotation + 1D texture search (2) or the quaternion
    route with the 3D texture search (1). Without a prior, a global association is tried as well
    (see :attr:`MotionSettings.global_search`).

    Parameters
    ----------
    obs1, obs2 : PlaneObservation
    T_1_2_prior : (4, 4) array, MotionPrior or None
        A bare array is a *prediction* (constant velocity): it gates the association with
        :class:`~navkit.planes.associate.AssociationSettings`' fixed gates and centres the
        2-plane search. A :class:`MotionPrior` (a measured motion with its uncertainty) also
        sets the gates, starts every texture search and fills the degrees of freedom nothing
        else fixes (``MotionEstimate.prior_dof``).
    settings : MotionSettings, optional
    """
    s = settings or MotionSettings()
    if isinstance(T_1_2_prior, MotionPrior):
        return _estimate_with_prior(obs1, obs2, T_1_2_prior, s)
    if not (s.global_search and T_1_2_prior is None):
        return _estimate(obs1, obs2, T_1_2_prior, s)
    # no prior: the global (prior-free) association, computed once and shared
    floor = min_plane_points(obs1, obs2, s)
    big1 = [sg for sg in obs1.segments if sg.plane.count >= floor]
    big2 = [sg for sg in obs2.segments if sg.plane.count >= floor]
    global_match = associate_global(big1, big2, points1=obs1.points, points2=obs2.points)
    res = _estimate(obs1, obs2, None, s, global_match)
    # no prior: also try the global (prior-free) association and keep whichever motion puts
    # more of frame 2's points onto frame 1's (large motions defeat the gated association)
    T_g = global_match[1]
    if T_g is None:
        return res
    res_g = _estimate(obs1, obs2, T_g, s)
    if not isinstance(res_g, MotionEstimate) or res_g.case < 3:
        return res
    if not isinstance(res, MotionEstimate):
        return res_g
    fit, fit_g = point_fit(obs1.points, obs2.points, [res.T, res_g.T])
    log.debug("point fit: gated %.3f, global %.3f", fit, fit_g)
    return res_g if fit_g > fit else res


@dataclass(frozen=True)
class DepthCheck:
    """Result of :func:`depth_consistency`.

    Attributes
    ----------
    tested : int
        Frame-2 points that project onto a valid frame-1 depth.
    consistent : float
        Fraction of them within the tolerance of frame 1's depth.
    violation : float
        ``violating / (consistent + violating)``: points in front of frame 1's visible surface
        (in its free space), among those not hidden behind it. NaN when nothing was tested.
    """

    tested: int
    consistent: float
    violation: float


def _depth_image(obs: PlaneObservation) -> tuple[NDArray[np.float64], object] | None:
    """Frame ``obs``'s depth in its camera (``(H, W)`` metres, NaN none) and the camera."""
    cam = obs.camera
    if cam is None:
        return None
    P = np.asarray(obs.points, dtype=np.float64)
    if obs.T_camera_sensor is None and P.shape == (cam.height, cam.width, 3):
        return P[..., 2], cam
    X = P.reshape(-1, 3)
    X = X[np.all(np.isfinite(X), axis=1)]
    if obs.T_camera_sensor is not None:
        T = np.asarray(obs.T_camera_sensor, dtype=np.float64)
        X = rows_matmul(X, T[:3, :3].T) + T[:3, 3]
    X = X[X[:, 2] > 1e-6]
    u = np.rint(cam.fx * X[:, 0] / X[:, 2] + cam.cx).astype(np.int64)
    v = np.rint(cam.fy * X[:, 1] / X[:, 2] + cam.cy).astype(np.int64)
    ok = (u >= 0) & (u < cam.width) & (v >= 0) & (v < cam.height)
    D = np.full(cam.height * cam.width, np.inf)
    np.minimum.at(D, v[ok] * cam.width + u[ok], X[ok, 2])  # z-buffer: the nearest point wins
    D[~np.isfinite(D)] = np.nan
    return D.reshape(cam.height, cam.width), cam


def depth_consistency(
    obs1: PlaneObservation,
    obs2: PlaneObservation,
    T_1_2: ArrayLike,
    exclude2: tuple[int, ...] | list[int] = (),
    tolerance: tuple[float, float] = (0.03, 0.02),
) -> DepthCheck:
    """Does the motion ``T_1_2`` also put frame 2's *other* points where frame 1 sees them?

    The points of frame 2 outside the planes ``exclude2`` (the matched planes, which agree by
    construction) are moved into frame 1 and projected into frame 1's camera; each is compared
    with frame 1's depth ``d`` at its pixel: within ``a + b d`` metres = consistent, nearer by
    more = a *violation* (frame 1 sees through the place where frame 2 puts a surface), farther
    = hidden (no evidence either way). Frame 1's depth is its own depth image (registered RGB-D)
    or the z-buffer of its points in the camera (range sensor + calibrated camera).

    Parameters
    ----------
    obs1, obs2 : PlaneObservation
    T_1_2 : (4, 4) array
        Motion, ``X1 = R X2 + t``.
    exclude2 : sequence of int
        Segment indices of frame 2 left out.
    tolerance : (a, b)
        Depth tolerance ``a + b d`` metres (Kinect-type noise ``0.0025 d^2`` is 4 cm at 4 m; the
        rest covers the rounding to a pixel at depth edges).
    """
    nan = DepthCheck(0, float("nan"), float("nan"))
    img = _depth_image(obs1)
    if img is None:
        return nan
    D1, cam = img
    T = np.asarray(T_1_2, dtype=np.float64)
    P2 = np.asarray(obs2.points, dtype=np.float64).reshape(-1, 3)
    lab = np.asarray(obs2.extraction.labels).reshape(-1)
    keep = np.all(np.isfinite(P2), axis=1)
    if len(lab) == len(P2) and len(exclude2):
        keep &= ~np.isin(lab, np.asarray(list(exclude2)))
    X = P2[keep]
    if len(X) > 60_000:  # a regular subsample bounds the cost
        X = X[:: len(X) // 60_000 + 1]
    if obs1.T_camera_sensor is not None:
        Tc = np.asarray(obs1.T_camera_sensor, dtype=np.float64) @ T
    else:
        Tc = T
    X = rows_matmul(X, Tc[:3, :3].T) + Tc[:3, 3]
    X = X[X[:, 2] > 0.1]
    u = np.rint(cam.fx * X[:, 0] / X[:, 2] + cam.cx).astype(np.int64)  # type: ignore[attr-defined]
    v = np.rint(cam.fy * X[:, 1] / X[:, 2] + cam.cy).astype(np.int64)  # type: ignore[attr-defined]
    h, w = D1.shape
    ok = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    d1 = D1[v[ok], u[ok]]
    z = X[ok, 2]
    fin = np.isfinite(d1)
    d1, z = d1[fin], z[fin]
    if len(z) == 0:
        return nan
    tol = tolerance[0] + tolerance[1] * d1
    cons = np.abs(z - d1) < tol
    viol = z < d1 - tol
    n_cv = int(cons.sum() + viol.sum())
    return DepthCheck(
        len(z), float(cons.mean()), float(viol.sum() / n_cv) if n_cv else float("nan")
    )


def point_fit(
    points1: ArrayLike,
    points2: ArrayLike,
    motions: list[NDArray[np.float64]],
    distance: float = 0.05,
    n: int = 3000,
) -> list[float]:
    """Fraction of a sample of frame-2 points that each motion ``T_1_2`` puts within
    ``distance`` metres of a frame-1 point (KD-tree)."""
    from scipy.spatial import cKDTree

    A = np.asarray(points1, dtype=np.float64).reshape(-1, 3)
    B = np.asarray(points2, dtype=np.float64).reshape(-1, 3)
    A = A[np.all(np.isfinite(A), axis=1)]
    B = B[np.all(np.isfinite(B), axis=1)]
    if len(A) == 0 or len(B) == 0:
        return [0.0 for _ in motions]
    rng = np.random.default_rng(0)
    A = A[rng.choice(len(A), min(len(A), 20 * n), replace=False)]
    B = B[rng.choice(len(B), min(len(B), n), replace=False)]
    tree = cKDTree(A)
    out = []
    for T in motions:
        d, _ = tree.query(rows_matmul(B, T[:3, :3].T) + T[:3, 3], distance_upper_bound=distance)
        out.append(float(np.isfinite(d).mean()))
    return out


def min_plane_points(obs1: PlaneObservation, obs2: PlaneObservation, s: MotionSettings) -> int:
    """Smallest plane used for motion: :attr:`MotionSettings.min_plane_points` for organised
    frames, :attr:`MotionSettings.min_cloud_plane_points` when either frame is a cloud."""
    organised = obs1.points.ndim == 3 and obs2.points.ndim == 3
    return s.min_plane_points if organised else s.min_cloud_plane_points


def _by_size(pairs, segs1, segs2, floor: int) -> list[tuple[int, int]]:
    """Pairs whose planes both have at least ``floor`` points, largest first."""
    kept = [(i, j) for i, j in pairs if min(segs1[i].plane.count, segs2[j].plane.count) >= floor]
    return sorted(kept, key=lambda p: -min(segs1[p[0]].plane.count, segs2[p[1]].plane.count))


def matched_pairs(
    obs1: PlaneObservation,
    obs2: PlaneObservation,
    T_1_2: ArrayLike | None = None,
    settings: MotionSettings | None = None,
    association: AssociationSettings | None = None,
) -> list[tuple[int, int]]:
    """The plane pairs the motion solvers use: :func:`~navkit.planes.associate.associate`
    (predicted by ``T_1_2``), planes of at least :func:`min_plane_points` points, largest first.

    ``association`` overrides ``settings.association`` (e.g. a prior's gates).
    """
    s = settings or MotionSettings()
    segs1, segs2 = obs1.segments, obs2.segments
    pairs = associate(segs1, segs2, T_1_2, association or s.association)
    return _by_size(pairs, segs1, segs2, min_plane_points(obs1, obs2, s))


def _confirm_by_depth(
    obs1: PlaneObservation,
    obs2: PlaneObservation,
    res: MotionEstimate,
    T: NDArray[np.float64],
    pairs: list[tuple[int, int]],
    s: MotionSettings,
) -> MotionEstimate | MotionFailure:
    """The depth-consistency check of a solution ``T`` (:attr:`MotionSettings.max_depth_violation`):
    a texture solution that puts too many off-plane points in frame 1's free space becomes a
    :class:`MotionFailure` naming the texture's degrees of freedom."""
    chk = depth_consistency(obs1, obs2, T, [j for _, j in pairs])
    resid = dict(res.residuals)
    resid.update(depth_tested=float(chk.tested), depth_violation=chk.violation)
    if (
        res.texture_dof
        and chk.tested >= s.min_depth_points
        and chk.violation > s.max_depth_violation
    ):
        log.info(
            "texture solution rejected: %.0f %% of %d off-plane points in free space",
            100 * chk.violation,
            chk.tested,
        )
        return MotionFailure(
            res.case,
            res.texture_dof,
            f"the texture match is not confirmed by the rest of the scene: "
            f"{100 * chk.violation:.0f} % of {chk.tested} off-plane points land in front of "
            f"frame 1's surfaces (limit {100 * s.max_depth_violation:.0f} %); "
            f"the texture cannot fix {', '.join(res.texture_dof)}",
        )
    return MotionEstimate(T, res.case, res.geometry_dof, res.texture_dof, resid, tuple(pairs))


def _estimate(
    obs1: PlaneObservation,
    obs2: PlaneObservation,
    T_1_2_prior: ArrayLike | None,
    s: MotionSettings,
    global_match: tuple[list[tuple[int, int]], NDArray[np.float64] | None] | None = None,
) -> MotionEstimate | MotionFailure:
    """One association + solve. ``global_match`` is :func:`associate_global`'s answer for the
    planes of at least :func:`min_plane_points` points (used when the gated association spans
    fewer than 3 directions and no prior is given)."""
    segs1 = [sg for sg in obs1.segments]
    segs2 = [sg for sg in obs2.segments]
    floor = min_plane_points(obs1, obs2, s)
    pairs = matched_pairs(obs1, obs2, T_1_2_prior, s)
    if global_match is not None and _rank(segs1, pairs, s) < 3:
        # associate_global indexed the big planes only: back to indices of all segments
        big1 = [i for i, sg in enumerate(segs1) if sg.plane.count >= floor]
        big2 = [j for j, sg in enumerate(segs2) if sg.plane.count >= floor]
        gpairs = [(big1[i], big2[j]) for i, j in global_match[0]]
        if _rank(segs1, gpairs, s) == 3:
            log.debug("global association: %d matches", len(gpairs))
            pairs = _by_size(gpairs, segs1, segs2, floor)
    if not pairs:
        return MotionFailure(0, ("rotation", "translation"), "no plane matched between the frames")
    p1 = [segs1[i].plane for i, _ in pairs]
    p2 = [segs2[j].plane for _, j in pairs]
    # planes with rho >= 0 flip their normal if the sensor crosses them: align frame 2's signs
    prior = np.eye(4) if T_1_2_prior is None else np.asarray(T_1_2_prior, float)
    rank, _ = normal_rank(np.array([p.normal for p in p1]), s.solver.parallel_deg)
    has_tex = s.texture and obs1.has_texture and obs2.has_texture
    if rank < 3 and not s.texture and T_1_2_prior is not None:
        # texture searches off (the caller's dense step measures what the planes leave
        # free): the planes' degrees of freedom, the rest from the prediction, and say so
        T, geo = _fill_from_prior(p1, p2, rank, prior, s)
        free = ("mu",) if rank == 2 else ("lambda", "mu", "eta")
        resid = _residuals(T[:3, :3], T[:3, 3], p1, p2)
        return MotionEstimate(T, rank, geo, (), resid, tuple(pairs), prior_dof=free)
    if rank >= 3:
        res = solve_three_planes(p1, p2, s.solver)
    elif rank == 2:
        if not has_tex:
            return MotionFailure(
                2,
                ("mu",),
                "two plane directions and no texture (no camera image, or texture searches "
                "off): the position along the "
                "planes' intersection line is free",
            )
        idx1 = [i for i, _ in pairs]
        idx2 = [j for _, j in pairs]
        res = solve_two_planes(
            p1,
            p2,
            lambda k, ax, ref, nu: obs1.texture(idx1[k], ax, ref, nu),
            lambda k, ax, ref, nu: obs2.texture(idx2[k], ax, ref, nu),
            s.solver,
            prior_translation=prior[:3, 3],
        )
    else:
        if not has_tex:
            return MotionFailure(
                1,
                ("lambda", "mu", "eta"),
                "one plane direction and no texture (no camera image, or texture searches off)",
            )
        i, j = pairs[0]
        res = solve_one_plane(p1[0], p2[0], obs1.texture, obs2.texture, i, j, s.solver)
    if isinstance(res, MotionEstimate):
        return _confirm_by_depth(obs1, obs2, res, res.T, pairs, s)
    return res


def _moved_plane(p: Plane, T: NDArray[np.float64]) -> Plane:
    """Plane ``p`` of frame 2 expressed in the frame ``X = T x`` (rho >= 0 again)."""
    R, t = T[:3, :3], T[:3, 3]
    n = R @ p.normal
    n, rho = canonical_plane(n, float(p.rho + n @ t))
    return Plane(n, rho, R @ np.asarray(p.centroid, float) + t, p.rms, p.count)


def _rotation_two_normals(
    n1a: NDArray[np.float64],
    n1b: NDArray[np.float64],
    n2a: NDArray[np.float64],
    n2b: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Least-squares rotation of eqs. 1 and 5: ``n1a ~ R n2a``, ``n1b ~ R n2b`` and their cross
    products (Procrustes on three vectors, as :func:`~navkit.planes.solve.solve_two_planes`)."""
    c1, c2 = cross3(n1a, n1b), cross3(n2a, n2b)
    A = np.stack([n1a, n1b, c1 / np.linalg.norm(c1)])
    B = np.stack([n2a, n2b, c2 / np.linalg.norm(c2)])
    U, _, Vt = np.linalg.svd(B.T @ A)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    return Vt.T @ np.diag([1.0, 1.0, d]) @ U.T


def _fill_from_prior(
    p1: list[Plane], p2: list[Plane], rank: int, Tp: NDArray[np.float64], s: MotionSettings
) -> tuple[NDArray[np.float64], tuple[str, ...]]:
    """Motion ``T_1_2`` with the geometric DoF measured and the others left at the prior's.

    Case 2: rotation from the two normal directions (eqs. 1, 5: Procrustes on the normals and
    their cross product), translation across their line from eq. 2 (minimum norm); the position
    along the line ``d`` is the prior's, ``t . d = t_prior . d``. Case 1: the prior's rotation
    turned by ``q1`` (eq. 8) so the normals agree, the shift along the normal from eq. 2; the
    turn about the normal and the in-plane translation are the prior's.
    """
    from navkit.geometry.rotations import quat_to_matrix

    Rp, tp = Tp[:3, :3], Tp[:3, 3]
    N1 = np.array([p.normal for p in p1])
    N2 = np.array([p.normal for p in p2]) @ Rp.T  # frame-2 normals turned by the prior
    sg = np.where(np.einsum("ij,ij->i", N1, N2) < 0, -1.0, 1.0)  # a normal flipped by rho >= 0
    N2 *= sg[:, None]
    drho = np.array([a.rho for a in p1]) - sg * np.array([b.rho for b in p2])
    if rank == 2:
        _, (a, b) = normal_rank(N1, s.solver.parallel_deg)
        R = _rotation_two_normals(N1[a], N1[b], N2[a], N2[b]) @ Rp
        d = cross3(N1[a], N1[b])
        d /= np.linalg.norm(d)
        t = np.linalg.lstsq(N1, drho, rcond=None)[0]
        t += (tp @ d - t @ d) * d
        return se3_from_rt(R, t), ("rotation", "translation across the line")
    n = N1[0]
    R = quat_to_matrix(q1_normal_alignment(N2[0], n)) @ Rp
    t = drho[0] * n + (tp - (tp @ n) * n)
    return se3_from_rt(R, t), ("rotation aligning the normal", "translation along the normal")


def _estimate_with_prior(
    obs1: PlaneObservation,
    obs2: PlaneObservation,
    prior: MotionPrior,
    s: MotionSettings,
) -> MotionEstimate | MotionFailure:
    """:func:`estimate_motion` with a :class:`MotionPrior` (see its docstring for the three uses).

    Frame 2's planes are moved by the prior (frame 2' = frame 2 seen from where the prior puts
    it); the solvers then find the small correction ``T_1_2'`` and ``T_1_2 = T_1_2' T_prior``.
    """
    Tp = np.asarray(prior.T, dtype=np.float64).reshape(4, 4)
    Rp, tp = Tp[:3, :3], Tp[:3, 3]
    segs1, segs2 = obs1.segments, obs2.segments
    pairs = matched_pairs(obs1, obs2, Tp, s, prior.association(s.association))  # 1. gate
    if not pairs:
        return MotionFailure(0, ("rotation", "translation"), "no plane matched between the frames")
    idx1 = [i for i, _ in pairs]
    idx2 = [j for _, j in pairs]
    p1 = [segs1[i].plane for i in idx1]
    p2m = [_moved_plane(segs2[j].plane, Tp) for j in idx2]  # 2. frame 2' (prior-centred)
    rank, _ = normal_rank(np.array([p.normal for p in p1]), s.solver.parallel_deg)
    has_tex = s.texture and obs1.has_texture and obs2.has_texture

    def tex2m(k: int, ax, ref, nu):  # frame 2' lattice -> frame 2's sampler
        return obs2.texture(k, np.asarray(ax) @ Rp, Rp.T @ (np.asarray(ref) - tp), nu)

    res: MotionEstimate | MotionFailure
    if rank >= 3:
        res = solve_three_planes(p1, p2m, s.solver)
    elif rank == 2:
        if has_tex:
            res = solve_two_planes(
                p1,
                p2m,
                lambda k, ax, ref, nu: obs1.texture(idx1[k], ax, ref, nu),
                lambda k, ax, ref, nu: tex2m(idx2[k], ax, ref, nu),
                s.solver,
                prior_translation=np.zeros(3),
            )
        else:
            res = MotionFailure(
                2,
                ("mu",),
                "two plane directions and no texture (no camera image, or texture searches off)",
            )
    else:
        if has_tex:
            res = solve_one_plane(
                p1[0],
                p2m[0],
                obs1.texture,
                tex2m,
                idx1[0],
                idx2[0],
                prior.one_plane_solver(s.solver),
            )
        else:
            res = MotionFailure(
                1,
                ("lambda", "mu", "eta"),
                "one plane direction and no texture (no camera image, or texture searches off)",
            )
    if isinstance(res, MotionEstimate):
        res = _confirm_by_depth(obs1, obs2, res, res.T @ Tp, pairs, s)
        if isinstance(res, MotionEstimate):
            return res
    # 3. the degrees of freedom nothing measured come from the prior, and say so
    free = res.free_dof
    if rank >= 3 or not free or "rotation" in free:
        return res
    p2 = [segs2[j].plane for j in idx2]
    T, geo = _fill_from_prior(p1, p2, min(rank, 2), Tp, s)
    resid = _residuals(T[:3, :3], T[:3, 3], p1, p2)
    log.info("case %d: %s from the prior (%s)", rank, ", ".join(free), res.reason)
    return MotionEstimate(T, rank, geo, (), resid, tuple(pairs), prior_dof=tuple(free))
