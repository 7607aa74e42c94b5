"""Compiled scoring loop of the correlative matcher (:mod:`navkit.localization.matcher`).

A candidate pose's score is a sum of uint8 field values gathered at the scan's cells shifted by
the candidate's translation. NumPy builds the (candidates x points) index array and gathers it;
:func:`gather_sums` walks it once without the temporary. Integer sums: the same values exactly
(the NumPy version stays in ``_Search`` as the oracle, ``tests/localization/test_kernels.py``).
Numba, ``cache=True``; imported on first use.

Data-dependent look-ups index with ``np.uint64`` offsets: Numba wraps a negative signed index
around (a compare and a select per look-up, which also keeps LLVM from scheduling the loads
freely); every such offset here is non-negative by construction, so the unsigned index reads the
same element without that code: 0.54 instead of 0.91 ns per look-up in ``expand_sums``' loop
(``depth_first`` of a global fix on Acapulco, the same nodes).
"""

from __future__ import annotations

import numpy as np
from numba import njit

TWINS = {
    "bilinear_pose_scores": "navkit.localization.matcher._bilinear_scores",
    "cubic_pose_scores": "navkit.localization.matcher._fine_scores",
    "depth_first": "navkit.localization.search._Search.run",
    "expand_sums": "navkit.localization.search._Search._expand",
    "flat_table": "navkit.localization.search._Search._table",
    "gather_sums": "navkit.localization.search._Search._sums",
    "order_desc": "navkit.localization.search._Search._order",
    "rotated_cells": "navkit.localization.search._Search._cells",
    "window_offsets": "navkit.localization.search._Search._padded_window",
}
"""Each kernel -> its NumPy twin, the NumPy path of that function (``depth_first``: ``run``'s
recursive ``descend``; ``expand_sums``: ``_children`` then ``scores``; ``gather_sums``: also
``_sums_group``'s; ``order_desc``: ``np.argsort(-bound, kind="stable")``)."""


@njit(cache=True)
def gather_sums(
    grid: np.ndarray, F: np.ndarray, rows: np.ndarray, shift: np.ndarray
) -> np.ndarray:  # pragma: no cover - compiled
    """``out[c] = sum_i grid[F[rows[c], i] + shift[c]]`` (uint8 values, int64 sums)."""
    C = len(rows)
    N = F.shape[1]
    out = np.empty(C, np.int64)
    for c in range(C):
        r = rows[c]
        s = shift[c]
        acc = 0
        for i in range(N):
            acc += grid[np.uint64(F[r, i] + s)]  # unsigned: no negative-index wraparound
        out[c] = acc
    return out


@njit(cache=True)
def window_offsets(
    c: np.ndarray,
    s: np.ndarray,
    pts: np.ndarray,
    base_x: float,
    base_y: float,
    origin_x: float,
    origin_y: float,
    res: float,
    pad: int,
    Wp: int,
    lim_x: int,
    lim_y: int,
) -> np.ndarray:  # pragma: no cover - compiled
    """The look-up table of a search window on the padded pyramid (``_Search.__init__``):
    point ``i`` rotated by ``(c[k], s[k])``, shifted to the window's base, its cell
    ``floor(((q + base) - origin) / res)``, flattened into the padded grid - or the all-zero
    corner (0) when a look-up over the window would leave the padded grid. The same float
    operations in the same order as the NumPy version: the same table exactly."""
    K = len(c)
    N = pts.shape[0]
    F = np.empty((K, N), np.int32)
    for k in range(K):
        ck = c[k]
        sk = s[k]
        for i in range(N):
            x = pts[i, 0]
            y = pts[i, 1]
            ox = np.floor(((ck * x - sk * y + base_x) - origin_x) / res)
            oy = np.floor(((sk * x + ck * y + base_y) - origin_y) / res)
            if ox >= -pad and ox <= lim_x and oy >= -pad and oy <= lim_y:
                F[k, i] = (int(oy) + pad) * Wp + int(ox) + pad
            else:
                F[k, i] = 0
    return F


