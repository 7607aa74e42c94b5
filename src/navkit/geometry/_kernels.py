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


@njit(cache=True, error_model="numpy")
def a6_search_kernel(P, counts, x0, step0, min_step, max_iter):  # type: ignore[no-untyped-def]
    """The compass search of ``shapes._a6_batch`` set by set: the final ``(x, y, phi, log k)``
    of every set ``(n, 4)``.

    ``P (n, m, 2)`` padded sets (``counts`` real points each), ``x0``, ``step0``, ``min_step``
    ``(n, 4)``. The 81 trials are evaluated as in the twin (u, v on the 27 (phi, x, y)
    combinations, a^2 on 81) in the twin's order; ``cos``, ``sin`` and ``exp`` are libm's.
    """
    n = P.shape[0]
    out = x0.copy()
    three = np.array([-1.0, 0.0, 1.0])
    vals = np.empty((3, 4))
    cs = np.empty(3)
    sn = np.empty(3)
    kk = np.empty(3)
    f = np.empty(81)
    for s in range(n):
        mh = counts[s]
        cur = x0[s].copy()
        step = step0[s].copy()
        # f at the start (``_a6_area``)
        k0 = np.exp(cur[3])
        c0, s0 = np.cos(cur[2]), np.sin(cur[2])
        a2 = 0.0
        for q in range(mh):
            dx = P[s, q, 0] - cur[0]
            dy = P[s, q, 1] - cur[1]
            u = c0 * dx + s0 * dy
            v = -s0 * dx + c0 * dy
            w = u * u + (v * v) / (k0 * k0)
            if q == 0 or w > a2:
                a2 = w
        f_cur = np.pi * a2 * k0
        for _ in range(max_iter):
            for t in range(3):
                for p in range(4):
                    vals[t, p] = cur[p] + three[t] * step[p]
                cs[t] = np.cos(vals[t, 2])
                sn[t] = np.sin(vals[t, 2])
                kk[t] = np.exp(vals[t, 3])
            for tx in range(3):
                for ty in range(3):
                    for tp in range(3):
                        a2k0 = -1.0
                        a2k1 = -1.0
                        a2k2 = -1.0
                        for q in range(mh):
                            dx = P[s, q, 0] - vals[tx, 0]
                            dy = P[s, q, 1] - vals[ty, 1]
                            u = cs[tp] * dx + sn[tp] * dy
                            v = -sn[tp] * dx + cs[tp] * dy
                            uu = u * u
                            vv = v * v
                            w0 = uu + vv / (kk[0] * kk[0])
                            w1 = uu + vv / (kk[1] * kk[1])
                            w2 = uu + vv / (kk[2] * kk[2])
                            if q == 0 or w0 > a2k0:
                                a2k0 = w0
                            if q == 0 or w1 > a2k1:
                                a2k1 = w1
                            if q == 0 or w2 > a2k2:
                                a2k2 = w2
                        base = ((tx * 3 + ty) * 3 + tp) * 3
                        f[base] = np.pi * a2k0 * kk[0]
                        f[base + 1] = np.pi * a2k1 * kk[1]
                        f[base + 2] = np.pi * a2k2 * kk[2]
            best = -1
            for t in range(81):
                if t == 40:  # the zero move
                    continue
                if best < 0 or f[t] < f[best]:
                    best = t
            if f[best] < f_cur * (1 - 1e-12):
                mv = best
                for p in range(3, -1, -1):  # the move's digits: x, y, phi, log k in base 3
                    cur[p] = cur[p] + (mv % 3 - 1) * step[p]
                    mv //= 3
                f_cur = f[best]
            else:
                for p in range(4):
                    step[p] *= 0.5
                if not (
                    step[0] > min_step[s, 0]
                    or step[1] > min_step[s, 1]
                    or step[2] > min_step[s, 2]
                    or step[3] > min_step[s, 3]
                ):
                    break
        out[s] = cur
    return out
