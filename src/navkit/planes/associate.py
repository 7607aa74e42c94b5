"""Association of planes between two frames.

A pair ``(i, j)`` (plane ``i`` of frame 1, plane ``j`` of frame 2) is a candidate when, after the
predicted motion ``T_1_2`` (identity by default), the normals agree within ``max_angle_deg``, the
distances ``rho`` within ``max_distance`` and the outlines overlap (some vertex or the centroid of
one outline lies within ``overlap_margin`` of the other). Candidates are assigned one-to-one by
minimum cost (Hungarian), then only the largest subset consistent with **one rotation** is kept:
every pair of non-parallel matches proposes a rotation, the one that agrees with the most
matches (within ``consistency_deg``) wins; then matches whose distances disagree with one
translation (eq. 2, by more than ``consistency_m``) are dropped, worst first. Planes with a TLS
rms above ``max_rms`` are never matched. Planes that appear or vanish simply stay unmatched.

Without a prior, :func:`associate_global` searches plane triples of both frames for motions
consistent with their mutual angles (rotation invariants) and keeps the one under which all the
points agree best (:func:`global_hypotheses`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment

from navkit.domains import (
    NON_NEGATIVE,
    NON_NEGATIVE_INT,
    POSITIVE_INT,
    Domain,
    domain_field,
)
from navkit.geometry._validate import check_settings
from navkit.geometry.polygons import points_in_polygon
from navkit.planes.extract_cloud import voxelize
from navkit.planes.segments import PlaneSegment, plane_frame

__all__ = [
    "AssociationSettings",
    "GlobalAssociationSettings",
    "GlobalHypothesis",
    "associate",
    "associate_global",
    "global_hypotheses",
]

log = logging.getLogger(__name__)


#: A tolerance between two plane normals taken with either sign (at most 90 deg apart), degrees;
#: 0 would refuse every pair.
_NORMAL_ANGLE = Domain(lo=0.0, hi=90.0, lo_open=True, note="degrees")
#: A distance gate or tolerance, metres (0 would refuse everything).
_METRES = Domain(lo=0.0, lo_open=True, note="metres")


@dataclass(frozen=True)
class AssociationSettings:
    """Gates of :func:`associate` (angles in degrees, distances in metres).

    Attributes
    ----------
    max_angle_deg : float
        Largest angle between the normals of a candidate pair after the predicted motion
        (either sign of the normal); 90 or more gates nothing.
    max_distance : float
        Largest difference of the distances ``rho`` of a candidate pair after the motion.
    overlap_margin : float
        Outlines of a candidate pair must come within this of each other.
    consistency_deg : float
        A match agrees with a rotation when its normals are within this after it.
    parallel_deg : float
        Normals closer than this are parallel (a pair of them proposes no rotation).
    require_overlap : bool
        Test the outlines' overlap (else only normals and distances gate).
    consistency_m, max_rms : float
        See each attribute.
    """

    max_angle_deg: float = domain_field(
        12.0, Domain(lo=0.0, lo_open=True, note="degrees; 90 or more gates nothing")
    )
    max_distance: float = domain_field(0.25, _METRES)
    overlap_margin: float = domain_field(0.3, Domain(lo=0.0, note="metres"))
    consistency_deg: float = domain_field(
        4.0, Domain(lo=0.0, hi=180.0, lo_open=True, note="degrees")
    )
    parallel_deg: float = domain_field(15.0, _NORMAL_ANGLE)
    require_overlap: bool = True
    consistency_m: float = domain_field(0.05, Domain(lo=0.0, note="metres, 0 = no check"))
    """A match whose distance disagrees with the least-squares translation of all matches by more
    than this (metres) is dropped, worst first (0 disables). Real planes agree to 1-4 cm (Kinect
    at 2.5-3 m, pcl-kinect and slambook under their reference motions); a stair tread matched
    to its neighbour is off by its ~20 cm rise."""
    max_rms: float = domain_field(0.08, _METRES)
    """Planes with a larger TLS residual (metres) are not matched: on real Kinect frames the
    organised extraction returns a few 10-13 cm "planes" (mixed surfaces), whose normals and
    distances bias the closed form (slambook 2 -> 3: 27 cm / 3.0 deg with them, 16.6 cm /
    3.0 deg without). 8 cm = twice the Kinect depth noise at 4 m (0.0025 z^2); the simulated
    floors reaching 10 m and more fit to 6-7 cm."""

    def __post_init__(self) -> None:
        check_settings(self)


def _overlap(a: PlaneSegment, b_pts: NDArray[np.float64], margin: float, frame=None) -> bool:
    """Whether 3D points ``b_pts`` (frame of ``a``) fall within ``margin`` of ``a``'s outline."""
    if len(a.outline) < 3 or len(b_pts) == 0:
        return True  # no outline to test against: do not veto
    o, ax = frame if frame is not None else plane_frame(a.plane)
    uv = (b_pts - o) @ ax.T
    return bool(points_in_polygon(uv, a.outline, tolerance=margin).any())


