"""Compiled kernels of the path recorder: the loop search, the chain's updates and the freeze.

The refinement passes that close a segment are the approximator's worst case per point (issue
12): ~30 NumPy calls per pass on a few dozen pairs. :func:`refine_crossings` runs all passes in
one compiled loop with the same arithmetic, pair by pair in the order NumPy's ``nonzero`` gives
them, so it finds the same crossings in the same order. The freeze's passes (power sums,
Gauss-Legendre arc lengths, Newton projection) and the exact deviation test are loops over the
points.

Equivalence contract (``docs/kernels.md``): every kernel gives its NumPy twin's results bit for
bit, on any CPU. Both sides use only IEEE-754 operations that are correctly rounded (``+ - * /``
and ``sqrt``; no ``hypot``, ``pow``, ``sin`` or other libm / SIMD-library calls, no BLAS
products), in the same order: sums run from 0 in point order (``np.cumsum`` / in-place adds on
the NumPy side, never pairwise ``sum`` or ``@``), powers are running products, and expressions
are written with the same association. Numba compiles without ``fastmath``, so LLVM neither
reassociates nor contracts ``a * b + c`` into an FMA. The twins stay in ``fitting.py``,
``spline.py``, ``approximator.py`` and ``loops.py`` as the oracles (``tests/path/test_kernels.py``).
Numba, ``cache=True``; imported on first use.
"""

from __future__ import annotations

import numpy as np
from numba import njit

TWINS = {
    "append_search": "navkit.path.loops.LoopFreeChain.append",
    "candidate_pairs": "navkit.path.loops.LoopFreeChain._candidate_pairs",
    "cut_search": "navkit.path.loops.LoopFreeChain._cut",
    "find_crossings": "navkit.path.loops.LoopFreeChain.find_crossings",
    "fit_endpoints": "navkit.path.fitting._fit_endpoints",
    "gauss_legendre_length": "navkit.path.spline.gauss_legendre_length",
    "monotone_breaks": "navkit.path.loops.monotone_breaks",
    "natural_fit_endpoints": "navkit.path.approximator.OnlineApproximator._natural_fit",
    "power_sums": "navkit.path.fitting.power_sums",
    "project": "navkit.path.fitting.project",
    "push_segment": "navkit.path.loops.LoopFreeChain._push_segment",
    "update_leaves": "navkit.path.loops.LoopFreeChain._update_leaves",
    "within": "navkit.path.approximator.OnlineApproximator._within",
}
"""Each public kernel -> its NumPy twin (``append_search``: ``append``'s push and first
search; ``cut_search``: ``_cut`` and the next search)."""

HELPERS = ("refine_crossings", "update_tree")
"""Kernels only other kernels call, with no NumPy function of their own: the refinement passes
inside ``LoopFreeChain.find_crossings`` and the ancestors' update inside ``_update_leaves``
(compared through :func:`find_crossings`, :func:`update_leaves` and the chain's tests)."""


@njit(cache=True)
def _cubic(c: np.ndarray, u: float) -> float:  # pragma: no cover - compiled
    return c[0] + u * (c[1] + u * (c[2] + u * c[3]))


@njit(cache=True)
def _cubic2(c: np.ndarray, u: float) -> float:  # pragma: no cover - compiled
    return 2.0 * c[2] + 6.0 * c[3] * u


@njit(cache=True)
def _clip01(x: float) -> float:  # pragma: no cover - compiled
    return min(max(x, 0.0), 1.0)


@njit(cache=True)
def _segment_distance(
    p1x: float,
    p1y: float,
    q1x: float,
    q1y: float,
    p2x: float,
    p2y: float,
    q2x: float,
    q2y: float,
) -> float:  # pragma: no cover - compiled
    """``loops._segment_distance`` for one pair of segments (same formulas)."""
    d1x, d1y = q1x - p1x, q1y - p1y
    d2x, d2y = q2x - p2x, q2y - p2y
    rx, ry = p1x - p2x, p1y - p2y
    a = d1x * d1x + d1y * d1y
    e = d2x * d2x + d2y * d2y
    f = d2x * rx + d2y * ry
    c = d1x * rx + d1y * ry
    b = d1x * d2x + d1y * d2y
    tiny = 1e-300
    a_ok, e_ok = a > tiny, e > tiny
    safe_a = a if a_ok else 1.0
    safe_e = e if e_ok else 1.0
    denom = a * e - b * b
    s = _clip01((b * f - c * e) / denom) if denom > tiny else 0.0
    if not a_ok:
        s = 0.0
    t = (b * s + f) / safe_e if e_ok else 0.0
    if t < 0.0:
        s = _clip01(-c / safe_a)
    elif t > 1.0:
        s = _clip01((b - c) / safe_a)
    if not e_ok:
        s = _clip01(-c / safe_a)
    if not a_ok:
        s = 0.0
    t = _clip01(t) if e_ok else 0.0
    vx = p1x + d1x * s - p2x - d2x * t
    vy = p1y + d1y * s - p2y - d2y * t
    return np.sqrt(vx * vx + vy * vy)


