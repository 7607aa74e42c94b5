"""Rotations: quaternions (scalar-last, as SciPy and the TUM format) and the papers' Euler order.

Paper 2 (planes) writes the rotation that maps the second sensor frame into the first as
``A = A_Z(dphi) A_X(dpsi) A_Y(dtheta)``: intrinsic rotations about Z, then the new X, then the new
Y, i.e. SciPy's ``"ZXY"`` (capital letters = intrinsic). :func:`euler_zxy_to_matrix` and
:func:`matrix_to_euler_zxy` implement that order; everything is built on
:class:`scipy.spatial.transform.Rotation`.

Quaternions are arrays ``(..., 4)`` ordered ``(x, y, z, w)``. :func:`quat_multiply` is the
Hamilton product, so ``quat_rotate(q, v)`` equals the paper's ``q V q^-1``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from navkit.errors import DegenerateGeometryError
from navkit.geometry._validate import as_points, as_quaternions, as_rotations, as_vectors

__all__ = [
    "EULER_ORDER_PAPER",
    "euler_zxy_to_matrix",
    "matrix_to_euler_zxy",
    "matrix_to_quat",
    "quat_conjugate",
    "quat_from_axis_angle",
    "quat_multiply",
    "quat_rotate",
    "quat_to_matrix",
    "rotation_angle",
    "rotation_between",
]

EULER_ORDER_PAPER = "ZXY"
"""SciPy sequence for the papers' ``A = A_Z(phi) A_X(psi) A_Y(theta)`` (intrinsic)."""


def quat_to_matrix(quat_xyzw: ArrayLike) -> NDArray[np.float64]:
    """Rotation matrices ``(..., 3, 3)`` from quaternions ``(..., 4)`` (normalised first)."""
    q = as_quaternions(quat_xyzw)
    return Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape((*q.shape[:-1], 3, 3))


def matrix_to_quat(R: ArrayLike) -> NDArray[np.float64]:
    """Unit quaternions ``(..., 4)`` with ``w >= 0`` from rotation matrices ``(..., 3, 3)``."""
    R = as_rotations(R)
    q = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat().reshape((*R.shape[:-2], 4))
    return np.where(q[..., 3:4] < 0, -q, q)


def euler_zxy_to_matrix(phi: ArrayLike, psi: ArrayLike, theta: ArrayLike) -> NDArray[np.float64]:
    """``A_Z(phi) A_X(psi) A_Y(theta)`` (radians), batched over broadcast inputs."""
    angles = np.stack(
        np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (phi, psi, theta))), -1
    )
    R = Rotation.from_euler(EULER_ORDER_PAPER, angles.reshape(-1, 3)).as_matrix()
    return R.reshape((*angles.shape[:-1], 3, 3))


def matrix_to_euler_zxy(R: ArrayLike) -> NDArray[np.float64]:
    """``(..., 3)`` angles ``(phi, psi, theta)`` with ``R = A_Z(phi) A_X(psi) A_Y(theta)``.

    ``psi`` lies in ``[-pi/2, pi/2]``; at ``|psi| = pi/2`` (gimbal lock) SciPy's convention is kept.
    """
    R = as_rotations(R)
    e = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_euler(EULER_ORDER_PAPER)
    return e.reshape((*R.shape[:-2], 3))


def quat_multiply(q1: ArrayLike, q2: ArrayLike) -> NDArray[np.float64]:
    """Hamilton product ``q1 q2`` of scalar-last quaternions (rotation ``q2`` first, then ``q1``)."""
    a = as_vectors(q1, 4, "q1")
    b = as_vectors(q2, 4, "q2")
    v1, w1 = a[..., :3], a[..., 3:]
    v2, w2 = b[..., :3], b[..., 3:]
    v = w1 * v2 + w2 * v1 + np.cross(v1, v2)
    w = w1 * w2 - np.sum(v1 * v2, axis=-1, keepdims=True)
    return np.concatenate([v, w], axis=-1)


def quat_conjugate(q: ArrayLike) -> NDArray[np.float64]:
    """Conjugate (the inverse of a unit quaternion)."""
    q = as_vectors(q, 4, "q")
    return np.concatenate([-q[..., :3], q[..., 3:]], axis=-1)


def quat_rotate(q: ArrayLike, vectors: ArrayLike) -> NDArray[np.float64]:
    """Rotate vectors ``(N, 3)`` by a unit quaternion: ``q V q^-1`` (paper 2, after eq. 8)."""
    V = as_points(vectors, 3, "vectors")
    q = as_vectors(q, 4, "q")
    Vq = np.concatenate([V, np.zeros((len(V), 1))], axis=1)
    return quat_multiply(quat_multiply(q, Vq), quat_conjugate(q))[:, :3]


def quat_from_axis_angle(axis: ArrayLike, angle: ArrayLike) -> NDArray[np.float64]:
    """``[axis/|axis| sin(w/2), cos(w/2)]`` (paper 2, eq. 8); axis ``(..., 3)``, angle radians."""
    axis = np.asarray(axis, dtype=np.float64)
    norm = np.linalg.norm(axis, axis=-1, keepdims=True)
    if np.any(norm == 0):
        raise DegenerateGeometryError("rotation axis has zero length")
    half = 0.5 * np.asarray(angle, dtype=np.float64)[..., None]
    return np.concatenate([axis / norm * np.sin(half), np.cos(half)], axis=-1)


def rotation_between(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """Shortest-arc unit quaternion turning direction ``a`` onto direction ``b`` (both ``(3,)``).

    This is paper 2's ``q1``: axis ``a x b``, angle ``arccos(a.b / |a||b|)``. Antiparallel inputs
    turn by pi about any axis perpendicular to ``a``.
    """
    va = np.asarray(a, dtype=np.float64)
    vb = np.asarray(b, dtype=np.float64)
    na, nb = np.linalg.norm(va), np.linalg.norm(vb)
    if na == 0 or nb == 0:
        raise DegenerateGeometryError("cannot turn a zero-length vector")
    va, vb = va / na, vb / nb
    axis = np.cross(va, vb)
    s = np.linalg.norm(axis)
    c = float(np.clip(va @ vb, -1.0, 1.0))
    if s < 1e-12:
        if c > 0:
            return np.array([0.0, 0.0, 0.0, 1.0])
        perp = np.cross(va, np.array([1.0, 0.0, 0.0]))
        if np.linalg.norm(perp) < 1e-6:
            perp = np.cross(va, np.array([0.0, 1.0, 0.0]))
        return quat_from_axis_angle(perp, np.pi)
    return quat_from_axis_angle(axis, np.arctan2(s, c))


def rotation_angle(R: ArrayLike) -> NDArray[np.float64]:
    """Angle (radians, in ``[0, pi]``) of rotation matrices ``(..., 3, 3)``; for errors between poses."""
    R = as_rotations(R)
    return Rotation.from_matrix(R.reshape(-1, 3, 3)).magnitude().reshape(R.shape[:-2])
