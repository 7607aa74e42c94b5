"""Association of planes between two frames.

A pair ``(i, j)`` (plane ``i`` of frame 1, plane ``j`` of frame 2) is a candidate when, after the
predicted motion ``T_1_2`` (identity by default), the normals agree within ``max_angle_deg``, the
distances ``rho`` within ``max_distance`` and the outlines overlap (some vertex or the centroid of
one outline lies within ``overlap_margin`` of the other). Candidates are assigned one-to-one by
minimum cost (Hungarian), then only the largest subset consistent with **one rotation** is kept:
every pair of non-parallel matches proposes a rotation, the one that agrees with the most
matches (within ``consistency_deg``) wins. Planes that appear or vanish simply stay unmatched.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment

from navkit.geometry import points_in_polygon
from navkit.planes.segments import PlaneSegment, plane_frame

__all__ = ["AssociationSettings", "GlobalAssociationSettings", "associate", "associate_global"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class AssociationSettings:
    """Gates of :func:`associate` (angles in degrees, distances in metres)."""

    max_angle_deg: float = 12.0
    max_distance: float = 0.25
    overlap_margin: float = 0.3
    consistency_deg: float = 4.0
    parallel_deg: float = 15.0
    require_overlap: bool = True


def _overlap(a: PlaneSegment, b_pts: NDArray[np.float64], margin: float) -> bool:
    """Whether 3D points ``b_pts`` (frame of ``a``) fall within ``margin`` of ``a``'s outline."""
    if len(a.outline) < 3 or len(b_pts) == 0:
        return True  # no outline to test against: do not veto
    o, ax = plane_frame(a.plane)
    uv = (b_pts - o) @ ax.T
    return bool(points_in_polygon(uv, a.outline, tolerance=margin).any())


def _rotation_from_two(n1a, n1b, n2a, n2b):
    c1 = np.cross(n1a, n1b)
    c2 = np.cross(n2a, n2b)
    A = np.stack([n1a, n1b, c1 / np.linalg.norm(c1)])
    B = np.stack([n2a, n2b, c2 / np.linalg.norm(c2)])
    U, _, Vt = np.linalg.svd(B.T @ A)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    return Vt.T @ np.diag([1.0, 1.0, d]) @ U.T


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
    if s.require_overlap:
        for i, j in zip(*np.nonzero(ok), strict=True):
            b = planes2[j]
            pts = np.vstack([b.outline_3d(), b.plane.centroid[None]]) @ R.T + t
            a = planes1[i]
            back = np.vstack([a.outline_3d(), a.plane.centroid[None]]) - t
            if not (_overlap(a, pts, s.overlap_margin) or _overlap(b, back @ R, s.overlap_margin)):
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
    best = np.ones(len(pairs), bool)
    best_count = -1
    found = False
    for a in range(len(pairs)):
        for b in range(a + 1, len(pairs)):
            if np.linalg.norm(np.cross(n1[a], n1[b])) < sin_par:
                continue
            Rab = _rotation_from_two(n1[a], n1[b], n2s[a], n2s[b])
            err = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", n1, n2s @ Rab.T), -1, 1)))
            inl = err < s.consistency_deg
            if inl.sum() > best_count:
                best, best_count, found = inl, int(inl.sum()), True
    if not found:  # all matches parallel: the rotation test cannot veto
        return sorted(pairs)
    kept = [p for p, k in zip(pairs, best, strict=True) if k]
    if len(kept) < len(pairs):
        log.debug(
            "association: %d of %d matches inconsistent with one rotation",
            len(pairs) - len(kept),
            len(pairs),
        )
    return sorted(kept)


@dataclass(frozen=True)
class GlobalAssociationSettings:
    """Settings of :func:`associate_global` (angles in degrees, distances in metres)."""

    max_planes: int = 8
    angle_tol_deg: float = 4.0
    distance_tol: float = 0.08
    min_triple_sin: float = 0.3
    verify: int = 20
    verify_points: int = 3000
    verify_distance: float = 0.05


