"""navkit.geometry.fixedmath and its scalar kernels: the same bits, within 2 ulp of the truth.

The reference is NumPy's long double (x87 80-bit on x86-64: 11 more bits than a double, so its
``sinl``, ``expl``, ``logl`` are a finer truth for double results); where long double is double
the reference is libm (itself within 1 ulp) and the bounds grow by 1 ulp.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from navkit.geometry.fixedmath import SINCOS_MAX, exp, log, sincos

pytest.importorskip("numba")

SPECIAL = np.array(
    [
        *(0.0, -0.0, np.inf, -np.inf, np.nan, 1.0, -1.0, 5e-324, -5e-324, 2.2e-308, 1e-300),
        *(0.5, 2.0, 709.78, 709.79, -745.13, -745.14, 1e300, -1e300, SINCOS_MAX, -SINCOS_MAX),
        *(np.nextafter(SINCOS_MAX, 0), math.pi, math.pi / 2, math.pi / 4, 3 * math.pi / 4),
    ]
)
FINER = np.finfo(np.longdouble).eps < np.finfo(np.float64).eps


def _ulp(got: np.ndarray, x: np.ndarray, fn: str) -> np.ndarray:
    """Error of ``got`` in units of the last place of the true ``fn(x)``."""
    if FINER:
        ref = getattr(np, fn)(x.astype(np.longdouble))
        return np.abs(got.astype(np.longdouble) - ref) / np.spacing(np.abs(ref.astype(np.float64)))
    ref = getattr(np, fn)(x)
    return np.abs(got - ref) / np.spacing(np.abs(ref))


# measured on the arguments below: sin / cos 1.56, exp 1.73, log 0.90 ulp (x87 reference)
BOUND = {"sin": 2.0, "cos": 2.0, "exp": 2.0, "log": 1.0}
EXTRA = 0.0 if FINER else 1.0  # libm as the reference: its own error on top


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return bool(np.array_equal(a.view(np.int64), b.view(np.int64)))


def _trig_args(rng: np.random.Generator) -> np.ndarray:
    """Uniform over ranges from 1 to 2^29 (the reduction's domain), both signs, and the
    doubles nearest to multiples of pi / 4 (the octant switches)."""
    x = rng.uniform(-1, 1, 300_000) * 10.0 ** rng.uniform(-8, math.log10(SINCOS_MAX), 300_000)
    k = np.arange(-2000, 2000) * (math.pi / 4)
    return np.concatenate([x, k, np.nextafter(k, np.inf), np.nextafter(k, -np.inf), SPECIAL])


@pytest.mark.twin("sincos_kernel")
def test_sincos_twin_and_kernel_give_the_same_bits(rng):
    from navkit.geometry._kernels_math import sincos_kernel

    x = _trig_args(rng)
    s, c = sincos(x)
    sk, ck = np.empty_like(x), np.empty_like(x)
    sincos_kernel(x, sk, ck)
    assert _same_bits(s, sk) and _same_bits(c, ck)


@pytest.mark.twin("exp_kernel", "log_kernel")
def test_exp_and_log_twins_and_kernels_give_the_same_bits(rng):
    from navkit.geometry._kernels_math import exp_kernel, log_kernel

    x = np.concatenate([rng.uniform(-750, 712, 300_000), rng.normal(0, 1, 100_000), SPECIAL])
    assert _same_bits(exp(x), exp_kernel(x, np.empty_like(x)))
    x = np.concatenate(
        [10.0 ** rng.uniform(-320, 308, 300_000), 1 + rng.normal(0, 1e-3, 100_000), SPECIAL]
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        assert _same_bits(log(x), log_kernel(x, np.empty_like(x)))


def test_sin_and_cos_within_two_ulp(rng):
    x = _trig_args(rng)
    x = x[np.isfinite(x) & (np.abs(x) < SINCOS_MAX)]
    s, c = sincos(x)
    # pi / 4 is carried to ~101 bits: an absolute error up to ~4e-31 |x| on top, which only
    # shows in ulps within ~1e-14 |x| of a zero of sin or cos (the doubles nearest k pi / 2)
    near_zero_s = np.abs(np.sin(x)) < 1e-13 * np.maximum(np.abs(x), 1.0)
    near_zero_c = np.abs(np.cos(x)) < 1e-13 * np.maximum(np.abs(x), 1.0)
    assert float(np.max(_ulp(s, x, "sin")[~near_zero_s])) <= BOUND["sin"] + EXTRA
    assert float(np.max(_ulp(c, x, "cos")[~near_zero_c])) <= BOUND["cos"] + EXTRA
    for got, fn in ((s, np.sin), (c, np.cos)):  # everywhere: 2 ulp + 1e-30 |x|
        ref = fn(x.astype(np.longdouble)) if FINER else fn(x)
        tol = (2.0 + EXTRA) * np.spacing(np.abs(ref.astype(np.float64))) + 1e-30 * np.abs(x)
        assert np.all(np.abs(got - ref) <= tol)
    # most results are the correctly rounded ones, not just within the bound
    assert float(np.mean(s == np.sin(x))) > 0.6 and float(np.mean(c == np.cos(x))) > 0.6


def test_exp_within_two_ulp(rng):
    x = np.concatenate([rng.uniform(-708, 709.7, 400_000), rng.normal(0, 1, 100_000)])
    assert float(np.max(_ulp(exp(x), x, "exp"))) <= BOUND["exp"] + EXTRA
    assert float(np.mean(exp(x) == np.exp(x))) > 0.6


def test_log_within_one_ulp(rng):
    x = np.concatenate(
        [10.0 ** rng.uniform(-307, 308, 400_000), rng.uniform(0.5, 2.0, 100_000), [4.0, 0.25]]
    )
    y = log(x)
    keep = x != 1.0  # log 1 = 0: no ulp to measure against
    assert float(np.max(_ulp(y[keep], x[keep], "log"))) <= BOUND["log"] + EXTRA
    assert float(np.mean(y == np.log(x))) > 0.6


def test_special_values():
    with np.errstate(invalid="ignore", divide="ignore"):
        s, c = sincos(np.array([0.0, -0.0, np.inf, np.nan, SINCOS_MAX, -SINCOS_MAX]))
        assert np.array_equal(s[:2], [0.0, -0.0]) and np.signbit(s[1]) and not np.signbit(s[0])
        assert np.array_equal(c[:2], [1.0, 1.0]) and np.isnan(s[2:]).all() and np.isnan(c[2:]).all()
        e = exp(np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 710.0, -746.0, -745.0]))
        assert np.array_equal(e[:4], [1.0, 1.0, np.inf, 0.0]) and np.isnan(e[4])
        assert e[5] == np.inf and e[6] == 0.0 and 0.0 < e[7] < 1e-320  # subnormal, not 0
        lg = log(np.array([1.0, 0.0, -0.0, np.inf, -1.0, np.nan, 5e-324, 2.0]))
        assert lg[0] == 0.0 and not np.signbit(lg[0])
        assert np.array_equal(lg[1:4], [-np.inf, -np.inf, np.inf]) and np.isnan(lg[4:6]).all()
        assert lg[6] == pytest.approx(math.log(5e-324), rel=1e-15)
        assert lg[7] == math.log(2.0)
