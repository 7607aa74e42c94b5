"""Constrained least-squares parametric cubics (paper 4, section 2, eq. 1 and fig. 1).

A segment starts at a fixed point ``P_a`` (the end of the previous segment) and is fitted to
points ``P_i`` at parameters ``tau_i`` (polyline length, or arc length for the refit of section
4). Coordinates are relative to ``P_a`` and the parameter is scaled to ``u = tau / T`` in
``[0, 1]`` (``T`` the last parameter) so the normal equations stay well conditioned. Every
variant writes the cubic ``d(u) = K(u) + sum_j c_j phi_j(u)`` with a *known* part ``K`` that
carries the constraints and free basis functions ``phi_j`` (the same for x and y):

==================== ===================================== ==========================================
variant              constraints (paper fig. 1)             ``K(u)`` / free ``phi_j(u)``
==================== ===================================== ==========================================
``start``            ``C(0) = P_a``                         0 / ``u, u^2, u^3``
``start_tangent``    ``C(0) = P_a, C'(0) = g``              ``g T u`` / ``u^2, u^3``
``endpoints``        ``C(0) = P_a, C(T) = P_n``             ``e u`` / ``u^2 - u, u^3 - u``
``endpoints_tangent````C(0) = P_a, C'(0) = g, C(T) = P_n``  ``g T u + (e - g T) u^2`` / ``u^3 - u^2``
==================== ===================================== ==========================================

(``e = P_n - P_a``, ``g`` the unit tangent at the end of the previous segment.) The normal
equations need only the power sums ``S_p = sum u_i^p`` (p <= 6), ``D_p = sum d_i u_i^p``
(p <= 3) and ``Q = sum |d_i|^2``, which the online approximator keeps as running sums so a new
point costs the same however long the segment is. The residual sum of squares follows from the
same sums, ``SSR = sum |r|^2 - c . b``; since ``max_i |r_i| <= sqrt(SSR)``, ``SSR <= eps^2`` proves
every point is within ``eps`` without looking at the points (the cheap deviation test).

``endpoints_tangent`` has one unknown per coordinate, ``c = b / G``: the closed form without
matrix inversion the paper mentions. With too few points for all free functions (or a
degenerate parameter grid) the highest-order functions are dropped (their coefficients are 0),
so two points always give the exact straight line (or parabola with a tangent).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from navkit.errors import ConfigError

__all__ = [
    "VARIANTS",
    "CubicFit",
    "Variant",
    "fit_from_sums",
    "fit_points",
    "power_sums",
    "project",
    "residuals",
]

Variant = Literal["start", "start_tangent", "endpoints", "endpoints_tangent"]
VARIANTS: tuple[str, ...] = ("start", "start_tangent", "endpoints", "endpoints_tangent")

_BASIS: dict[str, NDArray[np.float64]] = {
    "start": np.array([[0.0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]),
    "start_tangent": np.array([[0.0, 0, 1, 0], [0, 0, 0, 1]]),
    "endpoints": np.array([[0.0, -1, 1, 0], [0, -1, 0, 1]]),
    "endpoints_tangent": np.array([[0.0, 0, -1, 1]]),
}
# points (besides the anchor) that the constraints use up: the fixed end point
_FIXED_POINTS = {"start": 0, "start_tangent": 0, "endpoints": 1, "endpoints_tangent": 1}
_HANKEL = np.add.outer(np.arange(4), np.arange(4))  # H[p, q] = S[p + q]


def check_variant(variant: str) -> None:
    """Raise :class:`ConfigError` unless ``variant`` is one of :data:`VARIANTS`."""
    if variant not in _BASIS:
        raise ConfigError(
            f"unknown variant {variant!r}", field="variant", expected=" | ".join(VARIANTS)
        )


def needs_tangent(variant: str) -> bool:
    """True for the variants that continue the previous segment's tangent."""
    return variant in ("start_tangent", "endpoints_tangent")


