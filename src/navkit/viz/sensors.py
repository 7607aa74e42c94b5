"""Figures of the simulated world and of what each simulated sensor saw, with the truth.

Every function draws into a new matplotlib :class:`~matplotlib.figure.Figure` (Agg canvas, no
pyplot global state) and saves it atomically (:func:`navkit.io.atomic.atomic_path`), so an
interrupted run never leaves a half-written picture. Colours: ground returns green, obstacle
returns red, no return grey.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.io.atomic import atomic_path

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from navkit.sim import Scene, SimRGBD, SimScan, SimStereo

__all__ = [
    "GROUND_COLOR",
    "OBSTACLE_COLOR",
    "draw_scene_top",
    "new_figure",
    "plot_rgbd",
    "plot_scan",
    "plot_stereo",
    "plot_world",
    "save_figure",
]

log = logging.getLogger(__name__)

GROUND_COLOR = (0.20, 0.65, 0.25)
OBSTACLE_COLOR = (0.85, 0.15, 0.10)
_KIND_COLORS = {
    "wall": (0.45, 0.25, 0.20),
    "box": (0.80, 0.55, 0.25),
    "prism": (0.35, 0.45, 0.75),
    "sphere": (0.55, 0.55, 0.55),
    "hemisphere": (0.50, 0.48, 0.42),
    "cylinder": (0.75, 0.20, 0.15),
}


def new_figure(width: float, height: float) -> Figure:
    """A figure on an Agg canvas (no pyplot state; safe in threads and tests)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig: Figure, path: str | os.PathLike[str], dpi: int = 110) -> Path:
    """Save ``fig`` atomically to ``path`` (format from the suffix) and return the path."""
    target = Path(path)
    with atomic_path(target) as tmp:
        fig.savefig(tmp, dpi=dpi)
    log.info("wrote %s", target)
    return target


def _cmap(name: str, bad: tuple[float, float, float]) -> Any:
    import matplotlib

    return matplotlib.colormaps[name].with_extremes(bad=bad)


def _footprint(p: Any) -> NDArray[np.float64] | None:
    """Closed polygon ``(K, 2)`` of a primitive's footprint (a wall: its base line), or None for
    circles / the ground (from :func:`navkit.sim.footprints.footprint`)."""
    from navkit.sim.footprints import footprint

    fp = footprint(p)
    if fp is None or fp.circle is not None:
        return None
    if p.kind == "wall":  # the thickened base segment -> its centre line
        return np.array([fp.polygon[[0, 3]].mean(0), fp.polygon[[1, 2]].mean(0)])
    return np.vstack([fp.polygon, fp.polygon[:1]])


def draw_scene_top(ax: Axes, scene: Scene, *, labels: bool = True, alpha: float = 1.0) -> None:
    """Draw the scene seen from above (walls as lines, boxes / ramps as footprints, circles)."""
    from matplotlib.patches import Circle, Polygon

    for p in scene.primitives:
        if p.is_ground:
            continue
        color = _KIND_COLORS.get(p.kind, (0.4, 0.4, 0.4))
        poly = _footprint(p)
        if p.kind == "wall" and poly is not None:
            ax.plot(
                poly[:, 0], poly[:, 1], "-", color=color, lw=3, alpha=alpha, solid_capstyle="butt"
            )
            anchor = poly.mean(axis=0)
        elif poly is not None:
            ax.add_patch(
                Polygon(
                    poly,
                    closed=True,
                    facecolor=color,
                    edgecolor="k",
                    lw=0.6,
                    alpha=0.8 * alpha,
                    hatch="///" if p.kind == "prism" else None,
                )
            )
            anchor = poly[:-1].mean(axis=0)
        else:
            anchor = np.asarray(p.center[:2])  # type: ignore[attr-defined]
            ax.add_patch(
                Circle(
                    tuple(anchor),
                    p.radius,  # type: ignore[attr-defined]
                    facecolor=color,
                    edgecolor="k",
                    lw=0.6,
                    alpha=0.8 * alpha,
                )
            )
        if labels:
            ax.annotate(p.name, anchor, fontsize=6, ha="center", va="center", alpha=0.8)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def _draw_pose(
    ax: Axes, x: float, y: float, theta: float, label: str, color: str = "k", size: float = 1.0
) -> None:
    ax.plot([x], [y], "o", color=color, ms=5)
    ax.annotate(
        "",
        xy=(x + size * np.cos(theta), y + size * np.sin(theta)),
        xytext=(x, y),
        arrowprops={"arrowstyle": "->", "color": color, "lw": 1.8},
    )
    ax.annotate(label, (x, y), xytext=(4, -10), textcoords="offset points", fontsize=7, color=color)


def plot_world(
    scene: Scene,
    path: str | os.PathLike[str],
    poses: Sequence[ArrayLike] = (),
    pose_labels: Sequence[str] = (),
    title: str | None = None,
) -> Path:
    """Top view of the world with robot / sensor poses ``(x, y, theta)`` drawn as arrows."""
    fig = new_figure(8, 7)
    ax = fig.add_subplot()
    draw_scene_top(ax, scene)
    for i, pose in enumerate(poses):
        x, y, th = (float(v) for v in np.asarray(pose, dtype=float)[:3])
        _draw_pose(ax, x, y, th, pose_labels[i] if i < len(pose_labels) else f"pose {i}")
    lo, hi = scene.bounds()
    ax.set_xlim(lo[0] - 1, hi[0] + 1)
    ax.set_ylim(lo[1] - 1, hi[1] + 1)
    ax.grid(True, lw=0.3)
    ax.set_title(title or f"world '{scene.name}' ({len(scene)} primitives), top view")
    return save_figure(fig, path)


