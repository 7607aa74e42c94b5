"""Constrained least-squares cubics: running sums = batch fit = a KKT reference solution."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.path.fitting import (
    VARIANTS,
    fit_from_sums,
    fit_points,
    needs_tangent,
    power_sums,
    residuals,
)


def _kkt_reference(
    variant: str, u: np.ndarray, d: np.ndarray, tangent_T: np.ndarray | None
) -> np.ndarray:
    """Constrained least squares through the KKT system, one coordinate at a time (independent
    of the basis elimination in navkit): minimise |A c - y|^2 subject to C c = e."""
    A = np.c_[np.ones_like(u), u, u**2, u**3]
    out = np.zeros((2, 4))
    for k in range(2):
        rows, rhs = [[1.0, 0, 0, 0]], [0.0]  # C(0) = anchor (d is relative)
        if needs_tangent(variant):
            rows.append([0.0, 1, 0, 0])
            rhs.append(tangent_T[k])
        if variant in ("endpoints", "endpoints_tangent"):
            rows.append([1.0, 1, 1, 1])
            rhs.append(d[-1, k])
        C = np.array(rows)
        m = len(C)
        KKT = np.block([[2 * A.T @ A, C.T], [C, np.zeros((m, m))]])
        sol = np.linalg.solve(KKT, np.r_[2 * A.T @ d[:, k], rhs])
        out[k] = sol[:4]
    return out


@pytest.mark.parametrize("variant", VARIANTS)
def test_batch_fit_matches_kkt_reference(variant, rng):
    n = 40
    tau = np.r_[0.0, np.cumsum(rng.uniform(0.05, 0.15, n - 1))]
    d = np.c_[np.sin(tau), 0.3 * tau**2] + 0.01 * rng.standard_normal((n, 2))
    d[0] = 0.0
    g = np.array([np.cos(0.3), np.sin(0.3)])
    fit = fit_points(variant, tau, d, tangent=g if needs_tangent(variant) else None)
    ref = _kkt_reference(variant, tau / tau[-1], d, g * tau[-1])
    # both solve the same 4-unknown problem in double precision on u in [0, 1]: agreement to
    # ~1e-9 (the Gram matrices have condition numbers ~1e4)
    np.testing.assert_allclose(fit.coef, ref, atol=1e-9)
    r = residuals(fit, tau / tau[-1], d)
    np.testing.assert_allclose(fit.ssr, (r**2).sum(), rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize("variant", VARIANTS)
def test_constraints_hold(variant, rng):
    tau = np.linspace(0.0, 2.0, 25)
    d = np.c_[tau, np.cos(tau) - 1.0] + 0.02 * rng.standard_normal((25, 2))
    d[0] = 0.0
    g = np.array([0.0, 1.0])
    fit = fit_points(variant, tau, d, tangent=g)
    c = fit.coef
    np.testing.assert_allclose(c[:, 0], 0.0, atol=1e-14)  # passes through the anchor
    if variant in ("endpoints", "endpoints_tangent"):
        np.testing.assert_allclose(c.sum(1), d[-1], atol=1e-12)  # and through the last point
    if needs_tangent(variant):
        np.testing.assert_allclose(c[:, 1] / fit.T, g, atol=1e-12)  # dC/dtau(0) = g


@pytest.mark.parametrize("variant", VARIANTS)
def test_running_sums_equal_batch_sums(variant, rng):
    """Accumulating the sums point by point (in tau, rescaled) gives the batch answer."""
    tau = np.r_[0.0, np.cumsum(rng.uniform(0.1, 0.3, 30))]
    d = np.c_[tau, np.sin(tau)] + 0.01 * rng.standard_normal((31, 2))
    d[0] = 0.0
    S = np.zeros(7)
    D = np.zeros((2, 4))
    Q = 0.0
    for t, p in zip(tau, d, strict=True):
        tp = t ** np.arange(7.0)
        S += tp
        D += np.outer(p, tp[:4])
        Q += p @ p
    T = tau[-1]
    sc = T ** -np.arange(7.0)
    g = (1.0, 0.0)
    online = fit_from_sums(
        variant, (S * sc).tolist(), (D * sc[:4]).tolist(), Q, 30, T, end=d[-1], tangent=g
    )
    batch = fit_points(variant, tau, d, tangent=np.array(g))
    np.testing.assert_allclose(online.coef, batch.coef, atol=1e-10)
    assert online.ssr == pytest.approx(batch.ssr, rel=1e-7, abs=1e-12)


@pytest.mark.parametrize("variant", VARIANTS)
def test_two_points_are_fitted_exactly(variant):
    tau = np.array([0.0, 1.5])
    d = np.array([[0.0, 0.0], [1.2, -0.9]])
    fit = fit_points(variant, tau, d, tangent=np.array([1.0, 0.0]))
    assert residuals(fit, tau / tau[-1], d).max() < 1e-12


def test_power_sums_simple():
    S, D, Q = power_sums(np.array([0.0, 0.5, 1.0]), np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 1.0]]))
    np.testing.assert_allclose(S[:3], [3.0, 1.5, 1.25])
    np.testing.assert_allclose(D[0], [3.0, 2.5, 2.25, 2.125])
    assert Q == 6.0


def test_endpoints_fast_path_is_the_general_code(rng):
    """``fit_from_sums``' straight-line path for ``endpoints`` (the O(1) test of every point)
    gives the general code's numbers bit for bit, signs of zeros included, also on degenerate
    parameter grids and zero data."""
    from navkit.path.fitting import _fit_general

    for trial in range(3000):
        n = int(rng.integers(4, 60))
        u = np.sort(rng.random(n))
        u[0], u[-1] = 0.0, 1.0
        if trial % 7 == 0:
            u[1:] = 1.0  # every point at the end: no free function fits
        if trial % 11 == 0:
            u[1:-1] = 0.5
        d = np.c_[rng.normal(size=n).cumsum(), rng.normal(size=n).cumsum()]
        d *= 10.0 ** rng.integers(-6, 3)
        d[0] = 0.0
        if trial % 13 == 0:
            d[:] = 0.0
        S, D, Q = power_sums(u, d)
        args = (S.tolist(), D.tolist(), Q, n - 1, float(rng.random() * 10))
        a = fit_from_sums("endpoints", *args, end=d[-1].tolist())
        b = _fit_general("endpoints", *args, end=d[-1].tolist())
        assert np.array_equal(a.coef, b.coef) and (a.T, a.ssr) == (b.T, b.ssr)
        assert np.array_equal(np.signbit(a.coef), np.signbit(b.coef))
        assert np.signbit(a.ssr) == np.signbit(b.ssr)
