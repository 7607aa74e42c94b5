"""Figures of the obstacle detector: the 2D obstacle map like paper 1's fig. 12.

The map reads on real scans (a KITTI frame holds some 60 obstacles, some of them buildings tens of
metres long): every obstacle is drawn as its **footprint** - the outline of the ground its obstacle
returns cover seen from above, concave where the obstacle is - and numbered; the bounding shapes
(A1 rectangle, A6 ellipse, ...) are drawn only for compact obstacles (largest side at most
``max_shape_m``), since a 40 m ellipse round an L-shaped building says nothing. Shadows and
ground are a faint background; a scale bar gives the metres.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["CLASS_COLORS", "footprint_outlines", "plot_obstacle_map", "save_obstacle_map"]

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


def footprint_outlines(
    points_xy: NDArray[np.float64], cell_m: float = 0.2, close_m: float = 0.6
) -> list[NDArray[np.float64]]:
    """Outlines ``[(K, 2), ...]`` of the ground an obstacle's returns ``(N, 2)`` (m) cover, seen
    from above: the points rasterised at ``cell_m``, gaps up to ``close_m`` closed
    (morphological closing), outer contours traced (OpenCV ``findContours``)."""
    import cv2

    if len(points_xy) == 0:
        return []
    pad = close_m + 2 * cell_m
    lo = points_xy.min(axis=0) - pad
    w, h = (np.ceil((points_xy.max(axis=0) + pad - lo) / cell_m).astype(int) + 1).tolist()
    mask = np.zeros((h, w), np.uint8)
    ij = np.floor((points_xy - lo) / cell_m).astype(np.int64)
    mask[ij[:, 1], ij[:, 0]] = 1
    k = 2 * max(1, round(close_m / cell_m / 2)) + 1
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k))
    mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, kernel)
    mask = cv2.dilate(mask, np.ones((2, 2), np.uint8))  # one cell of margin round thin walls
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    return [(c.reshape(-1, 2) + 0.5) * cell_m + lo for c in contours if len(c) >= 3]


def _largest_side(ob: Any) -> float:
    p = ob.polygon_xy
    return float(np.max(np.ptp(p, axis=0))) if len(p) else 0.0


def plot_obstacle_map(
    detection: Any,
    *,
    shapes: Sequence[str] = ("A1", "A6"),
    max_shape_m: float = 4.0,
    guaranteed: bool = False,
    extent_m: float | None = None,
    scale_m: float | None = None,
    ax: Any = None,
    title: str | None = None,
) -> Any:
    """Draw the obstacles' footprints, numbered, over the faint ground / shadow classes.

    Parameters
    ----------
    detection : ObstacleDetection
    shapes : names of the bounding shapes drawn round compact obstacles
    max_shape_m : float
        Shapes are drawn only round obstacles whose convex hull's larger side is at most this
        (m); larger structures (walls, buildings, hedges) are drawn as their outline alone.
    guaranteed : bool
        Also draw the A7 versions of the shapes (obstacle plus shadows), dashed red.
    extent_m : half-width of the view around the sensor (m); by default the obstacles' extent
        plus 3 m, at least 10 m.
    scale_m : length of the scale bar (m); by default about a fifth of the view, rounded.
    ax : matplotlib axes, optional
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection
    from matplotlib.lines import Line2D
    from matplotlib.offsetbox import AnchoredOffsetbox, AuxTransformBox, TextArea, VPacker
    from matplotlib.patches import Patch, Polygon, Rectangle

    if ax is None:
        _, ax = plt.subplots(figsize=(9, 9))
    s = detection.sensor_origin
    if extent_m is None:
        pts = [ob.polygon_xy for ob in detection.obstacles if len(ob.polygon_xy)]
        ext = float(np.max(np.abs(np.concatenate(pts) - s[:2]))) + 3.0 if pts else 10.0
        extent_m = max(ext, 10.0)
    flat = detection.points.reshape(-1, 3)
    tri = detection.triangles.reshape(-1, 3)
    lab = detection.triangle_labels.reshape(-1)
    back = {0: "#cfe6cf", -3: "#e4dcef", -4: "#dde3ee"}  # faint ground and shadows
    keep = np.isin(lab, list(back))
    ax.add_collection(
        PolyCollection(
            flat[tri[keep]][..., :2],
            facecolors=[back[int(c)] for c in lab[keep]],
            edgecolors="none",
            linewidths=0,
            rasterized=True,
        )
    )
    vlab = detection.vertex_labels.reshape(-1)
    vown = detection.vertex_obstacle.reshape(-1)
    for ob in detection.obstacles:
        mine = (vown == ob.id) & (vlab == -2) & np.all(np.isfinite(flat), axis=1)
        outlines = footprint_outlines(flat[mine][:, :2])
        for o in outlines:
            ax.add_patch(Polygon(o, closed=True, facecolor="#f4a3a3", edgecolor="#a50f15", lw=0.9))
        compact = _largest_side(ob) <= max_shape_m
        for name in shapes if compact else ():
            if name in ob.shapes:
                color, ls = SHAPE_STYLE.get(name, ("#333333", "-"))
                o = ob.shapes[name].outline(72)
                ax.plot(*np.vstack([o, o[:1]]).T, color=color, ls=ls, lw=1.0)
        if guaranteed and compact:
            for g in (ob.guaranteed[n] for n in shapes if n in ob.guaranteed):
                o = g.outline(72)
                ax.plot(*np.vstack([o, o[:1]]).T, color="#d62728", ls=(0, (2, 2)), lw=0.8)
        # the number at the obstacle return nearest its hull's centre (on concave shapes too)
        c = ob.polygon_xy.mean(axis=0)
        own = flat[mine][:, :2] if np.any(mine) else ob.boundary_xy
        anchor = own[np.argmin(np.linalg.norm(own - c, axis=1))]
        if np.all(np.abs(anchor - s[:2]) < extent_m):
            ax.annotate(
                str(ob.id),
                anchor,
                fontsize=6.5,
                ha="center",
                va="center",
                color="#67000d",
                bbox={"boxstyle": "round,pad=0.12", "fc": "white", "ec": "none", "alpha": 0.75},
            )
    ax.plot(s[0], s[1], marker="^", color="k", ms=9, ls="none")
    ax.set_xlim(s[0] - extent_m, s[0] + extent_m)
    ax.set_ylim(s[1] - extent_m, s[1] + extent_m)
    ax.set_aspect("equal")
    ax.set_xlabel("x, forward (m)")
    ax.set_ylabel("y, left (m)")
    if scale_m is None:
        raw = 2 * extent_m / 8
        scale_m = float(min((1, 2, 5, 10, 20, 50, 100), key=lambda v: abs(v - raw)))
    # the scale bar (a bar in data units over its label, anchored at the lower right)
    bar = AuxTransformBox(ax.transData)
    bar.add_artist(Rectangle((0, 0), scale_m, extent_m / 200, facecolor="black", edgecolor="none"))
    box = VPacker(children=[bar, TextArea(f"{scale_m:g} m")], align="center", pad=0, sep=3)
    ax.add_artist(AnchoredOffsetbox("lower right", child=box, pad=0.5, frameon=False))
    handles: list[Any] = [
        Patch(facecolor="#f4a3a3", edgecolor="#a50f15", label="obstacle footprint (number = id)"),
        Patch(color=back[0], label="ground"),
        Patch(color=back[-3], label="shadow (unseen)"),
    ]
    handles += [
        Line2D(
            [],
            [],
            color=SHAPE_STYLE[n][0],
            ls=SHAPE_STYLE[n][1],
            label=f"{n} (<= {max_shape_m:g} m)",
        )
        for n in shapes
        if n in SHAPE_STYLE
    ]
    handles.append(Line2D([], [], color="k", marker="^", ls="none", label="sensor"))
    ax.legend(handles=handles, loc="upper right", fontsize=7, framealpha=0.9)
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
