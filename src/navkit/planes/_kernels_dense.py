"""Compiled kernels of the dense alignment (:mod:`navkit.planes.dense`).

One Gauss-Newton iteration of :func:`~navkit.planes.dense.dense_align` projects every source
point of a pyramid level into the target, reads the target's vertex, normal and brightness
maps there, and sums the weighted normal equations of both terms. NumPy does that in about
twenty passes over the points, each with its temporaries; :func:`dense_terms` does it in one
pass and :func:`normal_equations` sums ``J^T W J`` and ``J^T W r`` without forming ``J W``.

The equivalence contract of :mod:`navkit.planes._kernels` holds: the twins
(:func:`navkit.planes.dense._terms_numpy`, :func:`navkit.planes.dense._normal_equations_numpy`)
run the same float64 operations in the same order - the rotation's dot products left to
right, the bilinear sample as ``(top (1 - b)) + (bottom b)``, the sums one term after the
other from +0 - and no kernel uses ``fastmath``, so both give the same bits on any CPU
(``tests/planes/test_dense.py``).

Compiled with Numba (``@njit(cache=True)``); imported lazily by :mod:`navkit.planes.dense` on
the first dense alignment with kernels enabled (:func:`navkit.jit.kernels_enabled`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["dense_terms", "normal_equations"]

TWINS = {
    "dense_terms": "navkit.planes.dense._terms_numpy",
    "normal_equations": "navkit.planes.dense._normal_equations_numpy",
}
"""Each kernel -> its NumPy twin."""

SQRT2 = math.sqrt(2.0)


@njit(cache=True, inline="always")
def _bilinear(
    G3: np.ndarray, v0: int, u0: int, c: int, a: float, b: float
) -> float:  # pragma: no cover - compiled
    """Channel ``c`` of ``G3`` sampled bilinearly at ``(u0 + a, v0 + b)``."""
    top = np.float64(G3[v0, u0, c]) * (1 - a) + np.float64(G3[v0, u0 + 1, c]) * a
    bot = np.float64(G3[v0 + 1, u0, c]) * (1 - a) + np.float64(G3[v0 + 1, u0 + 1, c]) * a
    return top * (1 - b) + bot * b


@njit(cache=True)
def dense_terms(
    src: np.ndarray,
    src_gray: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    K: np.ndarray,
    V: np.ndarray,
    N: np.ndarray,
    G3: np.ndarray,
    max_diff: float,
    noise_k: float,
    level_scale: float,
    sigma_b: float,
) -> tuple[
    int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray
]:  # pragma: no cover - compiled
    """Residuals and Jacobians of the geometric and photometric terms of the source points
    ``src`` (``(M, 3)``, brightness ``src_gray``) moved by ``(R, t)`` into the target level
    (``K = (fx, fy, cx, cy)``; vertex map ``V``, normal map ``N``, brightness and gradients
    ``G3``, each ``(H, W, 3)`` float32).

    Returns ``(n, idx, rG, JG, rI, JI, sig)``; the first ``n`` rows are the correspondences:
    source index, geometric residual and Jacobian in sigmas of the point-to-plane noise
    ``sig = sqrt(2) k z^2`` (metres, at the target's depth), brightness residual and Jacobian
    in brightness sigmas ``sigma_b``. A correspondence projects inside the target's border
    pixels at ``z > 0.1`` onto a pixel with depth and normal whose depth agrees within
    ``max_diff k z^2 level_scale``."""
    M = src.shape[0]
    H = V.shape[0]
    W = V.shape[1]
    fx = K[0]
    fy = K[1]
    cx = K[2]
    cy = K[3]
    idx = np.empty(M, np.int64)
    rG = np.empty(M)
    JG = np.empty((M, 6))
    rI = np.empty(M)
    JI = np.empty((M, 6))
    sig = np.empty(M)
    n = 0
    for i in range(M):
        x = src[i, 0]
        y = src[i, 1]
        zs = src[i, 2]
        Y0 = x * R[0, 0] + y * R[0, 1] + zs * R[0, 2] + t[0]
        Y1 = x * R[1, 0] + y * R[1, 1] + zs * R[1, 2] + t[1]
        z = x * R[2, 0] + y * R[2, 1] + zs * R[2, 2] + t[2]
        if not z > 0.1:
            continue
        u = fx * Y0 / z + cx
        v = fy * Y1 / z + cy
        if not (u >= 0.0 and v >= 0.0 and u < W - 1 and v < H - 1):
            continue
        ui = int(np.rint(u))
        vi = int(np.rint(v))
        V0 = np.float64(V[vi, ui, 0])
        V1 = np.float64(V[vi, ui, 1])
        V2 = np.float64(V[vi, ui, 2])
        N0 = np.float64(N[vi, ui, 0])
        N1 = np.float64(N[vi, ui, 1])
        N2 = np.float64(N[vi, ui, 2])
        if not (np.isfinite(V2) and np.isfinite(N0)):
            continue
        if not abs(V2 - z) < max_diff * (noise_k * z * z) * level_scale:
            continue
        p = SQRT2 * (noise_k * V2 * V2)
        isg = 1.0 / p
        rG[n] = (N0 * (Y0 - V0) + N1 * (Y1 - V1) + N2 * (z - V2)) * isg
        JG[n, 0] = N0 * isg
        JG[n, 1] = N1 * isg
        JG[n, 2] = N2 * isg
        JG[n, 3] = (Y1 * N2 - z * N1) * isg
        JG[n, 4] = (z * N0 - Y0 * N2) * isg
        JG[n, 5] = (Y0 * N1 - Y1 * N0) * isg
        u0 = int(u)
        v0 = int(v)
        a = u - u0
        b = v - v0
        gxs = _bilinear(G3, v0, u0, 1, a, b) * fx
        gys = _bilinear(G3, v0, u0, 2, a, b) * fy
        rI[n] = (_bilinear(G3, v0, u0, 0, a, b) - src_gray[i]) / sigma_b
        iz = 1.0 / z
        j0 = gxs * iz
        j1 = gys * iz
        j2 = -(gxs * Y0 + gys * Y1) * iz * iz
        JI[n, 0] = j0 / sigma_b
        JI[n, 1] = j1 / sigma_b
        JI[n, 2] = j2 / sigma_b
        JI[n, 3] = (Y1 * j2 - z * j1) / sigma_b
        JI[n, 4] = (z * j0 - Y0 * j2) / sigma_b
        JI[n, 5] = (Y0 * j1 - Y1 * j0) / sigma_b
        sig[n] = p
        idx[n] = i
        n += 1
    return n, idx, rG, JG, rI, JI, sig


@njit(cache=True)
def normal_equations(
    J: np.ndarray, w: np.ndarray, r: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """``H = J^T diag(w) J`` and ``g = J^T diag(w) r`` of ``(M, 6)`` Jacobians, each entry
    summed over the rows in order from +0 (``H`` symmetric: the upper triangle, mirrored)."""
    H = np.zeros((6, 6))
    g = np.zeros(6)
    for i in range(J.shape[0]):
        wi = w[i]
        for a in range(6):
            ja = J[i, a] * wi
            g[a] += ja * r[i]
            for b in range(a, 6):
                H[a, b] += ja * J[i, b]
    for a in range(6):
        for b in range(a):
            H[a, b] = H[b, a]
    return H, g
