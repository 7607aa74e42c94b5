"""Figures of the obstacle detector: the 2D obstacle map like paper 1's fig. 12."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CLASS_COLORS", "plot_obstacle_map", "save_obstacle_map"]

CLASS_COLORS = {
    0: ("ground", "#8fbf8f"),
    -1: ("unreliable", "#d0d0d0"),
    -2: ("obstacle", "#d62728"),
    -3: ("side shadow", "#9467bd"),
    -4: ("shadow behind", "#1f3b73"),
}
"""Class value -> (name, colour) used in the map figure."""

SHAPE_STYLE = {
    "A1": ("#ff7f0e", "-"),
    "A2": ("#bcbd22", ":"),
    "A3": ("#17becf", "--"),
    "A4": ("#8c564b", ":"),
    "A5": ("#e377c2", "--"),
    "A6": ("#2ca02c", "-"),
    "MEC": ("#7f7f7f", "-."),
    "MVEE": ("#000000", "-."),
}


def plot_obstacle_map(
    detection: Any,
    *,
    shapes: Sequence[str] = ("A1", "A6"),
    guaranteed: bool = True,
    extent_m: float | None = None,
    ax: Any = None,
    title: str | None = None,
) -> Any:
    """Draw the classified triangles (by class colour), the obstacles' shapes and the sensor.

    Parameters
    ----------
    detection : ObstacleDetection
    shapes : names of the shapes to draw (their A7 versions in dashed red when ``guaranteed``)
    extent_m : half-width of the view around the sensor (m); by default the obstacles' extent
        plus 3 m, at least 10 m.
    ax : matplotlib axes, optional
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection
    from matplotlib.patches import Patch

    if ax is None:
        _, ax = plt.subplots(figsize=(9, 9))
    flat = detection.points.reshape(-1, 3)
    tri = detection.triangles.reshape(-1, 3)
    lab = detection.triangle_labels.reshape(-1)
    keep = lab != -1
    xy = flat[tri[keep]][..., :2]
    colors = np.array([CLASS_COLORS[int(c)][1] for c in (-4, -3, -2, -1, 0)])
    cidx = lab[keep] + 4
    ax.add_collection(
        PolyCollection(
            xy, facecolors=colors[cidx], edgecolors="none", linewidths=0, rasterized=True
        )
    )
    for ob in detection.obstacles:
        for name in shapes:
            if name in ob.shapes:
                color, ls = SHAPE_STYLE.get(name, ("#333333", "-"))
                o = ob.shapes[name].outline(72)
                ax.plot(*np.vstack([o, o[:1]]).T, color=color, ls=ls, lw=1.2)
        if guaranteed:  # A7: the drawn shapes over the obstacle and its shadows
            for g in (ob.guaranteed[n] for n in shapes if n in ob.guaranteed):
                o = g.outline(72)
                ax.plot(*np.vstack([o, o[:1]]).T, color="#d62728", ls=(0, (2, 2)), lw=0.8)
        c = ob.polygon_xy.mean(axis=0)
        ax.annotate(
            str(ob.id), c, fontsize=8, ha="center", va="center", color="white", weight="bold"
        )
    s = detection.sensor_origin
    ax.plot(s[0], s[1], marker="^", color="k", ms=10)
    if extent_m is None:
        pts = [ob.shadow_xy for ob in detection.obstacles if len(ob.shadow_xy)]
        ext = float(np.max(np.abs(np.concatenate(pts) - s[:2]))) + 3.0 if pts else 10.0
        extent_m = max(ext, 10.0)
    ax.set_xlim(s[0] - extent_m, s[0] + extent_m)
    ax.set_ylim(s[1] - extent_m, s[1] + extent_m)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, forward)")
    ax.set_ylabel("y (m, left)")
    handles: list[Any] = [Patch(color=c, label=n) for _, (n, c) in CLASS_COLORS.items()]
    handles += [
        matplotlib.lines.Line2D(
            [],
            [],
            color=SHAPE_STYLE.get(n, ("#333", "-"))[0],
            ls=SHAPE_STYLE.get(n, ("#333", "-"))[1],
            label=n,
        )
        for n in shapes
    ]
    if guaranteed:
        handles.append(
            matplotlib.lines.Line2D(
                [], [], color="#d62728", ls=(0, (2, 2)), label="A7 (with shadows)"
            )
        )
    ax.legend(handles=handles, loc="upper right", fontsize=7, framealpha=0.85)
    ax.set_title(title or f"{len(detection.obstacles)} obstacles")
    return ax


def save_obstacle_map(path: str | Path, detection: Any, **kwargs: Any) -> None:
    """Write :func:`plot_obstacle_map` to a PNG atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from navkit.io.atomic import atomic_path

    fig, ax = plt.subplots(figsize=(9, 9))
    try:
        plot_obstacle_map(detection, ax=ax, **kwargs)
        fig.tight_layout()
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110)
    finally:
        plt.close(fig)
