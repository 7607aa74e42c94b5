"""Figures and the one-page report of a mission run (``report.html``).

Every figure is a top-down view in the world frame (metres, x east, y north) or a time plot;
truth is drawn in black / grey, what the robot built in colour.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "figure_errors",
    "figure_obstacles",
    "figure_planes",
    "figure_room",
    "figure_trajectories",
    "write_report",
]

log = logging.getLogger(__name__)


CAPABILITY_NAMES = {
    # the report's labels of the mission's timing keys
    "obstacles_detect": "obstacles: detection per scan (paper 1)",
    "obstacles_fuse": "obstacles: fusion into the 2D map",
    "planes_extract": "planes: extraction per RGB-D frame (paper 2)",
    "planes_motion": "planes: motion between frames (paper 2)",
    "room_map": "room map: build on the first visit (paper 3)",
    "localize": "localization: correlation fix in the room map (paper 3)",
    "localize_obstacle_map": "localization: correlation fix in the obstacle map (return)",
    "obstacle_map_field": "localization: obstacle map -> likelihood field (once)",
    "sim_stereo": "simulator: render a stereo pair",
    "stereo_points": "stereo: disparity -> wall points (paper 3)",
    "path_record": "path memory: add one point (paper 4)",
    "path_finish": "path memory: finish",
    "return_control": "return: one control cycle (paper 4)",
    "block_check": "return: check the map ahead",
    "detour_plan": "return: plan a way round a block (detour)",
    "sim_lidar": "simulator: render a lidar scan",
    "sim_camera": "simulator: render an RGB-D frame",
}


def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _footprints(ax: Any, footprints: list[Any], **kw: Any) -> None:
    from matplotlib.patches import Polygon

    for f in footprints:
        ax.add_patch(Polygon(f.polygon, closed=True, **kw))


def _finish(ax: Any, title: str) -> None:
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title)
    ax.grid(alpha=0.3)


def figure_obstacles(lg: Any, score: dict[str, Any]) -> Any:
    """World with the true obstacles (left) and the fused obstacle map, found vs phantom (right)."""
    from navkit.sim.footprints import true_footprints

    plt = _plt()
    fps = true_footprints(lg.scene)
    grid = lg.obstacle_grid
    fig, axes = plt.subplots(1, 2, figsize=(15, 7.2), sharex=True, sharey=True)
    ax = axes[0]
    low = [f for f in fps if f.height < 0.2]
    high = [f for f in fps if f.height >= 0.2]
    _footprints(ax, low, facecolor="#d9d4c7", edgecolor="#a8a293", lw=0.8)
    _footprints(ax, high, facecolor="#6b6f7a", edgecolor="k", lw=0.8)
    for f in high:
        if f.kind != "wall":
            c = f.polygon.mean(0)
            ax.annotate(f.name, c, xytext=(4, 4), textcoords="offset points", fontsize=7)
    ax.plot(*lg.truth[:, :2].T, color="k", lw=1.0, label="true trajectory")
    if lg.route.room is not None:
        x0, y0, x1, y1 = lg.route.room
        ax.plot(
            [x0, x1, x1, x0, x0],
            [y0, y0, y1, y1, y0],
            ls=":",
            color="tab:purple",
            lw=1,
            label="room",
        )
    ax.plot(*lg.scene.start[:2], marker="*", ms=14, color="gold", mec="k", ls="", label="operator")
    ax.legend(loc="upper left", fontsize=8)
    _finish(ax, f"world '{lg.scene.name}': true obstacles (dark) and curb/sidewalk (light)")
    ax = axes[1]
    _footprints(ax, high, facecolor="none", edgecolor="k", lw=0.8)
    labels, _ = grid.components()
    matched = {c["id"]: c["matches"] is not None for c in score["component_list"]}
    img = np.zeros((*labels.shape, 4))
    seen = grid.seen > 0
    img[seen] = (0.92, 0.94, 0.97, 1.0)
    good = np.isin(labels, [k for k, v in matched.items() if v])
    bad = np.isin(labels, [k for k, v in matched.items() if not v])
    img[good] = (0.85, 0.15, 0.1, 1.0)
    img[bad] = (0.1, 0.45, 0.95, 1.0)
    h, w = labels.shape
    r = grid.resolution
    ext = (grid.origin[0], grid.origin[0] + w * r, grid.origin[1], grid.origin[1] + h * r)
    ax.imshow(img, origin="lower", extent=ext, interpolation="nearest", zorder=0)
    ax.plot(*lg.estimate[:, :2].T, color="tab:green", lw=0.8, label="estimated trajectory")
    from matplotlib.patches import Patch

    ax.legend(
        handles=[
            Patch(color=(0.85, 0.15, 0.1), label="found (matches a true obstacle)"),
            Patch(color=(0.1, 0.45, 0.95), label="phantom"),
            Patch(color=(0.92, 0.94, 0.97), label="observed"),
            Patch(facecolor="none", edgecolor="k", label="true outline"),
        ],
        loc="upper left",
        fontsize=8,
    )
    _finish(
        ax,
        f"fused obstacle map: recall {score['recall']:.2f}, precision {score['precision']:.2f}, "
        f"{score['phantoms']} phantoms",
    )
    rows, cols = np.nonzero(seen)
    if len(rows):  # the observed area, with a margin
        C = grid.centres(rows, cols)
        lo, hi = C.min(0) - 1.0, C.max(0) + 1.0
    else:
        lo, hi = grid.origin, grid.origin + np.array([w, h]) * r
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    fig.tight_layout()
    return fig


def figure_trajectories(lg: Any) -> Any:
    """Truth, raw VO, corrected estimate, stored spline, and the return."""
    from navkit.sim.footprints import true_footprints

    plt = _plt()
    fig, ax = plt.subplots(figsize=(12, 7.5))
    _footprints(
        ax,
        [f for f in true_footprints(lg.scene) if f.height >= 0.2],
        facecolor="#c9ccd3",
        edgecolor="#8a8f99",
        lw=0.6,
    )
    out = lg.phase == 0
    ax.plot(*lg.truth[out, :2].T, color="k", lw=1.6, label="truth (outbound)")
    ax.plot(*lg.truth[~out, :2].T, color="k", lw=1.6, ls="--", label="truth (return)")
    ax.plot(*lg.vo[:, :2].T, color="tab:red", lw=1.0, label="raw visual odometry")
    ax.plot(*lg.estimate[:, :2].T, color="tab:green", lw=1.0, label="corrected estimate")
    if lg.path is not None and lg.path.n_segments:
        _, xy = lg.path.sample(0.05)
        ax.plot(
            *xy.T,
            color="tab:orange",
            lw=2.2,
            alpha=0.7,
            label=f"stored spline ({lg.path.n_segments} segments)",
        )
        ax.plot(*lg.path.knots.T, "o", color="tab:orange", ms=4)
    ax.plot(*lg.scene.start[:2], marker="*", ms=16, color="gold", mec="k", ls="", label="operator")
    ax.plot(*lg.truth[-1, :2], marker="X", ms=11, color="k", ls="", label="robot at the end")
    if lg.link_lost_index >= 0:
        ax.plot(
            *lg.truth[lg.link_lost_index, :2],
            marker="v",
            ms=10,
            color="tab:purple",
            ls="",
            label="link lost",
        )
    if lg.dropped_obstacle is not None:
        from navkit.sim.footprints import footprint

        poly = footprint(lg.dropped_obstacle).polygon  # type: ignore[union-attr]
        ax.fill(*poly.T, color="tab:blue", alpha=0.6, label="obstacle dropped on the way back")
    for i, (pts, d) in enumerate(zip(lg.detour_paths, lg.detours, strict=True)):
        # the detour as first planned (estimate frame), and where it rejoined the stored path
        ax.plot(
            *pts.T,
            "-o",
            color="tab:pink",
            lw=2.0,
            ms=4,
            label="detour round the block (first plan)" if i == 0 else None,
        )
        ax.plot(
            *d["rejoin_xy"],
            marker="D",
            ms=8,
            color="tab:pink",
            mec="k",
            ls="",
            label="rejoin point" if i == 0 else None,
        )
    if lg.outcome == "blocked" and lg.blocked is not None:
        ax.plot(
            *lg.blocked["blocked_path_point_xy"],
            marker="x",
            ms=12,
            mew=3,
            color="tab:red",
            ls="",
            label="blocked, no detour",
        )
    ax.legend(loc="best", fontsize=8)
    _finish(ax, "trajectories")
    fig.tight_layout()
    return fig


def figure_errors(lg: Any) -> Any:
    """Position and heading error along the mission: raw VO vs corrected estimate."""
    plt = _plt()
    e_vo = np.hypot(*(lg.vo[:, :2] - lg.truth[:, :2]).T)
    e_est = np.hypot(*(lg.estimate[:, :2] - lg.truth[:, :2]).T)
    wrap = lambda a: np.angle(np.exp(1j * a))  # noqa: E731
    h_vo = np.degrees(np.abs(wrap(lg.vo[:, 2] - lg.truth[:, 2])))
    h_est = np.degrees(np.abs(wrap(lg.estimate[:, 2] - lg.truth[:, 2])))
    fig, axes = plt.subplots(2, 1, figsize=(11, 6), sharex=True)
    for ax, a, b, unit in (
        (axes[0], e_vo, e_est, "position error (m)"),
        (axes[1], h_vo, h_est, "heading error (deg)"),
    ):
        ax.plot(lg.time, a, color="tab:red", label="raw VO")
        ax.plot(lg.time, b, color="tab:green", label="corrected")
        ax.set_ylabel(unit)
        ax.grid(alpha=0.3)
        if lg.link_lost_index >= 0:
            ax.axvline(lg.time[lg.link_lost_index], color="tab:purple", ls=":", label="link lost")
        used = [f.time for f in lg.fixes if f.used]
        if used:
            ax.plot(
                used, np.interp(used, lg.time, b), "|", color="tab:blue", ms=8, label="room fix"
            )
        mused = [f.time for f in lg.map_fixes if f.used]
        if mused:
            ax.plot(
                mused,
                np.interp(mused, lg.time, b),
                "|",
                color="tab:orange",
                ms=8,
                label="obstacle-map fix",
            )
    axes[0].legend(fontsize=8)
    axes[1].set_xlabel("time (s)")
    axes[0].set_title("pose error against the truth")
    fig.tight_layout()
    return fig


def figure_planes(lg: Any) -> Any:
    """The plane map: planes seen by the RGB-D camera, placed with the corrected estimate."""
    from navkit.sim.footprints import true_footprints

    plt = _plt()
    fig, ax = plt.subplots(figsize=(12, 6.5))
    walls = [f for f in true_footprints(lg.scene) if f.height >= 0.2]
    _footprints(ax, walls, facecolor="none", edgecolor="k", lw=0.6)
    if lg.plane_points:
        for P, n in zip(lg.plane_points, lg.plane_normals, strict=True):
            vertical = abs(n[2]) < 0.5
            ax.plot(
                P[:, 0],
                P[:, 1],
                ".",
                ms=1.2,
                alpha=0.5,
                color="tab:blue" if vertical else "tab:olive",
            )
    ax.plot([], [], ".", color="tab:blue", label="vertical planes (walls, faces)")
    ax.plot([], [], ".", color="tab:olive", label="horizontal planes (ground, tops)")
    ax.plot(
        *lg.estimate[lg.phase == 0, :2].T, color="tab:green", lw=0.8, label="corrected estimate"
    )
    ax.legend(fontsize=8, loc="best")
    _finish(ax, f"plane map: {len(lg.plane_points)} plane observations (outbound)")
    fig.tight_layout()
    return fig


def figure_room(lg: Any) -> Any:
    """The room map from the first visit (walls, corners) against the truth, and the fixes."""
    from navkit.sim.footprints import room_walls

    plt = _plt()
    fig, ax = plt.subplots(figsize=(9, 8))
    for a, b in room_walls(lg.scene, lg.route.room):
        ax.plot([a[0], b[0]], [a[1], b[1]], color="k", lw=3, alpha=0.5)
    ax.plot([], [], color="k", lw=3, alpha=0.5, label="true walls")
    wm = lg.room_map
    for v, p in lg.room_views:
        c, s = np.cos(p[2]), np.sin(p[2])
        W = v @ np.array([[c, s], [-s, c]]) + p[:2]
        ax.plot(*W.T, ".", ms=1, color="tab:gray", alpha=0.4)
    if wm is not None:
        for w in wm.walls:
            ax.plot([w.start[0], w.end[0]], [w.start[1], w.end[1]], color="tab:blue", lw=1.6)
        ax.plot([], [], color="tab:blue", label=f"map walls ({len(wm.walls)})")
        if wm.corners:
            C = np.array([c.point for c in wm.corners])
            ax.plot(*C.T, "s", color="tab:blue", mfc="none", ms=8, label="map corners")
    if lg.fixes:
        F = np.array([f.pose for f in lg.fixes if f.used]).reshape(-1, 3)
        Tr = np.array([f.truth for f in lg.fixes if f.used]).reshape(-1, 3)
        ax.plot(*F[:, :2].T, "+", color="tab:red", ms=7, label="localization fixes")
        ax.plot(*Tr[:, :2].T, ".", color="k", ms=3, label="true pose at the fix")
    room = lg.route.room
    if room is not None:
        ax.set_xlim(room[0] - 1.5, room[2] + 1.5)
        ax.set_ylim(room[1] - 1.5, room[3] + 1.5)
    ax.plot(*lg.estimate[:, :2].T, color="tab:green", lw=0.6, label="corrected estimate")
    ax.legend(fontsize=8, loc="best")
    _finish(ax, "room map (first visit) and correlation fixes")
    fig.tight_layout()
    return fig


def _fmt(v: Any) -> Any:
    if isinstance(v, float):
        return v if np.isfinite(v) else "n/a"
    return v


def write_report(lg: Any, metrics: dict[str, Any], path: str | Path) -> Path:
    """Write ``report.html``: the figures above and the table of the mission's figures."""
    from navkit.viz.report import Report

    m = metrics
    pe, ob, pl, rm, ret = m["pose_error"], m["obstacles"], m["planes"], m["room"], m["return"]
    rep = Report(
        f"navkit mission - {m['scene']}",
        f"seed {m['seed']}, {m['simulated_time_s']:.0f} s simulated, {m['distance_travelled_m']:.1f} m "
        f"driven; outcome: {ret['outcome']}",
    )
    rep.section("Figures of the mission")
    rows = [
        ("final distance to the operator (truth)", "m", _fmt(ret["final_distance_to_operator_m"])),
        ("outbound route length", "m", _fmt(ret["outbound_length_m"])),
        (
            "position error, raw VO: mean / max",
            "m",
            f"{pe['raw_vo_m']['mean']:.3f} / {pe['raw_vo_m']['max']:.3f}",
        ),
        (
            "position error, corrected: mean / max",
            "m",
            f"{pe['corrected_m']['mean']:.3f} / {pe['corrected_m']['max']:.3f}",
        ),
        (
            "heading error, raw VO / corrected: mean",
            "deg",
            f"{pe['raw_vo_heading_deg']['mean']:.2f} / {pe['corrected_heading_deg']['mean']:.2f}",
        ),
        (
            "position error at link lost, raw VO / corrected",
            "m",
            f"{pe['raw_vo_at_link_lost_m']:.3f} / {pe['corrected_at_link_lost_m']:.3f}",
        ),
        (
            "obstacle recall (all seen / larger than the robot)",
            "",
            f"{ob['recall']:.3f} / {ob['recall_larger_than_robot']:.3f}",
        ),
        ("obstacle precision", "", _fmt(ob["precision"])),
        ("phantom obstacles", "", ob["phantoms"]),
        (
            "obstacle map error (cells to true outline): median / p95",
            "m",
            f"{ob['cell_error_median_m']:.3f} / {ob['cell_error_p95_m']:.3f}",
        ),
        (
            "plane motions used (geometry / texture)",
            "",
            f"{pl.get('by_case', {}).get('3', 0)} / {pl.get('by_case', {}).get('1', 0) + pl.get('by_case', {}).get('2', 0)}"
            f" of {pl.get('pairs', 0)}",
        ),
        (
            "increment error per frame, planes / VO (position)",
            "m",
            f"{pl.get('plane_increment_error_rms_m', float('nan')):.4f} / {pl.get('vo_increment_error_rms_m', float('nan')):.4f}",
        ),
        (
            "increment error per frame, planes / VO (heading)",
            "deg",
            f"{pl.get('plane_increment_heading_error_rms_deg', float('nan')):.3f} / "
            f"{pl.get('vo_increment_heading_error_rms_deg', float('nan')):.3f}",
        ),
        (
            "room map: walls / corner error mean",
            "m",
            f"{rm.get('walls', 0)} / {rm.get('corner_error_mean_m', float('nan')):.3f}",
        ),
        (
            "room fixes used / attempted",
            "",
            f"{rm.get('fixes_used', 0)} / {rm.get('fixes_attempted', 0)}",
        ),
        ("fix error vs truth: mean", "m", _fmt(rm.get("fix_error_mean_m", float("nan")))),
        (
            "return: obstacle-map fixes used / attempted",
            "",
            f"{m['obstacle_map_fixes']['used']} / {m['obstacle_map_fixes']['attempted']}",
        ),
        (
            "stored path: segments / length / max deviation",
            "m",
            f"{m['path'].get('segments', 0)} / {m['path'].get('length_m', float('nan')):.2f} / "
            f"{m['path'].get('max_deviation_m', float('nan')):.3f}",
        ),
    ]
    if ret.get("blocked"):
        b = ret["blocked"]
        rows.append(
            ("return: stops for an obstacle ahead (cleared or not)", "", int(b.get("stops", 1)))
        )
        if ret["outcome"] == "blocked":
            rows.append(("return blocked: obstacle ahead at", "m", _fmt(b.get("distance_ahead_m"))))
            rows.append(("return blocked: why it stopped", "", str(b.get("detour", ""))))
    if ret.get("detours"):
        rows.append(
            (
                "return: detours round a block (completed) / planned length",
                "m",
                f"{ret['detours']} ({ret['detours_completed']}) / {ret['detour_length_m']:.2f}",
            )
        )
    if "stopped_distance_to_dropped_obstacle_m" in ret:
        rows.append(
            (
                "ended at, from the dropped obstacle's centre",
                "m",
                _fmt(ret["stopped_distance_to_dropped_obstacle_m"]),
            )
        )
    rep.add_table("", rows, header=("figure", "unit", "value"))
    rep.section("Trajectories")
    rep.add_figure(
        figure_trajectories(lg),
        "Truth, raw visual odometry, corrected estimate, the stored spline "
        "(paper 4) and the return.",
    )
    rep.add_figure(figure_errors(lg), "Position and heading error along the mission.")
    rep.section("Obstacles")
    rep.add_figure(
        figure_obstacles(lg, ob),
        "Left: the world and its true obstacles. Right: the 2D obstacle "
        "map fused from every lidar scan (paper 1) with the pose estimate.",
    )
    orows = [
        (
            o["name"],
            o["kind"],
            o["extent_m"],
            o["height_m"],
            "yes" if o["seen"] else "no",
            "yes" if o["found"] else "NO",
        )
        for o in ob["obstacles"]
    ]
    rep.add_table(
        "True obstacles",
        orows,
        header=("name", "kind", "extent (m)", "height (m)", "in view", "found"),
    )
    rep.section("Plane map")
    rep.add_figure(figure_planes(lg), _plane_caption(m["planes"]))
    rep.section("Room map and localization")
    rep.add_figure(figure_room(lg), _room_caption(m["room"]))
    rep.section("Time per step of each capability")
    trows = [
        (CAPABILITY_NAMES.get(k, k), v["calls"], v["mean_ms"], v["max_ms"], v["total_s"])
        for k, v in m["timing"].items()
    ]
    rep.add_table("", trows, header=("step", "calls", "mean (ms)", "max (ms)", "total (s)"))
    return rep.write(path)