def _rotations_from_two(n1a, n1b, n2a, n2b):
    """The rotations ``(K, 3, 3)`` taking normals ``n2a``, ``n2b`` onto ``n1a``, ``n1b`` (least
    squares, with their cross products), for ``(K, 3)`` stacks of normals."""
    c1 = np.cross(n1a, n1b)
    c2 = np.cross(n2a, n2b)
    A = np.stack([n1a, n1b, c1 / np.linalg.norm(c1, axis=1, keepdims=True)], axis=1)
    B = np.stack([n2a, n2b, c2 / np.linalg.norm(c2, axis=1, keepdims=True)], axis=1)
    U, _, Vt = np.linalg.svd(np.swapaxes(B, 1, 2) @ A)
    V, Ut = np.swapaxes(Vt, 1, 2), np.swapaxes(U, 1, 2)
    d = np.sign(np.linalg.det(V @ Ut))
    d[d == 0] = 1.0
    D = np.zeros((len(d), 3, 3))
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = d
    return V @ D @ Ut


def associate(
    planes1: Sequence[PlaneSegment],
    planes2: Sequence[PlaneSegment],
    T_1_2: ArrayLike | None = None,
    settings: AssociationSettings | None = None,
) -> list[tuple[int, int]]:
    """Match planes of frame 2 to planes of frame 1.

    Parameters
    ----------
    planes1, planes2 : sequences of PlaneSegment
    T_1_2 : (4, 4) array, optional
        Predicted motion (frame 2 -> frame 1); identity if omitted.
    settings : AssociationSettings, optional

    Returns
    -------
    list of (int, int)
        Matched index pairs, sorted by frame-1 index.
    """
    s = settings or AssociationSettings()
    if not planes1 or not planes2:
        return []
    T = np.eye(4) if T_1_2 is None else np.asarray(T_1_2, dtype=np.float64)
    R, t = T[:3, :3], T[:3, 3]
    N1 = np.array([p.normal for p in planes1])
    r1 = np.array([p.rho for p in planes1])
    N2 = np.array([p.normal for p in planes2]) @ R.T
    r2 = np.array([p.rho for p in planes2]) + N2 @ t
    cos = N1 @ N2.T
    # planes given with rho >= 0 may flip their normal when the origin crosses them
    flip = cos < 0
    cos = np.abs(cos)
    dist = np.abs(r1[:, None] - np.where(flip, -r2[None, :], r2[None, :]))
    ang = np.degrees(np.arccos(np.clip(cos, -1, 1)))
    ok = (ang < s.max_angle_deg) & (dist < s.max_distance)
    ok &= (np.array([p.plane.rms for p in planes1]) <= s.max_rms)[:, None]
    ok &= (np.array([p.plane.rms for p in planes2]) <= s.max_rms)[None, :]
    if s.require_overlap:
        ii, jj = np.nonzero(ok)
        # outlines and plane frames once per plane (not once per candidate pair)
        f1 = {i: plane_frame(planes1[i].plane) for i in set(ii.tolist())}
        f2 = {j: plane_frame(planes2[j].plane) for j in set(jj.tolist())}
        fwd = {
            j: np.vstack([planes2[j].outline_3d(), planes2[j].plane.centroid[None]]) @ R.T + t
            for j in f2
        }
        back = {
            i: (np.vstack([planes1[i].outline_3d(), planes1[i].plane.centroid[None]]) - t) @ R
            for i in f1
        }
        for i, j in zip(ii.tolist(), jj.tolist(), strict=True):
            if not (
                _overlap(planes1[i], fwd[j], s.overlap_margin, f1[i])
                or _overlap(planes2[j], back[i], s.overlap_margin, f2[j])
            ):
                ok[i, j] = False
    cost = np.where(ok, ang / s.max_angle_deg + dist / s.max_distance, 1e6)
    rows, cols = linear_sum_assignment(cost)
    pairs = [(int(i), int(j)) for i, j in zip(rows, cols, strict=True) if ok[i, j]]
    if len(pairs) < 2:
        return pairs
    # consistency with one rotation
    sin_par = np.sin(np.radians(s.parallel_deg))
    n1 = np.array([planes1[i].normal for i, _ in pairs])
    n2 = np.array([planes2[j].normal for _, j in pairs])
    sg = np.sign(np.einsum("ij,ij->i", n1, n2 @ R.T))
    sg[sg == 0] = 1
    n2s = n2 * sg[:, None]
    # every non-parallel pair of matches proposes a rotation (all at once); the first with the
    # most matches within consistency_deg wins
    ia, ib = np.triu_indices(len(pairs), 1)
    c1 = np.cross(n1[ia], n1[ib])
    keep = np.linalg.norm(c1, axis=1) >= sin_par
    found = bool(keep.any())
    if found:
        Rs = _rotations_from_two(n1[ia[keep]], n1[ib[keep]], n2s[ia[keep]], n2s[ib[keep]])
        cos = np.einsum("kij,nj,ni->kn", Rs, n2s, n1)
        inl = np.degrees(np.arccos(np.clip(cos, -1, 1))) < s.consistency_deg
        best = inl[int(np.argmax(inl.sum(axis=1)))]
    kept = [p for p, k in zip(pairs, best, strict=True) if k] if found else list(pairs)
    if len(kept) < len(pairs):
        log.debug(
            "association: %d of %d matches inconsistent with one rotation",
            len(pairs) - len(kept),
            len(pairs),
        )
    return sorted(_translation_consistent(planes1, planes2, kept, R, s))