@njit(cache=True)
def cubic_pose_scores(
    V: np.ndarray,
    origin_x: float,
    origin_y: float,
    res: float,
    pts: np.ndarray,
    poses: np.ndarray,
    c: np.ndarray,
    s: np.ndarray,
) -> np.ndarray:  # pragma: no cover - compiled
    """Mean bicubic (Catmull-Rom) field value of the scan at each pose (``matcher.
    _fine_scores``): ``V`` the field with two zero cells around it, ``(c, s)`` the poses'
    cosines and sines (from NumPy). Per point: the rotated and shifted point, its padded index
    coordinates ``(p - origin) / res + 1.5``, the 4 x 4 stencil weighted row by row
    (``((w0 g0 + w1 g1) + w2 g2) + w3 g3`` across, then the same down), zero beyond the
    padding; the points summed in order. The NumPy version does the same operations in the
    same order: the same scores exactly."""
    Hp, Wp = V.shape
    Vf = V.ravel()
    one, two, three, uW = np.uint64(1), np.uint64(2), np.uint64(3), np.uint64(Wp)
    M = poses.shape[0]
    N = pts.shape[0]
    out = np.empty(M)
    wx = np.empty(4)
    wy = np.empty(4)
    for m in range(M):
        cm = c[m]
        sm = s[m]
        px = poses[m, 0]
        py = poses[m, 1]
        acc = 0.0
        for i in range(N):
            x = pts[i, 0]
            y = pts[i, 1]
            ux = ((cm * x - sm * y + px) - origin_x) / res + 1.5
            uy = ((sm * x + cm * y + py) - origin_y) / res + 1.5
            fx = np.floor(ux)
            fy = np.floor(uy)
            if fx < 1 or fx > Wp - 3 or fy < 1 or fy > Hp - 3:
                acc += 0.0
                continue
            _catmull_rom(ux - fx, wx)
            _catmull_rom(uy - fy, wy)
            # flat unsigned offsets (no negative-index wraparound): fx, fy >= 1 here
            at = np.uint64((int(fy) - 1) * Wp + int(fx) - 1)
            v = 0.0
            for a in range(4):
                row = wx[0] * Vf[at] + wx[1] * Vf[at + one]
                row = row + wx[2] * Vf[at + two]
                row = row + wx[3] * Vf[at + three]
                at += uW
                if a == 0:
                    v = wy[0] * row
                else:
                    v = v + wy[a] * row
            acc += v
        out[m] = acc / N
    return out


@njit(cache=True)
def _catmull_rom(t: float, w: np.ndarray) -> None:  # pragma: no cover - compiled
    """``field._catmull_rom`` for one offset, into ``w``."""
    t2 = t * t
    t3 = t2 * t
    w[0] = 0.5 * (-t3 + 2.0 * t2 - t)
    w[1] = 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0)
    w[2] = 0.5 * (-3.0 * t3 + 4.0 * t2 + t)
    w[3] = 0.5 * (t3 - t2)


