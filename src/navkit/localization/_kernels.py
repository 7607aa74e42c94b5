"""Compiled scoring loop of the correlative matcher (:mod:`navkit.localization.matcher`).

A candidate pose's score is a sum of uint8 field values gathered at the scan's cells shifted by
the candidate's translation. NumPy builds the (candidates x points) index array and gathers it;
:func:`gather_sums` walks it once without the temporary. Integer sums: the same values exactly
(the NumPy version stays in ``_Search`` as the oracle, ``tests/localization/test_kernels.py``).
Numba, ``cache=True``; imported on first use.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def gather_sums(
    grid: np.ndarray, F: np.ndarray, rows: np.ndarray, shift: np.ndarray
) -> np.ndarray:  # pragma: no cover - compiled
    """``out[c] = sum_i grid[F[rows[c], i] + shift[c]]`` (uint8 values, int64 sums)."""
    C = len(rows)
    N = F.shape[1]
    out = np.empty(C, np.int64)
    for c in range(C):
        r = rows[c]
        s = shift[c]
        acc = 0
        for i in range(N):
            acc += grid[F[r, i] + s]
        out[c] = acc
    return out
