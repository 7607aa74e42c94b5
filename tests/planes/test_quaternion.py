"""The paper's quaternion route (eqs. 8-11) against SciPy's rotations."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from navkit.geometry.rotations import quat_rotate, quat_to_matrix
from navkit.planes.quaternion import (
    compose_q3_q1,
    euler_zxy_from_quat,
    in_plane_axes,
    q1_normal_alignment,
    q2_to_optical_axis,
    q3_about_normal,
    translation_eq10,
)

unit = (
    st.lists(st.floats(-1, 1), min_size=3, max_size=3)
    .map(np.array)
    .filter(lambda v: np.linalg.norm(v) > 0.1)
)


def test_euler_closed_form_matches_scipy_zxy():
    R = Rotation.random(2000, random_state=7)
    ours = euler_zxy_from_quat(R.as_quat())
    ref = R.as_euler("ZXY")
    # away from gimbal lock (|psi| < 89 deg) the three angles are unique: agree to round-off
    ok = np.abs(ref[:, 1]) < np.radians(89)
    assert np.allclose(ours[ok], ref[ok], atol=1e-9)
    # and the angles rebuild the rotation everywhere: A = A_Z(phi) A_X(psi) A_Y(theta)
    back = Rotation.from_euler("ZXY", ours).as_matrix()
    assert np.allclose(back, R.as_matrix(), atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(unit, unit)
def test_q1_turns_n21_onto_n11(a, b):
    n21, n11 = a / np.linalg.norm(a), b / np.linalg.norm(b)
    q1 = q1_normal_alignment(n21, n11)
    assert np.allclose(quat_rotate(q1, n21[None])[0], n11, atol=1e-9)
    # shortest arc: the turn angle is the angle between the normals (eq. 8)
    angle = 2 * np.arctan2(np.linalg.norm(q1[:3]), abs(q1[3]))
    assert np.isclose(angle, np.arccos(np.clip(n21 @ n11, -1, 1)), atol=1e-6)


@settings(max_examples=60, deadline=None)
@given(unit)
def test_q2_axes_span_the_plane(a):
    n = a / np.linalg.norm(a)
    q2 = q2_to_optical_axis(n)
    assert np.allclose(quat_rotate(q2, n[None])[0], [0, 0, 1], atol=1e-9)
    u, v = in_plane_axes(q2)
    assert np.allclose([u @ n, v @ n, u @ v], 0, atol=1e-9)
    assert np.allclose(np.cross(u, v), n, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(
    unit,
    st.floats(-np.pi, np.pi),
    st.floats(-2, 2),
    st.floats(-2, 2),
    st.floats(0.5, 4),
    st.floats(0.5, 4),
)
def test_route_rebuilds_a_known_motion(a, lam, mu, eta, rho1, rho2):
    """A motion built from (q1, lambda, mu, eta) maps plane 2 onto plane 1 (eqs. 1, 2, 10)."""
    n1 = a / np.linalg.norm(a)
    n2 = Rotation.from_rotvec([0.2, -0.1, 0.3]).apply(n1)
    q1 = q1_normal_alignment(n2, n1)
    q2 = q2_to_optical_axis(n1)
    Q = compose_q3_q1(q3_about_normal(n1, lam), q1)
    t = translation_eq10(n1, rho1, rho2, q2, mu, eta)
    R = quat_to_matrix(Q)
    assert np.allclose(R @ n2, n1, atol=1e-9)  # eq. 1
    assert np.isclose(n1 @ t, rho1 - rho2, atol=1e-9)  # eq. 2
    # Q against SciPy: q3 then q1 composed as rotations
    ref = Rotation.from_rotvec(lam * n1) * Rotation.from_quat(q1)
    assert np.allclose(R, ref.as_matrix(), atol=1e-9)
    # the in-plane part of t is (mu, eta) on the q2 axes
    u, v = in_plane_axes(q2)
    assert np.allclose([t @ u, t @ v], [mu, eta], atol=1e-9)