@njit(cache=True)
def refine_crossings(
    sa: np.ndarray,
    sb: np.ndarray,
    ua0: np.ndarray,
    ua1: np.ndarray,
    ub0: np.ndarray,
    ub1: np.ndarray,
    ax: np.ndarray,
    ay: np.ndarray,
    s0: np.ndarray,
    f: np.ndarray,
    precision: float,
    min_loop_length: float,
    max_pairs: int,
    first_only: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:  # pragma: no cover - compiled
    """All refinement passes of ``find_crossings`` on the candidate pairs (segments ``sa``,
    ``sb``, parameter intervals ``[ua0, ua1]``, ``[ub0, ub1]``; segment coefficients ``ax``,
    ``ay`` ``(n_seg, 4)``, starts ``s0``; ``f`` the ``K + 1`` split fractions). Returns the
    crossings' ``s_a``, ``s_b``, points ``(N, 2)`` in the NumPy version's order and the number
    of passes that had to drop pairs beyond ``max_pairs``."""
    K = len(f) - 1
    n = len(sa)
    cap_found = 64
    fa = np.empty(cap_found)
    fb = np.empty(cap_found)
    fp = np.empty((cap_found, 2))
    n_found = 0
    truncated = 0
    best = np.inf
    Ua = np.empty(K + 1)
    Ub = np.empty(K + 1)
    Pa = np.empty((K + 1, 2))
    Pb = np.empty((K + 1, 2))
    acc_a = np.empty(K + 1)
    acc_b = np.empty(K + 1)
    for _ in range(100):
        if n == 0:
            break
        if n * K * K > max_pairs:
            keep = max(1, max_pairs // (K * K))
            order = np.argsort(s0[sa] + ua0, kind="mergesort")[:keep]
            sa, sb = sa[order], sb[order]
            ua0, ua1, ub0, ub1 = ua0[order], ua1[order], ub0[order], ub1[order]
            n = len(sa)
            truncated += 1
        m_cap = n * K * K
        nsa = np.empty(m_cap, np.int64)
        nsb = np.empty(m_cap, np.int64)
        nua0 = np.empty(m_cap)
        nua1 = np.empty(m_cap)
        nub0 = np.empty(m_cap)
        nub1 = np.empty(m_cap)
        nga = np.empty(m_cap)  # ga + ua[i] of each surviving sub-pair (first_only pruning)
        m = 0
        pass_best = best
        for p in range(n):
            ka, kb = sa[p], sb[p]
            da, db = ua1[p] - ua0[p], ub1[p] - ub0[p]
            for k in range(K + 1):
                Ua[k] = ua0[p] + da * f[k]
                Ub[k] = ub0[p] + db * f[k]
                Pa[k, 0] = _cubic(ax[ka], Ua[k])
                Pa[k, 1] = _cubic(ay[ka], Ua[k])
                Pb[k, 0] = _cubic(ax[kb], Ub[k])
                Pb[k, 1] = _cubic(ay[kb], Ub[k])
                x2, y2 = _cubic2(ax[ka], Ua[k]), _cubic2(ay[ka], Ua[k])
                acc_a[k] = np.sqrt(x2 * x2 + y2 * y2)
                x2, y2 = _cubic2(ax[kb], Ub[k]), _cubic2(ay[kb], Ub[k])
                acc_b[k] = np.sqrt(x2 * x2 + y2 * y2)
            ga, gb = s0[ka], s0[kb]
            dua = Ua[1] - Ua[0]
            dub = Ub[1] - Ub[0]
            for i in range(K):
                alox = min(Pa[i, 0], Pa[i + 1, 0])
                ahix = max(Pa[i, 0], Pa[i + 1, 0])
                aloy = min(Pa[i, 1], Pa[i + 1, 1])
                ahiy = max(Pa[i, 1], Pa[i + 1, 1])
                ext_a = max(ahix - alox, ahiy - aloy)
                delta_a = dua * dua / 8.0 * max(acc_a[i], acc_a[i + 1])
                for j in range(K):
                    blox = min(Pb[j, 0], Pb[j + 1, 0])
                    bhix = max(Pb[j, 0], Pb[j + 1, 0])
                    bloy = min(Pb[j, 1], Pb[j + 1, 1])
                    bhiy = max(Pb[j, 1], Pb[j + 1, 1])
                    if not (alox <= bhix and aloy <= bhiy and blox <= ahix and bloy <= ahiy):
                        continue
                    if (gb + Ub[j + 1]) - (ga + Ua[i]) < min_loop_length:
                        continue
                    gap = _segment_distance(
                        Pa[i, 0], Pa[i, 1], Pa[i + 1, 0], Pa[i + 1, 1],
                        Pb[j, 0], Pb[j, 1], Pb[j + 1, 0], Pb[j + 1, 1],
                    )  # fmt: skip
                    delta_b = dub * dub / 8.0 * max(acc_b[j], acc_b[j + 1])
                    if not gap <= delta_a + delta_b + 1e-12:
                        continue
                    ext_b = max(bhix - blox, bhiy - bloy)
                    if max(ext_a, ext_b) <= precision:
                        if n_found == len(fa):
                            fa = np.concatenate((fa, np.empty(len(fa))))
                            fb = np.concatenate((fb, np.empty(len(fb))))
                            fp = np.concatenate((fp, np.empty((len(fp), 2))))
                        s_a = ga + 0.5 * (Ua[i] + Ua[i + 1])
                        fa[n_found] = s_a
                        fb[n_found] = gb + 0.5 * (Ub[j] + Ub[j + 1])
                        fp[n_found, 0] = 0.25 * (Pa[i, 0] + Pa[i + 1, 0] + Pb[j, 0] + Pb[j + 1, 0])
                        fp[n_found, 1] = 0.25 * (Pa[i, 1] + Pa[i + 1, 1] + Pb[j, 1] + Pb[j + 1, 1])
                        n_found += 1
                        pass_best = min(pass_best, s_a)
                    else:
                        nsa[m], nsb[m] = ka, kb
                        nua0[m], nua1[m] = Ua[i], Ua[i + 1]
                        nub0[m], nub1[m] = Ub[j], Ub[j + 1]
                        nga[m] = ga + Ua[i]
                        m += 1
        best = pass_best
        if first_only and n_found > 0:  # a later-starting pair cannot give a smaller s_a
            w = 0
            for q in range(m):
                if nga[q] <= best:
                    nsa[w], nsb[w] = nsa[q], nsb[q]
                    nua0[w], nua1[w], nub0[w], nub1[w] = nua0[q], nua1[q], nub0[q], nub1[q]
                    w += 1
            m = w
        sa, sb = nsa[:m], nsb[:m]
        ua0, ua1, ub0, ub1 = nua0[:m], nua1[:m], nub0[:m], nub1[:m]
        n = m
    return fa[:n_found].copy(), fb[:n_found].copy(), fp[:n_found].copy(), truncated


@njit(cache=True)
def power_sums(
    u: np.ndarray, d: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float]:  # pragma: no cover
    """``fitting.power_sums`` in one pass: ``S (7,)`` = sums of ``u^p``, ``D (2, 4)`` = sums of
    ``d u^p``, ``Q`` = sum of ``|d|^2`` (powers by running products, sums from 0 in point order:
    the NumPy version's bits)."""
    return _power_sums_xy(u, d[:, 0], d[:, 1], len(u))


@njit(cache=True)
def gauss_legendre_length(
    ax: np.ndarray, ay: np.ndarray, u: np.ndarray, gx: np.ndarray, gw: np.ndarray
) -> np.ndarray:  # pragma: no cover - compiled
    """``spline.gauss_legendre_length`` (nodes ``gx``, weights ``gw`` on [0, 1]): the speeds at
    all nodes first (``sqrt(x'^2 + y'^2)``, a loop LLVM vectorises), each interval's weighted
    sum node by node from 0, then the running sum in point order: the NumPy version's bits."""
    n = len(u)
    speed = np.empty(n * len(gx))
    out = np.zeros(n)
    _gauss_legendre_into(ax, ay, u, n, gx, gw, speed, out)
    return out


@njit(cache=True)
def _project_one(
    c: np.ndarray, u0: float, px: float, py: float, iterations: int
) -> tuple[float, float]:  # pragma: no cover - compiled
    """``fitting.project`` for one point ``(px, py)`` from ``u0``: (u, distance)."""
    ui = min(max(u0, 0.0), 1.0)
    u = ui
    for _ in range(iterations):
        rx = c[0, 0] + u * (c[0, 1] + u * (c[0, 2] + u * c[0, 3])) - px
        ry = c[1, 0] + u * (c[1, 1] + u * (c[1, 2] + u * c[1, 3])) - py
        dx = c[0, 1] + u * (2 * c[0, 2] + 3 * c[0, 3] * u)
        dy = c[1, 1] + u * (2 * c[1, 2] + 3 * c[1, 3] * u)
        ddx = 2 * c[0, 2] + 6 * c[0, 3] * u
        ddy = 2 * c[1, 2] + 6 * c[1, 3] * u
        g = rx * dx + ry * dy
        H = dx * dx + dy * dy + rx * ddx + ry * ddy
        step = g / H if H > 1e-300 else 0.0
        u = min(max(u - step, 0.0), 1.0)
    ex = c[0, 0] + u * (c[0, 1] + u * (c[0, 2] + u * c[0, 3])) - px
    ey = c[1, 0] + u * (c[1, 1] + u * (c[1, 2] + u * c[1, 3])) - py
    r_new = np.sqrt(ex * ex + ey * ey)
    ex = c[0, 0] + ui * (c[0, 1] + ui * (c[0, 2] + ui * c[0, 3])) - px
    ey = c[1, 0] + ui * (c[1, 1] + ui * (c[1, 2] + ui * c[1, 3])) - py
    r_old = np.sqrt(ex * ex + ey * ey)
    if r_new <= r_old:
        return u, r_new
    return ui, r_old


@njit(cache=True)
def project(
    c: np.ndarray, u0: np.ndarray, d: np.ndarray, iterations: int
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """``fitting.project`` (the same Newton steps and formulas), one Newton step over all points
    at a time in branch-free loops LLVM vectorises; distances as ``sqrt(dx^2 + dy^2)``, as
    ``fitting.residuals`` computes them: the NumPy version's bits)."""
    n = len(u0)
    X = np.empty(n)  # the points' coordinates as two contiguous arrays: the loops vectorise
    Y = np.empty(n)  # (4x faster than reading the (n, 2) rows)
    for i in range(n):
        X[i] = d[i, 0]
        Y[i] = d[i, 1]
    ui = np.empty(n)
    u = np.empty(n)
    dist = np.empty(n)
    _project_into(c, u0, X, Y, n, iterations, ui, u, dist)
    return u, dist


@njit(cache=True)
def within(
    c: np.ndarray, tau: np.ndarray, buf: np.ndarray, n: int, limit: float, geometric: bool
) -> bool:  # pragma: no cover - compiled
    """The exact deviation test of ``OnlineApproximator._push`` on buffer rows ``[0, n)``
    (points ``buf - buf[0]`` at ``u = tau / tau[n - 1]``): every residual ``|C(u_i) - d_i|``
    (``fitting.residuals``) within ``limit``, or, with ``geometric``, every point beyond it
    within ``limit`` of the curve (``fitting.project``, 3 Newton steps). The same formulas
    point by point; stops at the first point that fails (only the verdict is used).

    The points are visited from the last one back (each point's verdict does not depend on the
    others, so neither does the answer): the point that ends a segment is usually the new one
    or close to it, and the points before it passed the test before. The residual is
    ``sqrt(ex^2 + ey^2)``, the NumPy twin's arithmetic, so both reach the same verdict on every
    CPU."""
    T = tau[n - 1]
    x0, y0 = buf[0, 0], buf[0, 1]
    for i in range(n - 1, -1, -1):
        u = tau[i] / T
        px, py = buf[i, 0] - x0, buf[i, 1] - y0
        ex = c[0, 0] + u * (c[0, 1] + u * (c[0, 2] + u * c[0, 3])) - px
        ey = c[1, 0] + u * (c[1, 1] + u * (c[1, 2] + u * c[1, 3])) - py
        r = np.sqrt(ex * ex + ey * ey)
        if r <= limit:
            continue
        if not geometric or not r > limit:  # (NaN: not from finite points) rejected
            return False
        _, dist = _project_one(c, u, px, py, 3)
        if not dist <= limit:
            return False
    return True


@njit(cache=True)
def update_tree(lo: np.ndarray, hi: np.ndarray, a: int, b: int) -> None:  # pragma: no cover
    """Ancestors of the leaves ``[a, b)`` of the box tree (``lo``, ``hi`` ``(2 cap, 2)``, leaves
    at ``[cap, 2 cap)``, already written): each node the min / max of its two children, level
    by level (``LoopFreeChain._update_leaves``; exact, the same boxes)."""
    lo_n, hi_n = a, b - 1
    while lo_n > 1:
        lo_n //= 2
        hi_n //= 2
        for node in range(lo_n, hi_n + 1):
            for c in range(2):
                lo[node, c] = min(lo[2 * node, c], lo[2 * node + 1, c])
                hi[node, c] = max(hi[2 * node, c], hi[2 * node + 1, c])


@njit(cache=True)
def candidate_pairs(
    lo: np.ndarray, hi: np.ndarray, cap: int, first: int, n_piece: int
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """``LoopFreeChain._candidate_pairs``: (older, newer) piece pairs whose boxes overlap, newer
    pieces ``>= first``, by depth-first descent of the box tree (the same pairs in the same
    order: newer piece, then older piece, increasing)."""
    out_a = np.empty(64, np.int64)
    out_b = np.empty(64, np.int64)
    n = 0
    stack = np.empty(128, np.int64)
    for q in range(first, n_piece):
        leaf = q + cap
        qlx, qly, qhx, qhy = lo[leaf, 0], lo[leaf, 1], hi[leaf, 0], hi[leaf, 1]
        top = 0
        stack[0] = 1
        top = 1
        while top > 0:
            top -= 1
            node = stack[top]
            if not (
                lo[node, 0] <= qhx
                and lo[node, 1] <= qhy
                and qlx <= hi[node, 0]
                and qly <= hi[node, 1]
            ):
                continue
            if node >= cap:
                older = node - cap
                if older < q:
                    if n == len(out_a):
                        out_a = np.concatenate((out_a, np.empty(n, np.int64)))
                        out_b = np.concatenate((out_b, np.empty(n, np.int64)))
                    out_a[n] = older
                    out_b[n] = q
                    n += 1
                continue
            if top + 2 > len(stack):
                stack = np.concatenate((stack, np.empty(len(stack), np.int64)))
            stack[top] = 2 * node + 1  # right child below: the left one is visited first
            stack[top + 1] = 2 * node
            top += 2
    return out_a[:n].copy(), out_b[:n].copy()


@njit(cache=True)
def update_leaves(
    lo: np.ndarray,
    hi: np.ndarray,
    cap: int,
    a: int,
    b: int,
    n_piece: int,
    pseg: np.ndarray,
    pu0: np.ndarray,
    pu1: np.ndarray,
    ax: np.ndarray,
    ay: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """``LoopFreeChain._update_leaves`` once the tree is large enough: the boxes of pieces
    ``[a, b)`` (end points of each monotone piece; empty boxes beyond ``n_piece``), then their
    ancestors (:func:`update_tree`)."""
    for idx in range(a, b):
        leaf = idx + cap
        if idx < n_piece:
            k = pseg[idx]
            x0, y0 = _cubic(ax[k], pu0[idx]), _cubic(ay[k], pu0[idx])
            x1, y1 = _cubic(ax[k], pu1[idx]), _cubic(ay[k], pu1[idx])
            lo[leaf, 0], hi[leaf, 0] = min(x0, x1), max(x0, x1)
            lo[leaf, 1], hi[leaf, 1] = min(y0, y1), max(y0, y1)
        else:
            lo[leaf, 0] = lo[leaf, 1] = np.inf
            hi[leaf, 0] = hi[leaf, 1] = -np.inf
    update_tree(lo, hi, a + cap, b + cap)


@njit(cache=True)
def find_crossings(
    lo: np.ndarray,
    hi: np.ndarray,
    cap: int,
    first_piece: int,
    n_piece: int,
    pseg: np.ndarray,
    pu0: np.ndarray,
    pu1: np.ndarray,
    ax: np.ndarray,
    ay: np.ndarray,
    s0: np.ndarray,
    f: np.ndarray,
    precision: float,
    min_loop_length: float,
    max_pairs: int,
    first_only: bool,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:  # pragma: no cover - compiled
    """``LoopFreeChain.find_crossings`` from the first piece of the new segments on, in one
    call: :func:`candidate_pairs`, the pairs' parameter intervals (neighbouring pieces trimmed
    by ``min_loop_length / 2`` on each side of their shared end, empty intervals dropped: the
    NumPy version's ``np.where`` / mask, pair by pair) and :func:`refine_crossings`."""
    ia, ib = candidate_pairs(lo, hi, cap, first_piece, n_piece)
    n = len(ia)
    sa = np.empty(n, np.int64)
    sb = np.empty(n, np.int64)
    ua0 = np.empty(n)
    ua1 = np.empty(n)
    ub0 = np.empty(n)
    ub1 = np.empty(n)
    m = 0.5 * min_loop_length
    w = 0
    for p in range(n):
        a, b = ia[p], ib[p]
        a0, a1, b0, b1 = pu0[a], pu1[a], pu0[b], pu1[b]
        if b == a + 1:
            a1 = a1 - m
            b0 = b0 + m
        if a1 > a0 and b1 > b0:
            sa[w], sb[w] = pseg[a], pseg[b]
            ua0[w], ua1[w], ub0[w], ub1[w] = a0, a1, b0, b1
            w += 1
    return refine_crossings(
        sa[:w], sb[:w], ua0[:w], ua1[:w], ub0[:w], ub1[:w], ax, ay, s0, f,
        precision, min_loop_length, max_pairs, first_only,
    )  # fmt: skip


# ---------------------------------------------------------------------- the chain's updates
@njit(cache=True)
def _quadratic_roots(
    a: float, b: float, c: float, out: np.ndarray, n: int
) -> int:  # pragma: no cover
    """``loops._quadratic_roots`` appending to ``out`` from index ``n``; returns the new count."""
    if abs(a) < 1e-300:
        if abs(b) > 1e-300:
            out[n] = -c / b
            return n + 1
        return n
    disc = b * b - 4.0 * a * c
    if disc < 0:
        return n
    q = -0.5 * (b + np.copysign(np.sqrt(disc), b))
    out[n] = q / a
    n += 1
    if abs(q) > 1e-300:
        out[n] = c / q
        n += 1
    return n


@njit(cache=True)
def monotone_breaks(
    ax: np.ndarray, ay: np.ndarray, length: float
) -> np.ndarray:  # pragma: no cover
    """``loops.monotone_breaks`` (the same roots, order and tolerance): ``0 = u_0 < ... < u_m =
    length`` with at most 4 inner breaks."""
    roots = np.empty(4)
    n = _quadratic_roots(3.0 * ax[3], 2.0 * ax[2], ax[1], roots, 0)
    n = _quadratic_roots(3.0 * ay[3], 2.0 * ay[2], ay[1], roots, n)
    inner = np.empty(4)
    m = 0
    for i in range(n):  # keep 0 < r < length, insertion-sorted
        r = roots[i]
        if 0.0 < r < length:
            j = m
            while j > 0 and inner[j - 1] > r:
                inner[j] = inner[j - 1]
                j -= 1
            inner[j] = r
            m += 1
    tol = 1e-12 * max(length, 1.0)
    cuts = np.empty(m + 2)
    cuts[0] = 0.0
    w = 1
    for i in range(m):
        r = inner[i]
        if r - cuts[w - 1] > tol and length - r > tol:
            cuts[w] = r
            w += 1
    cuts[w] = length
    return cuts[: w + 1]


@njit(cache=True)
def push_segment(
    seg_ax: np.ndarray,
    seg_ay: np.ndarray,
    seg_len: np.ndarray,
    s0: np.ndarray,
    first_piece: np.ndarray,
    pseg: np.ndarray,
    pu0: np.ndarray,
    pu1: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    cap: int,
    n_seg: int,
    n_piece: int,
    ax: np.ndarray,
    ay: np.ndarray,
    length: float,
) -> int:  # pragma: no cover - compiled
    """``LoopFreeChain._push_segment``: segment ``n_seg`` := ``(ax, ay, length)`` starting at the
    chain's end, its monotone pieces appended after piece ``n_piece`` and their leaves and
    ancestors updated. The caller has made room (segments, at most 5 pieces, tree capacity).
    Returns the new piece count."""
    k = n_seg
    for c in range(4):
        seg_ax[k, c] = ax[c]
        seg_ay[k, c] = ay[c]
    seg_len[k] = length
    s0[k] = s0[k - 1] + seg_len[k - 1] if k > 0 else 0.0
    breaks = monotone_breaks(ax, ay, length)
    a = n_piece
    b = n_piece + len(breaks) - 1
    first_piece[k] = a
    for i in range(a, b):
        pseg[i] = k
        pu0[i] = breaks[i - a]
        pu1[i] = breaks[i - a + 1]
    first_piece[k + 1] = b
    update_leaves(lo, hi, cap, a, b, b, pseg, pu0, pu1, seg_ax, seg_ay)
    return b


@njit(cache=True)
def _cubic_shift(c: np.ndarray, u0: float) -> np.ndarray:  # pragma: no cover - compiled
    """``spline.cubic_shift`` (the same formulas)."""
    out = np.empty(4)
    out[0] = c[0] + u0 * (c[1] + u0 * (c[2] + u0 * c[3]))
    out[1] = c[1] + u0 * (2.0 * c[2] + 3.0 * c[3] * u0)
    out[2] = c[2] + 3.0 * c[3] * u0
    out[3] = c[3]
    return out


@njit(cache=True)
def _locate(s0: np.ndarray, seg_len: np.ndarray, n_seg: int, s: float) -> tuple[int, float]:
    """``LoopFreeChain._locate``: ``bisect_right(s0[:n_seg], s) - 1`` clipped to a segment, and
    the offset in it clipped to its length."""  # pragma: no cover - compiled
    lo_i, hi_i = 0, n_seg
    while lo_i < hi_i:
        mid = (lo_i + hi_i) // 2
        if s < s0[mid]:
            hi_i = mid
        else:
            lo_i = mid + 1
    k = min(max(lo_i - 1, 0), n_seg - 1)
    return k, min(max(s - s0[k], 0.0), seg_len[k])


@njit(cache=True)
def _first_crossing(
    lo: np.ndarray,
    hi: np.ndarray,
    cap: int,
    first: int,
    n_piece: int,
    pseg: np.ndarray,
    pu0: np.ndarray,
    pu1: np.ndarray,
    ax: np.ndarray,
    ay: np.ndarray,
    s0: np.ndarray,
    f: np.ndarray,
    precision: float,
    min_loop_length: float,
    max_pairs: int,
) -> tuple[bool, float, float, float, float, int]:  # pragma: no cover - compiled
    """:func:`find_crossings` with ``first_only`` and ``LoopFreeChain._crossings``' choice (the
    smallest ``s_a``, then the largest ``s_b``, then the first found: ``np.lexsort``'s first):
    (found, s_a, s_b, x, y, truncated passes)."""
    A, B, P, truncated = find_crossings(
        lo, hi, cap, first, n_piece, pseg, pu0, pu1, ax, ay, s0, f,
        precision, min_loop_length, max_pairs, True,
    )  # fmt: skip
    if len(A) == 0:
        return False, 0.0, 0.0, 0.0, 0.0, truncated
    k = 0
    for i in range(1, len(A)):
        if A[i] < A[k] or (A[i] == A[k] and B[i] > B[k]):
            k = i
    return True, A[k], B[k], P[k, 0], P[k, 1], truncated


@njit(cache=True)
def append_search(
    seg_ax: np.ndarray,
    seg_ay: np.ndarray,
    seg_len: np.ndarray,
    s0: np.ndarray,
    first_piece: np.ndarray,
    pseg: np.ndarray,
    pu0: np.ndarray,
    pu1: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    cap: int,
    n_seg: int,
    n_piece: int,
    ax: np.ndarray,
    ay: np.ndarray,
    length: float,
    f: np.ndarray,
    precision: float,
    min_loop_length: float,
    max_pairs: int,
    search: bool,
) -> tuple[int, bool, float, float, float, float, int]:  # pragma: no cover - compiled
    """``LoopFreeChain.append``'s first step in one call: :func:`push_segment`, then (with
    ``search``) the first crossing of the new segment's pieces (:func:`_first_crossing`).
    Returns (piece count, found, s_a, s_b, x, y, truncated passes)."""
    n_new = push_segment(
        seg_ax, seg_ay, seg_len, s0, first_piece, pseg, pu0, pu1, lo, hi, cap, n_seg, n_piece,
        ax, ay, length,
    )  # fmt: skip
    if not search:
        return n_new, False, 0.0, 0.0, 0.0, 0.0, 0
    m = n_seg + 1
    found, sa, sb, x, y, tr = _first_crossing(
        lo, hi, cap, first_piece[n_seg], n_new, pseg, pu0, pu1, seg_ax[:m], seg_ay[:m], s0[:m],
        f, precision, min_loop_length, max_pairs,
    )  # fmt: skip
    return n_new, found, sa, sb, x, y, tr


@njit(cache=True)
def cut_search(
    seg_ax: np.ndarray,
    seg_ay: np.ndarray,
    seg_len: np.ndarray,
    s0: np.ndarray,
    first_piece: np.ndarray,
    pseg: np.ndarray,
    pu0: np.ndarray,
    pu1: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    cap: int,
    n_seg: int,
    n_piece: int,
    s_a: float,
    s_b: float,
    f: np.ndarray,
    precision: float,
    min_loop_length: float,
    max_pairs: int,
) -> tuple[int, int, int, bool, float, float, float, float, int]:  # pragma: no cover - compiled
    """``LoopFreeChain._cut`` and the next search in one call: locate ``s_a`` and ``s_b``, drop
    the segments from the one holding ``s_a`` on (their leaves emptied), push the part of that
    segment before ``s_a`` (if longer than 1e-12) and the part of the one holding ``s_b`` after
    it (``cubic_shift``'s formulas), then look for the first crossing of that last segment.
    The caller has made room for 2 more segments and 10 more pieces. Returns (index of the
    segment holding ``s_b`` before the cut, segment count, piece count, found, s_a, s_b, x, y,
    truncated passes)."""
    ka, ua = _locate(s0, seg_len, n_seg, s_a)
    kb, ub = _locate(s0, seg_len, n_seg, s_b)
    tx = _cubic_shift(seg_ax[kb], ub)
    ty = _cubic_shift(seg_ay[kb], ub)
    t_len = seg_len[kb] - ub
    hx = seg_ax[ka].copy()
    hy = seg_ay[ka].copy()
    # truncate to ka segments: their pieces' leaves become empty boxes
    first = first_piece[ka]
    if n_piece > first:
        update_leaves(lo, hi, cap, first, n_piece, first, pseg, pu0, pu1, seg_ax, seg_ay)
    n_seg, n_piece = ka, first
    if ua > 1e-12:
        n_piece = push_segment(
            seg_ax, seg_ay, seg_len, s0, first_piece, pseg, pu0, pu1, lo, hi, cap, n_seg,
            n_piece, hx, hy, ua,
        )  # fmt: skip
        n_seg += 1
    k = n_seg
    n_piece = push_segment(
        seg_ax, seg_ay, seg_len, s0, first_piece, pseg, pu0, pu1, lo, hi, cap, n_seg, n_piece,
        tx, ty, t_len,
    )  # fmt: skip
    n_seg += 1
    found, sa, sb, x, y, tr = _first_crossing(
        lo, hi, cap, first_piece[k], n_piece, pseg, pu0, pu1, seg_ax[:n_seg], seg_ay[:n_seg],
        s0[:n_seg], f, precision, min_loop_length, max_pairs,
    )  # fmt: skip
    return kb, n_seg, n_piece, found, sa, sb, x, y, tr


# ---------------------------------------------------------------------- the freeze
@njit(cache=True)
def fit_endpoints(
    S: np.ndarray, D: np.ndarray, Q: float, ex: float, ey: float
) -> tuple[bool, np.ndarray, float]:  # pragma: no cover - compiled
    """``fitting._fit_endpoints`` (the same operations in the same order): (solved, coef
    ``(2, 4)``, ssr); not solved on a degenerate grid (the caller falls back to
    ``fitting._fit_general``)."""
    S2, S3, S4, S5, S6 = S[2], S[3], S[4], S[5], S[6]
    k1x, k1y, k2x, k2y = ex, ey, 0.0, 0.0
    rr = (
        Q
        - 2.0 * (k1x * D[0, 1] + k1y * D[1, 1] + k2x * D[0, 2] + k2y * D[1, 2])
        + (k1x * k1x + k1y * k1y) * S2
        + 2.0 * (k1x * k2x + k1y * k2y) * S3
        + (k2x * k2x + k2y * k2y) * S4
    )
    Rx1 = D[0, 1] - k1x * S2 - k2x * S3
    Rx2 = D[0, 2] - k1x * S3 - k2x * S4
    Rx3 = D[0, 3] - k1x * S4 - k2x * S5
    Ry1 = D[1, 1] - k1y * S2 - k2y * S3
    Ry2 = D[1, 2] - k1y * S3 - k2y * S4
    Ry3 = D[1, 3] - k1y * S4 - k2y * S5
    g00 = S4 - 2 * S3 + S2
    g01 = S5 - S4 - S3 + S2
    g11 = S6 - 2 * S4 + S2
    bx0, bx1 = Rx2 - Rx1, Rx3 - Rx1
    by0, by1 = Ry2 - Ry1, Ry3 - Ry1
    det = g00 * g11 - g01 * g01
    diag = g00 * g11
    coef = np.zeros((2, 4))
    if diag > 0 and det > 1e-13 * diag:
        cx0 = (bx0 * g11 - g01 * bx1) / det
        cx1 = (g00 * bx1 - bx0 * g01) / det
        cy0 = (by0 * g11 - g01 * by1) / det
        cy1 = (g00 * by1 - by0 * g01) / det
        coef[0, 1], coef[0, 2], coef[0, 3] = k1x - cx0 - cx1, k2x + cx0, 0.0 + cx1
        coef[1, 1], coef[1, 2], coef[1, 3] = k1y - cy0 - cy1, k2y + cy0, 0.0 + cy1
        ssr = rr - (0 + (cx0 * bx0 + cy0 * by0) + (cx1 * bx1 + cy1 * by1))
        return True, coef, max(ssr, 0.0)
    return False, coef, 0.0


# rows of the freeze's workspace (``natural_fit_endpoints``; ``OnlineApproximator._work``)
W_X, W_Y, W_U, W_S, W_US, W_UP, W_DIST, W_UP2, W_DIST2, W_UI, W_OUT = range(11)
W_ROWS = 11


@njit(cache=True)
def _power_sums_xy(
    u: np.ndarray, X: np.ndarray, Y: np.ndarray, n: int
) -> tuple[np.ndarray, np.ndarray, float]:  # pragma: no cover - compiled
    """:func:`power_sums` of the points ``(X[i], Y[i])``, ``i < n`` (the same sums in the same
    order)."""
    S = np.zeros(7)
    D = np.zeros((2, 4))
    Q = 0.0
    for i in range(n):
        x = u[i]
        p = 1.0
        for k in range(7):
            S[k] += p
            if k < 4:
                D[0, k] += X[i] * p
                D[1, k] += Y[i] * p
            p *= x
        Q += X[i] * X[i] + Y[i] * Y[i]
    return S, D, Q


@njit(cache=True)
def _gauss_legendre_into(
    ax: np.ndarray,
    ay: np.ndarray,
    u: np.ndarray,
    n: int,
    gx: np.ndarray,
    gw: np.ndarray,
    speed: np.ndarray,
    out: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """:func:`gauss_legendre_length` of ``u[:n]`` into ``out[:n]`` (``speed``: scratch of
    ``len(gx) n``): node by node over all intervals (a contiguous loop over the intervals
    LLVM vectorises; interval by interval the 5 nodes would be a short loop it does not);
    each interval's weighted sum adds its nodes in order from 0, then the running sum in point
    order: the same numbers."""
    m = len(gx)
    for k in range(m):
        g = gx[k]
        row = k * n
        for i in range(1, n):
            h = u[i] - u[i - 1]
            t = u[i - 1] + h * g
            dx = ax[1] + t * (2.0 * ax[2] + 3.0 * ax[3] * t)
            dy = ay[1] + t * (2.0 * ay[2] + 3.0 * ay[3] * t)
            speed[row + i] = np.sqrt(dx * dx + dy * dy)
    for i in range(n):  # out[i]: interval i's weighted sum of speeds, then the running sum
        out[i] = 0.0
    for k in range(m):
        w = gw[k]
        row = k * n
        for i in range(1, n):
            out[i] += speed[row + i] * w
    acc = 0.0
    for i in range(1, n):
        acc += (u[i] - u[i - 1]) * out[i]
        out[i] = acc


@njit(cache=True)
def _project_into(
    c: np.ndarray,
    u0: np.ndarray,
    X: np.ndarray,
    Y: np.ndarray,
    n: int,
    iterations: int,
    ui: np.ndarray,
    u: np.ndarray,
    dist: np.ndarray,
) -> None:  # pragma: no cover - compiled
    """:func:`project` of the points ``(X[i], Y[i])``, ``i < n``, into ``u[:n]``, ``dist[:n]``
    (``ui``: scratch; the same loops)."""
    c00, c01, c02, c03 = c[0, 0], c[0, 1], c[0, 2], c[0, 3]
    c10, c11, c12, c13 = c[1, 0], c[1, 1], c[1, 2], c[1, 3]
    for i in range(n):
        ui[i] = min(max(u0[i], 0.0), 1.0)
        u[i] = ui[i]
    for _ in range(iterations):
        for i in range(n):
            x = u[i]
            px, py = X[i], Y[i]
            rx = c00 + x * (c01 + x * (c02 + x * c03)) - px
            ry = c10 + x * (c11 + x * (c12 + x * c13)) - py
            dx = c01 + x * (2 * c02 + 3 * c03 * x)
            dy = c11 + x * (2 * c12 + 3 * c13 * x)
            ddx = 2 * c02 + 6 * c03 * x
            ddy = 2 * c12 + 6 * c13 * x
            g = rx * dx + ry * dy
            H = dx * dx + dy * dy + rx * ddx + ry * ddy
            ok = H > 1e-300
            step = g / (H if ok else 1.0)
            u[i] = min(max(x - (step if ok else 0.0), 0.0), 1.0)
    for i in range(n):
        x, x0 = u[i], ui[i]
        px, py = X[i], Y[i]
        ex = c00 + x * (c01 + x * (c02 + x * c03)) - px
        ey = c10 + x * (c11 + x * (c12 + x * c13)) - py
        r_new = np.sqrt(ex * ex + ey * ey)
        ex = c00 + x0 * (c01 + x0 * (c02 + x0 * c03)) - px
        ey = c10 + x0 * (c11 + x0 * (c12 + x0 * c13)) - py
        r_old = np.sqrt(ex * ex + ey * ey)
        better = r_new <= r_old
        u[i] = x if better else x0
        dist[i] = r_new if better else r_old


@njit(cache=True)
def natural_fit_endpoints(
    buf: np.ndarray,
    tau: np.ndarray,
    n: int,
    gx: np.ndarray,
    gw: np.ndarray,
    eps: float,
    W: np.ndarray,
    speed: np.ndarray,
) -> tuple[bool, bool, float, float, np.ndarray, float, float, np.ndarray]:  # pragma: no cover
    """``OnlineApproximator._natural_fit`` for the ``endpoints`` variant (4 or more points) in
    one call: the points ``buf[:n] - buf[0]``, the fit over ``t`` (power sums,
    :func:`fit_endpoints`), its arc lengths (Gauss-Legendre), the refit over them and the
    projection - the loops of :func:`power_sums`, :func:`gauss_legendre_length` and
    :func:`project` in the same order, without the Python steps and 5 kernel calls between
    them, and in the caller's workspace ``W`` (rows ``W_*``, ``n`` columns used; ``speed``:
    ``5 n``, the Gauss-Legendre nodes) instead of ~25 fresh arrays of up to ``5 n`` numbers
    (their page faults would be a good part of the freeze's cost). When a distance exceeds ``eps``
    the fallback's projection (``OnlineApproximator._scaled_t_fit``: the fit over ``t`` at
    its own ``u``) is computed too (rows ``W_UP2``, ``W_DIST2``). Returns (solved, fallback
    computed, T_t, ssr_t, coef_t, T_s, ssr_s, coef_s); not solved (a degenerate grid): the
    caller takes the general route."""
    X, Y, u, s, us = W[W_X], W[W_Y], W[W_U], W[W_S], W[W_US]
    x0, y0 = buf[0, 0], buf[0, 1]
    for i in range(n):
        X[i] = buf[i, 0] - x0
        Y[i] = buf[i, 1] - y0
    T = tau[n - 1]
    for i in range(n):
        u[i] = tau[i] / T if T > 0 else 0.0
    ex, ey = X[n - 1], Y[n - 1]
    S, D, Q = _power_sums_xy(u, X, Y, n)
    ok, coef_t, ssr_t = fit_endpoints(S, D, Q, ex, ey)
    if not ok:
        return False, False, T, 0.0, coef_t, 0.0, 0.0, coef_t
    _gauss_legendre_into(coef_t[0], coef_t[1], u, n, gx, gw, speed, s)
    T_s = s[n - 1]
    for i in range(n):
        us[i] = s[i] / T_s if T_s > 0 else 0.0
    S, D, Q = _power_sums_xy(us, X, Y, n)
    ok, coef_s, ssr_s = fit_endpoints(S, D, Q, ex, ey)
    if not ok:
        return False, False, T, ssr_t, coef_t, T_s, 0.0, coef_s
    dist = W[W_DIST]
    _project_into(coef_s, us, X, Y, n, 3, W[W_UI], W[W_UP], dist)
    far = False
    for i in range(n):
        far = far or dist[i] > eps
    if far:
        _project_into(coef_t, u, X, Y, n, 3, W[W_UI], W[W_UP2], W[W_DIST2])
    return True, far, T, ssr_t, coef_t, T_s, ssr_s, coef_s
