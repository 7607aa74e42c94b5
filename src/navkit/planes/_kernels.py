"""Compiled kernels of the organised plane extraction (:mod:`navkit.planes.extract`).

Each kernel fuses what several NumPy passes over a 640 x 480 grid do in
:mod:`navkit.planes.extract`; the NumPy versions stay there as the oracle the tests compare
with (``tests/planes/test_kernels.py``). The float32 block sums reproduce NumPy's summation order
exactly - rows of a patch added one after the other per column, then the ``c`` column sums by
NumPy's pairwise summation (eight running sums, combined as ``((r0 + r1) + (r2 + r3)) + ((r4 +
r5) + (r6 + r7))``, then the remainder) - so the patch moments, the planar test and the region
growing get the same bits with either backend. The float64 arithmetic is the twins' too, term
for term: sums one term after the other from +0 (:func:`sum_rows`, the mixed patches' pixel
sums in :func:`refine_pixels`), three-term dot products left to right (:func:`_dot3`), the
closed-form eigenvalue's ``acos`` / ``cos`` with Cephes' arithmetic (:func:`acos_scalar`,
:func:`cos_scalar`; :mod:`navkit.geometry.angles` in the twins). No kernel uses ``fastmath``:
LLVM then neither reassociates nor contracts a product and a sum into a fused multiply-add, so
a whole extraction gives the twins' bits on any CPU (``tests/planes/test_kernels.py``).

The last step's kernels - the label image and the outlines - are in
:mod:`navkit.planes._kernels_outline`, under the same contract.

Compiled with Numba (``@njit(cache=True)``: machine code cached on disk beside this module, or
in ``NUMBA_CACHE_DIR``); imported lazily by :mod:`navkit.planes.extract` on the first organised
extraction, so ``import navkit`` does not pay for Numba.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from navkit.geometry.angles import (
    ASIN_P,
    ASIN_Q,
    ASIN_R,
    ASIN_S,
    ASIN_SPLIT,
    ASIN_TINY,
    COS_C,
    FOUR_OVER_PI,
    MOREBITS,
    PI4A,
    PI4B,
    PI4C,
    PI_4,
    SIN_C,
)

MAX_CELL = 128  # NumPy's PW_BLOCKSIZE: a patch's row sums are one pairwise block up to it

TWINS = {
    "acos_scalar": "navkit.geometry.angles.acos",
    "border_patches": "navkit.planes.regions._border_patches",
    "cell_components": "navkit.planes.regions._grow_regions",
    "cos_scalar": "navkit.geometry.angles.cos",
    "dense_components": "navkit.planes.regions._dense_components",
    "patch_graph": "navkit.planes.regions._grow_regions",
    "patch_moments": "navkit.planes.moments._patch_moments",
    "plane_rows": "navkit.planes.moments._planes_from_rows",
    "prune_merge": "navkit.planes.regions._prune_merge",
    "refine_pixels": "navkit.planes.extract._refine_border_numpy",
    "sum_rows": "navkit.planes.moments._sum_rows",
}
"""Each public kernel -> its NumPy twin (``patch_graph``: the planar and edge tests of
``_grow_regions``' NumPy path; ``cell_components``: its components of the cell graph by
``cv2.connectedComponents``). ``acos_scalar`` and ``cos_scalar`` are the scalar functions
:func:`plane_rows` calls, compared with :mod:`navkit.geometry.angles` value by value."""


@njit(cache=True)
def _pairwise32(a: np.ndarray, n: int) -> np.float32:  # pragma: no cover - compiled
    """NumPy's pairwise float32 sum of ``a[:n]``, ``n <= 128`` (same order, same bits)."""
    if n < 8:
        res = np.float32(0.0)
        for i in range(n):
            res = np.float32(res + a[i])
        return res
    r0 = a[0]
    r1 = a[1]
    r2 = a[2]
    r3 = a[3]
    r4 = a[4]
    r5 = a[5]
    r6 = a[6]
    r7 = a[7]
    i = 8
    while i < n - (n % 8):
        r0 = np.float32(r0 + a[i])
        r1 = np.float32(r1 + a[i + 1])
        r2 = np.float32(r2 + a[i + 2])
        r3 = np.float32(r3 + a[i + 3])
        r4 = np.float32(r4 + a[i + 4])
        r5 = np.float32(r5 + a[i + 5])
        r6 = np.float32(r6 + a[i + 6])
        r7 = np.float32(r7 + a[i + 7])
        i += 8
    res = np.float32(
        np.float32(np.float32(r0 + r1) + np.float32(r2 + r3))
        + np.float32(np.float32(r4 + r5) + np.float32(r6 + r7))
    )
    while i < n:
        res = np.float32(res + a[i])
        i += 1
    return res


