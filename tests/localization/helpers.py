"""2D ray casting against wall segments: exact synthetic laser scans for the localization tests."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

RECT = np.array(
    [[[0, 0], [8, 0]], [[8, 0], [8, 6]], [[8, 6], [0, 6]], [[0, 6], [0, 0]]], dtype=float
)
LSHAPE_POLY = np.array([[0, 0], [10, 0], [10, 4], [5, 4], [5, 8], [0, 8]], dtype=float)
LSHAPE = np.stack([LSHAPE_POLY, np.roll(LSHAPE_POLY, -1, axis=0)], axis=1)


def cast(
    segments: NDArray[np.float64],
    pose: NDArray[np.float64],
    bearings: NDArray[np.float64],
    max_range: float = 30.0,
) -> NDArray[np.float64]:
    """Ranges ``(B,)`` from ``pose = (x, y, theta)`` along ``bearings`` to the nearest segment (NaN = miss)."""
    o = np.asarray(pose[:2], dtype=float)
    a = pose[2] + bearings
    d = np.stack([np.cos(a), np.sin(a)], axis=1)  # (B, 2)
    S, E = segments[:, 0], segments[:, 1]
    e = E - S  # (W, 2)
    # solve o + t d = S + u e for every beam / segment pair
    den = d[:, None, 0] * (-e[None, :, 1]) - d[:, None, 1] * (-e[None, :, 0])
    w = S[None] - o[None, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * (-e[None, :, 1]) - w[..., 1] * (-e[None, :, 0])) / den
        u = (d[:, None, 0] * w[..., 1] - d[:, None, 1] * w[..., 0]) / den
    ok = np.isfinite(t) & (t > 1e-9) & (u >= 0) & (u <= 1)
    t = np.where(ok, t, np.inf).min(axis=1)
    t[~np.isfinite(t) | (t > max_range)] = np.nan
    return t


def scan_points(
    segments: NDArray[np.float64],
    pose: NDArray[np.float64],
    n: int = 361,
    fov: float = 2 * np.pi,
    noise: float = 0.0,
    rng: np.random.Generator | None = None,
) -> NDArray[np.float64]:
    """Body-frame end points ``(K, 2)`` of a simulated scan (misses dropped), range noise ``noise`` m."""
    b = np.linspace(-fov / 2, fov / 2, n, endpoint=fov < 2 * np.pi)
    r = cast(segments, np.asarray(pose, float), b)
    if noise > 0:
        r = r + (rng or np.random.default_rng(0)).normal(0.0, noise, r.shape)
    ok = np.isfinite(r)
    return np.stack([r[ok] * np.cos(b[ok]), r[ok] * np.sin(b[ok])], axis=1)


def sample_walls(segments: NDArray[np.float64], spacing: float = 0.01) -> NDArray[np.float64]:
    out = []
    for s, e in segments:
        n = max(2, int(np.ceil(np.linalg.norm(e - s) / spacing)) + 1)
        t = np.linspace(0, 1, n)[:, None]
        out.append(s + t * (e - s))
    return np.concatenate(out)
