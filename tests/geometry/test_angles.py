"""navkit.geometry.angles.atan2 and its kernel: the same bits, within 2 ulp of the true angle."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.geometry.angles import atan2

SPECIAL = np.array([0.0, -0.0, 1.0, -1.0, 1e-300, -1e-300, 5e-324, -5e-324, 1e300, -1e300, 0.66])


def _pairs(rng: np.random.Generator, n: int = 400_000) -> tuple[np.ndarray, np.ndarray]:
    """Random pairs over twelve decades of magnitude and both signs, the special values
    crossed with each other, and ratios at the reduction's switch points (0.66, tan(3 pi/8))."""
    x = rng.standard_normal(n) * 10.0 ** rng.uniform(-6, 6, n)
    y = rng.standard_normal(n) * 10.0 ** rng.uniform(-6, 6, n)
    X, Y = np.meshgrid(SPECIAL, SPECIAL)
    edge = np.array([0.66, np.nextafter(0.66, 1), 2.41421356237309504880, 2.414213562373095])
    xe = np.tile([1.0, -1.0, 3.0, -7.5], len(edge))
    ye = np.repeat(edge, 4) * np.abs(xe)
    return np.concatenate([y, Y.ravel(), ye, -ye]), np.concatenate([x, X.ravel(), xe, xe])


@pytest.mark.twin("atan2_kernel")
def test_twin_and_kernel_give_the_same_bits(rng):
    from navkit.geometry._kernels_math import atan2_kernel

    y, x = _pairs(rng)
    a = atan2(y, x)
    b = atan2_kernel(y, x, np.empty_like(x))
    assert np.array_equal(a.view(np.int64), b.view(np.int64))


def test_within_two_ulp_of_the_true_angle(rng):
    y, x = _pairs(rng)
    got = atan2(y, x)
    if np.finfo(np.longdouble).eps < np.finfo(np.float64).eps:  # x87 / quad: a finer reference
        ref = np.arctan2(y.astype(np.longdouble), x.astype(np.longdouble))
        err = np.abs(got.astype(np.longdouble) - ref) / np.spacing(np.abs(ref.astype(np.float64)))
        bound = 2.0  # Cephes' atan of the rounded ratio y / x (measured: 2.0 at most)
    else:  # long double is double here: against libm (itself within 1 ulp)
        ref = np.arctan2(y, x)
        err = np.abs(got - ref) / np.spacing(np.abs(ref))
        bound = 3.0
    assert float(np.max(err)) <= bound
    # most results are the correctly rounded ones, not just within the bound
    assert float(np.mean(got == np.arctan2(y, x))) > 0.6


def test_signed_zeros_and_axes_follow_c():
    X, Y = np.meshgrid(SPECIAL, SPECIAL)
    got, ref = atan2(Y, X), np.arctan2(Y, X)
    assert np.array_equal(np.signbit(got), np.signbit(ref))
    on_axes = (X == 0) | (Y == 0)
    assert np.array_equal(got[on_axes], ref[on_axes])  # exactly 0, +-pi/2, +-pi
    assert atan2(-0.0, -1.0) == -np.pi and atan2(0.0, -1.0) == np.pi


@pytest.mark.parametrize(
    ("y", "x"), [(1.0, 2.0), ([1.0, -1.0], 2.0), (np.ones((3, 1)), [1.0, -1.0])]
)
def test_broadcasts_as_numpy(y, x):
    got = atan2(y, x)
    assert got.shape == np.broadcast_shapes(np.shape(y), np.shape(x))
    np.testing.assert_allclose(got, np.arctan2(y, x), rtol=5e-16, atol=0)