def _translation_consistent(
    planes1: Sequence[PlaneSegment],
    planes2: Sequence[PlaneSegment],
    pairs: list[tuple[int, int]],
    R: NDArray[np.float64],
    s: AssociationSettings,
) -> list[tuple[int, int]]:
    """Drop matches whose distances disagree with one translation (eq. 2).

    ``N1 . dT = rho1 - rho2`` is solved by least squares over all matches (weighted by ``sqrt``
    of the smaller inlier count, minimum norm when the normals span fewer than 3 directions);
    the match with the largest residual is dropped while it exceeds ``consistency_m``. Catches
    a plane matched to its parallel neighbour (stair treads ~20 cm apart, inside the distance
    gate). Needs more matches than the normals' directions can absorb.
    """
    if s.consistency_m <= 0 or len(pairs) < 4:
        return pairs
    kept = list(pairs)
    while len(kept) >= 4:
        n1 = np.array([planes1[i].normal for i, _ in kept])
        n2 = np.array([planes2[j].normal for _, j in kept])
        sg = np.sign(np.einsum("ij,ij->i", n1, n2 @ R.T))
        sg[sg == 0] = 1
        drho = np.array([planes1[i].rho for i, _ in kept]) - sg * np.array(
            [planes2[j].rho for _, j in kept]
        )
        w = np.sqrt(
            np.minimum(
                [planes1[i].plane.count for i, _ in kept], [planes2[j].plane.count for _, j in kept]
            ).astype(np.float64)
            + 1.0
        )
        t = np.linalg.lstsq(n1 * w[:, None], drho * w, rcond=None)[0]
        res = np.abs(n1 @ t - drho)
        worst = int(np.argmax(res))
        if res[worst] <= s.consistency_m:
            break
        log.debug("association: match %s off one translation by %.3f m", kept[worst], res[worst])
        kept.pop(worst)
    return kept


