"""Bounding shapes of a 2D point set (paper 1, stage 8: shapes A1-A7) plus the exact optima.

The paper maps each obstacle by a small shape computed on its boundary points, and asks that more
shape methods can be "easily added". This module is that registry:

========  ==========================================================================
``A1``    axis-aligned rectangle ``(MnX, MxX, MnY, MxY)``
``A2``    circle circumscribed about the A1 rectangle
``A3``    reduced circle: the paper's linear-time iterative enlargement
``A4``    ellipse through three points (rectangle diagonal enlarged by ``gamma``)
``A5``    reduced ellipse: the A2 circle compressed across a diagonal by ``k``
``A6``    minimised ellipse: the area ``pi a^2 k`` minimised over ``(x, y, phi, k)`` from A5
``MEC``   exact minimum enclosing circle (Welzl's algorithm) - beyond the paper
``MVEE``  minimum-area enclosing ellipse (Khachiyan's algorithm) - beyond the paper
========  ==========================================================================

A7 ("guaranteed" bounds) is not a separate construction: it is any of these shapes computed over
the obstacle *together with its shadows* (see :mod:`navkit.obstacles`).

Add a method with :func:`register_shape`; :func:`compute_shapes` evaluates any set of registered
names. Every shape has ``area``, ``contains(points, tol)``, ``outline(n)`` and ``params()``.

Shapes depend only on the convex hull of the points, so every method first reduces the input to
its hull vertices (:func:`hull_points`); the Python loops in A3 and Welzl run over hull vertices
(tens), never over the raw points. Degenerate inputs (one point, collinear points) are handled by
a 1 mm dilation (documented in :func:`hull_points`), so every method returns a shape.
"""

from __future__ import annotations

import functools
import math
import random
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import ConvexHull, QhullError

from navkit.errors import InputError
from navkit.geometry import fixedmath
from navkit.geometry._validate import as_points, check_coordinates
from navkit.geometry.angles import atan2 as fixed_atan2
from navkit.geometry.shape_types import Circle, Ellipse, Rectangle, Shape, _ellipse
from navkit.jit import kernels_enabled

__all__ = [
    "SHAPES",
    "Circle",
    "Ellipse",
    "Rectangle",
    "Shape",
    "circle_a2",
    "circle_a3",
    "compute_shapes",
    "ellipse_a4",
    "ellipse_a5",
    "ellipse_a6",
    "hull_points",
    "min_circle_welzl",
    "mvee_khachiyan",
    "rect_a1",
    "register_shape",
]

DEGENERATE_DILATION_M = 1e-3
"""Half-size (m) of the cross of points added around degenerate inputs (see :func:`hull_points`)."""


# ----------------------------------------------------------------------------------------------
# input reduction


def hull_points(points: ArrayLike) -> NDArray[np.float64]:
    """Convex-hull vertices ``(M, 2)`` (counter-clockwise) of finite points ``(N, 2)``.

    The cycle starts at the lexicographically smallest vertex (smallest x, then smallest y),
    where Andrew's monotone chain starts: Qhull's own starting vertex is an artefact of its
    facet list, and A3 (one pass over the hull in its stored order) and Welzl's shuffled order
    depend on it, so fixing the start makes both reproducible by the compiled hulls
    (:func:`hulls_csr`).

    Every enclosing shape of a point set encloses its hull and vice versa, so the shapes are
    computed on the hull only. A degenerate set (one point, or all collinear) is dilated by a
    cross of four points at ``DEGENERATE_DILATION_M`` (1 mm) around each hull end point, so that
    every method returns a proper shape (a 1 mm-thin ellipse around a segment, for example).

    Raises
    ------
    InputError
        If there is no finite point.
    """
    P = as_points(points, 2)
    check_coordinates(P, field="points")
    P = P[np.all(np.isfinite(P), axis=1)]
    if len(P) == 0:
        raise InputError("no finite point", field="points", expected="at least one finite (x, y)")
    if len(P) >= 3:
        try:
            hull = ConvexHull(P)
            return _from_lowest(P[hull.vertices])
        except QhullError:
            pass
    # degenerate: keep the two extreme points along the main direction, dilate them
    centred = P - P.mean(axis=0)
    _, _, vt = (
        np.linalg.svd(centred, full_matrices=False) if len(P) > 1 else (None, None, np.eye(2))
    )
    t = centred @ vt[0]
    ends = P[[int(np.argmin(t)), int(np.argmax(t))]]
    e = DEGENERATE_DILATION_M
    cross = np.array([[e, 0.0], [-e, 0.0], [0.0, e], [0.0, -e]])
    Q = (ends[:, None, :] + cross[None]).reshape(-1, 2)
    return _from_lowest(Q[ConvexHull(Q).vertices])


def _from_lowest(H: NDArray[np.float64]) -> NDArray[np.float64]:
    """The cycle ``H`` started at its lexicographically smallest vertex (smallest x, then y)."""
    k = int(np.lexsort((H[:, 1], H[:, 0]))[0])
    return np.concatenate([H[k:], H[:k]]) if k else H  # np.roll's result, without its overhead


# ----------------------------------------------------------------------------------------------
# the paper's shapes A1-A6


def rect_a1(points: ArrayLike) -> Rectangle:
    """A1: the axis-aligned bounding rectangle ``(MnX, MxX, MnY, MxY)`` (paper 1, stage 8)."""
    return _rect_a1(hull_points(points))


def _norm(dx: float, dy: float) -> float:
    """``sqrt(dx^2 + dy^2)`` as three IEEE operations and a square root (the kernels' ``_norm``:
    the same bits; ``math.hypot`` is CPython's own algorithm, the kernels' the C library's)."""
    return math.sqrt(dx * dx + dy * dy)