def _plane_caption(p: dict[str, Any]) -> str:
    """What the plane map compares, with its figures."""
    text = (
        "Planes extracted from the RGB-D frames (paper 2), placed with the corrected estimate; "
        "compared with the true outlines (black)."
    )
    if p.get("pairs"):
        text += f" {p.get('ok', 0)} of {p['pairs']} frame pairs gave a plane motion"
        if "plane_increment_error_rms_m" in p:
            text += (
                f": increment error RMS {100 * p['plane_increment_error_rms_m']:.1f} cm against "
                f"{100 * p['vo_increment_error_rms_m']:.1f} cm for raw visual odometry"
            )
        text += "."
    return text


def _room_caption(r: dict[str, Any]) -> str:
    """What the room map compares, with its figures."""
    text = (
        "Room walls and corners mapped on the first visit (paper 3), compared with the true "
        "walls (black), and the correlation fixes against that map."
    )
    if "corner_error_mean_m" in r:
        text += (
            f" {r.get('walls', 0)} walls for {r.get('true_walls', 0)} true ones; corner error "
            f"mean {100 * r['corner_error_mean_m']:.1f} cm."
        )
    if r.get("fixes_attempted"):
        text += f" {r['fixes_used']} of {r['fixes_attempted']} fixes used"
        if "fix_error_mean_m" in r:
            text += f", mean error {100 * r['fix_error_mean_m']:.1f} cm against the truth"
        text += "."
    return text