def associate_global(
    planes1: Sequence[PlaneSegment],
    planes2: Sequence[PlaneSegment],
    settings: GlobalAssociationSettings | None = None,
    points1: ArrayLike | None = None,
    points2: ArrayLike | None = None,
) -> tuple[list[tuple[int, int]], NDArray[np.float64] | None]:
    """Match planes without any motion prior (large rotations and translations).

    Every triple of well-separated normals of frame 1 is compared with every ordered triple of
    frame 2 by their mutual angles (rotation invariants); each agreeing pair of triples gives a
    motion (Procrustes rotation, translation from the three plane distances), scored by how many
    planes (weighted by inliers) it maps onto a plane of the other frame. The best motion then
    gates the ordinary one-to-one association. Rooms are nearly symmetric and often hold
    several parallel walls, so when the frames' points are given the ``verify`` best hypotheses
    are re-scored by the fraction of a sample of frame-2 points that land within
    ``verify_distance`` of a frame-1 point (KD-tree).

    Returns
    -------
    pairs : list of (int, int)
        Matches (empty if no triple pair agrees).
    T_1_2 : (4, 4) array or None
        The motion of the best hypothesis.
    """
    from itertools import combinations, permutations

    s = settings or GlobalAssociationSettings()
    k1 = min(len(planes1), s.max_planes)
    k2 = min(len(planes2), s.max_planes)
    if k1 < 3 or k2 < 3:
        return [], None
    N1 = np.array([p.normal for p in planes1[:k1]])
    N2 = np.array([p.normal for p in planes2[:k2]])
    r1 = np.array([p.rho for p in planes1[:k1]])
    r2 = np.array([p.rho for p in planes2[:k2]])
    w2 = np.sqrt([p.plane.count for p in planes2[:k2]])
    t1 = np.array(
        [
            c
            for c in combinations(range(k1), 3)
            if abs(np.linalg.det(N1[list(c)])) > s.min_triple_sin
        ]
    )
    t2 = np.array(
        [
            c
            for c in permutations(range(k2), 3)
            if abs(np.linalg.det(N2[list(c)])) > s.min_triple_sin
        ]
    )
    if len(t1) == 0 or len(t2) == 0:
        return [], None

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
    agree = np.all(np.abs(s1[:, None, :] - s2[None, :, :]) < tol, axis=2)
    cos_tol = np.cos(np.radians(s.angle_tol_deg))
    hyps: list[tuple[float, NDArray[np.float64]]] = []
    for a, b in zip(*np.nonzero(agree), strict=True):
        i, j = t1[a], t2[b]
        U, _, Vt = np.linalg.svd(N2[j].T @ N1[i])
        d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
        R = Vt.T @ np.diag([1.0, 1.0, d]) @ U.T
        t = np.linalg.solve(N1[i], r1[i] - r2[j])
        M2 = N2 @ R.T
        ok = (M2 @ N1.T > cos_tol) & (
            np.abs(r1[None, :] - (r2[:, None] + (M2 @ t)[:, None])) < s.distance_tol
        )
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, t
        hyps.append((float((w2 * ok.any(axis=1)).sum()), T))
    if not hyps:
        return [], None
    hyps.sort(key=lambda h: -h[0])
    best_T = hyps[0][1]
    if points1 is not None and points2 is not None:
        from scipy.spatial import cKDTree

        A = np.asarray(points1, dtype=np.float64).reshape(-1, 3)
        B = np.asarray(points2, dtype=np.float64).reshape(-1, 3)
        A = A[np.all(np.isfinite(A), axis=1)]
        B = B[np.all(np.isfinite(B), axis=1)]
        rng = np.random.default_rng(0)
        A = A[rng.choice(len(A), min(len(A), 20 * s.verify_points), replace=False)]
        B = B[rng.choice(len(B), min(len(B), s.verify_points), replace=False)]
        tree = cKDTree(A)
        fits = []
        for _, T in hyps[: s.verify]:
            d, _ = tree.query(B @ T[:3, :3].T + T[:3, 3], distance_upper_bound=s.verify_distance)
            fits.append(float(np.isfinite(d).mean()))
        best_T = hyps[int(np.argmax(fits))][1]
        log.debug("global association: best point fit %.2f of %d hypotheses", max(fits), len(fits))
    tight = AssociationSettings(max_angle_deg=2 * s.angle_tol_deg, max_distance=2 * s.distance_tol)
    return associate(planes1, planes2, best_T, tight), best_T
