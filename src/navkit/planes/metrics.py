"""Trajectory errors with evo's definitions (Grupp, evo: ``evo_ape`` / ``evo_rpe``).

- ATE (absolute trajectory error): the estimate is aligned to the reference by the
  least-squares rigid motion (Umeyama 1991 without scale, evo's ``--align``), then the RMSE of
  the position differences (evo APE, ``translation_part``).
- RPE (relative pose error) for a frame delta ``d``: ``E_i = (Q_i^-1 Q_{i+d})^-1 (P_i^-1 P_{i+d})``
  for every pair, RMSE of ``|trans(E_i)|`` (metres) and of ``angle(E_i)`` (degrees) (evo RPE,
  ``translation_part`` / ``rotation_angle_deg``, ``--delta d --delta_unit f``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError
from navkit.geometry import rotation_angle, se3_inverse

__all__ = ["ate", "rpe", "umeyama_alignment"]


def umeyama_alignment(src: NDArray[np.float64], dst: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(4, 4)`` rigid ``T`` minimising ``sum |dst_i - T src_i|^2`` (no scale)."""
    ms, md = src.mean(0), dst.mean(0)
    C = (dst - md).T @ (src - ms) / len(src)
    U, _, Vt = np.linalg.svd(C)
    S = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1
    R = U @ S @ Vt
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, md - R @ ms
    return T


def _check(est, ref):
    P = np.asarray(est, dtype=np.float64)
    Q = np.asarray(ref, dtype=np.float64)
    if P.shape != Q.shape or P.ndim != 3 or P.shape[1:] != (4, 4):
        raise InputError(
            f"shapes {P.shape} and {Q.shape}", field="poses", expected="two (N, 4, 4) arrays"
        )
    return P, Q


def ate(est: ArrayLike, ref: ArrayLike, align: bool = True) -> float:
    """ATE RMSE, metres, of poses ``(N, 4, 4)`` against reference poses ``(N, 4, 4)``."""
    P, Q = _check(est, ref)
    if align and len(P) >= 3:
        T = umeyama_alignment(P[:, :3, 3], Q[:, :3, 3])
        P = T @ P
    return float(np.sqrt(np.mean(np.sum((P[:, :3, 3] - Q[:, :3, 3]) ** 2, axis=1))))


def rpe(est: ArrayLike, ref: ArrayLike, delta: int = 1) -> tuple[float, float]:
    """RPE RMSE (translation metres, rotation degrees) over frame pairs ``delta`` apart."""
    P, Q = _check(est, ref)
    if len(P) <= delta:
        return float("nan"), float("nan")
    dP = se3_inverse(P[:-delta]) @ P[delta:]
    dQ = se3_inverse(Q[:-delta]) @ Q[delta:]
    E = se3_inverse(dQ) @ dP
    t = np.linalg.norm(E[:, :3, 3], axis=1)
    a = np.degrees(rotation_angle(E[:, :3, :3]))
    return float(np.sqrt(np.mean(t**2))), float(np.sqrt(np.mean(a**2)))