@njit(cache=True)
def bilinear_pose_scores(
    values: np.ndarray,
    origin_x: float,
    origin_y: float,
    res: float,
    pts: np.ndarray,
    poses: np.ndarray,
    c: np.ndarray,
    s: np.ndarray,
) -> np.ndarray:  # pragma: no cover - compiled
    """Mean bilinear field value of the scan at each pose (``matcher._bilinear_scores``, the
    values of ``LikelihoodField.interpolate``): cell centres at ``origin + (i + 0.5) res``,
    zero outside the grid, ``v00 (1 - fx)(1 - fy) + v10 fx (1 - fy) + v01 (1 - fx) fy +
    v11 fx fy`` in that order, the points summed in order."""
    H, W = values.shape
    M = poses.shape[0]
    N = pts.shape[0]
    out = np.empty(M)
    for m in range(M):
        cm = c[m]
        sm = s[m]
        px = poses[m, 0]
        py = poses[m, 1]
        acc = 0.0
        for i in range(N):
            x = pts[i, 0]
            y = pts[i, 1]
            ux = ((cm * x - sm * y + px) - origin_x) / res - 0.5
            uy = ((sm * x + cm * y + py) - origin_y) / res - 0.5
            x0 = int(np.floor(ux))
            y0 = int(np.floor(uy))
            fx = ux - x0
            fy = uy - y0
            v00 = _at(values, x0, y0, W, H)
            v10 = _at(values, x0 + 1, y0, W, H)
            v01 = _at(values, x0, y0 + 1, W, H)
            v11 = _at(values, x0 + 1, y0 + 1, W, H)
            val = (
                v00 * (1 - fx) * (1 - fy)
                + v10 * fx * (1 - fy)
                + v01 * (1 - fx) * fy
                + v11 * fx * fy
            )
            acc += val
        out[m] = acc / N
    return out


@njit(cache=True)
def _at(g: np.ndarray, ix: int, iy: int, W: int, H: int) -> float:  # pragma: no cover
    if ix < 0 or ix >= W or iy < 0 or iy >= H:
        return 0.0
    return np.float64(g[np.uint64(iy), np.uint64(ix)])  # in range: no wraparound


