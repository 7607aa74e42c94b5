"""Plane and line fits recover known parameters within tolerances derived from the noise."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from navkit.errors import DegenerateGeometryError, InputError
from navkit.geometry.fitting import (
    Plane,
    canonical_plane,
    fit_line_2d,
    fit_plane,
    intersect_lines_2d,
    intersect_planes,
    line_from_points_2d,
)


def noisy_plane(rng, normal, rho, n, sigma, extent=5.0):
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    u = np.cross(normal, [1.0, 0, 0] if abs(normal[0]) < 0.9 else [0, 1.0, 0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    ab = rng.uniform(-extent, extent, size=(n, 2))
    return (
        rho * normal + ab[:, :1] * u + ab[:, 1:] * v + sigma * rng.standard_normal((n, 1)) * normal
    )


def test_plane_fit_recovers_parameters_under_noise(rng):
    normal = np.array([0.2, -0.5, 0.84])
    normal /= np.linalg.norm(normal)
    n, sigma, extent = 2000, 0.01, 5.0
    P = noisy_plane(rng, normal, 3.0, n, sigma, extent)
    plane = fit_plane(P)
    # Normal error of a TLS fit ~ sigma / (sqrt(n) * spread), spread = extent/sqrt(3) (uniform);
    # 6 standard deviations as the bound.
    tol_angle = 6 * sigma / (np.sqrt(n) * extent / np.sqrt(3))
    assert np.arccos(min(1.0, plane.normal @ normal)) < tol_angle
    assert abs(plane.rho - 3.0) < 6 * sigma / np.sqrt(n) + tol_angle * extent
    assert abs(plane.rms - sigma) < 0.1 * sigma  # residual estimates the noise
    assert plane.rho >= 0


def test_plane_convention_rho_nonnegative_and_unique():
    P = np.array([[0, 0, -2.0], [1, 0, -2.0], [0, 1, -2.0], [1, 1, -2.0]])
    plane = fit_plane(P)
    np.testing.assert_allclose(plane.normal, [0, 0, -1.0], atol=1e-12)
    assert plane.rho == pytest.approx(2.0)
    n, rho = canonical_plane([0, 0, -3.0], 0.0)
    np.testing.assert_allclose(n, [0, 0, 1.0])
    assert rho == 0.0


@settings(max_examples=50)
@given(st.integers(0, 10_000))
def test_plane_fit_exact_points_any_orientation(seed):
    rng = np.random.default_rng(seed)
    normal = Rotation.random(random_state=seed).apply([0, 0, 1.0])
    rho = rng.uniform(0, 10)
    plane = fit_plane(noisy_plane(rng, normal, rho, 30, 0.0))
    n_exp, rho_exp = canonical_plane(normal, rho)
    np.testing.assert_allclose(plane.normal, n_exp, atol=1e-9)
    assert plane.rho == pytest.approx(rho_exp, abs=1e-9)


def test_plane_fit_ignores_nan_rows_and_rejects_collinear(rng):
    P = noisy_plane(rng, [0, 0, 1], 1.0, 100, 0.0)
    P[::7] = np.nan
    assert fit_plane(P).rho == pytest.approx(1.0)
    with pytest.raises(DegenerateGeometryError):
        fit_plane(np.c_[np.arange(10.0), 2 * np.arange(10.0), np.zeros(10)])
    with pytest.raises(InputError):
        fit_plane(np.zeros((2, 3)))


def test_plane_basis_is_orthonormal_and_right_handed():
    plane = Plane(normal=np.array([0.0, 0.6, 0.8]), rho=1.0, centroid=np.zeros(3))
    u, v = plane.basis()
    np.testing.assert_allclose([u @ u, v @ v, u @ v, u @ plane.normal], [1, 1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(np.cross(u, v), plane.normal, atol=1e-12)


def test_line_fit_vertical_line_and_noise(rng):
    n, sigma = 500, 0.02
    y = rng.uniform(-4, 4, n)
    P = np.c_[3.0 + sigma * rng.standard_normal(n), y]  # the line x = 3, where y = kx + b fails
    line = fit_line_2d(P)
    np.testing.assert_allclose(
        np.abs(line.normal), [1, 0], atol=6 * sigma / (np.sqrt(n) * 8 / np.sqrt(12))
    )
    assert line.rho == pytest.approx(3.0, abs=6 * sigma / np.sqrt(n) + 0.01)
    assert abs(abs(line.angle) - np.pi / 2) < 0.01
    assert line.rms == pytest.approx(sigma, rel=0.15)


def test_line_intersection_known_corner():
    a = line_from_points_2d([0, 1], [4, 1])  # y = 1
    b = line_from_points_2d([2, -5], [2, 5])  # x = 2
    np.testing.assert_allclose(intersect_lines_2d(a, b), [2, 1], atol=1e-12)
    with pytest.raises(DegenerateGeometryError):
        intersect_lines_2d(a, line_from_points_2d([0, 3], [1, 3]))


def test_three_and_two_plane_intersections():
    px = Plane(np.array([1.0, 0, 0]), 1.0, np.zeros(3))
    py = Plane(np.array([0, 1.0, 0]), 2.0, np.zeros(3))
    pz = Plane(np.array([0, 0, 1.0]), 3.0, np.zeros(3))
    np.testing.assert_allclose(intersect_planes(px, py, pz), [1, 2, 3])
    point, direction = intersect_planes(px, py)
    np.testing.assert_allclose(point, [1, 2, 0], atol=1e-12)
    np.testing.assert_allclose(np.abs(direction), [0, 0, 1], atol=1e-12)
    with pytest.raises(DegenerateGeometryError):
        intersect_planes(px, Plane(np.array([1.0, 0, 0]), 5.0, np.zeros(3)))