def plot_scan(
    sim: SimScan, scene: Scene, path: str | os.PathLike[str], title: str = "range scan"
) -> Path:
    """Points of a simulated scan coloured by the ground / obstacle truth.

    Left: top view (world frame) over the scene; right: the range image (elevation rows x
    azimuth columns) and below it the truth label image.
    """
    from matplotlib.colors import ListedColormap

    fig = new_figure(14, 7)
    grid = fig.add_gridspec(2, 2, width_ratios=[1.0, 1.3])
    ax = fig.add_subplot(grid[:, 0])
    draw_scene_top(ax, scene, labels=False, alpha=0.35)
    valid = sim.scan.valid
    # noisy returns, placed in the world
    from navkit.geometry import se3_apply

    pts = se3_apply(sim.T_world_body, sim.scan.points("body")[valid])
    ground = sim.is_ground[valid]
    ax.scatter(
        pts[ground, 0],
        pts[ground, 1],
        s=0.4,
        c=[GROUND_COLOR],
        label="ground (truth)",
        rasterized=True,
    )
    ax.scatter(
        pts[~ground, 0],
        pts[~ground, 1],
        s=0.8,
        c=[OBSTACLE_COLOR],
        label="obstacle (truth)",
        rasterized=True,
    )
    T = sim.T_world_sensor
    _draw_pose(ax, T[0, 3], T[1, 3], float(np.arctan2(T[1, 0], T[0, 0])), "sensor", "b")
    if len(pts):
        span = np.nanpercentile(np.abs(pts[:, :2] - T[:2, 3]), 99) + 2
        ax.set_xlim(T[0, 3] - span, T[0, 3] + span)
        ax.set_ylim(T[1, 3] - span, T[1, 3] + span)
    ax.legend(loc="upper right", fontsize=7, markerscale=8)
    ax.set_title(f"{title}: top view, {int(valid.sum())} returns")
    az = np.degrees(sim.scan.azimuth)
    el = np.degrees(sim.scan.elevation)
    extent = (az[0], az[-1], el[0], el[-1])
    ax1 = fig.add_subplot(grid[0, 1])
    r = sim.scan.ranges.T  # (n_el, n_az), rows = elevation
    vmax = float(np.nanpercentile(r, 98)) if np.isfinite(r).any() else 1.0
    im = ax1.imshow(
        np.ma.masked_invalid(r),
        origin="lower",
        aspect="auto",
        extent=extent,
        cmap=_cmap("viridis", (0.75, 0.75, 0.75)),
        interpolation="nearest",
        vmin=0.0,
        vmax=vmax,
    )
    fig.colorbar(im, ax=ax1, label="range (m)")
    ax1.set_ylabel("elevation (deg)")
    ax1.set_title("range image (grey: no return)")
    ax2 = fig.add_subplot(grid[1, 1], sharex=ax1)
    label = np.where(~valid, 0, np.where(sim.is_ground, 1, 2)).T
    cmap = ListedColormap([(0.75, 0.75, 0.75), GROUND_COLOR, OBSTACLE_COLOR])
    ax2.imshow(
        label,
        origin="lower",
        aspect="auto",
        extent=extent,
        cmap=cmap,
        vmin=0,
        vmax=2,
        interpolation="nearest",
    )
    ax2.set_xlabel("azimuth (deg)")
    ax2.set_ylabel("elevation (deg)")
    ax2.set_title("truth: ground (green) / obstacle (red) / none (grey)")
    return save_figure(fig, path)


def plot_rgbd(sim: SimRGBD, path: str | os.PathLike[str], title: str = "RGB-D camera") -> Path:
    """Colour image, depth image and the per-pixel truth (primitive index)."""
    fig = new_figure(15, 4.4)
    axes = fig.subplots(1, 3)
    axes[0].imshow(sim.frame.color)
    axes[0].set_title(f"{title}: colour")
    d = sim.frame.depth
    vmax = float(np.nanpercentile(d, 98)) if np.isfinite(d).any() else 1.0
    im = axes[1].imshow(
        np.ma.masked_invalid(d), cmap=_cmap("magma", (0.85, 0.85, 0.95)), vmin=0.0, vmax=vmax
    )
    fig.colorbar(im, ax=axes[1], label="depth along z (m)")
    axes[1].set_title("depth (pale: no return)")
    idx = np.ma.masked_less(sim.hit_index, 0)
    axes[2].imshow(idx, cmap="tab20", interpolation="nearest")
    axes[2].set_title("truth: primitive seen per pixel")
    for a in axes:
        a.set_xticks([])
        a.set_yticks([])
    return save_figure(fig, path)


def plot_stereo(sim: SimStereo, path: str | os.PathLike[str], title: str = "stereo pair") -> Path:
    """Left and right rectified images and the true left disparity."""
    fig = new_figure(15, 4.4)
    axes = fig.subplots(1, 3)
    axes[0].imshow(sim.pair.left)
    axes[0].set_title(f"{title}: left")
    axes[1].imshow(sim.pair.right)
    axes[1].set_title(f"right (baseline {sim.pair.rig.baseline:.3f} m)")
    im = axes[2].imshow(
        np.ma.masked_invalid(sim.disparity), cmap=_cmap("turbo", (0.85, 0.85, 0.95))
    )
    fig.colorbar(im, ax=axes[2], label="disparity (px)")
    axes[2].set_title("true left disparity")
    for a in axes:
        a.set_xticks([])
        a.set_yticks([])
    for a in axes[:2]:  # epipolar lines: rows
        for v in np.linspace(0, sim.pair.left.shape[0] - 1, 6)[1:-1]:
            a.axhline(v, color="y", lw=0.5, alpha=0.6)
    return save_figure(fig, path)
