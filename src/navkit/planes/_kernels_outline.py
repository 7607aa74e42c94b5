"""Compiled kernels of the organised plane extraction's last step (:mod:`navkit.planes.extract`):
the label image and each plane's inliers, then the outlines - the samples every plane's outline
is rasterised from, the rasters of all planes and their 3 x 3 closings.

The kernels of the earlier steps are in :mod:`navkit.planes._kernels` (the module docstring
there states the equivalence contract; it holds here too: the same float64 operations as the
twins, in the same order, without ``fastmath``). :func:`outline_samples` inlines that module's
``_patch_stride``: Numba keys this module's cache by this file only, so after a change to
``_patch_stride`` touch this file too (or clear the cache; ``docs/kernels.md``).

Compiled with Numba (``@njit(cache=True)``); imported lazily by :mod:`navkit.planes.extract`
on the first organised extraction.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from navkit.planes._kernels import _patch_stride

__all__ = ["close_rasters", "label_image", "outline_rasters", "outline_samples"]

TWINS = {
    "close_rasters": "navkit.planes.segments.outline_of_raster",
    "label_image": "navkit.planes.outlines._label_image_numpy",
    "outline_rasters": "navkit.planes.segments.outline_from_points",
    "outline_samples": "navkit.planes.outlines._outlines",
}
"""Each kernel -> its NumPy twin (``close_rasters``: the OpenCV closing and the cell count of
``outline_of_raster``; ``outline_samples``: the NumPy path of ``_outlines`` before the
rasters)."""


@njit(cache=True)
def label_image(
    valid: np.ndarray,
    lab_cell: np.ndarray,
    ids: np.ndarray,
    complete: np.ndarray,
    label: np.ndarray,
    new_id: np.ndarray,
    sizes: np.ndarray,
    H: int,
    W: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """The label image and the inliers of each segment in raster order (see
    ``extract._extract``): ``valid (hc c, wc c)``, ``lab_cell (hc, wc)`` the segment of each
    wholesale patch (-1 = none), ``ids (B,)`` the border patches, ``complete (B,)`` those
    assigned whole (the others are mixed: refined pixel by pixel), ``label (B, c, c)`` their
    pixels' regions (-1 = none), ``new_id`` the segment of region + 1 and ``sizes (K,)`` the
    segments' inlier counts. Returns ``labels (H, W)`` int64 (-1 = none), the inlier indices
    ``row * W + col`` of all segments one after the other and the ``(K + 1,)`` cuts between
    segments.

    The segments' sizes ``sizes (K,)`` are known (the counts of their final moments: the valid
    pixels of the wholesale patches plus the mixed patches' pixels of the segment), so that one
    raster pass writes each label once and places each inlier, without a counting pass. A size that does not match the labels
    raises (checked before every write of a mixed patch's inlier and after every row of a
    wholesale patch, which can overrun by at most ``c - 1`` slots: the buffer has them spare)."""
    hc, wc = lab_cell.shape
    c = valid.shape[0] // hc
    K = len(sizes)
    mix = np.full(hc * wc, -1, np.int64)
    for b in range(len(ids)):
        if not complete[b]:
            mix[ids[b]] = b
    cuts = np.zeros(K + 1, np.int64)
    for k in range(K):
        cuts[k + 1] = cuts[k] + sizes[k]
    inl = np.empty(cuts[K] + c, np.int64)
    pos = cuts[:K].copy()
    labels = np.empty((H, W), np.int64)
    for y in range(H):
        i = y // c
        if i >= hc:
            labels[y, :] = -1
            continue
        r = y - i * c
        for j in range(wc):
            x0 = j * c
            b = mix[i * wc + j]
            s = lab_cell[i, j]
            if b >= 0:
                for q in range(c):
                    v = new_id[label[b, r, q] + 1]
                    labels[y, x0 + q] = v
                    if v >= 0:
                        if pos[v] >= cuts[v + 1]:
                            raise ValueError("label_image: a segment's size is too small")
                        inl[pos[v]] = y * W + x0 + q
                        pos[v] += 1
            elif s >= 0:  # the labels branch-free, then the inliers with a local position
                vr = valid[y, x0 : x0 + c]
                lr = labels[y, x0 : x0 + c]
                for q in range(c):
                    lr[q] = s if vr[q] else -1
                p = pos[s]
                i0 = y * W + x0
                for q in range(c):
                    if vr[q]:
                        inl[p] = i0 + q
                        p += 1
                if p > cuts[s + 1]:
                    raise ValueError("label_image: a segment's size is too small")
                pos[s] = p
            else:
                for q in range(c):
                    labels[y, x0 + q] = -1
        for x in range(wc * c, W):
            labels[y, x] = -1
    for k in range(K):
        if pos[k] != cuts[k + 1]:
            raise ValueError("label_image: a segment's size is too large")
    return labels, inl[: cuts[K]], cuts


@njit(cache=True)
def outline_rasters(
    uv: np.ndarray,
    cuts: np.ndarray,
    step: np.ndarray,
    quads: np.ndarray,
    qcuts: np.ndarray,
    cell: float,
) -> tuple[
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray
]:  # pragma: no cover - compiled
    """The rasters of :func:`navkit.planes.segments.outline_from_points` for all segments at
    once (see ``outlines._outlines``): segment ``k`` has the points ``uv[cuts[k]:cuts[k + 1]:
    step[k]] (., 2)`` and the quadrilaterals ``quads[qcuts[k]:qcuts[k + 1]] (., 4, 2)``.

    The bounding box, the raster size and the cells of the points are computed as that
    function does (the same float64 operations). Returns the rasters one after the other in one
    zeroed uint8 buffer with the points drawn (segment ``k`` from ``start[k]``, ``shape[k] =
    (columns, rows)``), ``lo (K, 2)``, a status per segment (0 = raster, 1 = fewer than 3
    points and corners: empty outline, 2 = raster above 4e6 cells: the caller calls
    ``outline_from_points``), the quadrilaterals' corners in 1/16 raster cell as OpenCV's
    ``fillPoly`` takes them ``(Q, 4, 2)`` int32 and whether each quadrilateral is finite."""
    K = len(cuts) - 1
    inv = 1.0 / cell
    lo = np.zeros((K, 2), np.float64)
    shape = np.zeros((K, 2), np.int64)
    start = np.zeros(K + 1, np.int64)
    status = np.zeros(K, np.int64)
    qfin = np.ones(len(quads), np.bool_)
    total = 0
    for k in range(K):
        lo0 = np.inf
        lo1 = np.inf
        hi0 = -np.inf
        hi1 = -np.inf
        n = 0
        for p in range(cuts[k], cuts[k + 1], step[k]):
            u = uv[p, 0]
            v = uv[p, 1]
            if np.isfinite(u) and np.isfinite(v):
                n += 1
                lo0 = min(lo0, u)
                hi0 = max(hi0, u)
                lo1 = min(lo1, v)
                hi1 = max(hi1, v)
        for qi in range(qcuts[k], qcuts[k + 1]):
            fin = True
            for a in range(4):
                fin = fin and np.isfinite(quads[qi, a, 0]) and np.isfinite(quads[qi, a, 1])
            qfin[qi] = fin
            if fin:
                n += 4
                for a in range(4):
                    lo0 = min(lo0, quads[qi, a, 0])
                    hi0 = max(hi0, quads[qi, a, 0])
                    lo1 = min(lo1, quads[qi, a, 1])
                    hi1 = max(hi1, quads[qi, a, 1])
        start[k + 1] = total
        if n < 3:
            status[k] = 1
            continue
        lo0 -= cell
        lo1 -= cell
        lo[k, 0] = lo0
        lo[k, 1] = lo1
        e0 = (hi0 - lo0) * inv + 2.0
        e1 = (hi1 - lo1) * inv + 2.0
        if e0 * e1 > 4_000_000:
            status[k] = 2
            continue
        shape[k, 0] = np.int64(e0)
        shape[k, 1] = np.int64(e1)
        total += shape[k, 0] * shape[k, 1]
        start[k + 1] = total
    grid = np.zeros(total, np.uint8)
    qint = np.zeros((len(quads), 4, 2), np.int32)
    for k in range(K):
        if status[k] != 0:
            continue
        lo0 = lo[k, 0]
        lo1 = lo[k, 1]
        w = shape[k, 0]
        s0 = start[k]
        for p in range(cuts[k], cuts[k + 1], step[k]):
            u = uv[p, 0]
            v = uv[p, 1]
            if np.isfinite(u) and np.isfinite(v):
                ii = np.int64((u - lo0) * inv)
                jj = np.int64((v - lo1) * inv)
                grid[s0 + jj * w + ii] = 1
        for qi in range(qcuts[k], qcuts[k + 1]):
            for a in range(4):
                qint[qi, a, 0] = np.int32(np.rint(((quads[qi, a, 0] - lo0) * inv - 0.5) * 16.0))
                qint[qi, a, 1] = np.int32(np.rint(((quads[qi, a, 1] - lo1) * inv - 0.5) * 16.0))
    return grid, start, shape, lo, status, qint, qfin


@njit(cache=True)
def _project(
    x: float, y: float, z: float, axes: np.ndarray, off: np.ndarray, k: int, a: int
) -> float:  # pragma: no cover - compiled
    """In-plane coordinate ``a`` of a point on segment ``k``'s axes (``outlines._outlines``'
    arithmetic: ``x A0 + y A1 + z A2 - off``, left to right)."""
    return x * axes[k, a, 0] + y * axes[k, a, 1] + z * axes[k, a, 2] - off[k, a]


@njit(cache=True)
def outline_samples(
    P: np.ndarray,
    valid: np.ndarray,
    labels: np.ndarray,
    wholesale: np.ndarray,
    segmap: np.ndarray,
    M: np.ndarray,
    points: np.ndarray,
    point_region: np.ndarray,
    new_id: np.ndarray,
    axes: np.ndarray,
    off: np.ndarray,
    c: int,
    cell: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """What every segment's outline is rasterised from (see ``outlines._outlines``), in plane
    coordinates: the quadrilaterals of its wholesale patches that sample the plane densely and
    the points - the sampled pixels ``points (3, N)`` float32 of the mixed patches (regions
    ``point_region``, segment ``new_id[region + 1]``, -1 = none), then every ``t``-th row and column of the valid pixels of its
    other wholesale patches (``t`` from the patch's scatter ``M``, ``moments._sample_stride``).

    ``labels (H, W)`` are segment indices, ``wholesale (hc, wc)`` the patches assigned whole,
    ``segmap (hc, wc)`` the segment of each patch's region (-1 = none), ``axes (K, 2, 3)`` and
    ``off (K, 2)`` the segments' plane frames. Returns ``uv (., 2)`` and its ``(K + 1,)`` cuts,
    the used quadrilaterals ``(Q, 4, 2)`` and their cuts; both grouped by segment, patches in
    raster order within one (the NumPy version's order and floats)."""
    hc, wc = segmap.shape
    K = len(axes)
    lim = 2.0 * cell * c
    sqrt2 = np.sqrt(2.0)
    # wholesale patches of kept segments, grouped by segment (counting sort: stable)
    nq = np.zeros(K + 1, np.int64)
    for i in range(hc):
        for j in range(wc):
            if wholesale[i, j] and segmap[i, j] >= 0:
                nq[segmap[i, j] + 1] += 1
    for k in range(K):
        nq[k + 1] += nq[k]
    Q = nq[K]
    cells = np.empty(Q, np.int64)
    pos = nq[:K].copy()
    for i in range(hc):
        for j in range(wc):
            if wholesale[i, j] and segmap[i, j] >= 0:
                cells[pos[segmap[i, j]]] = i * wc + j
                pos[segmap[i, j]] += 1
    quads = np.empty((Q, 4, 2), np.float64)
    use = np.empty(Q, np.bool_)
    stride = np.ones(Q, np.int64)
    n_use = np.zeros(K + 1, np.int64)
    count = np.zeros(K + 1, np.int64)  # points per segment (index + 1)
    for n in range(len(point_region)):
        count[new_id[point_region[n] + 1] + 1] += 1
    for p in range(Q):
        g = cells[p]
        i = g // wc
        j = g - i * wc
        k = segmap[i, j]
        ok = True
        for a in range(4):  # corners around the patch: lattice corner, else its own pixel
            lr = i * c + (c if a >= 2 else 0)
            lq = j * c + (c if a == 1 or a == 2 else 0)
            lr = min(lr, hc * c - 1)
            lq = min(lq, wc * c - 1)
            orr = i * c + (c - 1 if a >= 2 else 0)
            oq = j * c + (c - 1 if a == 1 or a == 2 else 0)
            lat = labels[lr, lq] == k
            ok = ok and (lat or labels[orr, oq] == k)
            rr = lr if lat else orr
            qq = lq if lat else oq
            for b in range(2):
                quads[p, a, b] = _project(P[rr, qq, 0], P[rr, qq, 1], P[rr, qq, 2], axes, off, k, b)
        e2 = 0.0
        for a in range(4):
            du = quads[p, (a + 1) % 4, 0] - quads[p, a, 0]
            dv = quads[p, (a + 1) % 4, 1] - quads[p, a, 1]
            e2 = max(e2, du * du + dv * dv)
        use[p] = ok and np.sqrt(e2) <= lim
        if use[p]:
            n_use[k + 1] += 1
            continue
        # the pixel stride of a patch rasterised pixel by pixel (moments._sample_stride)
        st = _patch_stride(M, g, c, cell, sqrt2)
        stride[p] = st
        for r in range(0, c, st):
            for q in range(0, c, st):
                if valid[i * c + r, j * c + q]:
                    count[k + 1] += 1
    qcut = np.zeros(K + 1, np.int64)
    for k in range(K):
        qcut[k + 1] = qcut[k] + n_use[k + 1]
    q_used = np.empty((qcut[K], 4, 2), np.float64)
    w = 0
    for p in range(Q):
        if use[p]:
            q_used[w] = quads[p]
            w += 1
    cuts = np.zeros(K + 1, np.int64)
    for k in range(K):
        cuts[k + 1] = cuts[k] + count[k + 1]
    uv = np.empty((cuts[K], 2), np.float64)
    pos = cuts[:K].copy()
    for n in range(len(point_region)):
        k = new_id[point_region[n] + 1]
        if k < 0:
            continue
        x = np.float64(points[0, n])
        y = np.float64(points[1, n])
        z = np.float64(points[2, n])
        for a in range(2):
            uv[pos[k], a] = _project(x, y, z, axes, off, k, a)
        pos[k] += 1
    for p in range(Q):
        if use[p]:
            continue
        g = cells[p]
        i = g // wc
        j = g - i * wc
        k = segmap[i, j]
        st = stride[p]
        for r in range(0, c, st):
            for q in range(0, c, st):
                yy = i * c + r
                xx = j * c + q
                if valid[yy, xx]:
                    for a in range(2):
                        uv[pos[k], a] = _project(
                            P[yy, xx, 0], P[yy, xx, 1], P[yy, xx, 2], axes, off, k, a
                        )
                    pos[k] += 1
    return uv, cuts, q_used, qcut


@njit(cache=True)
def _close3(grid: np.ndarray, tmp: np.ndarray) -> int:  # pragma: no cover - compiled
    """OpenCV's ``morphologyEx(grid, MORPH_CLOSE, ones((3, 3)))`` of a 0 / 1 raster ``(h, w)``
    in place (``tmp``: scratch of the same shape) and its number of non-zero cells afterwards.
    OpenCV's default border: outside the raster counts as 0 for the dilation and is ignored by
    the erosion. Both as a row pass then a column pass (a 3 x 3 max / min is separable)."""
    h, w = grid.shape
    for op in range(2):  # 0: dilation (max), 1: erosion (min)
        for y in range(h):
            g = grid[y]
            t = tmp[y]
            if w == 1:
                t[0] = g[0]
                continue
            if op == 0:
                t[0] = max(g[0], g[1])
                for x in range(1, w - 1):
                    t[x] = max(max(g[x - 1], g[x]), g[x + 1])
                t[w - 1] = max(g[w - 2], g[w - 1])
            else:
                t[0] = min(g[0], g[1])
                for x in range(1, w - 1):
                    t[x] = min(min(g[x - 1], g[x]), g[x + 1])
                t[w - 1] = min(g[w - 2], g[w - 1])
        for y in range(h):
            a = tmp[max(y - 1, 0)]
            b = tmp[y]
            c = tmp[min(y + 1, h - 1)]
            o = grid[y]
            if op == 0:
                for x in range(w):
                    o[x] = max(max(a[x], b[x]), c[x])
            else:
                for x in range(w):
                    o[x] = min(min(a[x], b[x]), c[x])
    n = 0
    for y in range(h):
        g = grid[y]
        for x in range(w):
            n += g[x] != 0
    return n


@njit(cache=True)
def close_rasters(
    buf: np.ndarray, start: np.ndarray, shape: np.ndarray, status: np.ndarray
) -> np.ndarray:  # pragma: no cover - compiled
    """The 3 x 3 closing of every raster of :func:`outline_rasters` (``status == 0``; raster
    ``k`` at ``buf[start[k]:]``, ``shape[k] = (columns, rows)``) in place, as
    ``segments.outline_of_raster`` closes one with OpenCV (:func:`_close3`: the same cells), and
    their numbers of covered cells ``(K,)`` (0 for the others)."""
    K = len(status)
    cells = np.zeros(K, np.int64)
    big = 0
    for k in range(K):
        if status[k] == 0:
            big = max(big, shape[k, 0] * shape[k, 1])
    tmp = np.empty(big, np.uint8)
    for k in range(K):
        if status[k] != 0:
            continue
        w = shape[k, 0]
        h = shape[k, 1]
        grid = buf[start[k] : start[k] + w * h].reshape(h, w)
        cells[k] = _close3(grid, tmp[: w * h].reshape(h, w))
    return cells
