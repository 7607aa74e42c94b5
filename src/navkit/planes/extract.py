"""Plane extraction: organised grids (CAPE-like cell region growing) and unorganised clouds.

Organised input (depth image back-projected, organised PCD, a range-scan grid), in the spirit of
CAPE (Proenca & Gao, 2018, "Fast cylinder and plane extraction from depth cameras for visual
odometry"):

1. cut the grid into ``cell x cell`` patches and accumulate their moments (count, mean, scatter)
   in one pass of block reductions, in float32 on coordinates centred per patch;
2. a patch is *planar* when it is nearly complete and its PCA thickness (smallest eigenvalue,
   closed form for all patches at once) is below a depth-dependent noise bound
   ``rms_base + rms_quadratic * r^2``;
3. neighbouring planar patches are joined when their normals agree and each centroid lies on the
   other's plane (region growing = connected components of that cell graph, drawn as an image
   for ``cv2.connectedComponents``);
4. each region is refit from its summed moments; patches that disagree with the region's plane are
   dropped and the regions recomputed; coplanar regions are merged;
5. boundary refinement (CAPE): the patches *inside* a region (all eight neighbours in the same
   region) are assigned wholesale - their valid pixels are inliers and their moments enter the
   refit as they are; only the pixels of the patches at a region's border and of the patches
   bordering it are tested against the planes (distance below ``inlier_factor`` x the noise
   bound; the closest plane wins). ``refine="full"`` tests every pixel of every region instead;
6. each plane is refit by total least squares from the moments of its inliers (interior patches
   + boundary pixels); its outline is rasterised in the plane from the densely sampled interior
   patches (one quadrilateral each) and a strided sample of the other pixels - not from all
   inliers; corners and samples of all planes are gathered at once, only the rasterisation runs
   per plane. Each plane's inlier list is searched in the rows of the 8-bit label image its
   region can reach.

Temporaries are kept per thread between calls (:class:`_Workspace`); the results never share
memory with them.

The hot passes - the patch moments, the patches' planes, the planar and edge tests, the
connected components (union-find instead of OpenCV on the cell-graph image; the same numbering),
the border candidates, the border refinement with its outline samples, the label image with the
inliers, the outline samples and rasters - run as compiled kernels (``navkit.planes._kernels*``,
Numba); the NumPy versions here are their oracle (``_extract(..., compiled=False)``;
``tests/planes/test_kernels.py``, ``docs/kernels.md``) and give the same result bit for bit on
any CPU: both run the same IEEE operations in the same order - float64 sums one term
after the other (:func:`_sum_rows`, the weighted ``bincount`` of the mixed patches' pixels; no
BLAS product), three-term dot products left to right (:func:`_dot3`; no ``einsum``), the
closed-form eigenvalue's ``acos`` / ``cos`` with Cephes' arithmetic
(:mod:`navkit.geometry.angles`; not NumPy's SIMD or libm's), no ``fastmath`` in the kernels.
LAPACK runs only for a matrix with a repeated smallest eigenvalue, in both paths on the same
matrix.

Unorganised clouds: :mod:`navkit.planes.extract_cloud` (sequential RANSAC with vectorised
hypotheses, a TLS refit, and the largest connected part of the inliers kept per plane); its names
are re-exported here.
"""

from __future__ import annotations

import logging

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError
from navkit.geometry.fitting import Plane, canonical_plane
from navkit.jit import kernels_enabled
from navkit.planes.extract_cloud import CloudExtractionSettings, extract_planes_cloud
from navkit.planes.moments import (
    _DEFAULT_SETTINGS,
    _IU,
    _MAX_CELL,
    _NM,
    _WS,
    ExtractionSettings,
    _Border,
    _kernels,
    _moment_rows,
    _outline_kernels,
    _patch_moments,
    _Patches,
    _planes_from_rows,
    _sample_stride,
    _stride_masks,
    _sum_rows,
    smallest_eigenpairs,
)
from navkit.planes.outlines import _label_image_numpy, _outlines
from navkit.planes.regions import _border_patches, _grow_regions
from navkit.planes.segments import (
    ExtractionResult,
    PlaneSegment,
)

__all__ = [
    "CloudExtractionSettings",
    "ExtractionSettings",
    "extract_planes_cloud",
    "extract_planes_organized",
    "smallest_eigenpairs",
]

log = logging.getLogger(__name__)


