"""Plane extraction from unorganised clouds: normal-aware sequential RANSAC on a voxel grid.

Stages (:func:`extract_planes_cloud`):

1. **Voxel grid** - the cloud is reduced to one centroid per occupied voxel. A scanner's density
   falls with the square of the range (the PCL room scans hold half their points within 1.4 m of
   the scanner: floor and ceiling rings); on voxels every square metre of surface weighs the
   same, so distant walls compete with the floor on their area, not their point count.
2. **Normals** - per voxel, PCA of its ``neighbours`` nearest voxels (KD-tree, batched 3 x 3
   eigen-decompositions). Voxels whose neighbourhood is a line (a single scan line) get no
   hypothesis.
3. **RANSAC** - each round draws ``hypotheses`` voxels and takes their (point, normal) planes as
   hypotheses (one-point RANSAC), scores all of them at once on a subsample: inliers are within
   ``distance`` of the plane *and* have a normal within ``normal_deg`` of it (a wall's voxels do
   not join the floor along their common edge); the best is refit by TLS (three times), its
   largest connected part kept (rasterised in the plane) and removed.
4. **Segments** - every input point of the plane's voxels that lies within ``distance`` of the
   plane is an inlier; TLS refit, outline, area from the full-resolution inliers; pieces of one
   plane merged.

Scales follow the data unless given: the voxel is 1/200 of the cloud's robust extent (the
diagonal of its 5-95 % box), the inlier band 3 x the larger of the points' robust sigma about
their voxel's local plane (the sensor's noise) and the median thickness ``sqrt(lambda_min)`` of
the voxel neighbourhoods (the surfaces' unevenness at that scale). Organised
grids use the faster cell region growing of :mod:`navkit.planes.extract`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from navkit.domains import (
    NON_NEGATIVE_INT,
    POSITIVE_INT,
    SEED,
    Domain,
    domain_field,
)
from navkit.errors import InputError
from navkit.geometry._validate import check_coordinates, check_grid_size, check_settings
from navkit.geometry.fitting import Plane, canonical_plane
from navkit.geometry.linalg import rows_matmul
from navkit.planes.segments import ExtractionResult, PlaneSegment, outline_from_points, plane_frame

__all__ = ["CloudExtractionSettings", "CloudScales", "cloud_scales", "extract_planes_cloud"]

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
    distance : float or None
        RANSAC inlier distance, metres; None = 3 x :attr:`CloudScales.thickness`
        (:func:`cloud_scales`), clipped to ``[0.005, 0.05]``.
    voxel : float or None
        Voxel edge, metres; None = 1/200 of the cloud's robust extent, clipped to
        ``[0.01, 0.2]``; 0 = no voxel grid (every point its own voxel).
    neighbours : int
        Voxels in each normal's PCA neighbourhood.
    normal_deg : float
        Largest angle between a voxel's normal and the plane for the voxel to be an inlier.
    min_points : int
        Smallest plane kept, input points.
    min_area : float
        Smallest plane kept, m^2 of voxels (``voxel^2`` each).
    max_planes : int
        Most planes extracted.
    hypotheses : int
        Plane hypotheses drawn per round (scored together on a subsample).
    score_sample : int
        Voxels of the subsample that scores hypotheses.
    connect_cell : float
        Raster cell (metres) in the plane for keeping the largest connected part of the inliers;
        0 disables the connectivity step.
    outline_cell : float
        Raster size for outlines and areas, metres.
    seed : int
        Seed of the hypothesis sampling (the result is deterministic).
    """

    distance: float | None = domain_field(
        None, Domain(lo=0.0, lo_open=True, note="metres, None = from the data")
    )
    voxel: float | None = domain_field(
        None, Domain(lo=0.0, note="metres, 0 = no voxel grid, None = from the data")
    )
    neighbours: int = domain_field(16, Domain(integer=True, lo=3, note="a plane needs 3"))
    normal_deg: float = domain_field(20.0, Domain(lo=0.0, hi=90.0, lo_open=True, note="degrees"))
    min_points: int = domain_field(500, NON_NEGATIVE_INT)
    min_area: float = domain_field(0.25, Domain(lo=0.0, note="m^2"))
    max_planes: int = domain_field(20, POSITIVE_INT)
    hypotheses: int = domain_field(256, POSITIVE_INT)
    score_sample: int = domain_field(4000, POSITIVE_INT)
    connect_cell: float = domain_field(0.3, Domain(lo=0.0, note="metres, 0 = no connectivity step"))
    outline_cell: float = domain_field(0.05, Domain(lo=0.0, lo_open=True, note="metres"))
    seed: int = domain_field(0, SEED)

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class CloudScales:
    """Scales of a cloud as :func:`extract_planes_cloud` uses them.

    Attributes
    ----------
    voxel : float
        Voxel edge, metres.
    distance : float
        RANSAC inlier band (half-width), metres.
    thickness : float
        The larger of the robust sigma of the points across their voxel's local plane
        (:func:`_noise`) and the median ``sqrt(lambda_min)`` of the voxel neighbourhoods
        (surface unevenness at that scale), metres.
    extent : float
        Diagonal of the 5-95 % box of the points, metres.
    """

    voxel: float
    distance: float
    thickness: float
    extent: float


