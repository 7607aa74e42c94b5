"""Compiled kernels of the organised plane extraction (:mod:`navkit.planes.extract`).

Each kernel fuses what several NumPy passes over a 640 x 480 grid do in
:mod:`navkit.planes.extract`; the NumPy versions stay there as the oracle the tests compare
with (``tests/planes/test_kernels.py``). The float32 block sums reproduce NumPy's summation order
exactly - rows of a patch added one after the other per column, then the ``c`` column sums by
NumPy's pairwise summation (eight running sums, combined as ``((r0 + r1) + (r2 + r3)) + ((r4 +
r5) + (r6 + r7))``, then the remainder) - so the patch moments, the planar test and the region
growing get the same bits with either backend.

Compiled with Numba (``@njit(cache=True)``: machine code cached on disk beside this module, or
in ``NUMBA_CACHE_DIR``); imported lazily by :mod:`navkit.planes.extract` on the first organised
extraction, so ``import navkit`` does not pay for Numba.
"""

from __future__ import annotations

import numpy as np
from numba import njit

MAX_CELL = 128  # NumPy's PW_BLOCKSIZE: a patch's row sums are one pairwise block up to it


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
def patch_moments(
    P: np.ndarray,
    hc: int,
    wc: int,
    c: int,
    tol_scale: np.float32,
    tol_base: np.float32,
    X: np.ndarray,
    tol: np.ndarray,
    valid: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Step 1 of the extraction in one pass per patch (see ``extract._patch_moments``).

    Fills ``X (3, hc c, wc c)`` float32 with the coordinates minus their patch's float32 mean
    (0 where invalid), ``tol (hc c, wc c)`` float32 with the inlier bound ``tol_scale r^2 +
    tol_base`` (-1 where invalid) and ``valid`` (finite, non-zero range). Returns per patch the
    count ``(G,)``, the float32 mean ``(G, 3)``, the sums of the centred coordinates ``(G, 3)``
    and of their products ``(G, 6)`` (xx, xy, xz, yy, yz, zz), float32 sums as float64.
    """
    G = hc * wc
    cnt = np.empty(G, np.float64)
    ref = np.empty((G, 3), np.float32)
    Sd = np.empty((G, 3), np.float64)
    SSd = np.empty((G, 6), np.float64)
    col = np.empty((10, c), np.float32)  # per-column sums of one patch
    for i in range(hc):
        for j in range(wc):
            g = i * wc + j
            # pass 1: coordinates, validity, bound; column sums of the count and coordinates
            for r in range(c):
                y = i * c + r
                for q in range(c):
                    x = j * c + q
                    px = np.float32(P[y, x, 0])
                    py = np.float32(P[y, x, 1])
                    pz = np.float32(P[y, x, 2])
                    r2 = np.float32(
                        np.float32(np.float32(px * px) + np.float32(py * py)) + np.float32(pz * pz)
                    )
                    ok = r2 > 0 and r2 < np.inf
                    valid[y, x] = ok
                    if ok:
                        tol[y, x] = np.float32(np.float32(r2 * tol_scale) + tol_base)
                        v = np.float32(1.0)
                    else:
                        tol[y, x] = np.float32(-1.0)
                        px = np.float32(0.0)
                        py = np.float32(0.0)
                        pz = np.float32(0.0)
                        v = np.float32(0.0)
                    X[0, y, x] = px
                    X[1, y, x] = py
                    X[2, y, x] = pz
                    if r == 0:
                        col[0, q] = v
                        col[1, q] = px
                        col[2, q] = py
                        col[3, q] = pz
                    else:
                        col[0, q] = np.float32(col[0, q] + v)
                        col[1, q] = np.float32(col[1, q] + px)
                        col[2, q] = np.float32(col[2, q] + py)
                        col[3, q] = np.float32(col[3, q] + pz)
            n = _pairwise32(col[0], c)
            den = max(n, np.float32(1.0))
            mx = np.float32(_pairwise32(col[1], c) / den)
            my = np.float32(_pairwise32(col[2], c) / den)
            mz = np.float32(_pairwise32(col[3], c) / den)
            cnt[g] = n
            ref[g, 0] = mx
            ref[g, 1] = my
            ref[g, 2] = mz
            # pass 2: centred coordinates (x 0 / 1 validity) and their products
            for r in range(c):
                y = i * c + r
                for q in range(c):
                    x = j * c + q
                    v = np.float32(1.0) if valid[y, x] else np.float32(0.0)
                    dx = np.float32(np.float32(X[0, y, x] - mx) * v)
                    dy = np.float32(np.float32(X[1, y, x] - my) * v)
                    dz = np.float32(np.float32(X[2, y, x] - mz) * v)
                    X[0, y, x] = dx
                    X[1, y, x] = dy
                    X[2, y, x] = dz
                    xx = np.float32(dx * dx)
                    xy = np.float32(dx * dy)
                    xz = np.float32(dx * dz)
                    yy = np.float32(dy * dy)
                    yz = np.float32(dy * dz)
                    zz = np.float32(dz * dz)
                    if r == 0:
                        col[1, q] = dx
                        col[2, q] = dy
                        col[3, q] = dz
                        col[4, q] = xx
                        col[5, q] = xy
                        col[6, q] = xz
                        col[7, q] = yy
                        col[8, q] = yz
                        col[9, q] = zz
                    else:
                        col[1, q] = np.float32(col[1, q] + dx)
                        col[2, q] = np.float32(col[2, q] + dy)
                        col[3, q] = np.float32(col[3, q] + dz)
                        col[4, q] = np.float32(col[4, q] + xx)
                        col[5, q] = np.float32(col[5, q] + xy)
                        col[6, q] = np.float32(col[6, q] + xz)
                        col[7, q] = np.float32(col[7, q] + yy)
                        col[8, q] = np.float32(col[8, q] + yz)
                        col[9, q] = np.float32(col[9, q] + zz)
            for k in range(3):
                Sd[g, k] = _pairwise32(col[1 + k], c)
            for k in range(6):
                SSd[g, k] = _pairwise32(col[4 + k], c)
    return cnt, ref, Sd, SSd


@njit(cache=True)
def refine_pixels(
    D: np.ndarray,
    tol: np.ndarray,
    ids: np.ndarray,
    own: np.ndarray,
    cand: np.ndarray,
    off: np.ndarray,
    n32: np.ndarray,
    wc: int,
    c: int,
    label: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Step 5, the border patches pixel by pixel (see ``extract._refine_border``).

    ``D (3, H, W)`` centred float32 coordinates, ``tol (H, W)`` inlier bounds (-1 = invalid),
    ``ids (B,)`` patches, ``own (B,)`` their regions (-1 = none), ``cand (B, m)`` candidate
    regions (-1 padded), ``off (B, m)`` float32 ``n . ref - rho`` per (patch, candidate),
    ``n32 (n_reg, 3)`` float32 normals. Fills ``label (B, c, c)`` (closest candidate within the
    bound, -1 = none; ties keep the earlier slot). Returns ``complete (B,)`` and the float64
    moments ``(B, m, 10)`` - count, sums of d, sums of d d^T (xx, xy, xz, yy, yz, zz) - of the
    pixels of each (incomplete patch, candidate) (zero for complete patches).
    """
    B, m = cand.shape
    complete = np.empty(B, np.bool_)
    G = np.zeros((B, m, 10), np.float64)
    for b in range(B):
        i = ids[b] // wc
        j = ids[b] - i * wc
        ok = own[b] >= 0
        for r in range(c):
            y = i * c + r
            for q in range(c):
                x = j * c + q
                t = tol[y, x]
                best = np.float32(np.inf)
                lab = -1
                dx = D[0, y, x]
                dy = D[1, y, x]
                dz = D[2, y, x]
                for s in range(m):
                    k = cand[b, s]
                    if k < 0:
                        break
                    dist = np.float32(
                        np.float32(
                            np.float32(np.float32(dx * n32[k, 0]) + np.float32(dy * n32[k, 1]))
                            + np.float32(dz * n32[k, 2])
                        )
                        + off[b, s]
                    )
                    dist = abs(dist)
                    if dist < t and dist < best:
                        best = dist
                        lab = k
                label[b, r, q] = lab
                if ok and lab != own[b] and t >= 0:
                    ok = False
        complete[b] = ok
        if ok:
            continue
        for r in range(c):
            y = i * c + r
            for q in range(c):
                lab = label[b, r, q]
                if lab < 0:
                    continue
                s = 0
                while cand[b, s] != lab:
                    s += 1
                x = j * c + q
                dx = np.float64(D[0, y, x])
                dy = np.float64(D[1, y, x])
                dz = np.float64(D[2, y, x])
                G[b, s, 0] += 1.0
                G[b, s, 1] += dx
                G[b, s, 2] += dy
                G[b, s, 3] += dz
                G[b, s, 4] += dx * dx
                G[b, s, 5] += dx * dy
                G[b, s, 6] += dx * dz
                G[b, s, 7] += dy * dy
                G[b, s, 8] += dy * dz
                G[b, s, 9] += dz * dz
    return complete, G
