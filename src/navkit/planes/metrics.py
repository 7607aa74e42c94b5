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
from navkit.geometry import se3_inverse
from navkit.geometry.rotations import rotation_angle

__all__ = ["ate", "poses_at", "rpe", "umeyama_alignment"]


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


def poses_at(
    times: ArrayLike, ref_times: ArrayLike, ref_poses: ArrayLike, max_gap: float = 0.02
) -> NDArray[np.float64]:
    """Reference poses ``(N, 4, 4)`` at the frame times ``times`` (seconds).

    Interpolated between the two reference samples around each time (linear position,
    spherical-linear rotation) when they are at most ``max_gap`` seconds apart (TUM's
    ``associate.py`` default, 0.02 s); NaN where the reference does not cover the time (a
    motion-capture recording often starts after the camera). Taking the first ``N`` rows of a
    100 Hz ground truth instead pairs a 30 Hz frame with the wrong pose."""
    from scipy.spatial.transform import Rotation, Slerp

    t = np.asarray(times, dtype=np.float64).reshape(-1)
    rt = np.asarray(ref_times, dtype=np.float64).reshape(-1)
    Q = np.asarray(ref_poses, dtype=np.float64)
    if Q.ndim != 3 or Q.shape[1:] != (4, 4) or len(Q) != len(rt) or len(rt) < 2:
        raise InputError(
            f"{len(rt)} times and poses of shape {Q.shape}",
            field="ref_poses",
            expected="(M, 4, 4) poses, one per reference time, M >= 2",
        )
    out = np.full((len(t), 4, 4), np.nan)
    k = np.searchsorted(rt, t, side="right")
    for i, (ti, ki) in enumerate(zip(t, k, strict=True)):
        if ki == 0 or ki == len(rt):
            if ki == len(rt) and ti == rt[-1]:
                out[i] = Q[-1]
            continue
        a, b = ki - 1, ki
        if rt[b] - rt[a] > max_gap:
            continue
        w = (ti - rt[a]) / (rt[b] - rt[a])
        R = Slerp([0.0, 1.0], Rotation.from_matrix(Q[[a, b], :3, :3]))([w]).as_matrix()[0]
        out[i] = np.eye(4)
        out[i, :3, :3] = R
        out[i, :3, 3] = (1 - w) * Q[a, :3, 3] + w * Q[b, :3, 3]
    return out