def voxelize(P: NDArray[np.float64], voxel: float) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Centroids ``(M, 3)`` of the occupied voxels and the voxel of every point ``(N,)``."""
    if voxel <= 0:
        return P, np.arange(len(P), dtype=np.int64)
    ijk = np.floor((P - P.min(axis=0)) / voxel).astype(np.int64)
    dims = ijk.max(axis=0) + 1
    key = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    _, inv = np.unique(key, return_inverse=True)
    inv = inv.ravel().astype(np.int64)
    cnt = np.bincount(inv).astype(np.float64)
    C = np.stack([np.bincount(inv, weights=P[:, a]) for a in range(3)], axis=1) / cnt[:, None]
    return C, inv


def _normals(C: NDArray[np.float64], k: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Unit normals ``(M, 3)`` and PCA eigenvalues ``(M, 3)`` (ascending) of ``k``-neighbourhoods."""
    k = int(min(k, len(C)))
    _, nb = cKDTree(C).query(C, k=k)
    X = C[nb.reshape(len(C), k)]
    X = X - X.mean(axis=1, keepdims=True)
    cov = np.einsum("mki,mkj->mij", X, X) / k
    w, V = np.linalg.eigh(cov)
    return V[:, :, 0], np.maximum(w, 0.0)


def cloud_scales(points: ArrayLike, settings: CloudExtractionSettings | None = None) -> CloudScales:
    """The voxel and inlier band :func:`extract_planes_cloud` would use for ``points (N, 3)``."""
    s = settings or CloudExtractionSettings()
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    P = P[np.all(np.isfinite(P), axis=1)]
    return _scales(P, s)[0]


def _scales(P, s: CloudExtractionSettings):
    lo, hi = np.percentile(P, [5, 95], axis=0) if len(P) else (np.zeros(3), np.zeros(3))
    extent = float(np.linalg.norm(hi - lo))
    voxel = s.voxel if s.voxel is not None else float(np.clip(extent / 200.0, 0.01, 0.2))
    C, inv = voxelize(P, voxel)
    n, w = _normals(C, s.neighbours) if len(C) >= 3 else (np.zeros((0, 3)), np.zeros((0, 3)))
    # the band must hold the sensor's noise (raw points about their voxel's local plane) and
    # the surface's own unevenness at the neighbourhood scale (scatter of the voxel centroids,
    # whose averaging removes most of the noise): the larger of the two
    local = float(np.median(np.sqrt(w[:, 0]))) if len(w) else 0.0
    thick = max(_noise(P, C, inv, n, w), local)
    dist = s.distance if s.distance is not None else float(np.clip(3.0 * thick, 0.005, 0.05))
    return CloudScales(voxel, dist, thick, extent), C, inv, n, w