def _angle(y: float, x: float) -> float:
    """``atan2(y, x)`` with the fixed arithmetic of :mod:`navkit.geometry.angles`."""
    return float(fixed_atan2(y, x))


def _sincos(x: float) -> tuple[float, float]:
    """``(sin x, cos x)`` with the fixed arithmetic of :mod:`navkit.geometry.fixedmath`."""
    s, c = fixedmath.sincos(x)
    return float(s), float(c)


def _rect_a1(H: NDArray[np.float64]) -> Rectangle:
    lo, hi = H.min(axis=0), H.max(axis=0)
    return Rectangle(float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1]))


def circle_a2(points: ArrayLike) -> Circle:
    """A2: the circle circumscribed about the A1 rectangle (centre at the diagonals' crossing)."""
    return _circle_a2(hull_points(points))


def _circle_a2(H: NDArray[np.float64]) -> Circle:
    r = _rect_a1(H)
    return Circle(
        0.5 * (r.xmin + r.xmax),
        0.5 * (r.ymin + r.ymax),
        0.5 * _norm(r.xmax - r.xmin, r.ymax - r.ymin),
        kind="circle",
    )


def circle_a3(points: ArrayLike) -> Circle:
    """A3: the paper's reduced circle, one pass over the points (linear time).

    Start with the circle having as diameter the two extreme points along the longer side of the
    A1 rectangle **[reading: the paper says "two points"; these two make the start deterministic
    and already wide]**. For each next point outside the current circle, the segment from that
    point through the centre to the far side of the circle becomes the new diameter; that circle
    is internally tangent to the old one and larger, so it still encloses every point seen so far.
    At the end every point is inside and the circle passes through an input point.
    """
    return _circle_a3(hull_points(points))


def _circle_a3(H: NDArray[np.float64]) -> Circle:
    span = H.max(axis=0) - H.min(axis=0)
    axis = 0 if span[0] >= span[1] else 1
    i0, i1 = int(np.argmin(H[:, axis])), int(np.argmax(H[:, axis]))
    (x0, y0), (x1, y1) = H[i0], H[i1]
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    r = 0.5 * _norm(x1 - x0, y1 - y0)
    for px, py in H.tolist():  # hull vertices only (tens), sequential by construction
        d = _norm(px - cx, py - cy)
        if d <= r * (1 + 1e-12) + 1e-12:
            continue
        new_r = 0.5 * (d + r)
        # the new centre is on the segment from p through the old centre, at new_r from p
        cx, cy = px + (cx - px) * new_r / d, py + (cy - py) * new_r / d
        r = new_r
    return Circle(cx, cy, r, kind="circle")


def _a4_gamma_optimal(cos_phi: float) -> float:
    # area^2 ∝ g^2 / (g - c) with g = gamma^2, c = cos^2(phi): minimum at g = 2c (see ellipse_a4)
    return max(1.0, math.sqrt(2.0) * abs(cos_phi))


def ellipse_a4(points: ArrayLike, gamma: float | None = None) -> Ellipse:
    """A4: the ellipse through three points, built on the A1 rectangle (paper 1, stage 8).

    The rectangle's diagonal from ``(MnX, MnY)`` to ``(MxX, MxY)``, enlarged by ``gamma >= 1``
    about the centre, is the major axis ``2a``; the ellipse passes through the other two corners
    (radius ``rho`` = half diagonal, angle ``phi`` from the major axis), which gives
    ``b^2 = rho^2 sin^2(phi) / (1 - rho^2 cos^2(phi) / a^2)`` and ``e^2 = 1 - b^2 / a^2``. It
    encloses the rectangle, hence every point.

    Parameters
    ----------
    gamma : float, optional
        Enlargement ``>= 1``. **[reading: the paper leaves gamma free]** By default the
        area-minimising value ``gamma = max(1, sqrt(2) |cos phi|)`` (from
        ``d/dg [g^2 / (g - cos^2 phi)] = 0`` with ``g = gamma^2``); ``gamma = 1`` gives the A2 circle.
    """
    return _ellipse_a4(hull_points(points), gamma)


def _ellipse_a4(H: NDArray[np.float64], gamma: float | None = None) -> Ellipse:
    r = _rect_a1(H)
    dx, dy = r.xmax - r.xmin, r.ymax - r.ymin
    rho = 0.5 * _norm(dx, dy)
    cx, cy = 0.5 * (r.xmin + r.xmax), 0.5 * (r.ymin + r.ymax)
    angle = _angle(dy, dx)
    # the other diagonal is at angle atan2(dy, -dx); phi is the angle between the diagonals
    cos_phi = (dx * -dx + dy * dy) / max(dx * dx + dy * dy, 1e-300)
    if gamma is None:
        gamma = _a4_gamma_optimal(cos_phi)
    if not gamma >= 1.0:
        raise InputError(f"gamma = {gamma}", field="gamma", expected="a number >= 1")
    a = gamma * rho
    sin2 = 1.0 - cos_phi * cos_phi
    denom = 1.0 - cos_phi * cos_phi / (gamma * gamma)
    b = rho * math.sqrt(sin2 / denom) if denom > 0 else rho
    return _ellipse(cx, cy, a, b, angle)


def ellipse_a5(points: ArrayLike) -> Ellipse:
    """A5: the reduced ellipse, the A2 circle compressed across a diagonal (paper 1, stage 8).

    In the frame whose x axis is a diagonal of the A1 rectangle (origin at its centre, ``r`` the
    A2 radius), each point ``(u_i, v_i)`` has distance ``d_i = |v_i|`` from the diameter and the
    circle's half-chord ``h_i = sqrt(r^2 - u_i^2)`` at its abscissa; the circle is compressed by
    ``k = max_i d_i / h_i`` **[reading: the printed "min" cannot enclose every point]**, giving
    ``a = r, b = k r, e = sqrt(1 - k^2)``; ``|v_i| <= k h_i`` puts each point inside. Both
    diagonals are tried and the smaller ellipse kept **[reading: the paper does not say which]**.
    """
    return _ellipse_a5(hull_points(points))