@njit(cache=True)
def _raw_row(
    out: np.ndarray, n: float, ref: np.ndarray, sd: np.ndarray, ssd: np.ndarray
) -> None:  # pragma: no cover - compiled
    """One raw float64 moment row ``out (13,)`` - count, sums, sums of outer products - from the
    moments about a reference point: ``n``, ``ref (3,)``, the sums of the coordinates minus it
    ``sd (3,)`` and of their products ``ssd (6,)`` (xx, xy, xz, yy, yz, zz). The operations of
    ``moments._moment_rows`` in its order: ``S = n ref + Sd``, ``SS = ((SSd + ref Sd^T) + Sd
    ref^T) + (n ref) ref^T``."""
    out[0] = n
    for a in range(3):
        out[1 + a] = n * ref[a] + sd[a]
    for a in range(3):
        for b in range(3):
            lo = min(a, b)
            hi = max(a, b)
            ss = ssd[lo * 3 - (lo * (lo - 1)) // 2 + (hi - lo)]
            out[4 + 3 * a + b] = ((ss + ref[a] * sd[b]) + ref[b] * sd[a]) + (n * ref[a]) * ref[b]


@njit(cache=True)
def patch_moments(
    P: np.ndarray, hc: int, wc: int, c: int, valid: np.ndarray, XP: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Step 1 of the extraction, one band of ``c`` rows at a time (see
    ``moments._patch_moments``).

    Fills ``valid (hc c, wc c)`` (finite, non-zero range) and ``XP (G, 3, c c)`` (each patch's
    float32 coordinates, 0 where invalid, patch by patch: :func:`refine_pixels` reads the
    border patches from it) and returns per patch the raw float64
    moment row ``(G, 13)`` (count, sums, sums of outer products: the float32 sums about the
    patch's float32 mean converted as ``moments._moment_rows`` does) and that mean ``(G, 3)``.

    The loops run along whole image rows (``wc c`` pixels: long, branch-free loops that LLVM
    vectorises without remainders; per patch they were ``c`` = 20 pixels, 8 + 8 + 4 scalar on
    AVX2, and the first pass, with its stride-3 loads, did not vectorise at all): per image row
    the float64 coordinates are converted to float32 in one flat loop, de-interleaved, zeroed
    where invalid and added to per-column sums; then per patch the column sums give the count
    and the mean (NumPy's pairwise order), and a second sweep of the band adds the centred
    coordinates and their products to per-column sums. The same additions in the same order
    as per patch: the same bits. The band's float32 coordinates (3 c (wc c) floats, ~150 kB)
    stay in cache between the two sweeps. An empty patch's sums are +0, as NumPy's.
    """
    G = hc * wc
    Wc = wc * c
    M = np.empty((G, 13), np.float64)
    ref = np.empty((G, 3), np.float32)
    ref64 = np.empty(3, np.float64)
    sd = np.zeros(3, np.float64)
    ssd = np.zeros(6, np.float64)
    X = np.empty((3, c, Wc), np.float32)  # the band's float32 coordinates, 0 where invalid
    V = np.empty((c, Wc), np.float32)  # its 0 / 1 validity
    col = np.empty((10, Wc), np.float32)  # per-column sums over the band's rows
    mc = np.empty((3, Wc), np.float32)  # each column's patch mean
    nn = np.empty(wc, np.float32)  # the band's patch counts
    buf = np.empty(3 * Wc, np.float32)  # one image row in float32, interleaved
    XP4 = XP.reshape(G, 3, c, c)
    for i in range(hc):
        # pass 1: coordinates and validity; column sums of the count and coordinates (the
        # first row added to 0: the same sums as NumPy's, up to the sign of a zero sum)
        col[:4] = 0.0
        c0 = col[0]
        c1 = col[1]
        c2 = col[2]
        c3 = col[3]
        for r in range(c):
            y = i * c + r
            Pf = P[y].reshape(-1)
            for k in range(3 * Wc):
                buf[k] = np.float32(Pf[k])
            X0 = X[0, r]
            X1 = X[1, r]
            X2 = X[2, r]
            Vr = V[r]
            for x in range(Wc):
                px = buf[3 * x]
                py = buf[3 * x + 1]
                pz = buf[3 * x + 2]
                r2 = np.float32(
                    np.float32(np.float32(px * px) + np.float32(py * py)) + np.float32(pz * pz)
                )
                ok = (r2 > 0) & (r2 < np.inf)
                v = np.float32(1.0) if ok else np.float32(0.0)
                px = px if ok else np.float32(0.0)
                py = py if ok else np.float32(0.0)
                pz = pz if ok else np.float32(0.0)
                X0[x] = px
                X1[x] = py
                X2[x] = pz
                Vr[x] = v
                c0[x] = np.float32(c0[x] + v)
                c1[x] = np.float32(c1[x] + px)
                c2[x] = np.float32(c2[x] + py)
                c3[x] = np.float32(c3[x] + pz)
            vy = valid[y]
            for x in range(Wc):
                vy[x] = Vr[x] != 0
        for j in range(wc):  # the band's coordinates patch by patch (for refine_pixels; 4-D
            q0 = j * c  # indices, no slices: 0.17 ms a frame alone, 0.22 with 1-D slices)
            for a in range(3):
                for r in range(c):
                    for q in range(c):
                        XP4[i * wc + j, a, r, q] = X[a, r, q0 + q]
        for j in range(wc):
            g = i * wc + j
            q0 = j * c
            n = _pairwise32(col[0, q0 : q0 + c], c)
            den = max(n, np.float32(1.0))
            mx = np.float32(_pairwise32(col[1, q0 : q0 + c], c) / den)
            my = np.float32(_pairwise32(col[2, q0 : q0 + c], c) / den)
            mz = np.float32(_pairwise32(col[3, q0 : q0 + c], c) / den)
            ref[g, 0] = mx
            ref[g, 1] = my
            ref[g, 2] = mz
            nn[j] = n
            for q in range(c):
                mc[0, q0 + q] = mx
                mc[1, q0 + q] = my
                mc[2, q0 + q] = mz
        # pass 2: centred coordinates (x 0 / 1 validity) and their products
        col[:] = 0.0
        m0 = mc[0]
        m1 = mc[1]
        m2 = mc[2]
        c4 = col[4]
        c5 = col[5]
        c6 = col[6]
        c7 = col[7]
        c8 = col[8]
        c9 = col[9]
        for r in range(c):
            X0 = X[0, r]
            X1 = X[1, r]
            X2 = X[2, r]
            Vr = V[r]
            for x in range(Wc):
                v = Vr[x]
                dx = np.float32(np.float32(X0[x] - m0[x]) * v)
                dy = np.float32(np.float32(X1[x] - m1[x]) * v)
                dz = np.float32(np.float32(X2[x] - m2[x]) * v)
                c1[x] = np.float32(c1[x] + dx)
                c2[x] = np.float32(c2[x] + dy)
                c3[x] = np.float32(c3[x] + dz)
                c4[x] = np.float32(c4[x] + np.float32(dx * dx))
                c5[x] = np.float32(c5[x] + np.float32(dx * dy))
                c6[x] = np.float32(c6[x] + np.float32(dx * dz))
                c7[x] = np.float32(c7[x] + np.float32(dy * dy))
                c8[x] = np.float32(c8[x] + np.float32(dy * dz))
                c9[x] = np.float32(c9[x] + np.float32(dz * dz))
        for j in range(wc):
            g = i * wc + j
            q0 = j * c
            n = nn[j]
            ref64[0] = ref[g, 0]
            ref64[1] = ref[g, 1]
            ref64[2] = ref[g, 2]
            if n == 0:  # no valid pixel: all sums +0
                sd[:] = 0.0
                ssd[:] = 0.0
            else:
                for k in range(3):
                    sd[k] = _pairwise32(col[1 + k, q0 : q0 + c], c)
                for k in range(6):
                    ssd[k] = _pairwise32(col[4 + k, q0 : q0 + c], c)
            _raw_row(M[g], np.float64(n), ref64, sd, ssd)
    return M, ref


@njit(cache=True, inline="always")
def _patch_stride(
    M: np.ndarray, g: int, c: int, cell: float, sqrt2: float
) -> np.int64:  # pragma: no cover - compiled
    """The pixel stride of patch ``g``'s outline samples from its scatter (moment row ``M[g]``):
    ``moments._sample_stride``'s float64 operations, in the same order."""
    n = max(M[g, 0], 1.0)
    m0 = M[g, 1] / n
    m1 = M[g, 2] / n
    m2 = M[g, 3] / n
    tr = M[g, 4] / n - m0 * m0 + M[g, 8] / n - m1 * m1 + M[g, 12] / n - m2 * m2
    spacing = np.sqrt(6.0 * max(tr, 0.0)) / c
    t = np.floor(cell / (sqrt2 * spacing)) if spacing > 0 else np.inf
    t = t if t >= 1.0 else 1.0
    return np.int64(min(t, c))


@njit(cache=True)
def refine_pixels(
    XP: np.ndarray,
    ref: np.ndarray,
    tol_scale: np.float32,
    tol_base: np.float32,
    ids: np.ndarray,
    own: np.ndarray,
    cand: np.ndarray,
    n32: np.ndarray,
    rho32: np.ndarray,
    M: np.ndarray,
    raster: float,
    wc: int,
    c: int,
    label: np.ndarray,
    n_reg: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Step 5, the border patches pixel by pixel (see ``extract._refine_border``).

    ``XP (G, 3, c c)`` the patches' float32 coordinates from :func:`patch_moments` (0 where
    invalid), ``ref (G, 3)`` the patches' float32 means, ``tol_scale r^2 +
    tol_base`` the inlier bound, ``ids (B,)`` patches, ``own (B,)`` their regions (-1 = none),
    ``cand (B, m)`` candidate regions (-1 padded), ``n32 (n_reg, 3)`` float32 normals and
    ``rho32 (n_reg,)`` distances, ``M (G, 13)`` the patch moments and ``raster`` the outline
    cell. Per (patch, candidate) the float32 offset ``n . ref - rho`` and per patch the outline
    samples' stride (``moments._sample_stride``) are computed here as the NumPy path computes
    them (the same float32 / float64 operations in the same order, instead of ~20 NumPy
    calls). The centred float32 coordinates and the bound are recomputed exactly as
    :func:`patch_moments` / the NumPy path define them.
    Fills ``label (B, c, c)`` (closest candidate within the bound, -1 = none; ties keep the
    earlier slot). Returns ``complete (B,)``, the raw float64 moments ``(n_reg, 13)`` of the
    pixels of the incomplete patches per region (per (patch, candidate): the float64 sums of d
    and d d^T, the pixels added one after the other in raster order as the twin's weighted
    ``bincount`` adds them, converted by ``moments._moment_rows``' arithmetic and added in
    (patch, slot) order as ``sum_rows`` adds them) and the outline samples of the incomplete
    patches: their labelled pixels on every ``stride[b]``-th row and column, ``float32(d + ref)``
    ``(3, K)``, and their regions ``(K,)`` (patch by patch, raster order within one).

    A whole patch at a time, in loops over its ``c c`` pixels (400: 50 AVX2 vectors, no
    remainder; a row of 20 pixels was 8 + 8 + 4 scalar): the bound and the centred
    coordinates from the patch's contiguous float32 block written by :func:`patch_moments` (the
    same floats as the grid's rows converted here: an invalid pixel's 0 has range 0 as its NaN
    has none; reading the float64 rows would be ~40 % of the kernel), then one sweep per
    candidate. The mixed patches' sums add only the pixels of
    the candidate (the other pixels added exact zeros before: the same sums).
    """
    B, m = cand.shape
    cc = c * c
    sqrt2 = np.sqrt(2.0)
    off = np.empty(m, np.float32)
    complete = np.empty(B, np.bool_)
    Mreg = np.zeros((n_reg, 13), np.float64)
    row = np.empty(13, np.float64)
    ref64 = np.empty(3, np.float64)
    sd = np.empty(3, np.float64)
    ssd = np.empty(6, np.float64)
    pts = np.empty((3, B * cc), np.float32)
    preg = np.empty(B * cc, np.int64)
    dx = np.empty(cc, np.float32)
    dy = np.empty(cc, np.float32)
    dz = np.empty(cc, np.float32)
    tt = np.empty(cc, np.float32)
    best = np.empty(cc, np.float32)
    lab = np.empty(cc, np.int32)  # 32-bit: as many lanes as the float32 distances
    n_pts = 0
    lflat = label.reshape(-1)
    for b in range(B):  # (no software prefetch: the blocks are contiguous - tried, no gain)
        g = ids[b]
        mx = ref[g, 0]
        my = ref[g, 1]
        mz = ref[g, 2]
        own_b = own[b]
        n_slot = 0
        while n_slot < m and cand[b, n_slot] >= 0:
            n_slot += 1
        for s in range(n_slot):  # n . ref - rho in float32: ((n0 r0 + n1 r1) + n2 r2) - rho
            k = cand[b, s]
            o01 = np.float32(np.float32(n32[k, 0] * mx) + np.float32(n32[k, 1] * my))
            o012 = np.float32(o01 + np.float32(n32[k, 2] * mz))
            off[s] = np.float32(o012 - rho32[k])
        xg = XP[g, 0]
        yg = XP[g, 1]
        zg = XP[g, 2]
        for p in range(cc):
            px = xg[p]
            py = yg[p]
            pz = zg[p]
            r2 = np.float32(
                np.float32(np.float32(px * px) + np.float32(py * py)) + np.float32(pz * pz)
            )
            val = (r2 > 0) & (r2 < np.inf)  # else never an inlier (bound -1)
            tt[p] = np.float32(np.float32(r2 * tol_scale) + tol_base) if val else np.float32(-1)
            dx[p] = np.float32(px - mx) if val else np.float32(0.0)
            dy[p] = np.float32(py - my) if val else np.float32(0.0)
            dz[p] = np.float32(pz - mz) if val else np.float32(0.0)
            best[p] = np.inf
            lab[p] = -1
        for s in range(n_slot):  # closest candidate within the bound; ties keep the earlier
            k32 = np.int32(cand[b, s])
            n0 = n32[k32, 0]
            n1 = n32[k32, 1]
            n2 = n32[k32, 2]
            o = off[s]
            for p in range(cc):
                dist = abs(
                    np.float32(
                        np.float32(
                            np.float32(np.float32(dx[p] * n0) + np.float32(dy[p] * n1))
                            + np.float32(dz[p] * n2)
                        )
                        + o
                    )
                )
                better = (dist < tt[p]) & (dist < best[p])
                best[p] = dist if better else best[p]
                lab[p] = k32 if better else lab[p]
        own32 = np.int32(own_b)
        lb_b = lflat[b * cc : (b + 1) * cc]
        bad = 0  # valid pixels not in the patch's own region
        for p in range(cc):
            lb_b[p] = lab[p]
            bad += (lab[p] != own32) & (tt[p] >= 0)
        ok = own_b >= 0 and bad == 0
        complete[b] = ok
        if ok:
            continue
        # the mixed patch: float64 moments per candidate, its pixels in raster order
        for s in range(n_slot):
            k = cand[b, s]
            k32 = np.int32(k)
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            s3 = 0.0
            s4 = 0.0
            s5 = 0.0
            s6 = 0.0
            s7 = 0.0
            s8 = 0.0
            s9 = 0.0
            for p in range(cc):
                if lab[p] == k32:
                    ex = np.float64(dx[p])
                    ey = np.float64(dy[p])
                    ez = np.float64(dz[p])
                    s0 += 1.0
                    s1 += ex
                    s2 += ey
                    s3 += ez
                    s4 += ex * ex
                    s5 += ex * ey
                    s6 += ex * ez
                    s7 += ey * ey
                    s8 += ey * ez
                    s9 += ez * ez
            if s0 > 0:
                ref64[0] = mx
                ref64[1] = my
                ref64[2] = mz
                sd[0] = s1
                sd[1] = s2
                sd[2] = s3
                ssd[0] = s4
                ssd[1] = s5
                ssd[2] = s6
                ssd[3] = s7
                ssd[4] = s8
                ssd[5] = s9
                _raw_row(row, s0, ref64, sd, ssd)
                for t in range(13):
                    Mreg[k, t] += row[t]
        # outline samples: labelled pixels on every st-th row and column, raster order (st:
        # moments._sample_stride's float64 operations)
        st = _patch_stride(M, g, c, raster, sqrt2)
        for r in range(0, c, st):
            for q in range(0, c, st):
                p = r * c + q
                lb = lab[p]
                if lb >= 0:
                    pts[0, n_pts] = np.float32(dx[p] + mx)
                    pts[1, n_pts] = np.float32(dy[p] + my)
                    pts[2, n_pts] = np.float32(dz[p] + mz)
                    preg[n_pts] = lb
                    n_pts += 1
    return complete, Mreg, pts[:, :n_pts], preg[:n_pts]  # views: read once, then dropped


_AP0, _AP1, _AP2, _AP3, _AP4, _AP5 = ASIN_P
_AQ0, _AQ1, _AQ2, _AQ3, _AQ4 = ASIN_Q
_AR0, _AR1, _AR2, _AR3, _AR4 = ASIN_R
_AS0, _AS1, _AS2, _AS3 = ASIN_S
_SC0, _SC1, _SC2, _SC3, _SC4, _SC5 = SIN_C
_CC0, _CC1, _CC2, _CC3, _CC4, _CC5 = COS_C


@njit(cache=True, inline="always")
def _asin_scalar(x: float) -> float:  # pragma: no cover - compiled
    """Cephes' ``asin`` of ``x`` in ``[-1, 1]``: ``navkit.geometry.angles._asin``'s operations
    in its order."""
    a = abs(x)
    if a > ASIN_SPLIT:
        zz = 1.0 - a
        p = zz * ((((_AR0 * zz + _AR1) * zz + _AR2) * zz + _AR3) * zz + _AR4)
        p = p / ((((zz + _AS0) * zz + _AS1) * zz + _AS2) * zz + _AS3)
        zz = np.sqrt(zz + zz)
        z = PI_4 - zz
        zz = zz * p - MOREBITS
        z = (z - zz) + PI_4
    elif a < ASIN_TINY:
        z = a
    else:
        z2 = a * a
        z = z2 * (((((_AP0 * z2 + _AP1) * z2 + _AP2) * z2 + _AP3) * z2 + _AP4) * z2 + _AP5)
        z = z / (((((z2 + _AQ0) * z2 + _AQ1) * z2 + _AQ2) * z2 + _AQ3) * z2 + _AQ4)
        z = a * z + a
    return -z if x < 0 else z


@njit(cache=True)
def acos_scalar(x: float) -> float:  # pragma: no cover - compiled
    """Cephes' ``acos`` of ``x`` in ``[-1, 1]`` (NaN beyond): the bits of
    :func:`navkit.geometry.angles.acos` (the same operations in the same order)."""
    if not abs(x) <= 1.0:
        return np.nan
    if x > 0.5:
        return 2.0 * _asin_scalar(np.sqrt(0.5 - 0.5 * x))
    return ((PI_4 - _asin_scalar(x)) + MOREBITS) + PI_4


@njit(cache=True)
def cos_scalar(x: float) -> float:  # pragma: no cover - compiled
    """Cephes' ``cos`` of a finite ``|x| < 2^29``: the bits of
    :func:`navkit.geometry.angles.cos` (the same operations in the same order)."""
    x = abs(x)
    y = np.floor(x * FOUR_OVER_PI)  # the octant
    j = np.int64(y)
    if j & 1:  # map zeros to the origin
        j += 1
        y += 1.0
    j &= 7
    z = ((x - y * PI4A) - y * PI4B) - y * PI4C
    zz = z * z
    flip = False
    if j > 3:
        j -= 4
        flip = True
    if j > 1:
        flip = not flip
    if j == 1 or j == 2:
        poly = ((((_SC0 * zz + _SC1) * zz + _SC2) * zz + _SC3) * zz + _SC4) * zz + _SC5
        v = z + z * zz * poly
    else:
        poly = ((((_CC0 * zz + _CC1) * zz + _CC2) * zz + _CC3) * zz + _CC4) * zz + _CC5
        v = 1.0 - 0.5 * zz + zz * zz * poly
    return -v if flip else v


@njit(cache=True)
def plane_rows(
    M: np.ndarray, rayleigh: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover
    """TLS planes of raw moment rows ``(G, 13)`` (see ``extract._planes_from_rows``): the
    smallest eigenpair of each covariance by the closed form of ``extract.smallest_eigenpairs``
    row by row, its operations in its order - ``acos`` / ``cos`` by :func:`acos_scalar` /
    :func:`cos_scalar` (its :mod:`navkit.geometry.angles`), the norm and ``n . mean`` left to
    right -, so the same bits (``rayleigh``: the eigenvalue as the Rayleigh quotient of the unit
    vector, as there). Returns normals ``(G, 3)`` away from the origin, rho, RMS, means ``(G, 3)`` and
    a flag per row whose smallest eigenvalue is repeated (the caller takes LAPACK's vector
    there)."""
    G = M.shape[0]
    normal = np.empty((G, 3), np.float64)
    rho = np.empty(G, np.float64)
    rms = np.empty(G, np.float64)
    mean = np.empty((G, 3), np.float64)
    rank1 = np.zeros(G, np.bool_)
    for g in range(G):
        n = max(M[g, 0], 1.0)
        mx = M[g, 1] / n
        my = M[g, 2] / n
        mz = M[g, 3] / n
        a00 = M[g, 4] / n - mx * mx
        a01 = M[g, 5] / n - mx * my
        a02 = M[g, 6] / n - mx * mz
        a11 = M[g, 8] / n - my * my
        a12 = M[g, 9] / n - my * mz
        a22 = M[g, 12] / n - mz * mz
        q = (a00 + a11 + a22) / 3.0
        b00 = a00 - q
        b11 = a11 - q
        b22 = a22 - q
        p2 = (b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)) / 6.0
        p = np.sqrt(p2)
        det = (
            b00 * (b11 * b22 - a12 * a12)
            - a01 * (a01 * b22 - a12 * a02)
            + a02 * (a01 * a12 - b11 * a02)
        )
        r = det / (2.0 * p * p2) if p > 0 else 0.0
        r = min(max(r, -1.0), 1.0)
        phi = acos_scalar(r) / 3.0
        lam = q + 2.0 * p * cos_scalar(phi + 2.0 * np.pi / 3.0)
        m00 = a00 - lam
        m11 = a11 - lam
        m22 = a22 - lam
        bx, by, bz, bn = 0.0, 0.0, 1.0, 0.0
        for pair in range(3):
            if pair == 0:
                x0, y0, z0, x1, y1, z1 = m00, a01, a02, a01, m11, a12
            elif pair == 1:
                x0, y0, z0, x1, y1, z1 = m00, a01, a02, a02, a12, m22
            else:
                x0, y0, z0, x1, y1, z1 = a01, m11, a12, a02, a12, m22
            cx = y0 * z1 - z0 * y1
            cy = z0 * x1 - x0 * z1
            cz = x0 * y1 - y0 * x1
            n2 = cx * cx + cy * cy + cz * cz
            if n2 > bn:
                bx, by, bz, bn = cx, cy, cz, n2
        if bn <= 1e-30 * max(p2 * p2, 1e-300):
            rank1[g] = True
            bn = 1.0
        inv = np.sqrt(bx * bx + by * by + bz * bz)
        bx /= inv
        by /= inv
        bz /= inv
        if rayleigh and not rank1[g]:  # v^T (C v), left to right (the NumPy version's order)
            u0 = a00 * bx + a01 * by + a02 * bz
            u1 = a01 * bx + a11 * by + a12 * bz
            u2 = a02 * bx + a12 * by + a22 * bz
            lam = bx * u0 + by * u1 + bz * u2
        d = bx * mx + by * my + bz * mz
        if d < 0:
            bx, by, bz = -bx, -by, -bz
        normal[g, 0] = bx
        normal[g, 1] = by
        normal[g, 2] = bz
        rho[g] = abs(d)
        rms[g] = np.sqrt(max(lam, 0.0))
        mean[g, 0] = mx
        mean[g, 1] = my
        mean[g, 2] = mz
    return normal, rho, rms, mean, rank1


@njit(cache=True)
def _dot3(a: np.ndarray, i: int, b: np.ndarray, j: int) -> float:  # pragma: no cover
    """``a[i] . b[j]`` of two ``(., 3)`` arrays, left to right: ``(a0 b0 + a1 b1) + a2 b2``
    (``extract._dot3``'s order)."""
    return a[i, 0] * b[j, 0] + a[i, 1] * b[j, 1] + a[i, 2] * b[j, 2]


@njit(cache=True)
def patch_graph(
    normal: np.ndarray,
    d: np.ndarray,
    mean: np.ndarray,
    count: np.ndarray,
    rms: np.ndarray,
    hc: int,
    wc: int,
    min_count: float,
    rms_base: float,
    rms_quadratic: float,
    cos_t: float,
    distance_factor: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Steps 2-3 of the extraction (see ``regions._grow_regions``) in one loop over the patches:
    the thickness bound ``rms_base + rms_quadratic |mean|^2``, the planar test (``count >=
    min_count`` and ``rms < bound``) and the tests of the edges to the right and below that do
    not depend on the kept set (normals within ``cos_t``, each centroid within ``distance_factor
    x`` the larger bound of the other's plane). Returns ``bound (G,)``, ``planar (G,)``, the
    horizontal edges ``(hc, wc - 1)`` and the vertical ones ``(hc - 1, wc)``."""
    G = hc * wc
    bound = np.empty(G, np.float64)
    planar = np.empty(G, np.bool_)
    for g in range(G):
        bound[g] = rms_base + rms_quadratic * _dot3(mean, g, mean, g)
        planar[g] = (count[g] >= min_count) and (rms[g] < bound[g])
    eh = np.zeros((hc, max(wc - 1, 0)), np.bool_)
    ev = np.zeros((max(hc - 1, 0), wc), np.bool_)
    for i in range(hc):
        for j in range(wc):
            a = i * wc + j
            for e in range(2):
                if e == 0:
                    if j + 1 >= wc:
                        continue
                    b = a + 1
                else:
                    if i + 1 >= hc:
                        continue
                    b = a + wc
                tol = distance_factor * max(bound[a], bound[b])
                ok = (
                    _dot3(normal, a, normal, b) > cos_t
                    and abs(_dot3(normal, a, mean, b) - d[a]) < tol
                    and abs(_dot3(normal, b, mean, a) - d[b]) < tol
                )
                if e == 0:
                    eh[i, j] = ok
                else:
                    ev[i, j] = ok
    return bound, planar, eh, ev


@njit(cache=True)
def _find(parent: np.ndarray, a: int) -> int:  # pragma: no cover - compiled
    """Root of ``a`` in a union-find forest, halving the path on the way (no recursion)."""
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@njit(cache=True)
def cell_components(
    keep: np.ndarray, eh: np.ndarray, ev: np.ndarray, min_cells: int
) -> tuple[int, np.ndarray]:  # pragma: no cover - compiled
    """Connected components of the kept patches ``keep (hc, wc)`` joined by the edges ``eh
    (hc, wc - 1)``, ``ev (hc - 1, wc)`` (union-find), numbered by their first patch in raster
    order - the order of OpenCV's ``connectedComponents`` on the cell-graph image of
    ``regions._grow_regions`` - those below ``min_cells`` patches dropped and the others
    renumbered in that order. Returns their number and the component of each patch ``(G,)``
    (-1 = none)."""
    hc, wc = keep.shape
    G = hc * wc
    parent = np.arange(G)
    for i in range(hc):
        for j in range(wc):
            if not keep[i, j]:
                continue
            a = i * wc + j
            if j + 1 < wc and keep[i, j + 1] and eh[i, j]:
                ra = _find(parent, a)
                rb = _find(parent, a + 1)
                if ra != rb:
                    parent[max(ra, rb)] = min(ra, rb)
            if i + 1 < hc and keep[i + 1, j] and ev[i, j]:
                ra = _find(parent, a)
                rb = _find(parent, a + wc)
                if ra != rb:
                    parent[max(ra, rb)] = min(ra, rb)
    size = np.zeros(G, np.int64)
    root = np.full(G, -1, np.int64)
    for g in range(G):
        if keep[g // wc, g % wc]:
            root[g] = _find(parent, g)
            size[root[g]] += 1
    # roots are each component's smallest patch: numbering roots in raster order
    new = np.full(G, -1, np.int64)
    n = 0
    for g in range(G):
        if root[g] == g and size[g] >= min_cells:
            new[g] = n
            n += 1
    comp = np.full(G, -1, np.int64)
    for g in range(G):
        if root[g] >= 0:
            comp[g] = new[root[g]]
    return n, comp


@njit(cache=True)
def dense_components(adj: np.ndarray) -> tuple[int, np.ndarray]:  # pragma: no cover - compiled
    """Connected components of a symmetric adjacency matrix ``(n, n)`` by union-find, numbered
    by their smallest member (``extract._dense_components``' numbering). Returns their number
    and the component of each node ``(n,)``."""
    n = adj.shape[0]
    parent = np.arange(n)
    for a in range(n):
        for b in range(a + 1, n):
            if adj[a, b]:
                ra = _find(parent, a)
                rb = _find(parent, b)
                if ra != rb:
                    parent[max(ra, rb)] = min(ra, rb)
    comp = np.empty(n, np.int64)
    new = np.full(n, -1, np.int64)
    k = 0
    for a in range(n):
        r = _find(parent, a)
        if new[r] < 0:
            new[r] = k
            k += 1
        comp[a] = new[r]
    return k, comp


@njit(cache=True)
def border_patches(
    cellmap: np.ndarray, full: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """``extract._border_patches`` in one loop over the patches: ``interior (hc, wc)`` (region
    patches whose 8 neighbours - the border repeating the edge patches - are in the same region;
    none when ``full``), the patches to refine ``(B,)`` (not interior, with a region among their
    9 patches) by decreasing number of candidate regions (stable) and their candidates ``(B,
    m)``: the distinct regions of the 9 patches in decreasing order, -1 padded."""
    hc, wc = cellmap.shape
    G = hc * wc
    interior = np.zeros((hc, wc), np.bool_)
    cand = np.full((G, 9), -1, np.int64)
    n_cand = np.zeros(G, np.int64)
    nb = np.empty(9, np.int64)
    for i in range(hc):
        for j in range(wc):
            g = i * wc + j
            own = cellmap[i, j]
            same = own >= 0
            t = 0
            for di in range(-1, 2):
                ii = min(max(i + di, 0), hc - 1)
                for dj in range(-1, 2):
                    jj = min(max(j + dj, 0), wc - 1)
                    v = cellmap[ii, jj]
                    same = same and v == own
                    # insertion into nb[:t], decreasing
                    p = t
                    while p > 0 and nb[p - 1] < v:
                        nb[p] = nb[p - 1]
                        p -= 1
                    nb[p] = v
                    t += 1
            interior[i, j] = same and not full
            n = 0
            for p in range(9):
                if nb[p] >= 0 and (p == 0 or nb[p] != nb[p - 1]):
                    cand[g, n] = nb[p]
                    n += 1
            n_cand[g] = n
    # border patches, by decreasing candidate count, then increasing id
    m = 0
    B = 0
    for g in range(G):
        if not interior[g // wc, g % wc] and n_cand[g] > 0:
            B += 1
            m = max(m, n_cand[g])
    ids = np.empty(B, np.int64)
    k = 0
    for n in range(9, 0, -1):
        for g in range(G):
            if n_cand[g] == n and not interior[g // wc, g % wc]:
                ids[k] = g
                k += 1
    out = np.empty((B, m), np.int64)
    for b in range(B):
        for p in range(m):
            out[b, p] = cand[ids[b], p]
    return interior, ids, out


@njit(cache=True)
def sum_rows(groups: np.ndarray, n_groups: int, M: np.ndarray) -> np.ndarray:  # pragma: no cover
    """Sums of the rows of ``M (G, 13)`` per group ``groups (G,)`` (-1 = none): ``(n_groups,
    13)``, each group's rows added one after the other from +0 (``moments._sum_rows``'
    ``numpy.add.at``: the same additions, the same bits)."""
    R = np.zeros((n_groups, M.shape[1]), np.float64)
    for g in range(len(groups)):
        k = groups[g]
        if k >= 0:
            for t in range(M.shape[1]):
                R[k, t] += M[g, t]
    return R


@njit(cache=True)
def _region_planes(
    cells: np.ndarray,
    M: np.ndarray,
    eh: np.ndarray,
    ev: np.ndarray,
    hc: int,
    wc: int,
    min_cells: int,
) -> tuple[int, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover
    """The components of the patches ``cells (G,)`` and their planes (sums of the patch rows,
    :func:`plane_rows`): ``(status, n, region of each patch, normals, rho, means)``, status 1
    when a region's smallest eigenvalue is repeated (:func:`prune_merge`), no planes when ``n``
    is 0 or status is 1."""
    n_reg, comp = cell_components(cells.reshape(hc, wc), eh, ev, min_cells)
    if n_reg == 0:
        return 0, 0, comp, np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3))
    rn, rd, _, rmean, rank1 = plane_rows(sum_rows(comp, n_reg, M))
    if rank1.any():
        return 1, n_reg, comp, np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3))
    return 0, n_reg, comp, rn, rd, rmean


@njit(cache=True)
def prune_merge(
    M: np.ndarray,
    normal: np.ndarray,
    mean: np.ndarray,
    bound: np.ndarray,
    planar: np.ndarray,
    eh: np.ndarray,
    ev: np.ndarray,
    hc: int,
    wc: int,
    min_cells: int,
    cos_t: float,
    distance_factor: float,
    rms_base: float,
    rms_quadratic: float,
) -> tuple[int, int, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Steps 3-4 of the extraction (``regions._prune_merge`` with ``regions._grow_regions``'
    components) in one call, and the planes of the final regions: the components of the planar
    patches, their region planes (sums of the patch rows, :func:`plane_rows`), the patches that
    disagree with their region's plane dropped, the components again, the coplanar regions'
    components (:func:`dense_components`) and the planes of the merged regions.

    Returns a status (0 = done; 1 = a region's smallest eigenvalue is repeated: the caller
    takes the NumPy path, whose LAPACK vector the closed form does not reproduce), the number of
    regions, the region of each patch ``(G,)`` (-1 = none) and the regions' normals ``(n, 3)``
    and rho ``(n,)``. The tests in the oracle's order: every dot product of three terms left to
    right (:func:`_dot3`, ``extract._dot3``), the region sums as :func:`sum_rows`, the planes as
    :func:`plane_rows`: the same decisions and the same bits."""
    G = hc * wc
    empty = np.zeros((0, 3), np.float64)
    status, n_reg, comp, rn, rd, _ = _region_planes(planar, M, eh, ev, hc, wc, min_cells)
    if status != 0 or n_reg == 0:
        return status, 0, comp, empty, np.zeros(0)
    keep = np.zeros(G, np.bool_)
    for g in range(G):
        k = comp[g]
        if planar[g] and k >= 0:
            keep[g] = (_dot3(normal, g, rn, k) > cos_t) and (
                abs(_dot3(rn, k, mean, g) - rd[k]) < distance_factor * bound[g]
            )
    status, n_reg, comp, rn, rd, rmean = _region_planes(keep, M, eh, ev, hc, wc, min_cells)
    if status != 0 or n_reg == 0:
        return status, 0, comp, empty, np.zeros(0)
    rtol = np.empty(n_reg, np.float64)
    for a in range(n_reg):
        rtol[a] = distance_factor * (rms_base + rms_quadratic * _dot3(rmean, a, rmean, a))
    same = np.zeros((n_reg, n_reg), np.bool_)
    for a in range(n_reg):
        for b in range(n_reg):
            nn = rn[a, 0] * rn[b, 0] + rn[a, 1] * rn[b, 1] + rn[a, 2] * rn[b, 2]
            dm = rn[a, 0] * rmean[b, 0] + rn[a, 1] * rmean[b, 1] + rn[a, 2] * rmean[b, 2]
            same[a, b] = (nn > cos_t) and (abs(dm - rd[a]) < max(rtol[a], rtol[b]))
    for a in range(n_reg):
        for b in range(a + 1, n_reg):
            both = same[a, b] and same[b, a]
            same[a, b] = both
            same[b, a] = both
    n_m, merged = dense_components(same)
    for g in range(G):
        if comp[g] >= 0:
            comp[g] = merged[comp[g]]
    if n_m == n_reg:  # no regions joined: their planes stand
        return 0, n_m, comp, rn, rd
    rn, rd, _, _, rank1 = plane_rows(sum_rows(comp, n_m, M))
    if rank1.any():
        return 1, 0, comp, empty, np.zeros(0)
    return 0, n_m, comp, rn, rd