@njit(cache=True)
def expand_sums(
    grid: np.ndarray,
    table: np.ndarray,
    a_shift: int,
    k: np.ndarray,
    ix: np.ndarray,
    iy: np.ndarray,
    s: int,
    split: int,
    kstep: int,
    K: int,
    n: int,
    Wp: int,
    grid_up: np.ndarray,
    table_up: np.ndarray,
    threshold: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """The children of branch-and-bound nodes and their score sums in one pass
    (``_Search._children`` then ``_Search._sums`` / ``_sums_group``).

    A parent ``(k, ix, iy)`` has, for each of its ``split`` rotations ``k + r kstep < K`` (one
    when the rotation group does not split at this level), the four translations ``(ix, iy)``,
    ``(ix + s, iy)``, ``(ix, iy + s)``, ``(ix + s, iy + s)`` inside the ``n x n`` window - in
    that order, the order of ``_children``. The four children of one rotation share the pass
    over the scan's points (one read of the table row for four sums). A child's sum is
    ``sum_i grid[table[row, i] + iy_c Wp + ix_c]`` with ``row = k_c >> a_shift`` (the rotation
    group's row). Integer sums: identical to the NumPy path.

    Where a rotation group splits (``split > 1``) and ``table_up`` has rows, each sub-group
    (``row = kk >> a_shift``) is first bounded over the parent's whole translation block
    (``grid_up[table_up[row, i] + b]``: the parent's level for single rotations, the
    sub-group's dilated windows at the parent's size otherwise): when that bound,
    ``sum / (255 N)``, is not above ``threshold`` none of its four children can be (each
    child's block lies inside the parent's), so they are not generated - the caller prunes at
    that threshold anyway (pass ``-inf`` where it does not), and the search visits the same
    nodes in the same order.
    """
    use_up = split > 1 and table_up.shape[0] > 0
    P = len(k)
    cap = P * split * 4
    ck = np.empty(cap, np.int64)
    cx = np.empty(cap, np.int64)
    cy = np.empty(cap, np.int64)
    out = np.empty(cap, np.int64)
    N = table.shape[1]
    m = 0
    for p in range(P):
        x0 = ix[p]
        y0 = iy[p]
        okx = x0 + s < n
        oky = y0 + s < n
        # a child outside the window reads its sibling's cells (never out of the tables' range)
        dx = s if okx else 0
        dy = s * Wp if oky else 0
        udx, udy, udxy = np.uint64(dx), np.uint64(dy), np.uint64(dx + dy)
        for r in range(split):
            kk = k[p] + r * kstep
            if kk >= K:
                continue
            row = kk >> a_shift
            b = y0 * Wp + x0
            if use_up:
                up = 0
                for i in range(N):
                    up += grid_up[np.uint64(table_up[row, i] + b)]
                if not up / (255.0 * N) > threshold:
                    continue
            a0 = 0
            a1 = 0
            a2 = 0
            a3 = 0
            for i in range(N):  # unsigned offsets: no wraparound code (module docstring)
                f = np.uint64(table[row, i] + b)
                a0 += grid[f]
                a1 += grid[f + udx]
                a2 += grid[f + udy]
                a3 += grid[f + udxy]
            ck[m] = kk
            cx[m] = x0
            cy[m] = y0
            out[m] = a0
            m += 1
            if okx:
                ck[m] = kk
                cx[m] = x0 + s
                cy[m] = y0
                out[m] = a1
                m += 1
            if oky:
                ck[m] = kk
                cx[m] = x0
                cy[m] = y0 + s
                out[m] = a2
                m += 1
            if okx and oky:
                ck[m] = kk
                cx[m] = x0 + s
                cy[m] = y0 + s
                out[m] = a3
                m += 1
    return ck[:m], cx[:m], cy[:m], out[:m]


@njit(cache=True)
def rotated_cells(
    c: np.ndarray,
    s: np.ndarray,
    pts: np.ndarray,
    base_x: float,
    base_y: float,
    origin_x: float,
    origin_y: float,
    res: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """Cells ``floor(((R_k p_i + base) - origin) / res)`` of every point at every rotation
    ``(c[k], s[k])``: x and y ``(K, N)`` int64, and their extremes ``[min x, min y, max x,
    max y]`` - the float operations of ``_Search.__init__``'s NumPy version in the same order,
    so the same cells exactly."""
    K = len(c)
    N = pts.shape[0]
    cx = np.empty((K, N), np.int64)
    cy = np.empty((K, N), np.int64)
    ext = np.empty(4, np.int64)
    ext[0] = ext[1] = np.iinfo(np.int64).max
    ext[2] = ext[3] = np.iinfo(np.int64).min
    for k in range(K):
        ck = c[k]
        sk = s[k]
        for i in range(N):
            x = pts[i, 0]
            y = pts[i, 1]
            qx = int(np.floor(((ck * x - sk * y + base_x) - origin_x) / res))
            qy = int(np.floor(((sk * x + ck * y + base_y) - origin_y) / res))
            cx[k, i] = qx
            cy[k, i] = qy
            ext[0] = min(ext[0], qx)
            ext[1] = min(ext[1], qy)
            ext[2] = max(ext[2], qx)
            ext[3] = max(ext[3], qy)
    return cx, cy, ext


@njit(cache=True)
def flat_table(
    cx: np.ndarray,
    cy: np.ndarray,
    d: np.ndarray,
    add: np.ndarray,
    lo_x: int,
    lo_y: int,
    W: int,
    out: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """``out[k, i] = add[i] + (cy[k, i] - d[i] - lo_y) W + (cx[k, i] - d[i] - lo_x)`` (the flat
    look-up tables of ``_Search``: ``d = add = 0`` for single rotations; a rotation group's
    dilation and pyramid level otherwise), in ``out``'s integer type."""
    K, N = cx.shape
    for k in range(K):
        for i in range(N):
            out[k, i] = add[i] + (cy[k, i] - d[i] - lo_y) * W + (cx[k, i] - d[i] - lo_x)


@njit(cache=True)
def order_desc(bound: np.ndarray, scale: float) -> np.ndarray:  # pragma: no cover - compiled
    """``np.argsort(-bound, kind="stable")`` for scores ``bound = sums / scale`` of non-negative
    integer sums (the branch-and-bound's bounds): a counting sort on the sums
    ``rint(bound * scale)`` (exact: the relative error of ``bound`` is ~1e-16), largest first,
    ties in their original order - the same permutation (bins over the keys' range
    ``[min, max]`` only). Returns int64 indices, or an empty array when a sum is negative (the
    caller then sorts with NumPy)."""
    n = len(bound)
    keys = np.empty(n, np.int64)
    kmax = 0
    kmin = np.iinfo(np.int64).max
    for i in range(n):
        k = int(np.rint(bound[i] * scale))
        if k < 0:
            return np.empty(0, np.int64)
        keys[i] = k
        if k > kmax:
            kmax = k
        if k < kmin:
            kmin = k
    # bins of the keys' range only (a batch's bounds span a few % of [0, 255 N])
    nb = kmax - kmin + 1 if n else 1
    start = np.zeros(nb + 1, np.int64)
    for i in range(n):
        start[kmax - keys[i] + 1] += 1
    for j in range(1, nb + 1):
        start[j] += start[j - 1]
    out = np.empty(n, np.int64)
    for i in range(n):
        j = kmax - keys[i]
        out[start[j]] = i
        start[j] += 1
    return out


@njit(cache=True)
def _grow(a: np.ndarray, n: int) -> np.ndarray:  # pragma: no cover - compiled
    if n <= len(a):
        return a
    b = np.empty(max(n, 2 * len(a)), a.dtype)
    b[: len(a)] = a
    return b


@njit(cache=True)
def _before(k: int, x: int, y: int, bk: float, bx: float, by: float) -> bool:  # pragma: no cover
    """``(k, x, y) < (bk, bx, by)`` lexicographically: the tie-break between leaves of the same
    integer score (the lowest ``(k, ix, iy)`` wins, ``matcher._Search.run``)."""
    if k != bk:
        return k < bk
    if x != bx:
        return x < bx
    return y < by


@njit(cache=True)
def depth_first(
    flat_all: np.ndarray,
    cells: int,
    tables: np.ndarray,
    row_start: np.ndarray,
    row_stop: np.ndarray,
    a_lv: np.ndarray,
    K: int,
    n: int,
    Wp: int,
    h0: int,
    k0: np.ndarray,
    ix0: np.ndarray,
    iy0: np.ndarray,
    b0: np.ndarray,
    keep: float,
    lower: float,
    best: np.ndarray,
    seen: np.ndarray,
    budget: int,
    batch: int,
    scale: float,
):  # type: ignore[no-untyped-def]  # pragma: no cover - compiled
    """``_Search.run``'s depth-first branch-and-bound (``descend``) in one loop, an explicit
    stack of levels instead of recursion (recursive cached kernels crash, ``docs/kernels.md``).

    The same search step by step: at each level the nodes sorted by bound (descending,
    stable: :func:`order_desc`), expanded ``batch`` at a time while the batch's first bound is
    above ``keep x lower`` and the budget lasts, the children of the live nodes from
    :func:`expand_sums`, at the leaves the best leaf raising ``lower`` / ``seen`` (of equal
    scores the lowest ``(k, ix, iy)``: :func:`_before`) and every leaf above ``keep x lower``
    collected in order; other children above ``keep x lower``
    descended into at once. Level ``lv``'s table is ``tables[row_start[lv]:row_stop[lv]]``
    (its rows the rotations, or the rotation groups of ``2^a_lv[lv]``); its grid the level's
    slice of ``flat_all`` (``cells`` per level) for single rotations, ``flat_all`` itself for
    groups (their table holds the level). ``best`` and ``seen`` are ``[score, k, ix, iy]``
    (``best[0] = -inf``: none), updated in place.

    Returns ``lower, budget, evaluated`` and the collected leaves ``score, k, ix, iy``.
    """
    D = h0 + 1
    fk = [np.empty(0, np.int64) for _ in range(D)]
    fx = [np.empty(0, np.int64) for _ in range(D)]
    fy = [np.empty(0, np.int64) for _ in range(D)]
    fb = [np.empty(0, np.float64) for _ in range(D)]
    cur = np.zeros(D, np.int64)
    ls = np.empty(256, np.float64)
    lk = np.empty(256, np.int64)
    lx = np.empty(256, np.int64)
    ly = np.empty(256, np.int64)
    nl = 0
    evaluated = 0
    empty = tables[0:0]

    o = order_desc(b0, scale)
    if len(o) != len(b0):
        o = np.argsort(-b0, kind="mergesort")
    fk[h0], fx[h0], fy[h0], fb[h0] = k0[o], ix0[o], iy0[o], b0[o]
    cur[h0] = 0
    h = h0
    while h <= h0:
        k, ix, iy, b = fk[h], fx[h], fy[h], fb[h]
        a = cur[h]
        if a >= len(k) or b[a] <= keep * lower or budget <= 0:
            h += 1  # this level is done: back to its parent's next batch
            continue
        e = min(a + batch, len(k))
        cur[h] = e
        thr = keep * lower
        m = 0
        for i in range(a, e):
            if b[i] > thr:
                m += 1
        pk = np.empty(m, np.int64)
        px = np.empty(m, np.int64)
        py = np.empty(m, np.int64)
        m = 0
        for i in range(a, e):
            if b[i] > thr:
                pk[m] = k[i]
                px[m] = ix[i]
                py[m] = iy[i]
                m += 1
        lv = h - 1
        al = a_lv[lv]
        tab = tables[row_start[lv] : row_stop[lv]]
        grid = flat_all if al else flat_all[lv * cells : (lv + 1) * cells]
        split = 1 << (a_lv[h] - al)
        if al:
            grid_up, tab_up = flat_all, empty
        else:
            grid_up = flat_all[h * cells : (h + 1) * cells]
            tab_up = tab
        ck, cx, cy, sums = expand_sums(
            grid, tab, al, pk, px, py, 1 << (h - 1), split, 1 << al, K, n, Wp, grid_up,
            tab_up, thr,
        )  # fmt: skip
        nc = len(ck)
        evaluated += nc
        budget -= nc
        cb = sums / scale
        if h == 1:
            if nc:
                j = 0
                for i in range(1, nc):
                    if cb[i] > cb[j] or (
                        cb[i] == cb[j] and _before(ck[i], cx[i], cy[i], ck[j], cx[j], cy[j])
                    ):
                        j = i
                if cb[j] > seen[0] or (
                    cb[j] == seen[0] and _before(ck[j], cx[j], cy[j], seen[1], seen[2], seen[3])
                ):
                    seen[0], seen[1], seen[2], seen[3] = cb[j], ck[j], cx[j], cy[j]
                if cb[j] > lower or (
                    cb[j] == best[0] and _before(ck[j], cx[j], cy[j], best[1], best[2], best[3])
                ):
                    lower = cb[j]
                    best[0], best[1], best[2], best[3] = cb[j], ck[j], cx[j], cy[j]
                if keep < 1.0:
                    t = keep * lower
                    for i in range(nc):
                        if cb[i] > t:
                            if nl >= len(ls):
                                ls = _grow(ls, nl + 1)
                                lk = _grow(lk, nl + 1)
                                lx = _grow(lx, nl + 1)
                                ly = _grow(ly, nl + 1)
                            ls[nl], lk[nl], lx[nl], ly[nl] = cb[i], ck[i], cx[i], cy[i]
                            nl += 1
            continue
        t = keep * lower
        m = 0
        for i in range(nc):
            if cb[i] > t:
                m += 1
        if m == 0:
            continue
        sel = np.empty(m, np.int64)
        m = 0
        for i in range(nc):
            if cb[i] > t:
                sel[m] = i
                m += 1
        bb = cb[sel]
        o = order_desc(bb, scale)
        if len(o) != len(bb):
            o = np.argsort(-bb, kind="mergesort")
        so = sel[o]
        fk[lv], fx[lv], fy[lv], fb[lv] = ck[so], cx[so], cy[so], bb[o]
        cur[lv] = 0
        h = lv
    return lower, budget, evaluated, ls[:nl], lk[:nl], lx[:nl], ly[:nl]