def _ellipse_a5(H: NDArray[np.float64]) -> Ellipse:
    c2 = _circle_a2(H)
    rect = _rect_a1(H)
    r = c2.radius
    best: Ellipse | None = None
    for sign in (1.0, -1.0):
        ang = _angle(sign * (rect.ymax - rect.ymin), rect.xmax - rect.xmin)
        s, c = _sincos(ang)
        dx, dy = H[:, 0] - c2.x, H[:, 1] - c2.y
        u = c * dx + s * dy
        v = -s * dx + c * dy
        h2 = np.maximum(r * r - u * u, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(
                h2 > 0, np.abs(v) / np.sqrt(h2), np.where(np.abs(v) > 1e-12 * r, np.inf, 0.0)
            )
        k = float(min(1.0, np.max(ratio)))
        cand = _ellipse(c2.x, c2.y, r, k * r, ang)
        if best is None or cand.area < best.area:
            best = cand
    assert best is not None
    return best


def _a6_area(
    params: NDArray[np.float64], P: NDArray[np.float64], mask: NDArray[np.bool_]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Batched A6 objective: ``params (n, q, 4) = (x, y, phi, log k)`` over padded points ``P (n, m, 2)``.

    Returns the area ``pi a^2 k`` and ``a`` (both ``(n, q)``), with
    ``a = max_i sqrt(u_i^2 + v_i^2 / k^2)``.
    """
    x, y, phi, logk = (params[..., i] for i in range(4))
    k = fixedmath.exp(logk)
    s, c = fixedmath.sincos(phi)
    c, s = c[..., None], s[..., None]
    dx = P[:, None, :, 0] - x[..., None]
    dy = P[:, None, :, 1] - y[..., None]
    u = c * dx + s * dy
    v = -s * dx + c * dy
    a2 = u * u + (v * v) / (k[..., None] ** 2)
    a2 = np.where(mask[:, None, :], a2, 0.0).max(axis=-1)
    return np.pi * a2 * k, np.sqrt(a2)


def ellipses_a6_batch(
    hulls: Sequence[NDArray[np.float64]],
    starts: Sequence[Ellipse],
    *,
    max_iter: int = 120,
    rel_tol: float = 3e-3,
) -> list[Ellipse]:
    """A6 for many point sets at once: a compass (pattern) search vectorised over the sets.

    The objective of paper 1's A6, area ``pi a^2 k`` with the smallest enclosing
    ``a = max_i sqrt(u_i^2 + v_i^2/k^2)`` for fixed ``(x, y, phi, k)``, is minimised over
    ``(x, y, phi, log k)``. **[reading: the paper names Newton's method; the objective is a
    maximum of smooth functions (not differentiable where the maximising point changes), so a
    derivative-free pattern search is used]**: each iteration tries the 80 moves of -1, 0 or +1
    step on each parameter (axis moves alone stall at the kinks) for all sets at once, moves to
    the best improving trial, and halves the steps of a set with no improvement, until its steps
    fall below ``rel_tol`` of its size. The result is never larger than the start (A5); on
    random elongated sets it lands within 0.6 % (median), 3 % (90th percentile) of the MVEE.

    With the compiled kernels (:mod:`navkit.jit`) the search runs set by set in a Numba kernel
    (:func:`navkit.geometry._kernels.a6_search_kernel`: the same trials in the same order);
    else the batched search below (its twin). Both take ``cos``, ``sin``, ``exp`` and ``log`` from
    :mod:`navkit.geometry.fixedmath` (NumPy's SIMD versions and the C library's, which a kernel
    would call, differ in the last bit and per CPU), so they give the same ellipses bit for bit.
    """
    compiled = kernels_enabled()
    n = len(hulls)
    if n == 0:
        return []
    # sets of similar size together (sizes within a factor 2): the trials are evaluated on
    # arrays padded to the largest set of a batch, so mixing 4- and 24-vertex hulls wastes most
    # of the work; each set's search is independent of the others, so the result is the same
    sizes = np.array([len(h) for h in hulls])
    bucket = np.floor(np.log2(np.maximum(sizes, 1))).astype(np.int64)
    out: list[Ellipse] = [starts[0]] * n
    for b in np.unique(bucket):
        members = np.flatnonzero(bucket == b).tolist()
        res = _a6_batch(
            [hulls[i] for i in members], [starts[i] for i in members], max_iter, rel_tol, compiled
        )
        for i, e in zip(members, res, strict=True):
            out[i] = e
    return out


def _a6_batch(
    hulls: Sequence[NDArray[np.float64]],
    starts: Sequence[Ellipse],
    max_iter: int,
    rel_tol: float,
    compiled: bool,
) -> list[Ellipse]:
    """The pattern search of :func:`ellipses_a6_batch` on one batch of sets."""
    n = len(hulls)
    m = max(len(h) for h in hulls)
    P = np.zeros((n, m, 2))
    mask = np.zeros((n, m), dtype=bool)
    for i, h in enumerate(hulls):
        P[i, : len(h)] = h
        mask[i, : len(h)] = True
    ratio = np.array([max(e.b / e.a, 1e-6) if e.a > 0 else 1.0 for e in starts])
    logk0 = fixedmath.log(ratio)  # log 1 = 0 exactly
    x0 = np.array([[e.x, e.y, e.angle, lk] for e, lk in zip(starts, logk0.tolist(), strict=True)])
    size = np.array([max(e.a, 1e-6) for e in starts])
    step = np.column_stack([0.25 * size, 0.25 * size, np.full(n, 0.2), np.full(n, 0.2)])
    min_step = np.column_stack(
        [rel_tol * size, rel_tol * size, np.full(n, rel_tol), np.full(n, rel_tol)]
    )
    cur = x0.copy()
    f_cur, _ = _a6_area(cur[:, None, :], P, mask)
    f_cur = f_cur[:, 0]
    # all 80 combinations of {-1, 0, +1} on the four parameters: the objective is a max of
    # smooth functions, whose descent directions at a kink are often not along an axis
    grid = np.stack(np.meshgrid(*([np.array([-1.0, 0.0, 1.0])] * 4), indexing="ij"), -1).reshape(
        -1, 4
    )
    moves = grid[np.any(grid != 0, axis=1)]  # (80, 4)
    centre = 40  # index of the zero move in the 3^4 grid (ij order over x, y, phi, log k)
    keep_moves = np.arange(81) != centre
    # padded points repeat each set's first point: a duplicate cannot change a maximum
    for i, h in enumerate(hulls):
        P[i, len(h) :] = h[0]
    three = np.array([-1.0, 0.0, 1.0])
    active = np.ones(n, dtype=bool)
    if compiled:
        from navkit.geometry import _kernels

        counts = np.array([len(h) for h in hulls], dtype=np.int64)
        cur = _kernels.a6_search_kernel(P, counts, x0, step, min_step, int(max_iter))
        active[:] = False  # nothing left for the loop below
    for _ in range(max_iter):
        if not active.any():
            break
        idx = np.flatnonzero(active)
        # the 80 trials factorised: x, y, phi and k take three values each, so u and v are
        # computed on 27 (phi, x, y) combinations and a^2 on 81, instead of 80 full passes
        vals = cur[idx, None, :] + three[None, :, None] * step[idx, None, :]  # (k, 3, 4)
        Pa = P[idx]
        dx = Pa[:, None, :, 0] - vals[:, :, 0, None]  # (k, 3x, m)
        dy = Pa[:, None, :, 1] - vals[:, :, 1, None]  # (k, 3y, m)
        sn, c = fixedmath.sincos(vals[:, :, 2])
        c = c[:, :, None, None, None]  # (k, 3phi, 1, 1, 1)
        sn = sn[:, :, None, None, None]
        dxb, dyb = dx[:, None, :, None, :], dy[:, None, None, :, :]
        u = c * dxb + sn * dyb  # (k, 3phi, 3x, 3y, m)
        v = -sn * dxb + c * dyb
        kk = fixedmath.exp(vals[:, :, 3])  # (k, 3k)
        a2 = (u * u)[..., None, :] + (v * v)[..., None, :] / (kk[:, None, None, None, :, None] ** 2)
        a2 = a2.max(axis=-1)  # (k, 3phi, 3x, 3y, 3k)
        f_all = (np.pi * a2 * kk[:, None, None, None, :]).transpose(0, 2, 3, 1, 4)
        f_trial = f_all.reshape(len(idx), 81)[:, keep_moves]  # same order as ``moves``
        best = np.argmin(f_trial, axis=1)
        f_best = f_trial[np.arange(len(idx)), best]
        improved = f_best < f_cur[idx] * (1 - 1e-12)
        upd = idx[improved]
        cur[upd] = cur[upd] + moves[best[improved]] * step[upd]
        f_cur[upd] = f_best[improved]
        shrink = idx[~improved]
        step[shrink] *= 0.5
        active[shrink] = np.any(step[shrink] > min_step[shrink], axis=1)
    _, a = _a6_area(cur[:, None, :], P, mask)
    a = a[:, 0] * (1 + 1e-12)
    k = fixedmath.exp(cur[:, 3])
    out = []
    for i in range(n):
        cand = _ellipse(cur[i, 0], cur[i, 1], a[i], a[i] * k[i], cur[i, 2])
        out.append(cand if cand.area <= starts[i].area else starts[i])
    return out


def ellipse_a6(points: ArrayLike, start: Ellipse | None = None) -> Ellipse:
    """A6: the minimised ellipse, from the A5 ellipse (or ``start``); see :func:`ellipses_a6_batch`."""
    H = hull_points(points)
    return ellipses_a6_batch([H], [start if start is not None else _ellipse_a5(H)])[0]


# ----------------------------------------------------------------------------------------------
# the exact optima (beyond the paper)


def _circle2(ax: float, ay: float, bx: float, by: float) -> tuple[float, float, float]:
    cx, cy = 0.5 * (ax + bx), 0.5 * (ay + by)
    return cx, cy, _norm(ax - cx, ay - cy)


def _circle3(
    ax: float, ay: float, bx: float, by: float, cx: float, cy: float
) -> tuple[float, float, float] | None:
    d = 2.0 * (ax * (by - cy) + bx * (cy - ay) + cx * (ay - by))
    if abs(d) < 1e-18:
        return None
    a2, b2, c2 = ax * ax + ay * ay, bx * bx + by * by, cx * cx + cy * cy
    ux = (a2 * (by - cy) + b2 * (cy - ay) + c2 * (ay - by)) / d
    uy = (a2 * (cx - bx) + b2 * (ax - cx) + c2 * (bx - ax)) / d
    return ux, uy, _norm(ax - ux, ay - uy)


def min_circle_welzl(points: ArrayLike, seed: int = 0) -> Circle:
    """The exact minimum enclosing circle (Welzl 1991, randomised incremental form).

    Expected linear time in the number of hull vertices; the order is shuffled with a fixed
    ``seed`` so results are reproducible. Coordinates are centred first for numerical stability.
    """
    return _min_circle_welzl(hull_points(points), seed)


def _min_circle_welzl(H: NDArray[np.float64], seed: int = 0) -> Circle:
    # the mean summed in index order (the kernel's order; a NumPy reduction may pair terms)
    ox = oy = 0.0
    for x, y in H.tolist():
        ox += x
        oy += y
    ox /= len(H)
    oy /= len(H)
    pts = [(x - ox, y - oy) for x, y in H.tolist()]
    random.Random(seed).shuffle(pts)

    def inside(c: tuple[float, float, float], p: tuple[float, float]) -> bool:
        return _norm(p[0] - c[0], p[1] - c[1]) <= c[2] * (1 + 1e-12) + 1e-12

    c = (pts[0][0], pts[0][1], 0.0)
    for i in range(1, len(pts)):
        p = pts[i]
        if inside(c, p):
            continue
        c = (p[0], p[1], 0.0)
        for j in range(i):
            q = pts[j]
            if inside(c, q):
                continue
            c = _circle2(*p, *q)
            for k in range(j):
                s = pts[k]
                if inside(c, s):
                    continue
                c3 = _circle3(*p, *q, *s)
                if c3 is not None:
                    c = c3
    return Circle(c[0] + ox, c[1] + oy, c[2] * (1 + 1e-12), kind="circle")


def mvee_batch(
    hulls: Sequence[NDArray[np.float64]],
    *,
    tol: float = 1e-3,
    max_iter: int = 2000,
) -> list[Ellipse]:
    """Minimum-volume enclosing ellipses of many 2D sets (Khachiyan 1996; Todd & Yildirim 2007).

    The barycentric weights ``u`` of the lifted points ``q_i = (x_i, y_i, 1)`` are updated by
    Khachiyan's step ``beta = (M_j - d - 1) / ((d + 1)(M_j - 1))`` on the point ``j`` with the
    largest ``M_j = q_j^T X(u)^{-1} q_j``, alternated with Todd & Yildirim's away steps from the
    support point with the smallest ``M_j``, until ``M_j / (d + 1)`` is within ``tol`` of 1 for all
    points (and support points), vectorised over all sets. The ellipse ``(x - c)^T A (x - c) <= 1`` with ``c = P u``,
    ``A = (P diag(u) P^T - c c^T)^{-1} / d`` is then scaled to contain every point exactly, so it
    encloses the set and its area is within ``(1 + tol)`` (about) of the optimum.

    With the compiled kernels (:mod:`navkit.jit`) the iterations run set by set in a Numba
    kernel (:func:`navkit.geometry._kernels.mvee_weights_kernel`; no per-iteration NumPy
    overhead); else the batched loop below (its twin). Both make the same IEEE operations in the same order
    (every sum over the points in index order, :func:`_sum_in_order`; the 2 x 2 inverse and
    eigen-decomposition written out, :func:`_mvee_axes`), so they give the same bits.
    """
    compiled = kernels_enabled()
    n = len(hulls)
    if n == 0:
        return []
    d = 2
    m = max(len(h) for h in hulls)
    origin = np.array([_mean_in_order(h) for h in hulls])
    # pad each set to m points by repeating its first point with weight 0: a padded copy never
    # wins argmax (ties go to the first index) and, weightless, never argmin over the support
    P = np.empty((n, m, 2))
    mask = np.zeros((n, m), dtype=bool)
    for i, h in enumerate(hulls):
        P[i, : len(h)] = h - origin[i]
        P[i, len(h) :] = h[0] - origin[i]
        mask[i, : len(h)] = True
    scale = np.maximum(np.abs(P).max(axis=(1, 2)), 1e-9)
    P = P / scale[:, None, None]
    counts = mask.sum(axis=1)
    u = mask / counts[:, None]
    # X(u)^{-1} of the lifted points from the weighted moments: with c = sum u p and
    # S = sum u p p^T - c c^T, q^T X^{-1} q = 1 + (p - c)^T S^{-1} (p - c) (block inverse), so
    # each iteration needs five weighted sums and a 2 x 2 inverse instead of 3 x 3 products
    F = np.stack([P[..., 0], P[..., 1], P[..., 0] ** 2, P[..., 0] * P[..., 1], P[..., 1] ** 2], 1)
    idx = np.arange(n)
    Fa, ua = F, u.copy()
    r = np.arange(n)
    if compiled:
        from navkit.geometry import _kernels

        u = _kernels.mvee_weights_kernel(P, mask, float(tol), int(max_iter))
        idx = np.arange(0)  # nothing left for the loop below
    with np.errstate(divide="ignore", invalid="ignore"):  # once: the loop is overhead-bound
        for _ in range(max_iter):
            if len(idx) == 0:
                break
            mom = _sum_in_order(Fa * ua[:, None, :])
            cx, cy = mom[:, 0:1], mom[:, 1:2]
            sxx, sxy, syy = mom[:, 2:3] - cx * cx, mom[:, 3:4] - cx * cy, mom[:, 4:5] - cy * cy
            det = np.maximum(sxx * syy - sxy * sxy, 1e-300)
            dx, dy = Fa[:, 0] - cx, Fa[:, 1] - cy
            M = 1.0 + (syy * dx * dx - 2.0 * sxy * dx * dy + sxx * dy * dy) / det
            j_up = np.argmax(M, axis=1)
            j_dn = np.argmin(np.where(ua > 0, M, np.inf), axis=1)
            M_up, M_dn = M[r, j_up], M[r, j_dn]
            eps_up = M_up / (d + 1) - 1
            eps_dn = 1 - M_dn / (d + 1)
            done = np.maximum(eps_up, eps_dn) <= tol
            toward = eps_up >= eps_dn
            # Khachiyan's step towards the farthest point, or Todd-Yildirim's away step from
            # the nearest support point (faster convergence, same fixed point)
            beta_up = (M_up - d - 1) / ((d + 1) * (M_up - 1))
            u_dn = ua[r, j_dn]
            beta_dn = np.minimum((d + 1 - M_dn) / ((d + 1) * (M_dn - 1)), u_dn / (1 - u_dn))
            beta_dn = np.where(np.isfinite(beta_dn), beta_dn, 0.0)
            up = toward & ~done
            dn = ~toward & ~done
            # one multiplicative factor per set, then the chosen point's additive term
            ua *= np.where(up, 1 - beta_up, np.where(dn, 1 + beta_dn, 1.0))[:, None]
            ua[r[up], j_up[up]] += beta_up[up]
            ua[r[dn], j_dn[dn]] -= beta_dn[dn]
            np.maximum(ua, 0.0, out=ua)
            if done.any():  # store the finished sets, keep iterating on the others only
                u[idx[done]] = ua[done]
                keep = ~done
                idx, Fa, ua = idx[keep], Fa[keep], ua[keep]
                r = np.arange(len(idx))
    if len(idx):
        u[idx] = ua
    # the centre c = P u and A = (P diag(u) P^T - c c^T)^-1 / d in closed form (the kernel's
    # ``mvee_csr_kernel`` operations), scaled so that the farthest point is on the ellipse
    x, y = P[..., 0], P[..., 1]
    cx, cy = _sum_in_order(u * x), _sum_in_order(u * y)
    sxx = _sum_in_order(x * u * x) - cx * cx
    sxy = _sum_in_order(x * u * y) - cx * cy
    syy = _sum_in_order(y * u * y) - cy * cy
    det = sxx * syy - sxy * sxy
    a00, a01, a11 = syy / det / d, -sxy / det / d, sxx / det / d
    dx, dy = x - cx[:, None], y - cy[:, None]
    val = dx * (a00[:, None] * dx + a01[:, None] * dy) + dy * (
        a01[:, None] * dx + a11[:, None] * dy
    )
    f = np.maximum(np.where(mask, val, 0.0).max(axis=1), 1e-300) * (1 + 1e-12)
    a, b, angle = _mvee_axes(a00 / f, a01 / f, a11 / f)
    ex, ey = cx * scale + origin[:, 0], cy * scale + origin[:, 1]
    cols = (ex.tolist(), ey.tolist(), (a * scale).tolist(), (b * scale).tolist(), angle)
    return [_ellipse(*row) for row in zip(*cols, strict=True)]


def _mean_in_order(H: NDArray[np.float64]) -> NDArray[np.float64]:
    """The mean of the rows of ``H (m, 2)``, summed in index order (the kernels' order)."""
    return (_sum_in_order(H.T) / len(H)).astype(np.float64)


def _sum_in_order(t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Sums over the last axis in index order, ``((0 + t0) + t1) + ...``, as a kernel's loop.

    The last element of a cumulative sum: ``add.accumulate`` adds each term to the running sum
    (its result at every index is defined by that order), where a reduction (``sum``,
    ``einsum``, ``dot``) may pair terms differently per CPU (SIMD width, BLAS); ``+ 0.0``
    gives the loop's ``+0`` for a sum of ``-0`` terms."""
    if t.shape[-1] == 0:
        return np.zeros(t.shape[:-1])
    return np.cumsum(t, axis=-1)[..., -1] + 0.0


def _mvee_axes(
    p: NDArray[np.float64], q: NDArray[np.float64], r: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], list[float]]:
    """Semi-axes ``a >= b`` and major-axis angle of the ellipses ``[[p, q], [q, r]]``
    (positive definite), the 2 x 2 eigen-decomposition written out (elementwise IEEE
    operations and the fixed :func:`~navkit.geometry.angles.atan2`: the same bits on any CPU,
    where LAPACK's ``eigh`` depends on the build and the machine).

    The eigenvalues are ``w1 = (p + r) / 2 + h`` and ``w0 = det / w1`` (``h = sqrt(((p - r)
    / 2)^2 + q^2)``; ``w0`` as a quotient, not ``(p + r) / 2 - h``, which cancels for elongated
    ellipses); the axes ``1 / sqrt(w)``. The eigenvector of ``w1`` is at
    ``atan2(2 q, p - r) / 2``, the major axis (of ``w0``) a quarter turn further."""
    hd = 0.5 * (p - r)
    h = np.sqrt(hd * hd + q * q)
    w1 = 0.5 * (p + r) + h
    w0 = (p * r - q * q) / w1
    angle = 0.5 * fixed_atan2(2.0 * q, p - r) + 0.5 * math.pi
    return 1.0 / np.sqrt(w0), 1.0 / np.sqrt(w1), angle.tolist()


def mvee_khachiyan(points: ArrayLike, tol: float = 1e-3) -> Ellipse:
    """The minimum-area enclosing ellipse of points ``(N, 2)``; see :func:`mvee_batch`."""
    return mvee_batch([hull_points(points)], tol=tol)[0]


# ----------------------------------------------------------------------------------------------
# registry

ShapeFn = Callable[[NDArray[np.float64]], Any]
SHAPES: dict[str, ShapeFn] = {}
"""Registered methods: name -> function of hull points ``(M, 2)`` returning a shape."""

_BATCHED = {"A6", "MVEE"}


def register_shape(name: str, fn: ShapeFn, *, replace: bool = False) -> None:
    """Add a bounding-shape method ``fn(points (M, 2)) -> shape`` under ``name``.

    The shape object must offer ``area``, ``contains(points, tol)``, ``outline(n)`` and
    ``params()`` (see :class:`Shape`).
    """
    if name in SHAPES and not replace:
        raise InputError(
            f"shape {name!r} is already registered",
            field="name",
            expected="a new name or replace=True",
        )
    SHAPES[name] = fn


register_shape("A1", _rect_a1)
register_shape("A2", _circle_a2)
register_shape("A3", _circle_a3)
register_shape("A4", _ellipse_a4)
register_shape("A5", _ellipse_a5)
register_shape("A6", ellipse_a6)
register_shape("MEC", _min_circle_welzl)
register_shape("MVEE", mvee_khachiyan)


def compute_shapes(
    point_sets: Iterable[ArrayLike],
    names: Sequence[str] = ("A1", "A2", "A3", "A4", "A5", "A6", "MEC", "MVEE"),
    *,
    are_hulls: bool = False,
) -> list[dict[str, Any]]:
    """Every requested shape for every point set: a list of ``{name: shape}`` dicts.

    A6 and MVEE are computed for all sets at once (vectorised); A6 starts from the set's A5.
    ``are_hulls=True`` says the sets already are :func:`hull_points` outputs (not recomputed).
    With the compiled kernels (:mod:`navkit.jit`) the hulls (:func:`hulls_csr`) and the shipped
    shapes (:func:`shapes_csr`) are computed in kernels over all sets at once; else set by set
    (the twin), the same shapes bit for bit.
    """
    unknown = [n for n in names if n not in SHAPES]
    if unknown:
        raise InputError(
            f"unknown shapes {unknown}", field="shapes", expected=f"names among {sorted(SHAPES)}"
        )
    if not hasattr(point_sets, "__len__") or (
        isinstance(point_sets, np.ndarray) and point_sets.ndim == 0
    ):
        raise InputError(
            f"is {type(point_sets).__name__}",
            field="point_sets",
            expected="a list of (N, 2) point arrays",
        )
    if kernels_enabled():
        sets = [as_points(p, 2) for p in point_sets]
        xy = np.concatenate(sets) if sets else np.empty((0, 2))
        check_coordinates(xy, field="point_sets")
        off = _offsets([len(p) for p in sets])
        H, hoff = (xy, off) if are_hulls else hulls_csr(xy, off)[:2]
        return shapes_csr(H, hoff, names)
    hulls = [as_points(p, 2) if are_hulls else hull_points(p) for p in point_sets]
    if are_hulls:
        for H in hulls:
            check_coordinates(H, field="point_sets")
    out: list[dict[str, Any]] = [{} for _ in hulls]
    for name in names:
        if name in _BATCHED and SHAPES[name] is {"A6": ellipse_a6, "MVEE": mvee_khachiyan}[name]:
            continue
        for res, H in zip(out, hulls, strict=False):
            res[name] = SHAPES[name](H)
    if "A6" in names and SHAPES["A6"] is ellipse_a6:
        starts = [
            res["A5"] if "A5" in res else _ellipse_a5(H) for res, H in zip(out, hulls, strict=False)
        ]
        for res, e in zip(out, ellipses_a6_batch(hulls, starts), strict=False):
            res["A6"] = e
    if "MVEE" in names and SHAPES["MVEE"] is mvee_khachiyan:
        for res, e in zip(out, mvee_batch(hulls), strict=False):
            res["MVEE"] = e
    return [{n: res[n] for n in names} for res in out]


# ----------------------------------------------------------------------------------------------
# many sets at once in a CSR layout (stage 8 with the compiled kernels)

_BUILTIN: dict[str, ShapeFn] = dict(SHAPES)
"""The registered methods as shipped: the compiled path computes these in kernels."""


@functools.lru_cache(maxsize=4096)
def _welzl_order(m: int, seed: int = 0) -> NDArray[np.int64]:
    """The permutation ``random.Random(seed).shuffle`` applies to ``m`` points (Welzl's order)."""
    idx = list(range(m))
    random.Random(seed).shuffle(idx)
    return np.array(idx, dtype=np.int64)


def _offsets(lengths: Sequence[int] | NDArray[np.int64]) -> NDArray[np.int64]:
    off = np.zeros(len(lengths) + 1, dtype=np.int64)
    np.cumsum(lengths, out=off[1:])
    return off


def hulls_csr(
    xy: NDArray[np.float64],
    off: NDArray[np.int64],
    inner: tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.bool_]] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.bool_]]:
    """Convex hulls of many sets at once (compiled): ``(H, hoff, chain)``, set ``s``'s hull is
    ``H[hoff[s]:hoff[s + 1]]``, the rows of ``xy[off[s]:off[s + 1]]`` on its hull.

    Andrew's monotone chain (:func:`navkit.geometry._kernels.hulls_csr_kernel`, after an
    Akl-Toussaint filter) gives the vertices of :func:`hull_points` in its order (counter-clockwise
    from the lexicographically smallest vertex). Sets the chain cannot decide exactly as Qhull -
    fewer than 3 hull vertices, non-finite values, or a turn within ``1e-9`` (relative) of
    collinear, where Qhull's precision handling decides - go to :func:`hull_points` itself
    (with its 1 mm dilation of degenerate sets); ``chain (n,)`` says which sets the chain did.

    ``inner``: the ``(H, hoff, chain)`` of subsets of the sets (the obstacles' boundary
    vertices when the sets are the obstacles with their shadows): the points clearly inside a
    subset's chain hull are dropped before the chain (the answer is the same, found faster).
    """
    from navkit.geometry import _kernels

    xy = np.ascontiguousarray(xy, dtype=np.float64)
    off = np.ascontiguousarray(off, dtype=np.int64)
    n = len(off) - 1
    if inner is None:
        Q, qoff = np.empty((0, 2)), np.zeros(n + 1, dtype=np.int64)
    else:
        Q, qoff, qchain = inner
        if not qchain.all():  # a dilated (Qhull) hull may reach outside the set's hull
            keep = np.repeat(qchain, np.diff(qoff))
            Q = Q[keep]
            qoff = _offsets(np.where(qchain, np.diff(qoff), 0))
    idx, hoff, ok = _kernels.hulls_csr_kernel(
        xy, off, np.ascontiguousarray(Q, dtype=np.float64), np.ascontiguousarray(qoff)
    )
    H = xy[idx]
    if not ok.all():
        parts = [
            H[hoff[s] : hoff[s + 1]] if ok[s] else hull_points(xy[off[s] : off[s + 1]])
            for s in range(len(ok))
        ]
        H = np.concatenate(parts) if parts else np.empty((0, 2))
        hoff = _offsets([len(p) for p in parts])
    return H, hoff, ok