def _noise(P, C, inv, n, w) -> float:
    """Robust noise of the raw points across the local surface, metres.

    Each point's offset from its voxel centroid along the voxel's normal (from the PCA of the
    neighbouring voxels); ``1.4826 x`` the median absolute offset (sigma of a Gaussian), over
    voxels that hold >= 3 points and lie on a surface (not a line). Voxel centroids average the
    noise away, so their own scatter would understate it.
    """
    if len(w) == 0:
        return 0.0
    cnt = np.bincount(inv, minlength=len(C))
    use = (cnt >= 3) & (w[:, 1] > 4.0 * w[:, 0] + 1e-12)
    sel = use[inv]
    if sel.sum() < 10:
        return float(np.median(np.sqrt(w[:, 0])))
    r = np.einsum("ij,ij->i", P[sel] - C[inv[sel]], n[inv[sel]])
    return float(1.4826 * np.median(np.abs(r)))


def extract_planes_cloud(
    points: ArrayLike, settings: CloudExtractionSettings | None = None
) -> ExtractionResult:
    """Planes of an unorganised cloud by normal-aware sequential RANSAC on a voxel grid.

    See the module docstring for the stages and the scales.

    Parameters
    ----------
    points : (N, 3) array
        Metres; NaN rows ignored.
    settings : CloudExtractionSettings, optional

    Returns
    -------
    ExtractionResult
        ``labels`` is ``(N,)``; segments sorted by decreasing inlier count.
    """
    s = settings or CloudExtractionSettings()
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(f"has shape {P.shape}", field="points", expected="(N, 3) array")
    check_coordinates(P, field="points")
    fin = np.flatnonzero(np.all(np.isfinite(P), axis=1))
    if len(fin) < max(3, s.min_points):
        return ExtractionResult((), -np.ones(len(P), np.int64))
    Pf = P[fin]
    sc, C, inv, nrm, ev = _scales(Pf, s)
    log.debug(
        "cloud: %d points -> %d voxels of %.3f m, band %.3f m",
        len(Pf),
        len(C),
        sc.voxel,
        sc.distance,
    )
    # a surface, not a line: the second eigenvalue clearly above the first (a single scan line
    # has both near zero and an arbitrary "normal")
    surface = ev[:, 1] > 4.0 * ev[:, 0] + 1e-12
    voxel_planes = _ransac(C, nrm, surface, sc, s)
    vox_of_plane = -np.ones(len(C), np.int64)
    for k, (vidx, _, _) in enumerate(voxel_planes):
        vox_of_plane[vidx] = k
    lab_pts = vox_of_plane[inv]
    segs: list[PlaneSegment] = []
    for k, (_, n, d) in enumerate(voxel_planes):
        mine = np.flatnonzero(lab_pts == k)
        mine = mine[np.abs(rows_matmul(Pf[mine], n[:, None])[:, 0] - d) < sc.distance]
        if len(mine) >= s.min_points:
            segs.append(_segment(fin[mine], P, s.outline_cell))
    segs = _merge_coplanar(segs, P, s, sc.distance)
    segs.sort(key=lambda sg: -sg.plane.count)
    labels = -np.ones(len(P), np.int64)
    for k, sg in enumerate(segs):
        labels[sg.inliers] = k
    return ExtractionResult(tuple(segs), labels)


