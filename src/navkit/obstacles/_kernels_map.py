"""Compiled (Numba) kernels of stages 6-8 that share passes or batch all obstacles at once.

Twins (the NumPy references) live in :mod:`navkit.obstacles.detector` and
:mod:`navkit.obstacles.segment`; see ``docs/kernels.md`` ("Obstacles"). The shape kernels of
stage 8 are in :mod:`navkit.geometry._kernels`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["guaranteed_sets_kernel"]


@njit(cache=True)
def guaranteed_sets_kernel(v_xyz, v_off, s_xy, s_off):  # type: ignore[no-untyped-def]
    """A7's input in a CSR layout: per obstacle its vertices' ``(x, y)`` (``v_xyz`` rows
    ``v_off[k]:v_off[k + 1]``) followed by its shadow vertices (``s_xy``, ``s_off``), as the
    twin's ``np.concatenate([vertices, shadows])``. Returns ``(g_xy (N, 2), g_off (n + 1,))``."""
    n = len(v_off) - 1
    g_off = np.empty(n + 1, np.int64)
    for k in range(n + 1):
        g_off[k] = v_off[k] + s_off[k]
    g = np.empty((g_off[n], 2))
    for k in range(n):
        p = g_off[k]
        for r in range(v_off[k], v_off[k + 1]):
            g[p, 0] = v_xyz[r, 0]
            g[p, 1] = v_xyz[r, 1]
            p += 1
        for r in range(s_off[k], s_off[k + 1]):
            g[p, 0] = s_xy[r, 0]
            g[p, 1] = s_xy[r, 1]
            p += 1
    return g, g_off