def _normalised(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    angle: NDArray[np.float64],
) -> NDArray[np.float64]:
    """:func:`_ellipse`'s normalisation on arrays: rows ``(x, y, a, b, angle)``."""
    a, b = np.abs(a), np.abs(b)
    swap = b > a
    a, b = np.where(swap, b, a), np.where(swap, a, b)
    angle = np.where(swap, angle + math.pi / 2, angle)
    angle = (angle + math.pi / 2) % math.pi - math.pi / 2
    return np.column_stack([x, y, a, b, angle])


def _mvee_rows(H: NDArray[np.float64], hoff: NDArray[np.int64]) -> NDArray[np.float64]:
    """:func:`mvee_batch` on CSR hulls (compiled weights and shape matrix, :func:`_mvee_axes`)."""
    from navkit.geometry import _kernels

    origin, scale, c, A = _kernels.mvee_csr_kernel(H, hoff, 1e-3, 2000)
    a, b, angle = _mvee_axes(A[:, 0, 0], A[:, 0, 1], A[:, 1, 1])
    centre = c * scale[:, None] + origin
    return _normalised(centre[:, 0], centre[:, 1], a * scale, b * scale, np.array(angle))


# The records of a frame's shapes (hundreds) are built without the dataclasses' ``__init__``,
# whose per-field ``object.__setattr__`` (the price of ``frozen=True``) is ~3x the cost of
# filling ``__dict__`` directly; these classes have no ``__post_init__`` and stay frozen. The
# fields are stored one by one into the instance's ``__dict__`` (no keyword dictionary built
# and merged per record as with ``__dict__.update(x=...)``: ~1.5-2x faster).


