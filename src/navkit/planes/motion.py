"""Frame-to-frame motion from planes: association, then the solver the geometry allows."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.geometry.linalg import rows_matmul
from navkit.planes.associate import AssociationSettings, associate, associate_global
from navkit.planes.frame import PlaneObservation
from navkit.planes.solve import (
    MotionEstimate,
    MotionFailure,
    SolverSettings,
    normal_rank,
    solve_one_plane,
    solve_three_planes,
    solve_two_planes,
)

__all__ = ["MotionSettings", "estimate_motion", "point_fit"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MotionSettings:
    """Association and solver settings together."""

    association: AssociationSettings = field(default_factory=AssociationSettings)
    solver: SolverSettings = field(default_factory=SolverSettings)
    min_plane_points: int = 2000
    global_search: bool = True
    """Without a prior, also try :func:`~navkit.planes.associate.associate_global` (large
    motions); its >= 3-plane solution replaces the gated one when it puts more of frame 2's
    points onto frame 1's (:func:`point_fit`)."""


def _rank(segs, pairs, s: MotionSettings) -> int:
    if not pairs:
        return 0
    return normal_rank(np.array([segs[i].normal for i, _ in pairs]), s.solver.parallel_deg)[0]


def estimate_motion(
    obs1: PlaneObservation,
    obs2: PlaneObservation,
    T_1_2_prior: ArrayLike | None = None,
    settings: MotionSettings | None = None,
) -> MotionEstimate | MotionFailure:
    """Motion ``T_1_2`` between two frames from their planes (paper 2).

    Stages: associate planes (gated by the prior), count the independent normal directions of
    the matches, then the closed form (>= 3), rotation + 1D texture search (2) or the quaternion
    route with the 3D texture search (1). Without a prior, a global association is tried as well
    (see :attr:`MotionSettings.global_search`).
    """
    s = settings or MotionSettings()
    res = _estimate(obs1, obs2, T_1_2_prior, s)
    if not (s.global_search and T_1_2_prior is None):
        return res
    # no prior: also try the global (prior-free) association and keep whichever motion puts
    # more of frame 2's points onto frame 1's (large motions defeat the gated association)
    big1 = [sg for sg in obs1.segments if sg.plane.count >= s.min_plane_points]
    big2 = [sg for sg in obs2.segments if sg.plane.count >= s.min_plane_points]
    _, T_g = associate_global(big1, big2, points1=obs1.points, points2=obs2.points)
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


def _estimate(
    obs1: PlaneObservation,
    obs2: PlaneObservation,
    T_1_2_prior: ArrayLike | None,
    s: MotionSettings,
) -> MotionEstimate | MotionFailure:
    segs1 = [sg for sg in obs1.segments]
    segs2 = [sg for sg in obs2.segments]
    pairs = associate(segs1, segs2, T_1_2_prior, s.association)
    pairs = [
        (i, j)
        for i, j in pairs
        if min(segs1[i].plane.count, segs2[j].plane.count) >= s.min_plane_points
    ]
    if s.global_search and T_1_2_prior is None and _rank(segs1, pairs, s) < 3:
        big1 = [sg for sg in segs1 if sg.plane.count >= s.min_plane_points]
        big2 = [sg for sg in segs2 if sg.plane.count >= s.min_plane_points]
        gpairs, _ = associate_global(big1, big2, points1=obs1.points, points2=obs2.points)
        if _rank(segs1, gpairs, s) == 3:
            log.debug("global association: %d matches", len(gpairs))
            pairs = gpairs
    if not pairs:
        return MotionFailure(0, ("rotation", "translation"), "no plane matched between the frames")
    pairs.sort(key=lambda p: -min(segs1[p[0]].plane.count, segs2[p[1]].plane.count))
    p1 = [segs1[i].plane for i, _ in pairs]
    p2 = [segs2[j].plane for _, j in pairs]
    # planes with rho >= 0 flip their normal if the sensor crosses them: align frame 2's signs
    prior = np.eye(4) if T_1_2_prior is None else np.asarray(T_1_2_prior, float)
    rank, _ = normal_rank(np.array([p.normal for p in p1]), s.solver.parallel_deg)
    has_tex = obs1.has_texture and obs2.has_texture
    if rank >= 3:
        res = solve_three_planes(p1, p2, s.solver)
    elif rank == 2:
        if not has_tex:
            return MotionFailure(
                2,
                ("mu",),
                "two plane directions and no camera image: the position along the "
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
                1, ("lambda", "mu", "eta"), "one plane direction and no camera image"
            )
        i, j = pairs[0]
        res = solve_one_plane(p1[0], p2[0], obs1.texture, obs2.texture, i, j, s.solver)
    if isinstance(res, MotionEstimate):
        res = MotionEstimate(
            res.T, res.case, res.geometry_dof, res.texture_dof, res.residuals, tuple(pairs)
        )
    return res
