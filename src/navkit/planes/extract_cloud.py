"""Plane extraction from unorganised clouds: sequential, vectorised RANSAC.

Each round draws many random point triples, scores all their planes at once on a subsample,
refits the best by total least squares, keeps the largest connected part of its inliers
(rasterised in the plane) and removes them; pieces of one plane returned separately are merged
at the end. Organised grids use the faster cell region growing of :mod:`navkit.planes.extract`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage
from scipy.sparse.csgraph import connected_components

from navkit.errors import InputError
from navkit.geometry import Plane, canonical_plane
from navkit.geometry.linalg import rows_dot, rows_matmul
from navkit.planes.segments import ExtractionResult, PlaneSegment, outline_from_points, plane_frame

__all__ = ["CloudExtractionSettings", "extract_planes_cloud"]

log = logging.getLogger(__name__)


def _fit(idx: NDArray[np.int64], P_flat: NDArray[np.float64]) -> tuple[Plane, NDArray[np.float64]]:
    """TLS plane of the inliers (from the 3 x 3 scatter) and the inlier points."""
    X = P_flat[idx]
    c = X.mean(axis=0)
    Xc = X - c
    w, V = np.linalg.eigh(np.einsum("ni,nj->ij", Xc, Xc))
    n, rho = canonical_plane(V[:, 0], float(V[:, 0] @ c))
    plane = Plane(
        normal=n, rho=rho, centroid=c, rms=float(np.sqrt(max(w[0], 0.0) / len(X))), count=len(X)
    )
    return plane, X


def _segment(
    idx: NDArray[np.int64], P_flat: NDArray[np.float64], outline_cell: float
) -> PlaneSegment:
    """Package inliers as a segment: TLS refit, outline and area from the rasterised points."""
    plane, X = _fit(idx, P_flat)
    origin, axes = plane_frame(plane)
    step = max(1, len(X) // 40_000)  # outlines from at most ~40k points (dense grids)
    uv = rows_matmul(X[::step] - origin, axes.T)
    outline, area = outline_from_points(uv, outline_cell)
    return PlaneSegment(plane=plane, inliers=idx.astype(np.int64), outline=outline, area=area)


@dataclass(frozen=True)
class CloudExtractionSettings:
    """Settings of :func:`extract_planes_cloud`.

    Attributes
    ----------
    distance : float
        RANSAC inlier distance, metres.
    min_points : int
        Smallest plane kept, points.
    max_planes : int
        Most planes extracted.
    hypotheses : int
        Plane hypotheses drawn per round (scored together on a subsample).
    score_sample : int
        Points of the subsample that scores hypotheses.
    connect_cell : float
        Raster cell (metres) in the plane for keeping the largest connected part of the inliers;
        0 disables the connectivity step.
    outline_cell : float
        Raster size for outlines and areas, metres.
    seed : int
        Seed of the hypothesis sampling (the result is deterministic).
    """

    distance: float = 0.02
    min_points: int = 500
    max_planes: int = 20
    hypotheses: int = 256
    score_sample: int = 4000
    connect_cell: float = 0.3
    outline_cell: float = 0.05
    seed: int = 0


def extract_planes_cloud(
    points: ArrayLike, settings: CloudExtractionSettings | None = None
) -> ExtractionResult:
    """Planes of an unorganised cloud by sequential, vectorised RANSAC.

    Each round draws ``hypotheses`` random triples of the remaining points, scores all of them at
    once on a subsample, refits the best by TLS over its inliers (twice), keeps the largest
    connected part of the inliers, and removes them.

    Parameters
    ----------
    points : (N, 3) array
        Metres; NaN rows ignored.
    settings : CloudExtractionSettings, optional

    Returns
    -------
    ExtractionResult
        ``labels`` is ``(N,)``.
    """
    s = settings or CloudExtractionSettings()
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(f"has shape {P.shape}", field="points", expected="(N, 3) array")
    rng = np.random.default_rng(s.seed)
    labels = -np.ones(len(P), np.int64)
    remaining = np.flatnonzero(np.all(np.isfinite(P), axis=1))
    segs: list[PlaneSegment] = []
    failures = 0
    while len(segs) < s.max_planes and len(remaining) >= s.min_points and failures < 3:
        R = P[remaining]
        tri = R[rng.integers(0, len(R), size=(s.hypotheses, 3))]
        nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        ln = np.linalg.norm(nrm, axis=1)
        good = ln > 1e-9
        nrm = nrm[good] / ln[good, None]
        dd = np.einsum("hi,hi->h", nrm, tri[good, 0])
        sample = R[rng.integers(0, len(R), size=min(s.score_sample, len(R)))]
        score = (np.abs(rows_matmul(sample, nrm.T) - dd) < s.distance).sum(axis=0)
        best = int(np.argmax(score))
        n, d = nrm[best], dd[best]
        for _ in range(2):  # TLS refit on the inliers
            inl = np.abs(rows_dot(R, n) - d) < s.distance
            if inl.sum() < 3:
                break
            X = R[inl]
            cm = X.mean(axis=0)
            n = np.linalg.svd(X - cm, full_matrices=False)[2][2]
            d = float(n @ cm)
        inl = np.abs(rows_dot(R, n) - d) < s.distance
        idx = remaining[inl]
        if s.connect_cell > 0 and len(idx) >= s.min_points:
            idx = _largest_connected(P[idx], n, d, s.connect_cell, idx)
        if len(idx) < s.min_points:
            failures += 1
            continue
        seg = _segment(idx, P, s.outline_cell)
        labels[idx] = len(segs)
        segs.append(seg)
        remaining = np.setdiff1d(remaining, idx, assume_unique=True)
    segs = _merge_coplanar(segs, P, s)
    labels = -np.ones(len(P), np.int64)
    for k, sg in enumerate(segs):
        labels[sg.inliers] = k
    return ExtractionResult(tuple(segs), labels)


def _merge_coplanar(segs: list[PlaneSegment], P, s: CloudExtractionSettings) -> list[PlaneSegment]:
    """Join segments of one plane that RANSAC returned in pieces (normals within 3 deg, each
    centroid within the inlier band of the other plane)."""
    if len(segs) < 2:
        return segs
    n = np.array([g.normal for g in segs])
    rho = np.array([g.rho for g in segs])
    c = np.array([g.plane.centroid for g in segs])
    same = (n @ n.T > np.cos(np.radians(3.0))) & (np.abs(c @ n.T - rho[None, :]) < s.distance)
    same &= same.T
    n_grp, grp = connected_components(same.astype(np.int8), directed=False)
    if n_grp == len(segs):
        return segs
    out = [
        _segment(
            np.concatenate([segs[k].inliers for k in np.flatnonzero(grp == g)]), P, s.outline_cell
        )
        for g in range(n_grp)
    ]
    out.sort(key=lambda sg: -sg.plane.count)
    return out


def _largest_connected(X, n, d, cell, idx):
    """Indices of the largest 8-connected part of planar points rasterised at ``cell`` metres."""
    nn, rho = canonical_plane(n, d)
    axes = Plane(normal=nn, rho=rho, centroid=X.mean(0)).basis()
    uv = rows_matmul(X, axes.T)
    ij = np.floor((uv - uv.min(axis=0)) / cell).astype(np.int64)
    shape = tuple(ij.max(axis=0) + 1)
    grid = np.zeros(shape, bool)
    grid[ij[:, 0], ij[:, 1]] = True
    lab, n_lab = ndimage.label(grid, structure=np.ones((3, 3), bool))
    if n_lab <= 1:
        return idx
    pl = lab[ij[:, 0], ij[:, 1]]
    big = np.argmax(np.bincount(pl)[1:]) + 1
    return idx[pl == big]