def _refine_border(
    pt: _Patches,
    comp: NDArray[np.int64],
    ids: NDArray[np.int64],
    cand: NDArray[np.int64],
    rn: NDArray[np.float64],
    rd: NDArray[np.float64],
    n_reg: int,
    hc: int,
    wc: int,
    c: int,
    raster: float,
    compiled: bool = True,
) -> _Border:
    """Step 5: the pixels of the border patches against their candidate planes.

    A pixel joins the closest candidate plane whose distance is below ``inlier_factor`` x the
    noise bound at its range. Distances use the centred coordinates: ``n . x - rho =
    n . d + (n . ref - rho)``, one offset per (patch, plane). A region patch whose valid pixels
    all stay in its own region is *complete* (its patch moments stand); the pixels of the other
    (*mixed*) patches give per-pixel moments, grouped by (patch, plane), summed in float64 (the
    products of the float32 coordinates are exact in float64). ``compiled``: one loop over the
    border pixels (:func:`navkit.planes._kernels.refine_pixels`); else NumPy passes per
    candidate slot (the oracle: the same labels, and the same moments bit for bit - per (patch,
    candidate) the pixels' float64 terms added one after the other in raster order, then the
    rows per region in (patch, candidate) order, as the kernel adds them).
    """
    B = len(cand)
    n32 = rn.astype(np.float32)
    rho32 = rd.astype(np.float32)
    own = comp[ids]
    ltype = np.int16 if n_reg < 32767 else np.int32
    if compiled:  # the offsets and strides below are computed in the kernel, the same floats
        label = np.empty((B, c, c), ltype)  # the kernel writes every pixel's label
        complete, M, cpoints, cregion = _kernels().refine_pixels(
            pt.XP, pt.ref, pt.tol_scale, pt.tol_base, ids, own, cand, n32, rho32, pt.M,
            float(raster), wc, c, label, n_reg,
        )  # fmt: skip
        return _Border(ids, label, complete, M, cpoints, cregion)
    ci, cj = np.divmod(ids, wc)
    ref = pt.ref[ids]  # (B, 3) float32
    label = np.full((B, c, c), -1, ltype)
    # n . ref - rho per (patch, candidate), float32 (-1 slots: unused)
    kc = np.maximum(cand, 0)
    nk = n32[kc]  # (B, m, 3)
    off = nk[..., 0] * ref[:, None, 0] + nk[..., 1] * ref[:, None, 1]
    off += nk[..., 2] * ref[:, None, 2]
    off -= rho32[kc]
    complete, G = _refine_border_numpy(pt, ids, ci, cj, own, cand, off, n32, label, hc, wc, c)
    mixed = np.flatnonzero(~complete)
    M = np.zeros((n_reg, _NM))
    points = np.zeros((3, 0), np.float32)
    point_region = np.zeros(0, label.dtype)
    if len(mixed):
        Bm = len(mixed)
        lm = label[mixed].reshape(Bm, -1)
        cm = cand[mixed]
        used = np.flatnonzero(G[:, 0] > 0)
        g = G[used]
        Sdd = np.empty((len(used), 3, 3))
        Sdd[:, _IU[0], _IU[1]] = g[:, 4:]
        Sdd[:, _IU[1], _IU[0]] = g[:, 4:]
        gref = np.repeat(ref[mixed].astype(np.float64), cm.shape[1], axis=0)[used]
        M = _sum_rows(cm.ravel()[used], n_reg, _moment_rows(g[:, 0], gref, g[:, 1:4], Sdd))
        # the pixels of the mixed patches per region for the outlines, every t-th row / column
        # (lattice masks per stride looked up, one index list for all three coordinates)
        t = _sample_stride(pt.M[ids[mixed]], c, raster)
        flat = np.flatnonzero((lm >= 0) & _stride_masks(c)[t])
        bi, pix = np.divmod(flat, c * c)
        pr, pq = np.divmod(pix, c)
        point_region = lm.ravel()[flat]
        rows, cols = ci[mixed][bi] * c + pr, cj[mixed][bi] * c + pq
        points = pt.D[:, rows, cols]  # type: ignore[index]
        points += np.take(np.ascontiguousarray(ref[mixed].T), bi, axis=1)
    return _Border(
        ids=ids, label=label, complete=complete, M=M, points=points, point_region=point_region
    )


