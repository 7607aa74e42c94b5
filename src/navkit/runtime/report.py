"""A picture of a ``results.mcap``: what a viewer would show, drawn top-down with matplotlib."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["render_results"]

CLASS_RGB = {0: "#3cb44b", -1: "#969696", -2: "#e6194b", -3: "#f58231", -4: "#911eb4"}
CLASS_NAMES = {
    0: "ground",
    -1: "unreliable",
    -2: "obstacle",
    -3: "side shadow",
    -4: "shadow behind",
}


def _grid_image(msg: Any) -> tuple[np.ndarray, list[float]]:
    info = msg.info
    occ = np.asarray(msg.data, dtype=np.int8).reshape(info.height, info.width)
    img = np.full(occ.shape, 1.0)
    img[occ == 0] = 0.92
    img[occ == 100] = 0.25
    x0, y0 = info.origin.position.x, info.origin.position.y
    ext = [x0, x0 + info.width * info.resolution, y0, y0 + info.height * info.resolution]
    return img, ext


def render_results(
    mcap: str | os.PathLike[str],
    png: str | os.PathLike[str] | None,
    *,
    ax: Any = None,
    title: str = "",
    cloud_index: int = 0,
    max_points: int = 40000,
    extent_m: float | None = None,
    shapes: tuple[str, ...] = ("A1", "A6"),
) -> Path | None:
    """Draw a results MCAP top-down: occupancy grids, the ``cloud_index``-th classified cloud
    (coloured by class), outlines (the bounding ``shapes`` named, walls, planes), paths and poses.

    With ``ax`` the drawing goes into that axes (``png`` may be None); else into ``png``.
    Frames are not chained: each item is drawn in its own frame's coordinates (right for the
    first lidar frame of a recording whose world frame is that frame, as for KITTI's poses).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from navkit.io.results_mcap import read_messages

    grids: dict[str, Any] = {}
    clouds: list[Any] = []
    markers: dict[str, Any] = {}
    paths: dict[str, Any] = {}
    poses: dict[str, list[tuple[float, float]]] = {}
    for m in read_messages(mcap):
        if m.msgtype.endswith("OccupancyGrid"):
            grids[m.topic] = m.message
        elif m.msgtype.endswith("PointCloud2"):
            if len(clouds) <= cloud_index:
                clouds.append(m.message)
        elif m.msgtype.endswith("MarkerArray"):
            # per-frame shapes: those of the drawn cloud; maps (walls): the last
            if "obstacles" not in m.topic or len(clouds) == cloud_index + 1:
                markers.setdefault(m.topic, m.message)
                if "obstacles" not in m.topic:
                    markers[m.topic] = m.message
        elif m.msgtype.endswith("/Path"):
            paths[m.topic] = m.message
        elif m.msgtype.endswith("PoseWithCovarianceStamped"):
            p = m.message.pose.pose.position
            poses.setdefault(m.topic, []).append((p.x, p.y))
        elif m.msgtype.endswith("PoseStamped"):
            p = m.message.pose.position
            poses.setdefault(m.topic, []).append((p.x, p.y))
    own = ax is None
    if own:
        fig, ax = plt.subplots(figsize=(8, 8))
    for g in grids.values():
        img, ext = _grid_image(g)
        ax.imshow(
            img, origin="lower", extent=ext, cmap="gray", vmin=0, vmax=1, interpolation="nearest"
        )
    if len(clouds) > cloud_index:
        c = clouds[cloud_index]
        rec = np.frombuffer(
            bytes(c.data),
            dtype=np.dtype(
                {
                    "names": ["x", "y", "class"],
                    "formats": ["<f4", "<f4", "i1"],
                    "offsets": [0, 4, 12],
                    "itemsize": int(c.point_step),
                }
            ),
        )
        step = max(1, len(rec) // max_points)
        rec = rec[::step]
        for k, col in CLASS_RGB.items():
            sel = rec["class"] == k
            if sel.any():
                ax.scatter(
                    rec["x"][sel],
                    rec["y"][sel],
                    s=0.3,
                    c=col,
                    label=CLASS_NAMES[k],
                    rasterized=True,
                )
    from matplotlib.collections import LineCollection

    from navkit.runtime.capabilities import A7_COLOR, SHAPE_COLORS

    keep = [SHAPE_COLORS[n] for n in shapes if n in SHAPE_COLORS]
    keep += [A7_COLOR] if "A7" in shapes else []
    for topic, arr in markers.items():
        for mk in arr.markers:
            if mk.action == 3 or not len(mk.points):
                continue
            if mk.type == 5:  # LINE_LIST: segment ends in pairs, a colour per vertex
                P = np.array([[p.x, p.y] for p in mk.points]).reshape(-1, 2, 2)
                C = np.array([[c.r, c.g, c.b, c.a] for c in mk.colors]).reshape(-1, 2, 4)[:, 0]
                if mk.ns == "shape":  # the bounding shapes named, by their colours
                    sel = np.zeros(len(C), bool)
                    for rgba in keep:
                        sel |= np.all(np.isclose(C, rgba, atol=1e-6), axis=1)
                    P, C = P[sel], C[sel]
                lw = 0.8 if "walls" in topic else 1.0
                ax.add_collection(LineCollection(list(P), colors=C[:, :3], linewidths=lw))
                continue
            if mk.ns.startswith("shape/") and mk.ns[len("shape/") :] not in shapes:
                continue
            P = np.array([[p.x, p.y] for p in mk.points])
            ax.plot(
                P[:, 0],
                P[:, 1],
                "-",
                lw=0.8 if "walls" in topic else 1.0,
                color=(mk.color.r, mk.color.g, mk.color.b),
            )
    for k, (topic, pth) in enumerate(paths.items()):
        P = np.array([[q.pose.position.x, q.pose.position.y] for q in pth.poses])
        if len(P):
            name = "stored path" if topic == "/navkit/path" else "path"
            color = "#0078ff" if k == 0 else "#00c8ff"
            ax.plot(P[:, 0], P[:, 1], "-", color=color, lw=1.5, label=f"{topic} ({name})")
    palette = ("#ff00aa", "#00a0a0", "#ff8c00", "#6a3d9a", "#8c564b")
    for k, (topic, xy) in enumerate(poses.items()):
        P = np.array(xy)
        ax.plot(P[:, 0], P[:, 1], ".", ms=3, color=palette[k % len(palette)], label=topic)
    if extent_m is not None:
        ax.set_xlim(-extent_m, extent_m)
        ax.set_ylim(-extent_m, extent_m)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title or Path(mcap).parent.name)
    ax.legend(loc="upper right", fontsize=7, markerscale=8)
    out = Path(png) if png is not None else None
    if own and out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=110, bbox_inches="tight")
        plt.close(fig)
    return out
