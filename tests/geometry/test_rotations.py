"""Quaternions and the papers' Euler order (intrinsic Z-X-Y) against SciPy and closed forms."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from navkit.errors import DegenerateGeometryError
from navkit.geometry import wrap_angle
from navkit.geometry.rotations import (
    euler_zxy_to_matrix,
    matrix_to_euler_zxy,
    matrix_to_quat,
    quat_conjugate,
    quat_from_axis_angle,
    quat_multiply,
    quat_rotate,
    quat_to_matrix,
    rotation_angle,
    rotation_between,
)


def Rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def Rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def Ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


angles = st.floats(-np.pi, np.pi)
half = st.floats(-np.pi / 2 + 1e-3, np.pi / 2 - 1e-3)


@given(angles, half, angles)
def test_euler_zxy_is_the_papers_product(phi, psi, theta):
    """Paper 2: A = A_Z(phi) A_X(psi) A_Y(theta)."""
    np.testing.assert_allclose(
        euler_zxy_to_matrix(phi, psi, theta), Rz(phi) @ Rx(psi) @ Ry(theta), atol=1e-12
    )


@given(angles, half, angles)
def test_euler_zxy_round_trip(phi, psi, theta):
    R = euler_zxy_to_matrix(phi, psi, theta)
    diff = wrap_angle(matrix_to_euler_zxy(R) - [phi, psi, theta])  # pi and -pi are one angle
    np.testing.assert_allclose(diff, 0.0, atol=1e-7)


def test_quaternion_matrix_round_trip():
    R = Rotation.random(100, random_state=1)
    q = matrix_to_quat(R.as_matrix())
    assert np.all(q[:, 3] >= 0)
    np.testing.assert_allclose(quat_to_matrix(q), R.as_matrix(), atol=1e-12)
    # quaternion -> matrix -> Euler ZXY -> matrix
    e = matrix_to_euler_zxy(quat_to_matrix(q))
    np.testing.assert_allclose(
        euler_zxy_to_matrix(e[:, 0], e[:, 1], e[:, 2]), R.as_matrix(), atol=1e-10
    )


def test_hamilton_product_matches_scipy_composition():
    a, b = Rotation.random(2, random_state=5)
    np.testing.assert_allclose(
        quat_to_matrix(quat_multiply(a.as_quat(), b.as_quat())), (a * b).as_matrix(), atol=1e-12
    )


def test_q_v_qinv_rotates_like_the_matrix(rng):
    r = Rotation.random(random_state=11)
    V = rng.normal(size=(10, 3))
    np.testing.assert_allclose(quat_rotate(r.as_quat(), V), r.apply(V), atol=1e-12)
    np.testing.assert_allclose(quat_rotate(quat_conjugate(r.as_quat()), r.apply(V)), V, atol=1e-12)


def test_axis_angle_paper_eq8_form():
    q = quat_from_axis_angle([0, 0, 2.0], np.pi / 2)
    np.testing.assert_allclose(q, [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)])
    with pytest.raises(DegenerateGeometryError):
        quat_from_axis_angle([0, 0, 0], 1.0)


@given(
    st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).filter(
        lambda v: np.linalg.norm(v) > 0.1
    ),
    st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)).filter(
        lambda v: np.linalg.norm(v) > 0.1
    ),
)
def test_rotation_between_turns_a_onto_b(a, b):
    a, b = np.array(a), np.array(b)
    q = rotation_between(a, b)
    turned = quat_rotate(q, a)[0]
    np.testing.assert_allclose(turned / np.linalg.norm(turned), b / np.linalg.norm(b), atol=1e-7)
    # shortest arc: the angle equals the angle between the vectors
    expected = np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))
    assert abs(rotation_angle(quat_to_matrix(q)) - expected) < 1e-6


def test_rotation_between_antiparallel():
    q = rotation_between([0, 0, 1.0], [0, 0, -1.0])
    np.testing.assert_allclose(quat_rotate(q, [0, 0, 1.0])[0], [0, 0, -1.0], atol=1e-12)


def test_rotation_angle_small_and_large():
    for a in (1e-9, 1e-4, 0.5, 3.0):
        assert abs(rotation_angle(Rotation.from_rotvec([0, a, 0]).as_matrix()) - a) < 1e-12
