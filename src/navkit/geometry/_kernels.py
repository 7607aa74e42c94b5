"""Compiled (Numba) kernels of the bounding shapes (:mod:`navkit.geometry.shapes`).

Each kernel repeats its NumPy twin's IEEE operations in the same order, set by set, so both
give the same bits on any CPU: no fused multiply-add (Numba without ``fastmath``), every sum in
index order, ``sqrt(x^2 + y^2)`` for ``hypot`` and ``atan2``, ``sin``, ``cos``, ``exp``, ``log``
with one fixed arithmetic (the scalar functions of :mod:`navkit.geometry._kernels_math`); see
``docs/kernels.md`` ("Equivalence contract: geometry"). Numba's cache of a kernel here does not
see a change to those functions: touch this file (or clear the cache) after changing them.
:func:`~navkit.geometry.shapes.compute_shapes`, :func:`~navkit.geometry.shapes.mvee_batch` and
:func:`~navkit.geometry.shapes.ellipses_a6_batch` run them when :mod:`navkit.jit` says so
(``navkit.jit.use``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from navkit.geometry._kernels_math import _atan2, _exp, _log, _sincos

__all__ = [
    "a6_csr_kernel",
    "a6_search_kernel",
    "basic_shapes_kernel",
    "hulls_csr_kernel",
    "mvee_csr_kernel",
    "mvee_weights_kernel",
]

TWINS = {
    "a6_csr_kernel": "navkit.geometry.shapes.ellipses_a6_batch",
    "a6_search_kernel": "navkit.geometry.shapes.ellipses_a6_batch",
    "basic_shapes_kernel": "navkit.geometry.shapes.compute_shapes",
    "hulls_csr_kernel": "navkit.geometry.shapes.hull_points",
    "mvee_csr_kernel": "navkit.geometry.shapes.mvee_batch",
    "mvee_weights_kernel": "navkit.geometry.shapes.mvee_batch",
}
"""Each public kernel -> its NumPy twin (``basic_shapes_kernel``: the set-by-set shapes A1-A5
and Welzl's circle of :func:`~navkit.geometry.shapes.compute_shapes`' twin)."""


@njit(cache=True, error_model="numpy")
def _mvee_weights(P, tol, max_iter):  # type: ignore[no-untyped-def]
    """Khachiyan / Todd-Yildirim weights ``u (m,)`` of one centred, scaled set ``P (m, 2)``.

    Three passes over the points per iteration: the moments (with the previous step's clamp
    of negative weights to 0), the Mahalanobis terms with the largest and the smallest (over
    the positive weights) in one pass, and the step; the same values as separate passes."""
    m = P.shape[0]
    d = 2
    u = np.full(m, 1.0 / m)
    for _ in range(max_iter):
        m0 = 0.0
        m1 = 0.0
        m2 = 0.0
        m3 = 0.0
        m4 = 0.0
        for k in range(m):
            w = u[k]
            if w < 0.0:  # the previous step's clamp
                w = 0.0
                u[k] = 0.0
            x, y = P[k, 0], P[k, 1]
            m0 += x * w
            m1 += y * w
            m2 += x * x * w
            m3 += x * y * w
            m4 += y * y * w
        cx, cy = m0, m1
        sxx, sxy, syy = m2 - cx * cx, m3 - cx * cy, m4 - cy * cy
        det = max(sxx * syy - sxy * sxy, 1e-300)
        j_up = 0
        j_dn = -1
        M_up = 0.0
        best = np.inf
        for k in range(m):
            dx = P[k, 0] - cx
            dy = P[k, 1] - cy
            Mk = 1.0 + (syy * dx * dx - 2.0 * sxy * dx * dy + sxx * dy * dy) / det
            if k == 0 or Mk > M_up or (Mk != Mk and M_up == M_up):
                j_up = k
                M_up = Mk
            v = Mk if u[k] > 0 else np.inf
            if j_dn < 0 or v < best or (v != v and best == best):
                j_dn = k
                best = v
        M_dn = best if u[j_dn] > 0 else _mahalanobis(P, j_dn, cx, cy, sxx, sxy, syy, det)
        eps_up = M_up / (d + 1) - 1
        eps_dn = 1 - M_dn / (d + 1)
        worst = eps_up if (eps_up != eps_up or eps_up >= eps_dn) else eps_dn
        if eps_dn != eps_dn:
            worst = eps_dn
        if worst <= tol:
            break
        if eps_up >= eps_dn:
            beta = (M_up - d - 1) / ((d + 1) * (M_up - 1))
            f = 1 - beta
            for k in range(m):
                u[k] *= f
            u[j_up] += beta
        else:
            u_dn = u[j_dn]
            b1 = (d + 1 - M_dn) / ((d + 1) * (M_dn - 1))
            b2 = u_dn / (1 - u_dn)
            beta = b1 if (b1 != b1 or b1 <= b2) else b2
            if b2 != b2:
                beta = b2
            if not np.isfinite(beta):
                beta = 0.0
            f = 1 + beta
            for k in range(m):
                u[k] *= f
            u[j_dn] -= beta
    for k in range(m):
        if u[k] < 0.0:
            u[k] = 0.0
    return u


@njit(cache=True, error_model="numpy", inline="always")
def _mahalanobis(P, k, cx, cy, sxx, sxy, syy, det):  # type: ignore[no-untyped-def]
    """The term ``M[k]`` of :func:`_mvee_weights`."""
    dx = P[k, 0] - cx
    dy = P[k, 1] - cy
    return 1.0 + (syy * dx * dx - 2.0 * sxy * dx * dy + sxx * dy * dy) / det


@njit(cache=True, error_model="numpy")
def mvee_weights_kernel(P, mask, tol, max_iter):  # type: ignore[no-untyped-def]
    """Khachiyan / Todd-Yildirim weights ``u (n, m)`` of ``mvee_batch``'s loop, set by set.

    ``P (n, m, 2)`` are the centred, scaled, padded sets and ``mask (n, m)`` their real points
    (a prefix of each row: the padding repeats the first point with weight 0, which changes
    no step, so each set is iterated on its real points alone). The moments are summed in
    index order, as the twin's ``_sum_in_order``: the same weights, bit for bit.
    """
    n, m = mask.shape
    u = np.zeros((n, m))
    for s in range(n):
        cnt = 0
        for k in range(m):
            if mask[s, k]:
                cnt += 1
        u[s, :cnt] = _mvee_weights(P[s, :cnt], tol, max_iter)
    return u


_A6_LEAD = 4
"""Points put first in A6's compass search (:func:`_a6_search`): the largest ``a^2`` at the
current parameters (the support of an ellipse in the plane has at most 5 points; 4 measured
best on the SemanticKITTI frames)."""


@njit(cache=True, error_model="numpy")
def _a6_search(P0, x0, step0, min_step, max_iter):  # type: ignore[no-untyped-def]
    """The compass search of ``shapes._a6_batch`` on one set ``P0 (m, 2)`` from ``x0 (4,)``
    (x, y, phi, log k) with steps ``step0 (4,)`` down to ``min_step (4,)``: the final parameters.

    The 81 trials are evaluated as in the twin (u, v on the 27 (phi, x, y) combinations, a^2 on
    81) in the twin's order; ``cos``, ``sin`` and ``exp`` with the fixed arithmetic of
    :func:`_sincos` and :func:`_exp` (the twin's ``fixedmath``). A group of three trials
    stops early once none of them can be chosen (its running maximum already gives an area at
    least the current one or an earlier trial's): the chosen trial and its area are unchanged.

    Two things make the early stop come sooner without changing any value: after each move
    the points are reordered so that the ``_A6_LEAD`` largest ``a^2`` at the current
    parameters (the current ellipse's support, which bounds the nearby trials too) come
    first - a maximum does not depend on the order of its terms, so a trial evaluated to
    the end has the same area - and the stop is tested every second point. ``cos``, ``sin``
    and ``exp`` of a trial value are only recomputed when the value changed (the same
    arguments give the same results).
    """
    mh = P0.shape[0]
    P = P0.copy()  # reordered below: the current support first
    wq = np.empty(mh)
    three = np.array([-1.0, 0.0, 1.0])
    vals = np.empty((3, 4))
    cs = np.empty(3)
    sn = np.empty(3)
    kk = np.empty(3)
    ph = np.full(3, np.nan)  # the arguments of cs, sn and kk (NaN: not computed yet)
    lk = np.full(3, np.nan)
    f = np.empty(81)
    cur = x0.copy()
    step = step0.copy()
    # f at the start (``_a6_area``)
    k0 = _exp(cur[3])
    s0, c0 = _sincos(cur[2])
    a2 = 0.0
    for q in range(mh):
        dx = P[q, 0] - cur[0]
        dy = P[q, 1] - cur[1]
        u = c0 * dx + s0 * dy
        v = -s0 * dx + c0 * dy
        w = u * u + (v * v) / (k0 * k0)
        wq[q] = w
        if q == 0 or w > a2:
            a2 = w
    f_cur = np.pi * a2 * k0
    moved = True
    for it in range(max_iter):
        if moved:  # the points of the largest a^2 at the current parameters first
            if it > 0:
                k0 = _exp(cur[3])
                s0, c0 = _sincos(cur[2])
                for q in range(mh):
                    dx = P[q, 0] - cur[0]
                    dy = P[q, 1] - cur[1]
                    u = c0 * dx + s0 * dy
                    v = -s0 * dx + c0 * dy
                    wq[q] = u * u + (v * v) / (k0 * k0)
            for t in range(min(_A6_LEAD, mh)):  # a partial selection sort
                b = t
                for q in range(t + 1, mh):
                    if wq[q] > wq[b]:
                        b = q
                if b != t:
                    wq[t], wq[b] = wq[b], wq[t]
                    P[t, 0], P[b, 0] = P[b, 0], P[t, 0]
                    P[t, 1], P[b, 1] = P[b, 1], P[t, 1]
            moved = False
        for t in range(3):
            for p in range(4):
                vals[t, p] = cur[p] + three[t] * step[p]
            if vals[t, 2] != ph[t]:
                ph[t] = vals[t, 2]
                sn[t], cs[t] = _sincos(ph[t])
            if vals[t, 3] != lk[t]:
                lk[t] = vals[t, 3]
                kk[t] = _exp(lk[t])
        # a trial whose running maximum already gives an area >= thr (the current area, or the
        # best earlier trial's) can be neither the first best trial nor an improvement: once
        # all three trials of a group are there, the group stops (f = inf); the chosen trial
        # and its area are the twin's exactly
        thr = f_cur * (1 - 1e-12)
        for tx in range(3):
            for ty in range(3):
                for tp in range(3):
                    a2k0 = -1.0
                    a2k1 = -1.0
                    a2k2 = -1.0
                    pruned = False
                    for q in range(mh):
                        dx = P[q, 0] - vals[tx, 0]
                        dy = P[q, 1] - vals[ty, 1]
                        u = cs[tp] * dx + sn[tp] * dy
                        v = -sn[tp] * dx + cs[tp] * dy
                        uu = u * u
                        vv = v * v
                        w0 = uu + vv / (kk[0] * kk[0])
                        w1 = uu + vv / (kk[1] * kk[1])
                        w2 = uu + vv / (kk[2] * kk[2])
                        if q == 0 or w0 > a2k0:
                            a2k0 = w0
                        if q == 0 or w1 > a2k1:
                            a2k1 = w1
                        if q == 0 or w2 > a2k2:
                            a2k2 = w2
                        if (
                            (q & 1) == 1
                            and np.pi * a2k0 * kk[0] >= thr
                            and np.pi * a2k1 * kk[1] >= thr
                            and np.pi * a2k2 * kk[2] >= thr
                        ):
                            pruned = True
                            break
                    base = ((tx * 3 + ty) * 3 + tp) * 3
                    if pruned:
                        f[base] = np.inf
                        f[base + 1] = np.inf
                        f[base + 2] = np.inf
                    else:
                        f[base] = np.pi * a2k0 * kk[0]
                        f[base + 1] = np.pi * a2k1 * kk[1]
                        f[base + 2] = np.pi * a2k2 * kk[2]
                        if base == 39:  # t = 40 is the zero move: not a candidate
                            thr = min(thr, f[base], f[base + 2])
                        else:
                            thr = min(thr, f[base], f[base + 1], f[base + 2])
        best = -1
        for t in range(81):
            if t == 40:  # the zero move
                continue
            if best < 0 or f[t] < f[best]:
                best = t
        if f[best] < f_cur * (1 - 1e-12):
            mv = best
            for p in range(3, -1, -1):  # the move's digits: x, y, phi, log k in base 3
                cur[p] = cur[p] + (mv % 3 - 1) * step[p]
                mv //= 3
            f_cur = f[best]
            moved = True
        else:
            for p in range(4):
                step[p] *= 0.5
            if not (
                step[0] > min_step[0]
                or step[1] > min_step[1]
                or step[2] > min_step[2]
                or step[3] > min_step[3]
            ):
                break
    return cur


@njit(cache=True, error_model="numpy")
def a6_search_kernel(P, counts, x0, step0, min_step, max_iter):  # type: ignore[no-untyped-def]
    """The compass search of ``shapes._a6_batch`` set by set (:func:`_a6_search`): the final
    ``(x, y, phi, log k)`` of every set ``(n, 4)``; ``P (n, m, 2)`` padded sets (``counts``
    real points each), ``x0``, ``step0``, ``min_step`` ``(n, 4)``."""
    n = P.shape[0]
    out = x0.copy()
    for s in range(n):
        out[s] = _a6_search(P[s, : counts[s]], x0[s], step0[s], min_step[s], max_iter)
    return out


# ------------------------------------------------------------------------------------------
# stage 8 in one call per frame: hulls and shapes of many sets in a CSR layout (``xy (N, 2)``
# rows of set ``s`` are ``off[s]:off[s + 1]``); twins in ``navkit.geometry.shapes``

AMBIGUOUS_TURN = 1e-9
"""Relative size of a turn (cross product over the product of the two edge lengths, L1) below
which the monotone chain calls a set ambiguous and leaves it to Qhull (``hull_points``)."""


@njit(cache=True)
def _lex_order(x, y):  # type: ignore[no-untyped-def]
    """Indices sorting ``(x, y)`` lexicographically (x, then y)."""
    order = np.argsort(x)
    n = len(order)
    i = 0
    while i < n:
        j = i + 1
        while j < n and x[order[j]] == x[order[i]]:
            j += 1
        for a in range(i + 1, j):  # runs of equal x (rare): insertion sort by y
            v = order[a]
            b = a - 1
            while b >= i and y[order[b]] > y[v]:
                order[b + 1] = order[b]
                b -= 1
            order[b + 1] = v
        i = j
    return order


_FULL_TEST_EDGES = 32
"""Polygons with at most this many edges are tested edge by edge before the binary search of
:func:`_outside_polygon`; larger ones by the octagon of their extreme vertices."""


@njit(cache=True, error_model="numpy")
def _turn(ox, oy, ax, ay, bx, by):  # type: ignore[no-untyped-def]
    """Cross product ``(a - o) x (b - o)`` and whether it is within ``AMBIGUOUS_TURN`` of 0."""
    ux, uy, vx, vy = ax - ox, ay - oy, bx - ox, by - oy
    cr = ux * vy - uy * vx
    scale = (abs(ux) + abs(uy)) * (abs(vx) + abs(vy))
    return cr, abs(cr) <= AMBIGUOUS_TURN * scale


@njit(cache=True, error_model="numpy")
def _outside_octagon(x, y):  # type: ignore[no-untyped-def]
    """Indices of the points not clearly inside the octagon of the extreme points, and their
    number (see :func:`_hull_one`; -1 when a coordinate is not finite).

    Both passes keep their state in registers and decide without a branch per point (the
    extremes as running values, not re-read through their indices; the eight edge tests of a
    point all evaluated): on a frame's 18k boundary points the filter took ~20 ns a point
    with a dependent load per comparison and an early exit per edge, a few ns now. The
    extremes are the same points (strict comparisons: the first index on ties) and the
    candidates the same list."""
    m = len(x)
    # Akl-Toussaint: drop the points clearly inside the octagon of the extreme points along
    # x, x + y, y, y - x and their opposites (hull vertices, counter-clockwise); "clearly":
    # beyond every edge line by more than the ambiguity margin, taken with the set's L1
    # extent (>= any |p - a|_1) so that every point the chain could call ambiguous is kept
    q0 = q1 = q2 = q3 = q4 = q5 = q6 = q7 = 0  # directions (-1, 0), (-1, -1), (0, -1), ...
    v0 = v4 = x[0]
    v2 = v6 = y[0]
    v1 = v5 = x[0] + y[0]
    v3 = x[0] - y[0]
    v7 = y[0] - x[0]
    finite = np.isfinite(x[0]) & np.isfinite(y[0])
    for k in range(1, m):
        xk, yk = x[k], y[k]
        finite &= np.isfinite(xk) & np.isfinite(yk)
        s, d, w = xk + yk, xk - yk, yk - xk
        if xk < v0:
            v0, q0 = xk, k
        if s < v1:
            v1, q1 = s, k
        if yk < v2:
            v2, q2 = yk, k
        if d > v3:
            v3, q3 = d, k
        if xk > v4:
            v4, q4 = xk, k
        if s > v5:
            v5, q5 = s, k
        if yk > v6:
            v6, q6 = yk, k
        if w > v7:
            v7, q7 = w, k
    if not finite:
        return np.empty(0, np.int64), -1
    q = np.empty(8, np.int64)
    q[0], q[1], q[2], q[3], q[4], q[5], q[6], q[7] = q0, q1, q2, q3, q4, q5, q6, q7
    extent = (x[q[4]] - x[q[0]]) + (y[q[6]] - y[q[2]])
    x0, y0 = x[0], y[0]
    # the edges' inequalities ``ex (px - x0) + ey (py - y0) > ec``; a degenerate edge (two equal
    # extremes) is skipped, i.e. left as ``0 > -inf`` (always true: the coordinates are finite)
    ex = np.zeros(8)
    ey = np.zeros(8)
    ec = np.full(8, -np.inf)
    ne = 0
    for e in range(8):
        a, b = q[e], q[(e + 1) % 8]
        ux, uy = x[b] - x[a], y[b] - y[a]
        if ux == 0.0 and uy == 0.0:
            continue
        # inside: ux (py - ay) - uy (px - ax) > margin, in coordinates relative to the first
        # point (their rounding, ~1e-16 x extent, is far below the margin)
        ex[ne] = -uy
        ey[ne] = ux
        ec[ne] = (
            ux * (y[a] - y0) - uy * (x[a] - x0) + 2 * AMBIGUOUS_TURN * (abs(ux) + abs(uy)) * extent
        )
        ne += 1
    cand = np.empty(m, np.int64)
    if ne < 3:  # no polygon: every point is a candidate
        for k in range(m):
            cand[k] = k
        return cand, m
    ex0, ex1, ex2, ex3, ex4, ex5, ex6, ex7 = ex[0], ex[1], ex[2], ex[3], ex[4], ex[5], ex[6], ex[7]
    ey0, ey1, ey2, ey3, ey4, ey5, ey6, ey7 = ey[0], ey[1], ey[2], ey[3], ey[4], ey[5], ey[6], ey[7]
    ec0, ec1, ec2, ec3, ec4, ec5, ec6, ec7 = ec[0], ec[1], ec[2], ec[3], ec[4], ec[5], ec[6], ec[7]
    nc = 0
    for k in range(m):
        dx, dy = x[k] - x0, y[k] - y0
        inside = (
            (ex0 * dx + ey0 * dy > ec0)
            & (ex1 * dx + ey1 * dy > ec1)
            & (ex2 * dx + ey2 * dy > ec2)
            & (ex3 * dx + ey3 * dy > ec3)
            & (ex4 * dx + ey4 * dy > ec4)
            & (ex5 * dx + ey5 * dy > ec5)
            & (ex6 * dx + ey6 * dy > ec6)
            & (ex7 * dx + ey7 * dy > ec7)
        )
        cand[nc] = k
        nc += 1 - np.int64(inside)
    return cand, nc


@njit(cache=True, error_model="numpy")
def _clearly_left(ax, ay, bx, by, px, py, extent):  # type: ignore[no-untyped-def]
    """``p`` left of the line ``a -> b`` by more than the ambiguity margin (with the set's L1
    ``extent`` >= any ``|p - a|_1``, as the octagon filter)."""
    ux, uy = bx - ax, by - ay
    cr = ux * (py - ay) - uy * (px - ax)
    return cr > 2 * AMBIGUOUS_TURN * (abs(ux) + abs(uy)) * extent


@njit(cache=True, error_model="numpy")
def _octagon_edges(rx, ry, extent):  # type: ignore[no-untyped-def]
    """The edges of the octagon of a convex polygon's extreme vertices (``rx, ry``: counter-
    clockwise, strictly convex) as the rows ``(ex, ey, ec)`` of an ``(8, 3)`` array: a point ``p`` with
    ``ex px + ey py > ec`` for all eight is inside the octagon by more than twice
    :func:`_clearly_left`'s margin. A degenerate edge (two equal extremes) is ``(0, 0, -inf)``
    (always true for finite points); all eight are ``(0, 0, inf)`` (never true) when fewer than
    three edges remain or the extremes do not follow the polygon's order (ties), so that the
    octagon could leave the polygon."""
    h = len(rx)
    q = np.zeros(8, np.int64)  # directions (-1, 0), (-1, -1), (0, -1), (1, -1), (1, 0), ...
    for k in range(1, h):
        xk, yk = rx[k], ry[k]
        if xk < rx[q[0]]:
            q[0] = k
        if xk + yk < rx[q[1]] + ry[q[1]]:
            q[1] = k
        if yk < ry[q[2]]:
            q[2] = k
        if xk - yk > rx[q[3]] - ry[q[3]]:
            q[3] = k
        if xk > rx[q[4]]:
            q[4] = k
        if xk + yk > rx[q[5]] + ry[q[5]]:
            q[5] = k
        if yk > ry[q[6]]:
            q[6] = k
        if yk - xk > ry[q[7]] - rx[q[7]]:
            q[7] = k
    E = np.zeros((8, 3))
    descents = 0  # the extremes in the polygon's (cyclic) order: at most one wrap-around
    ne = 0
    for e in range(8):
        a, b = q[e], q[(e + 1) % 8]
        if b < a:
            descents += 1
        ux, uy = rx[b] - rx[a], ry[b] - ry[a]
        if ux == 0.0 and uy == 0.0:
            E[e, 2] = -np.inf
            continue
        E[e, 0] = -uy
        E[e, 1] = ux
        E[e, 2] = ux * ry[a] - uy * rx[a] + 4 * AMBIGUOUS_TURN * (abs(ux) + abs(uy)) * extent
        ne += 1
    if ne < 3 or descents > 1:
        for e in range(8):
            E[e, 0] = 0.0
            E[e, 1] = 0.0
            E[e, 2] = np.inf
    return E


@njit(cache=True, error_model="numpy")
def _outside_polygon(x, y, qx, qy):  # type: ignore[no-untyped-def]
    """Indices of the points not clearly inside the convex polygon ``qx, qy`` (counter-
    clockwise, strictly convex), and their number: each point is located in the fan of
    triangles from the polygon's first vertex by a binary search (O(log h) tests); -1 when a
    coordinate is not finite."""
    m = len(x)
    h = len(qx)
    ox, oy = qx[0], qy[0]  # coordinates relative to the fan's apex
    # one pass over the set (it is read from memory once): finiteness, extent and the
    # relative coordinates, contiguous for the vector loops below
    px_ = np.empty(m)
    py_ = np.empty(m)
    xmin, xmax, ymin, ymax = x[0], x[0], y[0], y[0]
    finite = True
    for k in range(m):
        xk, yk = x[k], y[k]
        finite &= np.isfinite(xk) & np.isfinite(yk)
        xmin = min(xmin, xk)
        xmax = max(xmax, xk)
        ymin = min(ymin, yk)
        ymax = max(ymax, yk)
        px_[k] = xk - ox
        py_[k] = yk - oy
    if not finite:
        return np.empty(0, np.int64), -1
    extent = (xmax - xmin) + (ymax - ymin)
    rx = np.empty(h)
    ry = np.empty(h)
    for t in range(h):
        rx[t] = qx[t] - ox
        ry[t] = qy[t] - oy
    # a quick first test, branch-free: a point inside every edge line by twice the margin
    # is dropped by the binary search too (the same candidates), and most of an obstacle's
    # points are; only the others pay the search's ~log h dependent, mispredicted tests
    # (~20 ns a point before, on A7's 53k points per frame). A large polygon is tested by the
    # octagon of its extreme vertices (inside it) instead of all its edges.
    if h <= _FULL_TEST_EDGES:
        E = np.zeros((h, 3))
        for t in range(h):
            u = (t + 1) % h
            ux, uy = rx[u] - rx[t], ry[u] - ry[t]
            E[t, 0] = -uy
            E[t, 1] = ux
            E[t, 2] = ux * ry[t] - uy * rx[t] + 4 * AMBIGUOUS_TURN * (abs(ux) + abs(uy)) * extent
    else:
        E = _octagon_edges(rx, ry, extent)
    # edge by edge over all points (vector loops)
    clear = np.ones(m, np.bool_)
    for t in range(len(E)):
        ex, ey, ec = E[t, 0], E[t, 1], E[t, 2]
        for k in range(m):
            clear[k] &= ex * px_[k] + ey * py_[k] > ec
    cand = np.empty(m, np.int64)
    nc = 0
    for k in range(m):
        if clear[k]:
            continue
        px, py = px_[k], py_[k]
        inside = _clearly_left(0.0, 0.0, rx[1], ry[1], px, py, extent) and _clearly_left(
            rx[h - 1], ry[h - 1], 0.0, 0.0, px, py, extent
        )
        if inside:
            lo, hi = 1, h - 1
            while hi - lo > 1:
                mid = (lo + hi) // 2
                if rx[mid] * py - ry[mid] * px >= 0.0:
                    lo = mid
                else:
                    hi = mid
            inside = _clearly_left(rx[lo], ry[lo], rx[hi], ry[hi], px, py, extent)
        if not inside:
            cand[nc] = k
            nc += 1
    return cand, nc


@njit(cache=True, error_model="numpy")
def _hull_one(x, y, out, qx, qy):  # type: ignore[no-untyped-def]
    """Andrew's monotone chain on one set: writes the hull's local indices to ``out``
    (counter-clockwise from the lexicographically smallest vertex) and returns their number,
    or -1 when the set is for Qhull (fewer than 3 hull vertices, a non-finite value, or a turn
    within ``AMBIGUOUS_TURN`` of collinear, where Qhull's precision handling decides).

    The points clearly inside a convex polygon inside the hull - ``qx, qy`` (counter-clockwise,
    strictly convex, at least 3 vertices, e.g. the hull of a subset) or else the octagon of the
    extreme points - are dropped first (Akl-Toussaint)."""
    m = len(x)
    if m < 3:
        return -1
    if len(qx) >= 3:
        cand, nc = _outside_polygon(x, y, qx, qy)
    else:
        cand, nc = _outside_octagon(x, y)
    if nc < 0:  # a coordinate is not finite
        return -1
    cand = cand[:nc]
    order = cand[_lex_order(x[cand], y[cand])]
    # distinct points only (duplicates are adjacent after the sort)
    u = 0
    for k in range(nc):
        if k == 0 or x[order[k]] != x[order[u - 1]] or y[order[k]] != y[order[u - 1]]:
            order[u] = order[k]
            u += 1
    if u < 3:
        return -1
    h = 0
    for k in range(u):  # lower chain, left to right
        p = order[k]
        while h >= 2:
            cr, amb = _turn(x[out[h - 2]], y[out[h - 2]], x[out[h - 1]], y[out[h - 1]], x[p], y[p])
            if amb:
                return -1
            if cr > 0.0:
                break
            h -= 1
        out[h] = p
        h += 1
    low = h + 1
    for k in range(u - 2, -1, -1):  # upper chain, right to left
        p = order[k]
        while h >= low:
            cr, amb = _turn(x[out[h - 2]], y[out[h - 2]], x[out[h - 1]], y[out[h - 1]], x[p], y[p])
            if amb:
                return -1
            if cr > 0.0:
                break
            h -= 1
        out[h] = p
        h += 1
    h -= 1  # the last point is the first again
    if h < 3:
        return -1
    return h


@njit(cache=True)
def hulls_csr_kernel(xy, off, inner, ioff):  # type: ignore[no-untyped-def]
    """Convex hulls of the sets of ``xy`` (CSR ``off``): the global row of every hull vertex,
    the hulls' offsets ``(n + 1,)`` and ``ok (n,)`` (False: left to Qhull, empty here).

    ``inner`` (CSR ``ioff``; a set may have none): for each set, a strictly convex polygon
    (counter-clockwise) inside its hull, such as the hull of a subset; the points clearly
    inside it are dropped before the chain."""
    n = len(off) - 1
    idx = np.empty(len(xy) + 1, np.int64)
    hoff = np.zeros(n + 1, np.int64)
    ok = np.zeros(n, np.bool_)
    h = 0
    for s in range(n):
        a, b = off[s], off[s + 1]
        buf = np.empty(b - a + 1, np.int64)
        qa, qb = ioff[s], ioff[s + 1]
        k = _hull_one(xy[a:b, 0], xy[a:b, 1], buf, inner[qa:qb, 0], inner[qa:qb, 1])
        if k > 0:
            ok[s] = True
            for t in range(k):
                idx[h + t] = a + buf[t]
            h += k
        hoff[s + 1] = h
    return idx[:h], hoff, ok


@njit(cache=True, error_model="numpy")
def _ellipse_norm(out, c, x, y, a, b, angle):  # type: ignore[no-untyped-def]
    """``shapes._ellipse``: ``a >= b``, angle in ``(-pi/2, pi/2]``; written to ``out[c:c + 5]``."""
    a, b = abs(a), abs(b)
    if b > a:
        a, b, angle = b, a, angle + math.pi / 2
    angle = (angle + math.pi / 2) % math.pi - math.pi / 2
    out[c] = x
    out[c + 1] = y
    out[c + 2] = a
    out[c + 3] = b
    out[c + 4] = angle


@njit(cache=True, error_model="numpy")
def _inside(px, py, cx, cy, r):  # type: ignore[no-untyped-def]
    return _norm(px - cx, py - cy) <= r * (1 + 1e-12) + 1e-12


@njit(cache=True, error_model="numpy")
def _norm(dx, dy):  # type: ignore[no-untyped-def]
    """``sqrt(dx^2 + dy^2)``: ``shapes._norm`` (not ``hypot``, whose algorithm is the C
    library's here and CPython's own in the twin)."""
    return math.sqrt(dx * dx + dy * dy)


@njit(cache=True, error_model="numpy")
def _welzl(hx, hy, perm, out, c):  # type: ignore[no-untyped-def]
    """``shapes._min_circle_welzl`` on one hull, its points taken in the order ``perm`` (the
    twin's ``random.Random(seed).shuffle``); ``(x, y, r)`` to ``out[c:c + 3]``."""
    m = len(hx)
    ox = 0.0
    oy = 0.0
    for k in range(m):
        ox += hx[k]
        oy += hy[k]
    ox /= m
    oy /= m
    px = np.empty(m)
    py = np.empty(m)
    for k in range(m):
        px[k] = hx[perm[k]] - ox
        py[k] = hy[perm[k]] - oy
    cx, cy, r = px[0], py[0], 0.0
    for i in range(1, m):
        if _inside(px[i], py[i], cx, cy, r):
            continue
        cx, cy, r = px[i], py[i], 0.0
        for j in range(i):
            if _inside(px[j], py[j], cx, cy, r):
                continue
            cx, cy = 0.5 * (px[i] + px[j]), 0.5 * (py[i] + py[j])
            r = _norm(px[i] - cx, py[i] - cy)
            for k in range(j):
                if _inside(px[k], py[k], cx, cy, r):
                    continue
                ax, ay, bx, by, qx, qy = px[i], py[i], px[j], py[j], px[k], py[k]
                d = 2.0 * (ax * (by - qy) + bx * (qy - ay) + qx * (ay - by))
                if abs(d) < 1e-18:
                    continue
                a2, b2, c2 = ax * ax + ay * ay, bx * bx + by * by, qx * qx + qy * qy
                cx = (a2 * (by - qy) + b2 * (qy - ay) + c2 * (ay - by)) / d
                cy = (a2 * (qx - bx) + b2 * (ax - qx) + c2 * (bx - ax)) / d
                r = _norm(ax - cx, ay - cy)
    out[c] = cx + ox
    out[c + 1] = cy + oy
    out[c + 2] = r * (1 + 1e-12)


N_BASIC = 23
"""Columns of :func:`basic_shapes_kernel`: A1 ``0:4`` (MnX, MxX, MnY, MxY), A2 ``4:7`` and A3
``7:10`` (x, y, r), A4 ``10:15`` and A5 ``15:20`` (x, y, a, b, angle), MEC ``20:23``."""


@njit(cache=True, error_model="numpy")
def basic_shapes_kernel(H, hoff, perm):  # type: ignore[no-untyped-def]
    """A1-A5 and Welzl's circle of every hull (CSR ``H``, ``hoff``; ``perm`` the Welzl order
    of each hull in the same layout), the twins' arithmetic in the twins' order (``_rect_a1``,
    ``_circle_a2``, ``_circle_a3``, ``_ellipse_a4``, ``_ellipse_a5``, ``_min_circle_welzl``)."""
    n = len(hoff) - 1
    out = np.empty((n, N_BASIC))
    for s in range(n):
        a, b = hoff[s], hoff[s + 1]
        hx, hy = H[a:b, 0], H[a:b, 1]
        o = out[s]
        # A1
        xmin, xmax, ymin, ymax = hx[0], hx[0], hy[0], hy[0]
        for k in range(1, b - a):
            xmin = min(xmin, hx[k])
            xmax = max(xmax, hx[k])
            ymin = min(ymin, hy[k])
            ymax = max(ymax, hy[k])
        o[0], o[1], o[2], o[3] = xmin, xmax, ymin, ymax
        # A2
        r2 = 0.5 * _norm(xmax - xmin, ymax - ymin)
        c2x, c2y = 0.5 * (xmin + xmax), 0.5 * (ymin + ymax)
        o[4], o[5], o[6] = c2x, c2y, r2
        # A3
        if xmax - xmin >= ymax - ymin:
            i0, i1 = np.argmin(hx), np.argmax(hx)
        else:
            i0, i1 = np.argmin(hy), np.argmax(hy)
        x0, y0, x1, y1 = hx[i0], hy[i0], hx[i1], hy[i1]
        cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        r = 0.5 * _norm(x1 - x0, y1 - y0)
        for k in range(b - a):
            px, py = hx[k], hy[k]
            d = _norm(px - cx, py - cy)
            if d <= r * (1 + 1e-12) + 1e-12:
                continue
            new_r = 0.5 * (d + r)
            cx, cy = px + (cx - px) * new_r / d, py + (cy - py) * new_r / d
            r = new_r
        o[7], o[8], o[9] = cx, cy, r
        # A4 (gamma minimising the area)
        dx, dy = xmax - xmin, ymax - ymin
        rho = 0.5 * _norm(dx, dy)
        angle = _atan2(dy, dx)
        cos_phi = (dx * -dx + dy * dy) / max(dx * dx + dy * dy, 1e-300)
        gamma = max(1.0, math.sqrt(2.0) * abs(cos_phi))
        sin2 = 1.0 - cos_phi * cos_phi
        denom = 1.0 - cos_phi * cos_phi / (gamma * gamma)
        b4 = rho * math.sqrt(sin2 / denom) if denom > 0 else rho
        _ellipse_norm(o, 10, c2x, c2y, gamma * rho, b4, angle)
        # A5: both diagonals, the smaller ellipse
        best = np.inf
        for sign in (1.0, -1.0):
            ang = _atan2(sign * (ymax - ymin), xmax - xmin)
            sn, c = _sincos(ang)
            kmax = -np.inf
            for k in range(b - a):
                ddx, ddy = hx[k] - c2x, hy[k] - c2y
                u = c * ddx + sn * ddy
                v = -sn * ddx + c * ddy
                h2 = max(r2 * r2 - u * u, 0.0)
                if h2 > 0:
                    ratio = abs(v) / np.sqrt(h2)
                elif abs(v) > 1e-12 * r2:
                    ratio = np.inf
                else:
                    ratio = 0.0
                kmax = max(kmax, ratio)
            kk = min(1.0, kmax)
            aa, bb = abs(r2), abs(kk * r2)
            area = math.pi * max(aa, bb) * min(aa, bb)
            if area < best:
                best = area
                _ellipse_norm(o, 15, c2x, c2y, r2, kk * r2, ang)
        # Welzl
        _welzl(hx, hy, perm[a:b], o, 20)
    return out


@njit(cache=True, error_model="numpy")
def a6_csr_kernel(H, hoff, start, rel_tol, max_iter):  # type: ignore[no-untyped-def]
    """A6 of every hull (CSR) from its start ellipse ``start (n, 5)`` (normalised A5: x, y, a,
    b, angle): ``shapes._a6_batch``'s set-up, compass search (``_a6_search``) and final choice;
    returns ``(n, 5)`` normalised ellipses."""
    n = len(hoff) - 1
    out = np.empty((n, 5))
    for s in range(n):
        a, b = hoff[s], hoff[s + 1]
        P = H[a:b]
        x, y, ea, eb, ang = start[s, 0], start[s, 1], start[s, 2], start[s, 3], start[s, 4]
        cur = np.empty(4)
        cur[0], cur[1], cur[2] = x, y, ang
        cur[3] = _log(max(eb / ea, 1e-6)) if ea > 0 else 0.0
        size = max(ea, 1e-6)
        step = np.array([0.25 * size, 0.25 * size, 0.2, 0.2])
        min_step = np.array([rel_tol * size, rel_tol * size, rel_tol, rel_tol])
        cur = _a6_search(P, cur, step, min_step, max_iter)
        k = _exp(cur[3])
        sn, c = _sincos(cur[2])
        a2 = 0.0
        for q in range(b - a):
            dx = P[q, 0] - cur[0]
            dy = P[q, 1] - cur[1]
            u = c * dx + sn * dy
            v = -sn * dx + c * dy
            a2 = max(a2, u * u + (v * v) / (k * k))
        am = np.sqrt(a2) * (1 + 1e-12)
        _ellipse_norm(out[s], 0, cur[0], cur[1], am, am * k, cur[2])
        if math.pi * out[s, 2] * out[s, 3] > math.pi * ea * eb:
            out[s, 0], out[s, 1], out[s, 2], out[s, 3], out[s, 4] = x, y, ea, eb, ang
    return out


@njit(cache=True, error_model="numpy")
def mvee_csr_kernel(H, hoff, tol, max_iter):  # type: ignore[no-untyped-def]
    """``shapes.mvee_batch`` up to the shape matrix, set by set on a CSR layout: each set
    centred on its mean and scaled by its largest coordinate, the weights (``_mvee_weights``),
    the centre ``c``, ``A = S^-1 / 2`` scaled so that the farthest point is on the ellipse.

    Returns ``origin (n, 2)``, ``scale (n,)``, ``c (n, 2)`` and ``A (n, 2, 2)``
    (the 2 x 2 inverse in closed form, as the twin; the axes from ``shapes._mvee_axes``).
    """
    n = len(hoff) - 1
    origin = np.empty((n, 2))
    scale = np.empty(n)
    cen = np.empty((n, 2))
    A = np.empty((n, 2, 2))
    for s in range(n):
        a, b = hoff[s], hoff[s + 1]
        m = b - a
        ox = 0.0
        oy = 0.0
        for k in range(a, b):
            ox += H[k, 0]
            oy += H[k, 1]
        ox /= m
        oy /= m
        P = np.empty((m, 2))
        sc = 0.0
        for k in range(m):
            P[k, 0] = H[a + k, 0] - ox
            P[k, 1] = H[a + k, 1] - oy
            sc = max(sc, abs(P[k, 0]), abs(P[k, 1]))
        sc = max(sc, 1e-9)
        for k in range(m):
            P[k, 0] /= sc
            P[k, 1] /= sc
        u = _mvee_weights(P, tol, max_iter)
        cx = 0.0
        cy = 0.0
        for k in range(m):
            cx += u[k] * P[k, 0]
            cy += u[k] * P[k, 1]
        sxx = 0.0
        sxy = 0.0
        syy = 0.0
        for k in range(m):
            sxx += P[k, 0] * u[k] * P[k, 0]
            sxy += P[k, 0] * u[k] * P[k, 1]
            syy += P[k, 1] * u[k] * P[k, 1]
        sxx -= cx * cx
        sxy -= cx * cy
        syy -= cy * cy
        det = sxx * syy - sxy * sxy
        a00, a01, a11 = syy / det / 2, -sxy / det / 2, sxx / det / 2
        worst = 0.0
        for k in range(m):
            dx, dy = P[k, 0] - cx, P[k, 1] - cy
            worst = max(worst, dx * (a00 * dx + a01 * dy) + dy * (a01 * dx + a11 * dy))
        f = max(worst, 1e-300) * (1 + 1e-12)
        origin[s, 0], origin[s, 1], scale[s] = ox, oy, sc
        cen[s, 0], cen[s, 1] = cx, cy
        A[s, 0, 0], A[s, 0, 1], A[s, 1, 0], A[s, 1, 1] = a00 / f, a01 / f, a01 / f, a11 / f
    return origin, scale, cen, A
