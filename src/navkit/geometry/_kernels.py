"""Compiled (Numba) kernels of the bounding shapes (:mod:`navkit.geometry.shapes`).

Each kernel repeats its NumPy twin's arithmetic set by set; see ``docs/kernels.md``
("Obstacles"). Selected by the ``backend`` keyword of :func:`~navkit.geometry.shapes.mvee_batch`
and :func:`~navkit.geometry.shapes.compute_shapes` (``"compiled"`` by default).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["mvee_weights_kernel"]


@njit(cache=True, error_model="numpy")
def mvee_weights_kernel(P, mask, tol, max_iter):  # type: ignore[no-untyped-def]
    """Khachiyan / Todd-Yildirim weights ``u (n, m)`` of ``mvee_batch``'s loop, set by set.

    ``P (n, m, 2)`` are the centred, scaled, padded sets and ``mask (n, m)`` their real points.
    The moments are summed in index order (the twin's ``einsum`` may group them differently:
    the weights agree to rounding).
    """
    n, m = mask.shape
    d = 2
    u = np.zeros((n, m))
    for s in range(n):
        cnt = 0
        for k in range(m):
            if mask[s, k]:
                cnt += 1
        for k in range(m):
            u[s, k] = (1.0 if mask[s, k] else 0.0) / cnt
        M = np.empty(m)
        for _ in range(max_iter):
            m0 = 0.0
            m1 = 0.0
            m2 = 0.0
            m3 = 0.0
            m4 = 0.0
            for k in range(m):
                x, y, w = P[s, k, 0], P[s, k, 1], u[s, k]
                m0 += x * w
                m1 += y * w
                m2 += x * x * w
                m3 += x * y * w
                m4 += y * y * w
            cx, cy = m0, m1
            sxx, sxy, syy = m2 - cx * cx, m3 - cx * cy, m4 - cy * cy
            det = max(sxx * syy - sxy * sxy, 1e-300)
            j_up = 0
            j_dn = -1
            for k in range(m):
                dx = P[s, k, 0] - cx
                dy = P[s, k, 1] - cy
                M[k] = 1.0 + (syy * dx * dx - 2.0 * sxy * dx * dy + sxx * dy * dy) / det
                if M[k] > M[j_up] or (M[k] != M[k] and M[j_up] == M[j_up]):
                    j_up = k
            best = np.inf
            for k in range(m):
                v = M[k] if u[s, k] > 0 else np.inf
                if j_dn < 0 or v < best or (v != v and best == best):
                    j_dn = k
                    best = v
            M_up, M_dn = M[j_up], M[j_dn]
            eps_up = M_up / (d + 1) - 1
            eps_dn = 1 - M_dn / (d + 1)
            worst = eps_up if (eps_up != eps_up or eps_up >= eps_dn) else eps_dn
            if eps_dn != eps_dn:
                worst = eps_dn
            if worst <= tol:
                break
            if eps_up >= eps_dn:
                beta = (M_up - d - 1) / ((d + 1) * (M_up - 1))
                f = 1 - beta
                for k in range(m):
                    u[s, k] *= f
                u[s, j_up] += beta
            else:
                u_dn = u[s, j_dn]
                b1 = (d + 1 - M_dn) / ((d + 1) * (M_dn - 1))
                b2 = u_dn / (1 - u_dn)
                beta = b1 if (b1 != b1 or b1 <= b2) else b2
                if b2 != b2:
                    beta = b2
                if not np.isfinite(beta):
                    beta = 0.0
                f = 1 + beta
                for k in range(m):
                    u[s, k] *= f
                u[s, j_dn] -= beta
            for k in range(m):
                if u[s, k] < 0.0:
                    u[s, k] = 0.0
    return u
