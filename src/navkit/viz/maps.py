"""Figures of wall maps, localization fixes and disparity images (matplotlib Agg, saved atomically)."""

from __future__ import annotations

import os

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.io.atomic import atomic_path
from navkit.localization.mapping import WallMap

__all__ = ["colorize_disparity", "plot_map"]


def colorize_disparity(
    disparity: ArrayLike, vmin: float | None = None, vmax: float | None = None
) -> NDArray[np.uint8]:
    """RGB ``(H, W, 3)`` uint8 picture of a disparity map (turbo colour map, invalid = black).

    ``vmin`` / ``vmax`` default to the 1st / 99th percentiles of the valid disparities.
    """
    import cv2

    d = np.asarray(disparity, dtype=np.float64)
    ok = np.isfinite(d)
    if not ok.any():
        return np.zeros((*d.shape, 3), dtype=np.uint8)
    lo = float(np.percentile(d[ok], 1)) if vmin is None else vmin
    hi = float(np.percentile(d[ok], 99)) if vmax is None else vmax
    scaled = np.clip((np.nan_to_num(d, nan=lo) - lo) / max(hi - lo, 1e-9), 0, 1)
    bgr = cv2.applyColorMap((scaled * 255).astype(np.uint8), cv2.COLORMAP_TURBO)
    rgb = bgr[:, :, ::-1].copy()
    rgb[~ok] = 0
    return np.asarray(rgb, dtype=np.uint8)


def plot_map(
    wall_map: WallMap,
    path: str | os.PathLike[str],
    *,
    poses: ArrayLike | None = None,
    truth: ArrayLike | None = None,
    true_walls: ArrayLike | None = None,
    title: str = "",
    dpi: int = 110,
) -> None:
    """Save a picture of the map: occupancy grid, walls, corners, outline; optional poses.

    Parameters
    ----------
    wall_map : WallMap
    path : path
        PNG (or any matplotlib format by suffix); written atomically.
    poses : (K, 3) array, optional
        Estimated ``(x, y, theta)`` (drawn as arrows; NaN rows skipped).
    truth : (K, 3) array, optional
        Reference poses (drawn as dots, joined to the estimates).
    true_walls : (K, 2, 2) array, optional
        True wall segments (grey dashed) for comparison.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 8))
    try:
        if wall_map.occupancy is not None:
            g = wall_map.occupancy
            img = np.where(g < 0, 0.75, np.where(g >= 50, 0.0, 1.0))
            H, W = g.shape
            x0, y0 = wall_map.origin
            r = wall_map.resolution
            ax.imshow(
                img,
                cmap="gray",
                vmin=0,
                vmax=1,
                origin="lower",
                extent=(x0, x0 + W * r, y0, y0 + H * r),
                interpolation="nearest",
            )
        if true_walls is not None:
            for seg in np.asarray(true_walls, dtype=np.float64).reshape(-1, 2, 2):
                ax.plot(seg[:, 0], seg[:, 1], "--", color="0.5", lw=1.0)
        for w in wall_map.walls:
            ax.plot([w.start[0], w.end[0]], [w.start[1], w.end[1]], "-", color="tab:blue", lw=1.6)
        if wall_map.outline is not None:
            o = np.vstack([wall_map.outline, wall_map.outline[:1]])
            ax.plot(o[:, 0], o[:, 1], "-", color="tab:green", lw=0.8, alpha=0.8)
        if wall_map.corners:
            C = np.array([c.point for c in wall_map.corners])
            ax.plot(C[:, 0], C[:, 1], "o", color="tab:red", ms=4)
        if poses is not None:
            X = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
            ok = np.all(np.isfinite(X), axis=1)
            X = X[ok]
            ax.quiver(
                X[:, 0],
                X[:, 1],
                np.cos(X[:, 2]),
                np.sin(X[:, 2]),
                color="tab:orange",
                scale=40,
                width=0.003,
            )
            if truth is not None:
                Tr = np.asarray(truth, dtype=np.float64).reshape(-1, 3)[ok]
                ax.plot(Tr[:, 0], Tr[:, 1], ".", color="tab:purple", ms=3)
                for a, b in zip(X, Tr, strict=True):
                    ax.plot([a[0], b[0]], [a[1], b[1]], "-", color="tab:purple", lw=0.5)
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_title(title or f"{len(wall_map.walls)} walls, {len(wall_map.corners)} corners")
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi, bbox_inches="tight")
    finally:
        plt.close(fig)