def _refine_border_numpy(
    pt: _Patches,
    ids: NDArray[np.int64],
    ci: NDArray[np.int64],
    cj: NDArray[np.int64],
    own: NDArray[np.int64],
    cand: NDArray[np.int64],
    off: NDArray[np.float32],
    n32: NDArray[np.float32],
    label: NDArray[np.signedinteger],
    hc: int,
    wc: int,
    c: int,
) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
    """NumPy oracle of :func:`navkit.planes._kernels.refine_pixels`: fills ``label`` and returns
    ``complete (B,)`` and the float64 moments ``(Bm * m, 10)`` of the mixed patches' pixels per
    (patch, candidate slot)."""
    B, m = cand.shape
    assert pt.D is not None and pt.tol is not None
    d = [pt.D[k].reshape(hc, c, wc, c)[ci, :, cj, :] for k in range(3)]  # (B, c, c) each
    tol = pt.tol.reshape(hc, c, wc, c)[ci, :, cj, :]  # -1 where invalid: never an inlier
    e = (slice(None), None, None)
    best_d = _WS.get("best_d", (B, c, c), np.float32)
    best_d.fill(np.inf)
    dist_ws = _WS.get("dist", (B, c, c), np.float32)
    tmp_ws = _WS.get("dist_tmp", (B, c, c), np.float32)
    better_ws = _WS.get("better", (B, c, c), np.bool_)
    ok_ws = _WS.get("ok", (B, c, c), np.bool_)
    n_with = (cand >= 0).sum(axis=0)  # patches with more than `slot` candidates: a prefix
    for slot in range(m):
        b = int(n_with[slot])
        k = cand[:b, slot]
        nk = n32[k]
        dist, tmp, better, ok = dist_ws[:b], tmp_ws[:b], better_ws[:b], ok_ws[:b]
        np.multiply(d[0][:b], nk[:, 0][e], out=dist)
        for a in (1, 2):
            np.multiply(d[a][:b], nk[:, a][e], out=tmp)
            dist += tmp
        dist += off[:b, slot][e]
        np.abs(dist, out=dist)
        np.less(dist, tol[:b], out=better)
        better &= np.less(dist, best_d[:b], out=ok)
        np.copyto(best_d[:b], dist, where=better)
        np.copyto(label[:b], k.astype(label.dtype)[e], where=better)
    complete = (own >= 0) & np.all((label == own[e]) | (tol < 0), axis=(1, 2))
    # per-pixel moments of the mixed patches per (patch, candidate slot): the labelled pixels'
    # [1, d, d d^T] in float64 (the products of float32 values are exact) summed by a weighted
    # bincount per quantity - one addition per pixel from +0, in raster order within a patch,
    # as the kernel adds them
    mixed = np.flatnonzero(~complete)
    Bm = len(mixed)
    G = np.zeros((Bm * m, 10))
    if Bm == 0:
        return complete, G
    lm = label[mixed].reshape(Bm, c * c)
    cm = cand[mixed]
    slot = np.argmax(lm[:, None, :] == cm[:, :, None], axis=1)  # (Bm, c^2), a label's slot
    bi, pix = np.nonzero(lm >= 0)  # raster order within a patch, patches in order
    gid = bi * m + slot[bi, pix]
    q = [a[mixed].reshape(Bm, c * c)[bi, pix].astype(np.float64) for a in d]
    G[:, 0] = np.bincount(gid, minlength=Bm * m)
    for a in range(3):
        G[:, 1 + a] = np.bincount(gid, weights=q[a], minlength=Bm * m)
    for j, (a_, b_) in enumerate(zip(*_IU, strict=True)):
        G[:, 4 + j] = np.bincount(gid, weights=q[a_] * q[b_], minlength=Bm * m)
    return complete, G


# ------------------------------------------------------------------------------ main entry


def extract_planes_organized(
    points: ArrayLike, settings: ExtractionSettings | None = None
) -> ExtractionResult:
    """Planes of an organised point grid (depth image back-projected, organised PCD, scan grid).

    Parameters
    ----------
    points : (H, W, 3) array
        Points in the sensor frame, metres; NaN (or all-zero rows) = no measurement. Depth-like
        range for the noise model is the distance from the origin. Rows / columns beyond the last
        whole ``cell`` are not used.
    settings : ExtractionSettings, optional

    Returns
    -------
    ExtractionResult
        ``labels`` is ``(H, W)``; inlier indices are ``row * W + col``, increasing.
    """
    return _extract(points, settings, compiled=kernels_enabled())


