"""The paper's quaternion route (section "experimental results", eqs. 8-11).

Quaternions are scalar-last ``(x, y, z, w)`` (navkit convention); ``q V q^-1`` rotates a vector.

Eq. 11 as printed is damaged; the closed form used here is derived from the rotation matrix of a
unit quaternion and the paper's order ``A = A_Z(phi) A_X(psi) A_Y(theta)``:

``A_Z A_X A_Y`` has ``A[2,1] = sin psi``, ``A[0,1] = -sin phi cos psi``, ``A[1,1] = cos phi cos psi``,
``A[2,0] = -cos psi sin theta``, ``A[2,2] = cos psi cos theta``; with the quaternion matrix entries
``A[2,1] = 2(yz + wx)``, ``A[0,1] = 2(xy - wz)``, ``A[1,1] = 1 - 2(x^2 + z^2)``,
``A[2,0] = 2(xz - wy)``, ``A[2,2] = 1 - 2(x^2 + y^2)`` this gives (eq. 11, derived)::

    phi   = atan2(2(wz - xy), 1 - 2(x^2 + z^2))
    psi   = asin(2(wx + yz))
    theta = atan2(2(wy - xz), 1 - 2(x^2 + y^2))

which equals SciPy's ``Rotation.as_euler("ZXY")`` away from the gimbal lock ``|psi| = 90 deg``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.geometry._validate import as_quaternions
from navkit.geometry.rotations import (
    quat_conjugate,
    quat_from_axis_angle,
    quat_multiply,
    quat_rotate,
    rotation_between,
)

__all__ = [
    "OPTICAL_AXIS",
    "euler_zxy_from_quat",
    "q1_normal_alignment",
    "q2_to_optical_axis",
    "q3_about_normal",
    "translation_eq10",
]

OPTICAL_AXIS = np.array([0.0, 0.0, 1.0])
"""The sensor's optical axis in navkit's camera frame (OpenCV z); the paper's ``Y``."""


def euler_zxy_from_quat(q: ArrayLike) -> NDArray[np.float64]:
    """Paper's Euler angles ``(dphi, dpsi, dtheta)`` (radians) of unit quaternion(s) ``(..., 4)``.

    ``A = A_Z(dphi) A_X(dpsi) A_Y(dtheta)`` (eq. 11, derived in the module docstring).
    """
    qa = as_quaternions(q, "q")
    qa = qa / np.linalg.norm(qa, axis=-1, keepdims=True)
    x, y, z, w = qa[..., 0], qa[..., 1], qa[..., 2], qa[..., 3]
    phi = np.arctan2(2 * (w * z - x * y), 1 - 2 * (x * x + z * z))
    psi = np.arcsin(np.clip(2 * (w * x + y * z), -1.0, 1.0))
    theta = np.arctan2(2 * (w * y - x * z), 1 - 2 * (x * x + y * y))
    return np.stack([phi, psi, theta], axis=-1)


def q1_normal_alignment(n21: ArrayLike, n11: ArrayLike) -> NDArray[np.float64]:
    """Eq. 8: ``q1`` turning the second image's normal ``N21`` onto the first's ``N11``.

    Axis ``R1 = N21 x N11``, angle ``w1 = arccos(N21 . N11 / |N21| |N11|)``,
    ``q1 = [R1 / |R1| sin(w1 / 2), cos(w1 / 2)]`` (identity for equal normals, a half turn about
    a perpendicular axis for opposite ones).
    """
    return rotation_between(n21, n11)


def q2_to_optical_axis(n11: ArrayLike) -> NDArray[np.float64]:
    """Eq. 9: ``q2`` turning ``N11`` onto the optical axis (axis ``N11 x Y``).

    After it, the sensor's other two axes lie in the plane: ``mu`` along ``q2^-1 x q2`` and
    ``eta`` along ``q2^-1 y q2`` (navkit's optical axis is z, the paper's is Y).
    """
    return rotation_between(n11, OPTICAL_AXIS)


def q3_about_normal(n11: ArrayLike, lam: float) -> NDArray[np.float64]:
    """``q3``: rotation by ``lambda`` (radians) about ``N11`` (step 6; ``Q = q3 q1``)."""
    return quat_from_axis_angle(np.asarray(n11, dtype=np.float64), lam)


def in_plane_axes(q2: ArrayLike) -> NDArray[np.float64]:
    """``(2, 3)`` in-plane axes ``(mu, eta)`` = ``q2^-1 [x, y] q2`` (their cross product is N11)."""
    return quat_rotate(quat_conjugate(np.asarray(q2, float)), np.eye(3)[:2])


def translation_eq10(
    n11: ArrayLike, rho11: float, rho21: float, q2: ArrayLike, mu: float, eta: float
) -> NDArray[np.float64]:
    """Eq. 10: ``dT = (rho11 - rho21) N11 + q2^-1 [mu, eta, 0] q2`` (metres)."""
    n = np.asarray(n11, dtype=np.float64)
    shift = quat_rotate(quat_conjugate(np.asarray(q2, float)), np.array([[mu, eta, 0.0]]))[0]
    return (rho11 - rho21) * n + shift


def compose_q3_q1(q3: ArrayLike, q1: ArrayLike) -> NDArray[np.float64]:
    """Step 6: ``Q = q3 q1`` (first q1, then q3), scalar part made non-negative."""
    Q = quat_multiply(q3, q1)
    return np.where(Q[..., 3:4] < 0, -Q, Q)