@dataclass(frozen=True)
class GlobalAssociationSettings:
    """Settings of :func:`associate_global` (angles in degrees, distances in metres).

    Attributes
    ----------
    max_planes : int
        Planes per frame that form triples (the largest, at most ``per_direction`` per normal
        direction, so that a few big parallel pieces - ceiling panels, floor - do not crowd out
        the one wall that fixes the third direction).
    per_direction : int
        Most planes taken per direction (normals within ``direction_deg``, either sign).
    direction_deg : float
        Normals closer than this share a direction.
    angle_tol_deg : float
        Tolerance of the triples' mutual angles and of a plane's normal after the motion.
    distance_tol : float
        Tolerance of a plane's distance after the motion.
    min_triple_sin : float
        Smallest ``|det|`` of a triple's normals (well-conditioned translation).
    verify : int
        Distinct hypotheses (best plane scores first) re-scored by the points.
    verify_points : int
        Frame-2 sample (voxel centroids) of the point score.
    verify_distance : float
        A frame-2 point agrees when a frame-1 point lies within this distance.
    distinct_deg, distinct_m : float
        Hypotheses closer than this in rotation and translation are one hypothesis.
    max_rms : float
        Planes with a larger TLS residual (metres) take no part (as
        :attr:`AssociationSettings.max_rms`).
    refine : bool
        Refine the ``refine_top`` best hypotheses by points with the closed form
        (:func:`~navkit.planes.solve.solve_three_planes`) over all the planes each associates,
        then score them again.
    refine_top : int
        Hypotheses refined (the best by the point score).
    """

    max_planes: int = domain_field(12, Domain(integer=True, lo=3, note="a triple needs 3"))
    per_direction: int = domain_field(4, POSITIVE_INT)
    direction_deg: float = domain_field(10.0, Domain(lo=0.0, hi=90.0, note="degrees"))
    angle_tol_deg: float = domain_field(4.0, _NORMAL_ANGLE)
    distance_tol: float = domain_field(0.08, _METRES)
    min_triple_sin: float = domain_field(
        0.3, Domain(lo=0.0, hi=1.0, hi_open=True, note="|det| of three unit normals")
    )
    verify: int = domain_field(60, POSITIVE_INT)
    verify_points: int = domain_field(3000, POSITIVE_INT)
    verify_distance: float = domain_field(0.05, _METRES)
    distinct_deg: float = domain_field(2.0, Domain(lo=0.0, hi=180.0, note="degrees"))
    distinct_m: float = domain_field(0.1, NON_NEGATIVE)
    refine: bool = True
    refine_top: int = domain_field(8, NON_NEGATIVE_INT)
    max_rms: float = domain_field(0.08, _METRES)

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class GlobalHypothesis:
    """One motion hypothesis of :func:`global_hypotheses`.

    Attributes
    ----------
    T : (4, 4) array
        ``T_1_2`` proposed by a pair of agreeing plane triples.
    plane_score : float
        Sum of ``sqrt(inliers)`` of the frame-2 planes the motion maps onto a frame-1 plane.
    point_fit : float
        Fraction of the frame-2 sample within ``verify_distance`` of a frame-1 point after the
        motion (NaN when the points were not given).
    """

    T: NDArray[np.float64]
    plane_score: float
    point_fit: float


