"""Rigid transforms in SE(3) and SE(2) as homogeneous matrices, batched over a leading axis.

Convention (used everywhere in navkit): ``T_a_b`` maps points from frame *b* to frame *a*,
``p_a = T_a_b @ p_b``; so ``T_a_c = T_a_b @ T_b_c``. Poses of a sensor are ``T_world_sensor``.
World frames are z up. Arrays: a single transform is ``(4, 4)`` (SE(3)) or ``(3, 3)`` (SE(2)); a
stack is ``(N, 4, 4)`` / ``(N, 3, 3)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from navkit.geometry._validate import as_matrices, as_points
from navkit.geometry.linalg import rows_matmul

__all__ = [
    "se2_apply",
    "se2_compose",
    "se2_from_xytheta",
    "se2_inverse",
    "se2_to_xytheta",
    "se3_adjoint",
    "se3_apply",
    "se3_compose",
    "se3_from_rt",
    "se3_from_xyz_quat",
    "se3_inverse",
    "se3_to_rt",
    "se3_to_xyz_quat",
    "wrap_angle",
]


def wrap_angle(angle: ArrayLike) -> NDArray[np.float64]:
    """Wrap angles (radians) into ``[-pi, pi)``."""
    a = np.asarray(angle, dtype=np.float64)
    return (a + np.pi) % (2.0 * np.pi) - np.pi


# --------------------------------------------------------------------------- SE(3)
def se3_from_rt(R: ArrayLike, t: ArrayLike) -> NDArray[np.float64]:
    """Build ``(..., 4, 4)`` transforms from rotations ``(..., 3, 3)`` and translations ``(..., 3)``."""
    R = np.asarray(R, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    batch = np.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    T = np.zeros((*batch, 4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def se3_to_rt(T: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Split ``(..., 4, 4)`` transforms into rotations ``(..., 3, 3)`` and translations ``(..., 3)``."""
    T = as_matrices(T, 4)
    return T[..., :3, :3].copy(), T[..., :3, 3].copy()


def se3_inverse(T: ArrayLike) -> NDArray[np.float64]:
    """Invert rigid transforms exactly (``R^T, -R^T t``), batched."""
    R, t = se3_to_rt(T)
    Rt = np.swapaxes(R, -1, -2)
    return se3_from_rt(Rt, -np.einsum("...ij,...j->...i", Rt, t))


def se3_adjoint(T: ArrayLike) -> NDArray[np.float64]:
    """``(6, 6)`` adjoint of a rigid transform for twists ``(v, w)`` (translation first):
    ``T exp(xi) T^-1 = exp(Ad(T) xi)``, ``Ad(T) = [[R, [t]x R], [0, R]]``. It moves a left
    perturbation of a pose expressed in frame ``T``'s axes into its parent's."""
    R, t = se3_to_rt(T)
    tx = np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])
    Ad = np.zeros((6, 6))
    Ad[:3, :3] = R
    Ad[:3, 3:] = tx @ R
    Ad[3:, 3:] = R
    return Ad


def se3_compose(*transforms: ArrayLike) -> NDArray[np.float64]:
    """Compose transforms left to right: ``se3_compose(T_a_b, T_b_c) == T_a_c`` (batched)."""
    out = as_matrices(transforms[0], 4)
    for T in transforms[1:]:
        out = out @ as_matrices(T, 4)
    return out


def se3_apply(T: ArrayLike, points: ArrayLike) -> NDArray[np.float64]:
    """Apply one transform ``(4, 4)`` to points ``(N, 3)``: ``points @ R.T + t``."""
    T = as_matrices(T, 4)
    P = as_points(points, 3)
    return rows_matmul(P, T[:3, :3].T) + T[:3, 3]


def se3_from_xyz_quat(xyz: ArrayLike, quat_xyzw: ArrayLike) -> NDArray[np.float64]:
    """Transforms from positions ``(..., 3)`` and scalar-last quaternions ``(..., 4)`` (TUM order)."""
    q = np.asarray(quat_xyzw, dtype=np.float64)
    R = Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape((*q.shape[:-1], 3, 3))
    return se3_from_rt(R, xyz)


def se3_to_xyz_quat(T: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Positions ``(..., 3)`` and scalar-last unit quaternions ``(..., 4)`` with ``w >= 0``."""
    R, t = se3_to_rt(T)
    q = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat().reshape((*R.shape[:-2], 4))
    q = np.where(q[..., 3:4] < 0, -q, q)
    return t, q


# --------------------------------------------------------------------------- SE(2)
def se2_from_xytheta(x: ArrayLike, y: ArrayLike, theta: ArrayLike) -> NDArray[np.float64]:
    """``(..., 3, 3)`` planar transforms from positions and headings (radians, CCW from +x)."""
    x, y, theta = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x, y, theta)))
    c, s = np.cos(theta), np.sin(theta)
    T = np.zeros((*x.shape, 3, 3))
    T[..., 0, 0], T[..., 0, 1], T[..., 0, 2] = c, -s, x
    T[..., 1, 0], T[..., 1, 1], T[..., 1, 2] = s, c, y
    T[..., 2, 2] = 1.0
    return T


def se2_to_xytheta(T: ArrayLike) -> NDArray[np.float64]:
    """``(..., 3)`` rows ``(x, y, theta)`` of planar transforms."""
    T = as_matrices(T, 3)
    return np.stack([T[..., 0, 2], T[..., 1, 2], np.arctan2(T[..., 1, 0], T[..., 0, 0])], axis=-1)


def se2_inverse(T: ArrayLike) -> NDArray[np.float64]:
    """Invert planar rigid transforms exactly, batched."""
    T = as_matrices(T, 3)
    R = T[..., :2, :2]
    Rt = np.swapaxes(R, -1, -2)
    out = np.zeros_like(T)
    out[..., :2, :2] = Rt
    out[..., :2, 2] = -np.einsum("...ij,...j->...i", Rt, T[..., :2, 2])
    out[..., 2, 2] = 1.0
    return out


def se2_compose(*transforms: ArrayLike) -> NDArray[np.float64]:
    """Compose planar transforms left to right (``T_a_b, T_b_c -> T_a_c``)."""
    out = as_matrices(transforms[0], 3)
    for T in transforms[1:]:
        out = out @ as_matrices(T, 3)
    return out


def se2_apply(T: ArrayLike, points: ArrayLike) -> NDArray[np.float64]:
    """Apply one planar transform ``(3, 3)`` to points ``(N, 2)``."""
    T = as_matrices(T, 3)
    P = as_points(points, 2)
    return P @ T[:2, :2].T + T[:2, 2]