@dataclass(frozen=True)
class CubicFit:
    """A fitted segment in scaled form.

    Attributes
    ----------
    coef : (2, 4) array
        ``d(u) = coef[:, 0] + coef[:, 1] u + ...`` for x (row 0) and y (row 1), relative to the
        anchor, ``u = tau / T``.
    T : float
        Parameter scale (the last point's parameter), metres.
    ssr : float
        Residual sum of squares over the points, m^2 (from the sums; rounding error ~1e-16 * Q).
    """

    coef: NDArray[np.float64]
    T: float
    ssr: float

    def metric_coefficients(
        self, anchor: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Coefficients in metres of ``tau`` (``a_k = c_k / T^k``) with the anchor added: (ax, ay)."""
        scale = self.T ** -np.arange(4.0) if self.T > 0 else np.array([1.0, 0.0, 0.0, 0.0])
        ax = self.coef[0] * scale
        ay = self.coef[1] * scale
        ax[0] += anchor[0]
        ay[0] += anchor[1]
        return ax, ay


def power_sums(
    u: NDArray[np.float64], d: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """``S (7,)``, ``D (2, 4)`` and ``Q`` of points ``d (n, 2)`` at scaled parameters ``u (n,)``.

    The arithmetic of ``_kernels.power_sums``, so both give the same bits on every CPU: the
    powers as running products ``u^p = u^(p-1) u``, every sum from 0 in point order
    (``np.cumsum``, a sequential accumulation; ``sum`` would add pairwise and ``@`` in the BLAS
    library's order)."""
    u = np.asarray(u, dtype=np.float64)
    d = np.asarray(d, dtype=np.float64)
    n = len(u)
    P = np.empty((n + 1, 7))
    P[0] = 0.0  # the sums start from 0, as the kernel's do
    P[1:, 0] = 1.0
    for p in range(1, 7):
        np.multiply(P[1:, p - 1], u, out=P[1:, p])
    S = np.cumsum(P, axis=0)[-1]
    D = np.empty((2, 4))
    for c in range(2):
        terms = np.zeros((n + 1, 4))
        np.multiply(d[:, c, None], P[1:, :4], out=terms[1:])
        D[c] = np.cumsum(terms, axis=0)[-1]
    q = np.zeros(n + 1)
    q[1:] = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]
    return S, D, float(np.cumsum(q)[-1])


def _det(G: list[list[float]]) -> float:
    m = len(G)
    if m == 1:
        return G[0][0]
    if m == 2:
        return G[0][0] * G[1][1] - G[0][1] * G[1][0]
    return (
        G[0][0] * (G[1][1] * G[2][2] - G[1][2] * G[2][1])
        - G[0][1] * (G[1][0] * G[2][2] - G[1][2] * G[2][0])
        + G[0][2] * (G[1][0] * G[2][1] - G[1][1] * G[2][0])
    )


def _solve(G: list[list[float]], det: float, b: list[float]) -> list[float]:
    """Cramer's rule for 1 x 1, 2 x 2 and 3 x 3 systems (the determinant is given)."""
    m = len(G)
    if m == 1:
        return [b[0] / det]
    if m == 2:
        return [(b[0] * G[1][1] - G[0][1] * b[1]) / det, (G[0][0] * b[1] - b[0] * G[1][0]) / det]
    out = []
    for j in range(3):
        Gj = [[*row[:j], b[i], *row[j + 1 :]] for i, row in enumerate(G)]
        out.append(_det(Gj) / det)
    return out


def fit_from_sums(
    variant: str,
    S: Sequence[float],
    D: Sequence[Sequence[float]],
    Q: float,
    n_free_points: int,
    T: float,
    end: Sequence[float] | None = None,
    tangent: Sequence[float] | None = None,
) -> CubicFit:
    """Solve the constrained normal equations from power sums (all in scaled ``u``).

    Parameters
    ----------
    variant : str
        One of :data:`VARIANTS`.
    S : (7,) sequence
        ``sum u^p``.
    D : (2, 4) sequence
        ``sum d u^p`` (x row, y row), ``d`` relative to the anchor.
    Q : float
        ``sum |d|^2``.
    n_free_points : int
        Number of points besides the anchor.
    T : float
        The parameter scale (metres).
    end : (2,) sequence
        ``P_n - P_a`` (endpoint variants).
    tangent : (2,) sequence
        Unit tangent at the start (tangent variants).
    """
    if variant == "endpoints" and end is not None and n_free_points >= 3:
        return _fit_endpoints(S, D, Q, T, float(end[0]), float(end[1]))
    return _fit_general(variant, S, D, Q, n_free_points, T, end, tangent)


def _fit_general(
    variant: str,
    S: Sequence[float],
    D: Sequence[Sequence[float]],
    Q: float,
    n_free_points: int,
    T: float,
    end: Sequence[float] | None = None,
    tangent: Sequence[float] | None = None,
) -> CubicFit:
    """:func:`fit_from_sums` for every variant (the table's basis functions)."""
    # the known part K(u) = k1 u + k2 u^2 (per coordinate)
    k1 = [0.0, 0.0]
    k2 = [0.0, 0.0]
    if variant in ("start_tangent", "endpoints_tangent"):
        assert tangent is not None
        k1 = [float(tangent[0]) * T, float(tangent[1]) * T]
        if variant == "endpoints_tangent":
            assert end is not None
            k2 = [float(end[0]) - k1[0], float(end[1]) - k1[1]]
    elif variant == "endpoints":
        assert end is not None
        k1 = [float(end[0]), float(end[1])]
    Dx, Dy = D[0], D[1]
    # sum |r|^2 with r = d - K(u)
    rr = (
        Q
        - 2.0 * (k1[0] * Dx[1] + k1[1] * Dy[1] + k2[0] * Dx[2] + k2[1] * Dy[2])
        + (k1[0] * k1[0] + k1[1] * k1[1]) * S[2]
        + 2.0 * (k1[0] * k2[0] + k1[1] * k2[1]) * S[3]
        + (k2[0] * k2[0] + k2[1] * k2[1]) * S[4]
    )
    # sum r u^p, p = 0..3
    Rx = [Dx[p] - k1[0] * S[p + 1] - k2[0] * S[p + 2] for p in range(4)]
    Ry = [Dy[p] - k1[1] * S[p + 1] - k2[1] * S[p + 2] for p in range(4)]
    free = min(len(_BASIS[variant]), n_free_points - _FIXED_POINTS[variant])
    S2, S3, S4, S5, S6 = S[2], S[3], S[4], S[5], S[6]
    while free > 0:
        # Gram matrix G_jk = sum phi_j phi_k and right-hand sides b_j = sum r phi_j, written out
        # per variant from the basis table above (phi in powers of u, so sums of S and R)
        if variant == "endpoints":  # phi = u^2 - u, u^3 - u
            G = [[S4 - 2 * S3 + S2, S5 - S4 - S3 + S2], [S5 - S4 - S3 + S2, S6 - 2 * S4 + S2]]
            bx = [Rx[2] - Rx[1], Rx[3] - Rx[1]]
            by = [Ry[2] - Ry[1], Ry[3] - Ry[1]]
        elif variant == "start":  # phi = u, u^2, u^3
            G = [[S[2 + j + k] for k in range(3)] for j in range(3)]
            bx, by = Rx[1:4], Ry[1:4]
        elif variant == "start_tangent":  # phi = u^2, u^3
            G = [[S4, S5], [S5, S6]]
            bx, by = Rx[2:4], Ry[2:4]
        else:  # endpoints_tangent: phi = u^3 - u^2
            G = [[S6 - 2 * S5 + S4]]
            bx, by = [Rx[3] - Rx[2]], [Ry[3] - Ry[2]]
        if free < len(G):
            G = [row[:free] for row in G[:free]]
            bx, by = bx[:free], by[:free]
        det = _det(G)
        diag = G[0][0]
        for j in range(1, free):
            diag *= G[j][j]
        if diag > 0 and det > 1e-13 * diag:
            cx = _solve(G, det, bx)
            cy = _solve(G, det, by)
            rows = []
            for k, c in ((0, cx), (1, cy)):
                row = [0.0, k1[k], k2[k], 0.0]
                if variant == "endpoints":
                    row[2] += c[0]
                    row[1] -= c[0]
                    if free > 1:
                        row[3] += c[1]
                        row[1] -= c[1]
                elif variant == "start":
                    for j in range(free):
                        row[1 + j] += c[j]
                elif variant == "start_tangent":
                    for j in range(free):
                        row[2 + j] += c[j]
                else:
                    row[3] += c[0]
                    row[2] -= c[0]
                rows.append(row)
            coef = np.array(rows)
            ssr = rr - sum(cx[j] * bx[j] + cy[j] * by[j] for j in range(free))
            return CubicFit(coef=coef, T=T, ssr=max(ssr, 0.0))
        free -= 1  # degenerate grid: drop the highest-order function
    coef = np.array([[0.0, k1[0], k2[0], 0.0], [0.0, k1[1], k2[1], 0.0]])
    return CubicFit(coef=coef, T=T, ssr=max(rr, 0.0))


def _fit_endpoints(
    S: Sequence[float], D: Sequence[Sequence[float]], Q: float, T: float, ex: float, ey: float
) -> CubicFit:
    """:func:`fit_from_sums` for ``endpoints`` with both free functions (3 or more free points):
    the general code's operations in the same order, on plain locals (the O(1) test of every
    point calls it; the list and loop machinery was most of its cost)."""
    Dx, Dy = D[0], D[1]
    _, _, S2, S3, S4, S5, S6 = S
    k1x, k1y, k2x, k2y = ex, ey, 0.0, 0.0
    rr = (
        Q
        - 2.0 * (k1x * Dx[1] + k1y * Dy[1] + k2x * Dx[2] + k2y * Dy[2])
        + (k1x * k1x + k1y * k1y) * S2
        + 2.0 * (k1x * k2x + k1y * k2y) * S3
        + (k2x * k2x + k2y * k2y) * S4
    )
    Rx1 = Dx[1] - k1x * S2 - k2x * S3
    Rx2 = Dx[2] - k1x * S3 - k2x * S4
    Rx3 = Dx[3] - k1x * S4 - k2x * S5
    Ry1 = Dy[1] - k1y * S2 - k2y * S3
    Ry2 = Dy[2] - k1y * S3 - k2y * S4
    Ry3 = Dy[3] - k1y * S4 - k2y * S5
    g00 = S4 - 2 * S3 + S2
    g01 = S5 - S4 - S3 + S2
    g11 = S6 - 2 * S4 + S2
    bx0, bx1 = Rx2 - Rx1, Rx3 - Rx1
    by0, by1 = Ry2 - Ry1, Ry3 - Ry1
    det = g00 * g11 - g01 * g01
    diag = g00 * g11
    if diag > 0 and det > 1e-13 * diag:
        cx0 = (bx0 * g11 - g01 * bx1) / det
        cx1 = (g00 * bx1 - bx0 * g01) / det
        cy0 = (by0 * g11 - g01 * by1) / det
        cy1 = (g00 * by1 - by0 * g01) / det
        coef = np.array(
            [
                [0.0, k1x - cx0 - cx1, k2x + cx0, 0.0 + cx1],
                [0.0, k1y - cy0 - cy1, k2y + cy0, 0.0 + cy1],
            ]
        )
        ssr = rr - (0 + (cx0 * bx0 + cy0 * by0) + (cx1 * bx1 + cy1 * by1))
        return CubicFit(coef=coef, T=T, ssr=max(ssr, 0.0))
    return _fit_general("endpoints", S, D, Q, 3, T, end=(ex, ey))  # degenerate grid


def residuals(fit: CubicFit, u: NDArray[np.float64], d: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(n,)`` distances ``|C(u_i) - d_i|`` (an upper bound of the point-to-curve distance),
    as ``sqrt(ex^2 + ey^2)``: IEEE operations only, the kernels' bits on every CPU
    (``np.hypot`` is a libm call whose last bit is the library's)."""
    c = fit.coef
    ex = c[0, 0] + u * (c[0, 1] + u * (c[0, 2] + u * c[0, 3])) - d[:, 0]
    ey = c[1, 0] + u * (c[1, 1] + u * (c[1, 2] + u * c[1, 3])) - d[:, 1]
    return np.sqrt(ex * ex + ey * ey)


def project(
    fit: CubicFit, u0: NDArray[np.float64], d: NDArray[np.float64], iterations: int = 3
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Distance from points ``d (n, 2)`` to the curve ``u in [0, 1]``, starting Newton at ``u0``.

    Returns ``(u, distance)``; the distance is never larger than ``|C(u0) - d|`` (the better of
    the start and the Newton result is kept), so it is a true point-to-curve distance bound.
    """
    c = fit.coef
    u = np.clip(u0, 0.0, 1.0)
    for _ in range(iterations):  # Newton on |C(u) - d|^2 / 2, clipped to the segment
        rx = c[0, 0] + u * (c[0, 1] + u * (c[0, 2] + u * c[0, 3])) - d[:, 0]
        ry = c[1, 0] + u * (c[1, 1] + u * (c[1, 2] + u * c[1, 3])) - d[:, 1]
        dx = c[0, 1] + u * (2 * c[0, 2] + 3 * c[0, 3] * u)
        dy = c[1, 1] + u * (2 * c[1, 2] + 3 * c[1, 3] * u)
        ddx = 2 * c[0, 2] + 6 * c[0, 3] * u
        ddy = 2 * c[1, 2] + 6 * c[1, 3] * u
        g = rx * dx + ry * dy
        H = dx * dx + dy * dy + rx * ddx + ry * ddy
        u = np.clip(u - np.where(H > 1e-300, g / np.where(H > 1e-300, H, 1.0), 0.0), 0.0, 1.0)
    r_new = residuals(fit, u, d)
    r_old = residuals(fit, np.clip(u0, 0.0, 1.0), d)
    better = r_new <= r_old
    return np.where(better, u, np.clip(u0, 0.0, 1.0)), np.where(better, r_new, r_old)


def fit_points(
    variant: str,
    tau: NDArray[np.float64],
    d: NDArray[np.float64],
    tangent: NDArray[np.float64] | None = None,
) -> CubicFit:
    """Fit a segment to points ``d (n, 2)`` (relative to the anchor, ``d[0] = 0``) at ``tau (n,)``.

    The batch form of :func:`fit_from_sums` (used for the natural-parameterisation refit, and as
    the reference for the running sums in the tests).
    """
    check_variant(variant)
    T = float(tau[-1])
    u = tau / T if T > 0 else np.zeros_like(tau)
    S, D, Q = power_sums(u, d)
    return fit_from_sums(
        variant,
        S.tolist(),
        D.tolist(),
        Q,
        len(tau) - 1,
        T,
        end=d[-1].tolist(),
        tangent=None if tangent is None else np.asarray(tangent).tolist(),
    )
