"""SE(3) / SE(2) transforms: round trips, composition, agreement with SciPy."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from navkit.errors import InputError
from navkit.geometry import (
    se2_apply,
    se2_compose,
    se2_from_xytheta,
    se2_inverse,
    se2_to_xytheta,
    se3_apply,
    se3_compose,
    se3_from_rt,
    se3_from_xyz_quat,
    se3_inverse,
    se3_to_xyz_quat,
    wrap_angle,
)

finite = st.floats(-100, 100, allow_nan=False, allow_infinity=False)
quats = arrays(np.float64, 4, elements=st.floats(-1, 1)).filter(lambda q: np.linalg.norm(q) > 0.1)
vec3 = arrays(np.float64, 3, elements=finite)


@given(quats, vec3)
def test_inverse_round_trip(q, t):
    T = se3_from_xyz_quat(t, q)
    np.testing.assert_allclose(T @ se3_inverse(T), np.eye(4), atol=1e-12)
    np.testing.assert_allclose(se3_inverse(se3_inverse(T)), T, atol=1e-12)


@given(quats, vec3, quats, vec3)
def test_composition_applies_right_first(q1, t1, q2, t2):
    T_ab, T_bc = se3_from_xyz_quat(t1, q1), se3_from_xyz_quat(t2, q2)
    p_c = np.array([[0.3, -1.2, 2.5]])
    expected = se3_apply(T_ab, se3_apply(T_bc, p_c))
    np.testing.assert_allclose(se3_apply(se3_compose(T_ab, T_bc), p_c), expected, atol=1e-9)


def test_apply_matches_scipy(rng):
    R = Rotation.random(random_state=7)
    t = rng.normal(size=3)
    P = rng.normal(size=(50, 3))
    T = se3_from_rt(R.as_matrix(), t)
    np.testing.assert_allclose(se3_apply(T, P), R.apply(P) + t, atol=1e-12)


def test_batched_inverse_and_quat_round_trip(rng):
    q = Rotation.random(20, random_state=3).as_quat()
    t = rng.normal(size=(20, 3))
    T = se3_from_xyz_quat(t, q)
    assert T.shape == (20, 4, 4)
    np.testing.assert_allclose(
        T @ se3_inverse(T), np.broadcast_to(np.eye(4), (20, 4, 4)), atol=1e-12
    )
    t2, q2 = se3_to_xyz_quat(T)
    np.testing.assert_allclose(t2, t, atol=1e-12)
    # q and -q are the same rotation; the function returns w >= 0
    q_pos = np.where(q[:, 3:] < 0, -q, q)
    np.testing.assert_allclose(q2, q_pos, atol=1e-12)


@given(finite, finite, st.floats(-10, 10), finite, finite, st.floats(-10, 10))
def test_se2_round_trip_and_compose(x1, y1, a1, x2, y2, a2):
    A, B = se2_from_xytheta(x1, y1, a1), se2_from_xytheta(x2, y2, a2)
    np.testing.assert_allclose(A @ se2_inverse(A), np.eye(3), atol=1e-9)
    xyt = se2_to_xytheta(A)
    np.testing.assert_allclose(xyt[:2], [x1, y1])
    assert abs(wrap_angle(xyt[2] - a1)) < 1e-9
    p = np.array([[1.0, 2.0]])
    np.testing.assert_allclose(
        se2_apply(se2_compose(A, B), p), se2_apply(A, se2_apply(B, p)), atol=1e-8
    )


def test_se2_is_the_planar_part_of_se3():
    T2 = se2_from_xytheta(1.0, -2.0, 0.7)
    T3 = se3_from_rt(Rotation.from_euler("z", 0.7).as_matrix(), [1.0, -2.0, 0.0])
    p = np.array([[0.5, 1.5]])
    np.testing.assert_allclose(se2_apply(T2, p), se3_apply(T3, np.c_[p, [0.0]])[:, :2], atol=1e-12)


@settings(max_examples=200)
@given(st.floats(-1e4, 1e4))
def test_wrap_angle_range_and_equivalence(a):
    w = float(wrap_angle(a))
    assert -np.pi <= w < np.pi
    assert abs(np.sin(w) - np.sin(a)) < 1e-7 and abs(np.cos(w) - np.cos(a)) < 1e-7


def test_bad_shapes_are_input_errors():
    with pytest.raises(InputError, match="expected"):
        se3_apply(np.eye(3), np.zeros((2, 3)))
    with pytest.raises(InputError, match="points"):
        se3_apply(np.eye(4), np.zeros((2, 2)))