def _pick_planes(planes: Sequence[PlaneSegment], s: GlobalAssociationSettings) -> list[int]:
    """Indices of the largest planes, at most ``per_direction`` per normal direction."""
    order = np.argsort([-p.plane.count for p in planes], kind="stable")
    cos_dir = np.cos(np.radians(s.direction_deg))
    chosen: list[int] = []
    for i in order:
        if planes[int(i)].plane.rms > s.max_rms:
            continue
        n = planes[int(i)].normal
        same = sum(abs(float(planes[j].normal @ n)) > cos_dir for j in chosen)
        if same < s.per_direction:
            chosen.append(int(i))
        if len(chosen) == s.max_planes:
            break
    return chosen


def _kabsch_batch(A: NDArray[np.float64], B: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rotations ``(H, 3, 3)`` minimising ``sum_k |A[h, k] - R B[h, k]|^2`` (rows are vectors)."""
    U, _, Vt = np.linalg.svd(np.einsum("hki,hkj->hij", B, A))
    V = np.swapaxes(Vt, 1, 2)
    d = np.sign(np.linalg.det(V @ np.swapaxes(U, 1, 2)))
    d[d == 0] = 1.0
    D = np.zeros((len(A), 3, 3))
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = d
    return V @ D @ np.swapaxes(U, 1, 2)


def global_hypotheses(
    planes1: Sequence[PlaneSegment],
    planes2: Sequence[PlaneSegment],
    settings: GlobalAssociationSettings | None = None,
    points1: ArrayLike | None = None,
    points2: ArrayLike | None = None,
) -> list[GlobalHypothesis]:
    """Prior-free motion hypotheses from plane triples, best first.

    Every triple of well-separated normals of frame 1 (among the ``max_planes`` largest with
    ``rms <= max_rms``, at most ``per_direction`` per direction) is compared
    with every ordered triple of frame 2 by their mutual angles and handedness (rotation
    invariants). Each agreeing pair of triples gives a motion: rotation by Procrustes on the
    three normal pairs (eq. 1), translation from the three plane distances (eq. 2). All motions
    are scored at once by the planes they explain (sum of ``sqrt(inliers)`` of frame-2 planes
    mapped within the tolerances onto some frame-1 plane); near-duplicates are suppressed
    (``distinct_deg``, ``distinct_m``). Rooms are nearly symmetric - every corner of a box gives
    the same angles - so when the points are given the ``verify`` best distinct hypotheses are
    re-scored by how well *all* the points agree after the motion: the fraction of frame-2 voxel
    centroids (``verify_distance`` voxels) within ``verify_distance`` of a frame-1 point
    (KD-tree); the ``refine_top`` best are refined by the closed form over all the planes each
    associates and scored again. The list is sorted by the point fit (else by the plane score;
    without points every kept hypothesis is refined).

    Parameters
    ----------
    planes1, planes2 : sequences of PlaneSegment
    settings : GlobalAssociationSettings, optional
    points1, points2 : (..., 3) arrays, optional
        Each frame's points, metres (NaN ignored).

    Returns
    -------
    list of GlobalHypothesis
        Empty when no triple pair agrees (fewer than three directions in a frame).
    """
    from itertools import combinations, permutations

    s = settings or GlobalAssociationSettings()
    c1 = _pick_planes(planes1, s)
    c2 = _pick_planes(planes2, s)
    if len(c1) < 3 or len(c2) < 3:
        return []
    N1 = np.array([planes1[i].normal for i in c1])
    N2 = np.array([planes2[j].normal for j in c2])
    r1 = np.array([planes1[i].rho for i in c1])
    r2 = np.array([planes2[j].rho for j in c2])
    w2 = np.sqrt([float(planes2[j].plane.count) for j in c2])
    t1 = np.array(
        [
            c
            for c in combinations(range(len(c1)), 3)
            if abs(np.linalg.det(N1[list(c)])) > s.min_triple_sin
        ]
    ).reshape(-1, 3)
    t2 = np.array(
        [
            c
            for c in permutations(range(len(c2)), 3)
            if abs(np.linalg.det(N2[list(c)])) > s.min_triple_sin
        ]
    ).reshape(-1, 3)
    if len(t1) == 0 or len(t2) == 0:
        return []

    def signature(N, T):
        a, b, c = N[T[:, 0]], N[T[:, 1]], N[T[:, 2]]
        return np.stack(
            [
                np.einsum("ij,ij->i", a, b),
                np.einsum("ij,ij->i", a, c),
                np.einsum("ij,ij->i", b, c),
                np.einsum("ij,ij->i", a, np.cross(b, c)),
            ],
            axis=1,
        )

    s1, s2 = signature(N1, t1), signature(N2, t2)
    tol = np.sin(np.radians(s.angle_tol_deg)) * 2
    ia, ib = np.nonzero(np.all(np.abs(s1[:, None, :] - s2[None, :, :]) < tol, axis=2))
    if len(ia) == 0:
        return []
    i1, i2 = t1[ia], t2[ib]  # (H, 3) plane indices of the agreeing triples
    R = _kabsch_batch(N1[i1], N2[i2])
    t = np.linalg.solve(N1[i1], (r1[i1] - r2[i2])[..., None])[..., 0]
    # plane score of every hypothesis at once: frame-2 planes mapped onto a frame-1 plane
    M2 = np.einsum("hij,kj->hki", R, N2)  # (H, k2, 3)
    cos_ok = np.einsum("hki,li->hkl", M2, N1) > np.cos(np.radians(s.angle_tol_deg))
    rho2 = r2[None, :] + np.einsum("hki,hi->hk", M2, t)
    d_ok = np.abs(r1[None, None, :] - rho2[:, :, None]) < s.distance_tol
    score = ((cos_ok & d_ok).any(axis=2) * w2).sum(axis=1)
    # distinct hypotheses, best plane score first (non-maximum suppression)
    order = np.argsort(-score, kind="stable")
    R, t, score = R[order], t[order], score[order]
    alive = np.ones(len(R), bool)
    keep: list[int] = []
    cos_half = np.cos(np.radians(s.distinct_deg) / 2)
    while alive.any() and len(keep) < max(s.verify, 1):
        h = int(np.argmax(alive))
        keep.append(h)
        # rotation angle between R_h and R_k: trace(R_h^T R_k) = 1 + 2 cos(angle)
        tr = np.einsum("ij,kij->k", R[h], R)
        same = ((tr - 1) / 2 > 2 * cos_half**2 - 1) & (
            np.linalg.norm(t - t[h], axis=1) < s.distinct_m
        )
        alive &= ~same
        alive[h] = False
    Ts = np.tile(np.eye(4), (len(keep), 1, 1))
    Ts[:, :3, :3], Ts[:, :3, 3] = R[keep], t[keep]
    fit = np.full(len(keep), np.nan)
    have_points = points1 is not None and points2 is not None
    score_fit = _point_fit(points1, points2, s) if have_points else None
    if score_fit is not None:
        fit = score_fit(Ts)
    # the closed form over all the planes each motion associates, for the best by points
    # (or, without points, for all)
    top = np.argsort(-fit, kind="stable")[: s.refine_top] if have_points else np.arange(len(Ts))
    if s.refine and len(top):
        Ts[top] = np.array([_refine(planes1, planes2, Ts[k], s)[1] for k in top])
        if score_fit is not None:
            fit[top] = score_fit(Ts[top])
    hyps = [GlobalHypothesis(Ts[k], float(score[h]), float(fit[k])) for k, h in enumerate(keep)]
    if points1 is not None and points2 is not None:
        hyps.sort(key=lambda g: (-g.point_fit, -g.plane_score))
    return hyps


def _refine(
    planes1: Sequence[PlaneSegment],
    planes2: Sequence[PlaneSegment],
    T: NDArray[np.float64],
    s: GlobalAssociationSettings,
) -> tuple[list[tuple[int, int]], NDArray[np.float64]]:
    """The planes a motion associates (tight gates, planes with ``rms <= max_rms``) and the
    motion refined by the closed form over all of them (a triple alone carries the noise of
    three normals; all matched planes average it)."""
    from navkit.planes.solve import MotionEstimate, solve_three_planes

    tight = AssociationSettings(max_angle_deg=2 * s.angle_tol_deg, max_distance=2 * s.distance_tol)
    g1 = [i for i, p in enumerate(planes1) if p.plane.rms <= s.max_rms]
    g2 = [j for j, p in enumerate(planes2) if p.plane.rms <= s.max_rms]
    sub = associate([planes1[i] for i in g1], [planes2[j] for j in g2], T, tight)
    pairs = [(g1[a], g2[b]) for a, b in sub]
    if len(pairs) < 3:
        return pairs, T
    est = solve_three_planes(
        [planes1[i].plane for i, _ in pairs], [planes2[j].plane for _, j in pairs]
    )
    return pairs, (est.T if isinstance(est, MotionEstimate) else T)


def _point_fit(points1, points2, s: GlobalAssociationSettings):
    """A scorer ``(H, 4, 4) motions -> (H,) fractions`` of frame-2 voxel centroids within
    ``verify_distance`` of frame 1's (both clouds voxelised and indexed once)."""
    from scipy.spatial import cKDTree

    A = np.asarray(points1, dtype=np.float64).reshape(-1, 3)
    B = np.asarray(points2, dtype=np.float64).reshape(-1, 3)
    A = A[np.all(np.isfinite(A), axis=1)]
    B = B[np.all(np.isfinite(B), axis=1)]
    if len(A) == 0 or len(B) == 0:
        return lambda Ts: np.zeros(len(Ts))
    # one centroid per occupied voxel: equal weight per surface area, not per point
    A = voxelize(A, s.verify_distance / 2)[0]
    B = voxelize(B, s.verify_distance)[0]
    rng = np.random.default_rng(0)
    B = B[rng.choice(len(B), min(len(B), s.verify_points), replace=False)]
    tree = cKDTree(A)

    def score(Ts: NDArray[np.float64]) -> NDArray[np.float64]:
        out = np.empty(len(Ts))
        for k, T in enumerate(Ts):
            d, _ = tree.query(B @ T[:3, :3].T + T[:3, 3], distance_upper_bound=s.verify_distance)
            out[k] = np.isfinite(d).mean()
        return out

    return score


def associate_global(
    planes1: Sequence[PlaneSegment],
    planes2: Sequence[PlaneSegment],
    settings: GlobalAssociationSettings | None = None,
    points1: ArrayLike | None = None,
    points2: ArrayLike | None = None,
) -> tuple[list[tuple[int, int]], NDArray[np.float64] | None]:
    """Match planes without any motion prior (large rotations and translations).

    The best hypothesis of :func:`global_hypotheses` (plane triples consistent with one motion,
    verified by how well all points agree after it when the points are given) gates the
    ordinary one-to-one association (:func:`associate` with tolerances twice ``angle_tol_deg``
    and ``distance_tol``) over all planes with ``rms <= max_rms``.

    Returns
    -------
    pairs : list of (int, int)
        Matches (empty if no triple pair agrees).
    T_1_2 : (4, 4) array or None
        The motion of the best hypothesis.
    """
    s = settings or GlobalAssociationSettings()
    hyps = global_hypotheses(planes1, planes2, s, points1, points2)
    if not hyps:
        return [], None
    best = hyps[0]
    log.debug(
        "global association: %d distinct hypotheses, best plane score %.0f, point fit %.2f",
        len(hyps),
        best.plane_score,
        best.point_fit,
    )
    pairs, _ = _refine(planes1, planes2, best.T, s)
    return sorted(pairs), best.T