def _extract(
    points: ArrayLike, settings: ExtractionSettings | None, *, compiled: bool
) -> ExtractionResult:
    """:func:`extract_planes_organized` with the compiled kernels (``compiled=True``; the public
    function passes the process's policy, :func:`navkit.jit.kernels_enabled`) or their NumPy
    oracles (the tests compare the two)."""
    s = settings or _DEFAULT_SETTINGS  # validated once (check_settings costs ~50 us a call)
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 3 or P.shape[2] != 3:
        raise InputError(
            f"has shape {P.shape}", field="points", expected="(H, W, 3) organised grid"
        )
    H, W = P.shape[:2]
    c = int(s.cell)
    hc, wc = H // c, W // c
    if hc == 0 or wc == 0:
        return ExtractionResult((), -np.ones((H, W), np.int64))
    compiled = compiled and c <= _MAX_CELL
    if compiled:
        P = np.ascontiguousarray(P)  # the kernels' layout (a no-op for a fresh grid)
    # 1. patch moments
    pt = _patch_moments(P, s, hc, wc, compiled)
    # 2.-4. planar patches, region growing, pruning, merging
    n_reg, comp, n_planar, reg_planes = _grow_regions(pt.M, hc, wc, s, compiled)
    if n_reg == 0:
        return ExtractionResult((), -np.ones((H, W), np.int64))
    # 5. wholesale patches; the others pixel by pixel against the region planes
    if reg_planes is None:  # regions were merged: their planes anew
        rn, rd, _, _ = _planes_from_rows(_sum_rows(comp, n_reg, pt.M))
    else:
        rn, rd = reg_planes
    cellmap = comp.reshape(hc, wc)
    if compiled:
        wholesale, ids, cand = _kernels().border_patches(cellmap, s.refine == "full")
    else:
        wholesale, ids, cand = _border_patches(cellmap, s.refine == "full")
    bd = _refine_border(pt, comp, ids, cand, rn, rd, n_reg, hc, wc, c, s.outline_cell, compiled)
    wholesale = wholesale.ravel()
    wholesale[ids[bd.complete]] = True
    # 6. final planes from the moments of their inliers: wholesale patches + mixed pixels
    whole = np.where(wholesale, comp, -1)
    Mf = _kernels().sum_rows(whole, n_reg, pt.M) if compiled else _sum_rows(whole, n_reg, pt.M)
    Mf += bd.M
    normal, rho, rms, mean = _planes_from_rows(Mf, compiled, rayleigh=True)
    count = np.rint(Mf[:, 0]).astype(np.int64)
    keep = np.flatnonzero(count >= s.min_cells * c * c * s.min_fill)
    keep = keep[np.argsort(-count[keep], kind="stable")]  # segments by decreasing inlier count
    new_id = np.full(n_reg + 1, -1, np.int64)  # region + 1 -> segment index
    new_id[keep + 1] = np.arange(len(keep))
    mixed = ~bd.complete
    segmap = new_id[cellmap + 1]
    lab_cell = new_id[np.where(wholesale, comp, -1) + 1].reshape(hc, wc)
    if compiled:
        labels, inl, cuts = _outline_kernels().label_image(
            pt.valid, lab_cell, ids, bd.complete, bd.label, new_id, count[keep], H, W
        )
        inliers = [inl[cuts[k] : cuts[k + 1]] for k in range(len(keep))]
    else:
        labels, inliers = _label_image_numpy(
            pt.valid, lab_cell, ids, mixed, bd, new_id, segmap, H, W
        )
    kept = count[keep]
    cn, cr = _canonical_planes(normal[keep], rho[keep])
    planes = [
        Plane(normal=cn[i], rho=float(cr[i]), centroid=mean[k], rms=float(rms[k]), count=int(n))
        for i, (k, n) in enumerate(zip(keep, kept, strict=True))
    ]
    outlines = _outlines(
        pt,
        labels,
        wholesale.reshape(hc, wc),
        segmap,
        bd.points,
        bd.point_region,
        new_id,
        planes,
        c,
        s.outline_cell,
        compiled,
    )
    segs = [
        PlaneSegment(
            plane=plane,
            inliers=inl_k,
            outline=ol,
            area=area,
        )
        for plane, inl_k, (ol, area) in zip(planes, inliers, outlines, strict=True)
    ]
    log.debug(
        "organised extraction: %d planar patches of %d, %d refined (%d pixel by pixel), %d planes",
        n_planar,
        hc * wc,
        len(ids),
        int(mixed.sum()),
        len(segs),
    )
    return ExtractionResult(tuple(segs), labels)


def _canonical_planes(
    normal: NDArray[np.float64], rho: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`navkit.geometry.fitting.canonical_plane` of every row ``(K, 3)``, ``(K,)`` at once, the
    same bits on every CPU (the same IEEE operations in the same order: three products and two
    sums, a square root, two divisions). A zero or non-finite normal or a plane
    through the origin (``_orient``'s special cases) takes ``canonical_plane`` row by row."""
    n0, n1, n2 = normal[:, 0], normal[:, 1], normal[:, 2]
    norm = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = rho / norm
    if not (np.all(np.isfinite(norm) & (norm > 0)) and np.all(r > 1e-12)):
        rows = [canonical_plane(n, float(d)) for n, d in zip(normal, rho, strict=True)]
        return np.array([n for n, _ in rows]).reshape(-1, 3), np.array([d for _, d in rows])
    return normal / norm[:, None], r
