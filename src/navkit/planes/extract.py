"""Plane extraction: organised grids (CAPE-like cell region growing) and unorganised clouds.

Organised input (depth image back-projected, organised PCD, a range-scan grid), in the spirit of
CAPE (Proenca & Gao, 2018):

1. cut the grid into ``cell x cell`` patches and accumulate their moments (count, sum, scatter);
2. a patch is *planar* when it is nearly complete and its PCA thickness (smallest eigenvalue)
   is below a depth-dependent noise bound ``rms_base + rms_quadratic * z^2``;
3. neighbouring planar patches are joined when their normals agree and each centroid lies on the
   other's plane (region growing = connected components of that cell graph);
4. each region is refit from its summed moments; patches that disagree with the region's plane are
   dropped and the regions recomputed; coplanar regions are merged;
5. pixels of the region and of the cells bordering it are re-assigned by their distance to the
   plane (boundary refinement) and the plane is refit by total least squares.

Unorganised clouds: :mod:`navkit.planes.extract_cloud` (sequential RANSAC with vectorised
hypotheses, a TLS refit, and the largest connected part of the inliers kept per plane); its names
are re-exported here.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from navkit.errors import InputError
from navkit.geometry import Plane, canonical_plane
from navkit.planes.extract_cloud import CloudExtractionSettings, extract_planes_cloud
from navkit.planes.segments import ExtractionResult, PlaneSegment, outline_from_points, plane_frame

__all__ = [
    "CloudExtractionSettings",
    "ExtractionSettings",
    "extract_planes_cloud",
    "extract_planes_organized",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ExtractionSettings:
    """Settings of :func:`extract_planes_organized`.

    Attributes
    ----------
    cell : int
        Patch size, pixels (CAPE uses 20 for 640 x 480).
    min_fill : float
        Fraction of valid points a patch needs to be tested.
    rms_base, rms_quadratic : float
        Patch thickness bound ``rms_base + rms_quadratic * z^2`` (metres, z in metres): the
        structured-light noise model (Khoshelham & Elberink 2012: sigma_z ~ 1.4e-3 z^2 ... 2.9e-3 z^2)
        plus a margin for quantisation.
    angle_deg : float
        Largest normal angle between joined patches / merged regions, degrees.
    distance_factor : float
        Joined patches: centroid-to-plane distance below ``distance_factor`` x the thickness bound.
    min_cells : int
        Smallest region kept, patches.
    inlier_factor : float
        Boundary refinement: a pixel is an inlier when its distance to the plane is below
        ``inlier_factor`` x the thickness bound at its depth.
    outline_cell : float
        Raster size for outlines and areas, metres.
    """

    cell: int = 20
    min_fill: float = 0.6
    rms_base: float = 0.002
    rms_quadratic: float = 0.0025
    angle_deg: float = 12.0
    distance_factor: float = 3.0
    min_cells: int = 4
    inlier_factor: float = 3.0
    outline_cell: float = 0.02

    def __post_init__(self) -> None:
        if int(self.cell) < 3:
            raise InputError(f"is {self.cell}", field="cell", expected="an integer >= 3")
        if not 0 < self.angle_deg < 90:
            raise InputError(f"is {self.angle_deg}", field="angle_deg", expected="0 < angle < 90")

    def noise(self, z: NDArray[np.float64]) -> NDArray[np.float64]:
        """Thickness bound (metres) at range ``z`` (metres)."""
        return self.rms_base + self.rms_quadratic * z * z


def _planes_from_moments(cnt, S, SS):
    """Normals ``(G, 3)`` (pointing away from the origin), rho ``(G,)``, rms ``(G,)``, means."""
    n = np.maximum(cnt, 1.0)
    m = S / n[:, None]
    C = SS / n[:, None, None] - m[:, :, None] * m[:, None, :]
    w, V = np.linalg.eigh(C)
    normal = V[:, :, 0]
    d = np.einsum("gi,gi->g", normal, m)
    flip = d < 0
    normal[flip] *= -1
    d = np.abs(d)
    rms = np.sqrt(np.maximum(w[:, 0], 0.0))
    return normal, d, rms, m, w


def _segment_from_moments(
    idx: NDArray[np.int64],
    P_flat: NDArray[np.float64],
    normal: NDArray[np.float64],
    rho: float,
    centroid: NDArray[np.float64],
    rms: float,
    outline_cell: float,
) -> PlaneSegment:
    """Package inliers as a segment whose TLS plane came from their summed moments."""
    n, r = canonical_plane(normal, float(rho))
    plane = Plane(normal=n, rho=r, centroid=centroid, rms=float(rms), count=len(idx))
    origin, axes = plane_frame(plane)
    step = max(1, len(idx) // 40_000)  # outlines from at most ~40k points (dense grids)
    sub = idx[::step]
    x, y, z = (P_flat[sub, k] for k in range(3))  # 1D gathers, no (N, 3) temporaries
    uv = np.empty((len(sub), 2))
    for k in range(2):
        a = axes[k]
        uv[:, k] = x * a[0] + y * a[1] + z * a[2] - float(a @ origin)
    outline, area = outline_from_points(uv, outline_cell)
    return PlaneSegment(plane=plane, inliers=idx.astype(np.int64), outline=outline, area=area)


def extract_planes_organized(
    points: ArrayLike, settings: ExtractionSettings | None = None
) -> ExtractionResult:
    """Planes of an organised point grid (depth image back-projected, organised PCD, scan grid).

    Parameters
    ----------
    points : (H, W, 3) array
        Points in the sensor frame, metres; NaN (or all-zero rows) = no measurement. Depth-like
        range for the noise model is the distance from the origin.
    settings : ExtractionSettings, optional

    Returns
    -------
    ExtractionResult
        ``labels`` is ``(H, W)``; inlier indices are ``row * W + col``.
    """
    s = settings or ExtractionSettings()
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 3 or P.shape[2] != 3:
        raise InputError(
            f"has shape {P.shape}", field="points", expected="(H, W, 3) organised grid"
        )
    H, W = P.shape[:2]
    c = int(s.cell)
    hc, wc = H // c, W // c
    labels = -np.ones((H, W), np.int64)
    if hc == 0 or wc == 0:
        return ExtractionResult((), labels)
    px, py, pz = P[..., 0], P[..., 1], P[..., 2]
    valid = (
        np.isfinite(px) & np.isfinite(py) & np.isfinite(pz) & ((px != 0) | (py != 0) | (pz != 0))
    )
    Pc = P[: hc * c, : wc * c]
    vc = valid[: hc * c, : wc * c]
    # 1. patch moments: block sums of 1, x, y, z, xx, xy, xz, yy, yz, zz - one contiguous 2D
    #    image per quantity, rows of a patch summed first, then columns (exact in float64)
    gx, gy, gz = np.where(vc, np.moveaxis(Pc, 2, 0), 0.0)  # one pass, contiguous planes

    def block_sum(a: NDArray[np.float64]) -> NDArray[np.float64]:
        return a.reshape(hc, c, wc * c).sum(axis=1).reshape(hc, wc, c).sum(axis=2).ravel()

    cnt = block_sum(vc.astype(np.float64))
    S = np.stack([block_sum(gx), block_sum(gy), block_sum(gz)], axis=1)
    iu = np.array([0, 0, 0, 1, 1, 2]), np.array([0, 1, 2, 1, 2, 2])
    xyz = (gx, gy, gz)
    Q = np.stack([block_sum(xyz[a] * xyz[b]) for a, b in zip(*iu, strict=True)], axis=1)
    SS = np.empty((hc * wc, 3, 3))
    SS[:, iu[0], iu[1]] = Q
    SS[:, iu[1], iu[0]] = Q
    # 2. planar patches
    normal, d, rms, mean, _ = _planes_from_moments(cnt, S, SS)
    z = np.linalg.norm(mean, axis=1)
    bound = s.noise(z)
    planar = (cnt >= s.min_fill * c * c) & (rms < bound)
    # 3. region growing on the patch graph
    cos_t = np.cos(np.radians(s.angle_deg))
    ids = np.arange(hc * wc).reshape(hc, wc)
    pairs = np.concatenate(
        [
            np.stack([ids[:, :-1].ravel(), ids[:, 1:].ravel()], axis=1),
            np.stack([ids[:-1, :].ravel(), ids[1:, :].ravel()], axis=1),
        ]
    )

    def edges_ok(keep: NDArray[np.bool_]) -> NDArray[np.int64]:
        a, b = pairs[:, 0], pairs[:, 1]
        ok = keep[a] & keep[b]
        ok &= np.einsum("ei,ei->e", normal[a], normal[b]) > cos_t
        tol = s.distance_factor * np.maximum(bound[a], bound[b])
        ok &= np.abs(np.einsum("ei,ei->e", normal[a], mean[b]) - d[a]) < tol
        ok &= np.abs(np.einsum("ei,ei->e", normal[b], mean[a]) - d[b]) < tol
        return pairs[ok]

    def regions(keep: NDArray[np.bool_]) -> tuple[int, NDArray[np.int64]]:
        e = edges_ok(keep)
        g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(hc * wc, hc * wc))
        n_comp, comp = connected_components(g, directed=False)
        comp = np.where(keep, comp, -1)
        sizes = np.bincount(comp[comp >= 0], minlength=n_comp)
        big = sizes >= s.min_cells
        remap = -np.ones(n_comp, np.int64)
        remap[big] = np.arange(big.sum())
        comp = np.where(comp >= 0, remap[np.maximum(comp, 0)], -1)
        return int(big.sum()), comp

    def region_planes(n_reg, comp):
        sel = comp >= 0
        g = comp[sel]
        rc = np.bincount(g, cnt[sel], minlength=n_reg)
        rS = np.stack([np.bincount(g, S[sel, k], minlength=n_reg) for k in range(3)], axis=1)
        rSS = np.zeros((n_reg, 3, 3))
        np.add.at(rSS, g, SS[sel])
        return _planes_from_moments(rc, rS, rSS)

    n_reg, comp = regions(planar)
    if n_reg == 0:
        return ExtractionResult((), labels)
    # 4. prune patches that disagree with their region's refit plane, then regroup
    rn, rd, _, _, _ = region_planes(n_reg, comp)
    r = np.maximum(comp, 0)
    agree = (np.einsum("gi,gi->g", normal, rn[r]) > cos_t) & (
        np.abs(np.einsum("gi,gi->g", rn[r], mean) - rd[r]) < s.distance_factor * bound
    )
    n_reg, comp = regions(planar & (comp >= 0) & agree)
    if n_reg == 0:
        return ExtractionResult((), labels)
    rn, rd, _, rmean, _ = region_planes(n_reg, comp)
    # merge coplanar regions (e.g. a wall cut in two by an object in front of it)
    rz = np.linalg.norm(rmean, axis=1)
    rtol = s.distance_factor * s.noise(rz)
    same = (rn @ rn.T > cos_t) & (
        np.abs(np.einsum("ai,bi->ab", rn, rmean) - rd[:, None])
        < np.maximum(rtol[:, None], rtol[None, :])
    )
    same &= same.T
    n_m, merged = connected_components(same.astype(np.int8), directed=False)
    comp = np.where(comp >= 0, merged[np.maximum(comp, 0)], -1)
    n_reg = n_m
    rn, rd, _, _, _ = region_planes(n_reg, comp)
    # 5. boundary refinement at pixel level: pixels of the region's patches and of the patches
    #    bordering them join the plane when close enough to it
    #    (every pixel of a region's patches is tested against its plane in one pass; the pixels
    #    of the patches bordering a region are also tested against it, the closest plane wins)
    cellmap = comp.reshape(hc, wc)
    lab_c = labels[: hc * c, : wc * c].reshape(hc, c, wc, c)
    vcb = vc.reshape(hc, c, wc, c)
    vblocks = vcb.transpose(0, 2, 1, 3)
    # interior: every pixel against its own region's plane, in one pass
    k_cell = np.maximum(cellmap, 0)
    nx, ny, nz = (rn[k_cell][:, None, :, None, k] for k in range(3))  # (hc, 1, wc, 1) each
    xb, yb, zb = (a.reshape(hc, c, wc, c) for a in (gx, gy, gz))  # contiguous, zeros where invalid
    d4 = np.abs(xb * nx + yb * ny + zb * nz - rd[k_cell][:, None, :, None])
    r4 = np.sqrt(xb * xb + yb * yb + zb * zb)
    ok4 = vcb & (cellmap >= 0)[:, None, :, None] & (d4 < s.inlier_factor * s.noise(r4))
    lab_c[...] = np.where(ok4, cellmap[:, None, :, None], -1)
    d_in = d4.transpose(0, 2, 1, 3)  # (hc, wc, c, c) views for the ring step
    ok_in = ok4.transpose(0, 2, 1, 3)
    # ring: every (bordering patch, region) pair at once; per pixel the closest plane wins
    # among the patch's own region (interior pass above) and the regions it borders
    # (patch, region) pairs: the regions among a patch's 8 neighbours other than its own
    padded = np.pad(cellmap, 1, constant_values=-1)
    nb = np.stack(
        [
            padded[1 + di : 1 + di + hc, 1 + dj : 1 + dj + wc]
            for di in (-1, 0, 1)
            for dj in (-1, 0, 1)
        ]
    ).reshape(9, -1)
    own_l = cellmap.ravel()
    pair_ok = (nb >= 0) & (nb != own_l[None, :])
    cell_idx = np.broadcast_to(np.arange(hc * wc), nb.shape)[pair_ok]
    pair_key = np.unique(cell_idx * (n_reg + 1) + nb[pair_ok])  # sorted by cell, then region
    rc_, rk_ = np.divmod(pair_key, n_reg + 1)  # patch, bordering region
    if len(rc_):
        U, first, per = np.unique(rc_, return_index=True, return_counts=True)
        slot = np.arange(len(rc_)) - np.repeat(first, per) + 1  # 0 = the patch's own region
        gpos = np.repeat(np.arange(len(U)), per)
        ci, cj = np.divmod(rc_, wc)
        # gathers of the ring patches only, per coordinate (contiguous (hc, c, wc, c) images)
        xr, yr, zr, rr = (a.transpose(0, 2, 1, 3)[ci, cj] for a in (xb, yb, zb, r4))
        with np.errstate(invalid="ignore"):
            dist = np.abs(
                xr * rn[rk_, 0, None, None]
                + yr * rn[rk_, 1, None, None]
                + zr * rn[rk_, 2, None, None]
                - rd[rk_, None, None]
            )
            z = rr
            ok = vblocks[ci, cj] & (dist < s.inlier_factor * s.noise(z))
        ui, uj = np.divmod(U, wc)
        Dd = np.full((len(U), int(per.max()) + 1, c, c), np.inf, np.float32)  # ranking only
        Kd = np.full(Dd.shape, -1, np.int32)
        oin = ok_in[ui, uj]
        Dd[:, 0] = np.where(oin, d_in[ui, uj], np.inf)
        Kd[:, 0] = np.where(oin, cellmap[ui, uj][:, None, None], -1)
        Dd[gpos, slot] = np.where(ok, dist, np.inf)
        Kd[gpos, slot] = np.where(ok, rk_[:, None, None], -1)
        win = np.argmin(Dd, axis=1)[:, None]
        lab_c[ui, :, uj, :] = np.take_along_axis(Kd, win, axis=1)[:, 0]
    labels[: hc * c, : wc * c] = lab_c.reshape(hc * c, wc * c)
    # 6. final planes from the moments of their pixels (one weighted bincount per quantity),
    #    inlier lists by one stable sort of the labels (radix sort for 16-bit labels)
    flat = labels.ravel()
    lc = lab_c.reshape(hc * c, wc * c).ravel()
    sel = lc >= 0
    g = lc[sel]
    fx, fy, fz = (a.ravel()[sel] for a in (gx, gy, gz))
    n_pix = np.bincount(g, minlength=n_reg).astype(np.float64)
    fS = np.stack([np.bincount(g, a, minlength=n_reg) for a in (fx, fy, fz)], axis=1)
    fQ = np.stack(
        [
            np.bincount(g, (fx, fy, fz)[a] * (fx, fy, fz)[b], minlength=n_reg)
            for a, b in zip(*iu, strict=True)
        ],
        axis=1,
    )
    fSS = np.empty((n_reg, 3, 3))
    fSS[:, iu[0], iu[1]] = fQ
    fSS[:, iu[1], iu[0]] = fQ
    fn, frho, frms, fmean, _ = _planes_from_moments(n_pix, fS, fSS)
    P_flat = P.reshape(-1, 3)
    key = flat.astype(np.int16) if n_reg < 32000 else flat
    order = np.argsort(key, kind="stable")
    bounds = np.searchsorted(key[order], np.arange(n_reg + 1))
    segs = []
    for k in range(n_reg):
        if n_pix[k] < s.min_cells * c * c * s.min_fill:
            continue
        idx = order[bounds[k] : bounds[k + 1]]
        segs.append(
            _segment_from_moments(idx, P_flat, fn[k], frho[k], fmean[k], frms[k], s.outline_cell)
        )
    segs.sort(key=lambda sg: -sg.plane.count)
    labels = -np.ones(H * W, np.int64)
    for k, sg in enumerate(segs):
        labels[sg.inliers] = k
    log.debug(
        "organised extraction: %d planar patches of %d, %d planes",
        int(planar.sum()),
        hc * wc,
        len(segs),
    )
    return ExtractionResult(tuple(segs), labels.reshape(H, W))
