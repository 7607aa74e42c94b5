"""Compiled loops around OpenCV's matcher (:mod:`navkit.stereo.disparity`): the background fill,
the right disparity by forward warping and the left-right check, each one pass over the image
instead of ~10 NumPy passes. No
arithmetic beyond NumPy's (comparisons, copies, ``rint``, maxima): the same results exactly (the NumPy
versions stay as the oracle, ``tests/stereo/test_kernels.py``). Numba, ``cache=True``;
imported on first use.
"""

from __future__ import annotations

import numpy as np
from numba import njit

TWINS = {
    "fill_background": "navkit.stereo.disparity.fill_background",
    "lr_consistency": "navkit.stereo.disparity.lr_consistency",
    "warp_right": "navkit.stereo.disparity.warp_right_disparity",
}
"""Each kernel -> its NumPy twin (the NumPy path of that function)."""


@njit(cache=True)
def fill_background(d: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """``disparity.fill_background``: NaN pixels get the smaller of the nearest valid values to
    their left and right in the row (either one where only one exists)."""
    H, W = d.shape
    out = d.copy()
    right = np.empty(W)
    for y in range(H):
        nxt = np.nan
        for x in range(W - 1, -1, -1):
            if np.isfinite(d[y, x]):
                nxt = d[y, x]
            right[x] = nxt
        prev = np.nan
        for x in range(W):
            v = d[y, x]
            if np.isfinite(v):
                prev = v
                continue
            r = right[x]
            if np.isnan(prev):
                out[y, x] = r
            elif np.isnan(r):
                out[y, x] = prev
            else:
                out[y, x] = min(prev, r)
    return out


@njit(cache=True)
def lr_consistency(
    dl: np.ndarray, dr: np.ndarray, max_diff: float
) -> np.ndarray:  # pragma: no cover
    """``disparity.lr_consistency``: left disparity ``d`` at ``x`` agrees with the right
    disparity at ``rint(x - d)`` within ``max_diff``."""
    H, W = dl.shape
    ok = np.zeros((H, W), np.bool_)
    for y in range(H):
        for x in range(W):
            d = dl[y, x]
            if not np.isfinite(d):
                continue
            xr = np.rint(x - d)
            if xr < 0 or xr >= W:
                continue
            other = dr[y, int(xr)]
            ok[y, x] = abs(other - d) <= max_diff
    return ok


@njit(cache=True)
def warp_right(dl: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """``disparity.warp_right_disparity``: every finite left disparity ``d`` at ``x`` lands on
    the right pixel ``rint(x - d)``; each right pixel keeps the largest (nearest) disparity that
    lands on it, NaN where none does."""
    H, W = dl.shape
    dr = np.full((H, W), np.nan)
    for y in range(H):
        for x in range(W):
            d = dl[y, x]
            if not np.isfinite(d):
                continue
            xr = np.rint(x - d)
            if xr < 0 or xr >= W:
                continue
            i = int(xr)
            o = dr[y, i]
            if np.isnan(o) or d > o:
                dr[y, i] = d
    return dr