def _ellipses(rows: NDArray[np.float64]) -> list[Ellipse]:
    new = object.__new__
    out = []
    for x, y, a, b, angle in rows.tolist():
        e = new(Ellipse)
        d = e.__dict__
        d["x"] = x
        d["y"] = y
        d["a"] = a
        d["b"] = b
        d["angle"] = angle
        d["kind"] = "ellipse"
        out.append(e)
    return out


def _circles(rows: NDArray[np.float64]) -> list[Circle]:
    new = object.__new__
    out = []
    for x, y, r in rows.tolist():
        c = new(Circle)
        d = c.__dict__
        d["x"] = x
        d["y"] = y
        d["radius"] = r
        d["kind"] = "circle"
        out.append(c)
    return out


def _rectangles(rows: NDArray[np.float64]) -> list[Rectangle]:
    new = object.__new__
    out = []
    for xmin, xmax, ymin, ymax in rows.tolist():
        r = new(Rectangle)
        d = r.__dict__
        d["xmin"] = xmin
        d["xmax"] = xmax
        d["ymin"] = ymin
        d["ymax"] = ymax
        d["kind"] = "rectangle"
        out.append(r)
    return out


def shapes_csr(
    H: NDArray[np.float64], hoff: NDArray[np.int64], names: Sequence[str]
) -> list[dict[str, Any]]:
    """Every requested shape of every hull ``H[hoff[s]:hoff[s + 1]]`` (compiled kernels).

    The shipped methods run in kernels over all hulls at once
    (:func:`navkit.geometry._kernels.basic_shapes_kernel`: A1-A5 and Welzl's circle;
    ``a6_csr_kernel``; ``mvee_csr_kernel``) with their twins' arithmetic, so the shapes equal
    :func:`compute_shapes`' NumPy twin bit for bit, on any CPU. A method
    replaced or added with :func:`register_shape` is called hull by hull.
    """
    from navkit.geometry import _kernels

    H = np.ascontiguousarray(H, dtype=np.float64)
    hoff = np.ascontiguousarray(hoff, dtype=np.int64)
    n = len(hoff) - 1
    if n == 0 or not names:
        return [{} for _ in range(n)]
    fast = {name for name in names if SHAPES[name] is _BUILTIN.get(name)}
    cols: dict[str, list[Any]] = {}
    basic = None
    if fast - {"MVEE"}:
        lengths = np.diff(hoff)
        perm = np.concatenate([_welzl_order(int(m)) for m in lengths.tolist()])
        basic = _kernels.basic_shapes_kernel(H, hoff, perm)
        if "A1" in fast:
            cols["A1"] = _rectangles(basic[:, 0:4])
        if "A2" in fast:
            cols["A2"] = _circles(basic[:, 4:7])
        if "A3" in fast:
            cols["A3"] = _circles(basic[:, 7:10])
        if "A4" in fast:
            cols["A4"] = _ellipses(basic[:, 10:15])
        if "A5" in fast:
            cols["A5"] = _ellipses(basic[:, 15:20])
        if "MEC" in fast:
            cols["MEC"] = _circles(basic[:, 20:23])
        if "A6" in fast:
            cols["A6"] = _ellipses(
                _kernels.a6_csr_kernel(H, hoff, np.ascontiguousarray(basic[:, 15:20]), 3e-3, 120)
            )
    if "MVEE" in fast:
        cols["MVEE"] = _ellipses(_mvee_rows(H, hoff))
    for name in names:
        if name not in cols:
            cols[name] = [SHAPES[name](H[hoff[s] : hoff[s + 1]]) for s in range(n)]
    per_name = [cols[name] for name in names]
    return [dict(zip(names, objs, strict=True)) for objs in zip(*per_name, strict=True)]
