"""Pictures of the planes pipeline: extraction overlays, textures, the map with the trajectory."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["extraction_overlay", "plot_map", "texture_to_uint8"]

log = logging.getLogger(__name__)

_PALETTE = np.array(
    [
        [230, 25, 75],
        [60, 180, 75],
        [255, 225, 25],
        [0, 130, 200],
        [245, 130, 48],
        [145, 30, 180],
        [70, 240, 240],
        [240, 50, 230],
        [210, 245, 60],
        [250, 190, 190],
        [0, 128, 128],
        [170, 110, 40],
    ],
    dtype=np.float64,
)


def extraction_overlay(
    image: ArrayLike, labels: ArrayLike, alpha: float = 0.45
) -> NDArray[np.uint8]:
    """``(H, W, 3)`` uint8: the image with each plane's pixels tinted by its colour and its
    border drawn (labels ``-1`` untouched)."""
    import cv2

    img = np.asarray(image)
    lab = np.asarray(labels)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    if img.dtype != np.uint8:
        img = np.clip(img * (255.0 if img.max() <= 1.0 else 1.0), 0, 255).astype(np.uint8)
    out = img.astype(np.float64)
    m = lab >= 0
    colors = _PALETTE[np.where(m, lab, 0) % len(_PALETTE)]
    out[m] = (1 - alpha) * out[m] + alpha * colors[m]
    edge = np.zeros(lab.shape, bool)
    edge[:-1] |= lab[:-1] != lab[1:]
    edge[:, :-1] |= lab[:, :-1] != lab[:, 1:]
    edge &= m
    out[edge] = colors[edge]
    out = np.clip(out, 0, 255).astype(np.uint8)
    for k in range(int(lab.max()) + 1 if m.any() else 0):
        ys, xs = np.nonzero(lab == k)
        if len(xs):
            cv2.putText(
                out,
                str(k),
                (int(np.median(xs)), int(np.median(ys))),
                cv2.FONT_HERSHEY_SIMPLEX,
                0.6,
                (255, 255, 255),
                2,
                cv2.LINE_AA,
            )
    return np.asarray(out, dtype=np.uint8)


def texture_to_uint8(image: ArrayLike) -> NDArray[np.uint8]:
    """Brightness in [0, 1] with NaN (invalid) -> gray uint8 image, invalid pixels black."""
    a = np.asarray(image, dtype=np.float64)
    return np.where(np.isfinite(a), np.clip(np.rint(np.nan_to_num(a) * 255), 1, 255), 0).astype(
        np.uint8
    )


def plot_map(
    path: str | Path,
    planes: Sequence[dict],
    poses: ArrayLike,
    *,
    truth: ArrayLike | None = None,
    title: str = "plane map and trajectory",
) -> None:
    """Top view (x right, z forward of the first camera) of map planes and the trajectory.

    Parameters
    ----------
    path : str or Path
        PNG written atomically.
    planes : sequence of dict
        ``map.to_dict()["planes"]`` entries (``outline_world`` (M, 3), ``normal``, ``id``).
    poses : (N, 4, 4) array
        ``T_world_frame``.
    truth : (N, 4, 4) array, optional
        Reference trajectory drawn dashed.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from navkit.io.atomic import atomic_path

    P = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
    fig, ax = plt.subplots(figsize=(7, 6))
    for p in planes:
        o = np.asarray(p["outline_world"], dtype=np.float64).reshape(-1, 3)
        if len(o) < 3:
            continue
        n = np.asarray(p["normal"], dtype=np.float64)
        c = _PALETTE[int(p["id"]) % len(_PALETTE)] / 255
        closed = np.vstack([o, o[:1]])
        # horizontal-ish planes (normal along camera y) are floors: fill lightly
        ax.fill(closed[:, 0], closed[:, 2], color=c, alpha=0.15 if abs(n[1]) > 0.7 else 0.35, lw=0)
        ax.plot(closed[:, 0], closed[:, 2], color=c, lw=1)
    ax.plot(P[:, 0, 3], P[:, 2, 3], "k.-", lw=1.5, label="estimate")
    if truth is not None:
        Tt = np.asarray(truth, dtype=np.float64).reshape(-1, 4, 4)
        ax.plot(Tt[:, 0, 3], Tt[:, 2, 3], "--", color="tab:red", lw=1.2, label="reference")
    fwd = P[:, :3, 2]  # optical axes
    ax.quiver(P[:, 0, 3], P[:, 2, 3], fwd[:, 0], fwd[:, 2], angles="xy", scale=12, width=0.004)
    ax.set_xlabel("x (m, first camera right)")
    ax.set_ylabel("z (m, first camera forward)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(title)
    ax.legend(loc="best")
    ax.grid(alpha=0.3)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, bbox_inches="tight")
    plt.close(fig)