def _ransac(
    C: NDArray[np.float64],
    nrm: NDArray[np.float64],
    surface: NDArray[np.bool_],
    sc: CloudScales,
    s: CloudExtractionSettings,
) -> list[tuple[NDArray[np.int64], NDArray[np.float64], float]]:
    """Sequential one-point RANSAC on voxels: ``(voxel indices, normal, d)`` per plane."""
    rng = np.random.default_rng(s.seed)
    cos_n = np.cos(np.radians(s.normal_deg))
    min_vox = max(3, int(np.ceil(s.min_area / max(sc.voxel, 1e-3) ** 2)))
    if s.voxel == 0:
        min_vox = max(3, s.min_points)
    rem = np.ones(len(C), bool)
    out: list[tuple[NDArray[np.int64], NDArray[np.float64], float]] = []
    failures = 0

    def inliers(n, d):
        return rem & (np.abs(C @ n - d) < sc.distance) & (np.abs(nrm @ n) > cos_n)

    while len(out) < s.max_planes and failures < 5:
        cand = np.flatnonzero(rem & surface)
        left = np.flatnonzero(rem)
        if len(cand) < min_vox:
            break
        h = cand[rng.integers(0, len(cand), size=s.hypotheses)]
        hn = nrm[h]
        hd = np.einsum("hi,hi->h", hn, C[h])
        smp = left[rng.integers(0, len(left), size=min(s.score_sample, len(left)))]
        # scored in float32 (a ranking: 1e-7 relative precision is ample), centred on the
        # sample so that the distances stay small numbers
        ctr = C[smp].mean(axis=0)
        X32 = (C[smp] - ctr).astype(np.float32)
        N32 = nrm[smp].astype(np.float32)
        H32 = hn.astype(np.float32)
        d32 = (hd - hn @ ctr).astype(np.float32)
        dist = X32[:, :1] * H32[:, 0] + X32[:, 1:2] * H32[:, 1] + X32[:, 2:3] * H32[:, 2] - d32
        cosn = N32[:, :1] * H32[:, 0] + N32[:, 1:2] * H32[:, 1] + N32[:, 2:3] * H32[:, 2]
        score = ((np.abs(dist) < sc.distance) & (np.abs(cosn) > cos_n)).sum(axis=0)
        best = int(np.argmax(score))
        n, d = hn[best], float(hd[best])
        for _ in range(3):  # TLS refit on the inliers
            inl = inliers(n, d)
            if inl.sum() < 3:
                break
            X = C[inl]
            cm = X.mean(axis=0)
            n = np.linalg.svd(X - cm, full_matrices=False)[2][2]
            d = float(n @ cm)
        vidx = np.flatnonzero(inliers(n, d))
        if s.connect_cell > 0 and len(vidx) >= min_vox:
            vidx = _largest_connected(C[vidx], n, d, max(s.connect_cell, 2 * sc.voxel), vidx)
        if len(vidx) < min_vox:
            failures += 1
            rem[h[best]] = False  # do not draw this seed again
            continue
        rem[vidx] = False
        out.append((vidx, n, d))
    return out


def _merge_coplanar(
    segs: list[PlaneSegment], P, s: CloudExtractionSettings, distance: float
) -> list[PlaneSegment]:
    """Join segments of one plane that RANSAC returned in pieces (normals within 3 deg, each
    centroid within the inlier band of the other plane)."""
    if len(segs) < 2:
        return segs
    n = np.array([g.normal for g in segs])
    rho = np.array([g.rho for g in segs])
    c = np.array([g.plane.centroid for g in segs])
    same = (n @ n.T > np.cos(np.radians(3.0))) & (np.abs(c @ n.T - rho[None, :]) < distance)
    same &= same.T
    n_grp, grp = connected_components(same.astype(np.int8), directed=False)
    if n_grp == len(segs):
        return segs
    return [
        _segment(
            np.concatenate([segs[k].inliers for k in np.flatnonzero(grp == g)]), P, s.outline_cell
        )
        for g in range(n_grp)
    ]


def _largest_connected(X, n, d, cell, idx):
    """Indices of the largest 8-connected part of planar points rasterised at ``cell`` metres."""
    nn, rho = canonical_plane(n, d)
    axes = Plane(normal=nn, rho=rho, centroid=X.mean(0)).basis()
    uv = rows_matmul(X, axes.T)
    f = np.floor((uv - uv.min(axis=0)) / cell)
    # the raster's size before it is allocated (points spread over kilometres at a fine cell)
    check_grid_size(tuple(f.max(axis=0) + 1), setting="connect_cell", source="plane raster")
    ij = f.astype(np.int64)
    shape = tuple(ij.max(axis=0) + 1)
    grid = np.zeros(shape, bool)
    grid[ij[:, 0], ij[:, 1]] = True
    lab, n_lab = ndimage.label(grid, structure=np.ones((3, 3), bool))
    if n_lab <= 1:
        return idx
    pl = lab[ij[:, 0], ij[:, 1]]
    big = np.argmax(np.bincount(pl)[1:]) + 1
    return idx[pl == big]
