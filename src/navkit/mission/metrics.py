"""The mission's figures, measured against the simulator's truth (``metrics.json``)."""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
from numpy.typing import NDArray

from navkit.geometry import wrap_angle
from navkit.mission.run import MissionLog
from navkit.obstacles.evaluate import score_obstacle_map
from navkit.sim.footprints import room_walls as room_truth
from navkit.sim.footprints import true_footprints

__all__ = ["mission_metrics", "room_truth", "timing_table"]

log = logging.getLogger(__name__)


def _err_stats(err: NDArray[np.float64]) -> dict[str, float]:
    if len(err) == 0:
        return {
            "mean": float("nan"),
            "rms": float("nan"),
            "max": float("nan"),
            "final": float("nan"),
        }
    return {
        "mean": float(err.mean()),
        "rms": float(np.sqrt((err**2).mean())),
        "max": float(err.max()),
        "final": float(err[-1]),
    }


def timing_table(lg: MissionLog) -> dict[str, dict[str, float]]:
    """Per capability: calls, mean and max milliseconds per call, total seconds."""
    out = {}
    for key, vals in lg.timings.items():
        a = np.asarray(vals)
        if len(a) == 0:
            continue
        out[key] = {
            "calls": len(a),
            "mean_ms": float(1e3 * a.mean()),
            "max_ms": float(1e3 * a.max()),
            "total_s": float(a.sum()),
        }
    return out


def _point_segment_distance(
    P: NDArray[np.float64], a: NDArray[np.float64], b: NDArray[np.float64]
) -> NDArray[np.float64]:
    ab = b - a
    t = np.clip((P - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
    return np.hypot(*(a + t[:, None] * ab - P).T)


def _room_metrics(lg: MissionLog) -> dict[str, Any]:
    truth = room_truth(lg.scene, lg.route.room)
    wm = lg.room_map
    out: dict[str, Any] = {
        "views": len(lg.room_views),
        "walls": 0 if wm is None else len(wm.walls),
        "true_walls": len(truth),
    }
    if wm is not None and wm.walls and truth:
        ends = np.array([[w.start, w.end] for w in wm.walls]).reshape(-1, 2)
        d = np.min(np.stack([_point_segment_distance(ends, a, b) for a, b in truth], 1), axis=1)
        out["wall_end_error_mean_m"] = float(d.mean())
        out["wall_end_error_max_m"] = float(d.max())
        # per true wall: the best map wall (both its ends closest to the true wall) - how far
        # off the mapped version of each true wall is; NaN-free since the map has walls
        per_wall = []
        for a, b in truth:
            e = np.stack(
                [_point_segment_distance(np.array([w.start, w.end]), a, b).max() for w in wm.walls]
            )
            per_wall.append(float(e.min()))
        out["true_wall_map_error_m"] = per_wall
        # true corners: end points shared by two true walls
        tc = np.array([q for a, b in truth for q in (a, b)])
        if wm.corners:
            mc = np.array([c.point for c in wm.corners])
            dc = np.min(np.hypot(*(mc[:, None, :] - tc[None]).transpose(2, 0, 1)), axis=1)
            out["corners"] = len(mc)
            out["corner_error_mean_m"] = float(dc.mean())
            out["corner_error_max_m"] = float(dc.max())
    fixes = lg.fixes
    used = [f for f in fixes if f.used]
    out["fixes_attempted"] = len(fixes)
    out["fixes_ok"] = sum(f.ok for f in fixes)
    out["fixes_used"] = len(used)
    if used:
        fe = np.array([np.hypot(*(f.pose[:2] - f.truth[:2])) for f in used])
        be = np.array([np.hypot(*(f.estimate_before[:2] - f.truth[:2])) for f in used])
        he = np.array([abs(float(wrap_angle(f.pose[2] - f.truth[2]))) for f in used])
        out["fix_error_mean_m"] = float(fe.mean())
        out["fix_error_max_m"] = float(fe.max())
        out["fix_heading_error_mean_deg"] = float(np.degrees(he.mean()))
        out["estimate_error_before_fix_mean_m"] = float(be.mean())
    return out


def _plane_metrics(lg: MissionLog) -> dict[str, Any]:
    steps = lg.plane_steps
    out: dict[str, Any] = {"frames": len(steps) + (1 if steps else 0), "pairs": len(steps)}
    if not steps:
        return out
    status = [p.status.split(":")[0] for p in steps]
    out["ok"] = status.count("ok")
    out["gated"] = status.count("gated")
    out["failed"] = status.count("failed")
    out["by_case"] = {
        str(c): sum(1 for p in steps if p.case == c and p.status == "ok") for c in (1, 2, 3)
    }
    ok = [p for p in steps if p.status == "ok"]
    if ok:
        pe = np.array([p.plane_inc - p.true_inc for p in ok])
        ve = np.array([p.vo_inc - p.true_inc for p in ok])
        pe[:, 2] = wrap_angle(pe[:, 2])
        ve[:, 2] = wrap_angle(ve[:, 2])
        out["plane_increment_error_rms_m"] = float(np.sqrt((pe[:, :2] ** 2).sum(1).mean()))
        out["vo_increment_error_rms_m"] = float(np.sqrt((ve[:, :2] ** 2).sum(1).mean()))
        out["plane_increment_heading_error_rms_deg"] = float(
            np.degrees(np.sqrt((pe[:, 2] ** 2).mean()))
        )
        out["vo_increment_heading_error_rms_deg"] = float(
            np.degrees(np.sqrt((ve[:, 2] ** 2).mean()))
        )
    out["map_planes_observed"] = len(lg.plane_points)
    return out


def _fix_stats(fixes: list[Any]) -> dict[str, Any]:
    used = [f for f in fixes if f.used]
    out: dict[str, Any] = {
        "attempted": len(fixes),
        "ok": sum(f.ok for f in fixes),
        "used": len(used),
    }
    if used:
        fe = np.array([np.hypot(*(f.pose[:2] - f.truth[:2])) for f in used])
        be = np.array([np.hypot(*(f.estimate_before[:2] - f.truth[:2])) for f in used])
        out["fix_error_mean_m"] = float(fe.mean())
        out["estimate_error_before_fix_mean_m"] = float(be.mean())
    return out


def mission_metrics(lg: MissionLog) -> dict[str, Any]:
    """All figures of a run (what ``metrics.json`` holds).

    Pose errors are horizontal distances ``|estimate - truth|`` at every control step (metres)
    and wrapped heading differences (degrees); ``raw_vo`` is the dead-reckoned visual odometry,
    ``corrected`` the estimate after plane motions and room fixes.
    """
    s = lg.settings
    out_i = lg.phase == 0
    e_vo = np.hypot(*(lg.vo[:, :2] - lg.truth[:, :2]).T)
    e_est = np.hypot(*(lg.estimate[:, :2] - lg.truth[:, :2]).T)
    h_vo = np.degrees(np.abs(wrap_angle(lg.vo[:, 2] - lg.truth[:, 2])))
    h_est = np.degrees(np.abs(wrap_angle(lg.estimate[:, 2] - lg.truth[:, 2])))
    travelled = float(np.hypot(*np.diff(lg.truth[:, :2], axis=0).T).sum())
    operator = np.asarray(lg.scene.start[:2], dtype=np.float64)
    L = lg.link_lost_index
    pose = {
        "raw_vo_m": _err_stats(e_vo),
        "corrected_m": _err_stats(e_est),
        "raw_vo_outbound_m": _err_stats(e_vo[out_i]),
        "corrected_outbound_m": _err_stats(e_est[out_i]),
        "raw_vo_heading_deg": _err_stats(h_vo),
        "corrected_heading_deg": _err_stats(h_est),
        "raw_vo_at_link_lost_m": float(e_vo[L]) if L >= 0 else float("nan"),
        "corrected_at_link_lost_m": float(e_est[L]) if L >= 0 else float("nan"),
    }
    fps = true_footprints(lg.scene)
    grid = lg.obstacle_grid
    assert grid is not None
    obst = score_obstacle_map(
        grid.grid(),
        fps,
        lg.seen_primitives,
        min_height=0.2,
        robot_width=s.robot.width,
        tolerance=s.obstacle_map.match_tolerance,
    )
    outbound_len = (
        float(np.hypot(*np.diff(lg.truth[: L + 1, :2], axis=0).T).sum()) if L > 0 else float("nan")
    )
    ret = {
        "outcome": lg.outcome,
        "final_distance_to_operator_m": float(np.hypot(*(lg.truth[-1, :2] - operator))),
        "final_estimated_distance_m": float(np.hypot(*(lg.estimate[-1, :2] - operator))),
        "outbound_length_m": outbound_len,
        "return_time_s": float(lg.time[-1] - lg.time[L]) if L >= 0 else float("nan"),
        "blocked": lg.blocked,
        "detours": len(lg.detours),
        "detours_completed": sum(1 for d in lg.detours if d.get("completed_time") is not None),
        "detour_length_m": float(sum(d["length_m"] for d in lg.detours)),
        "detour_list": lg.detours,
    }
    if lg.dropped_obstacle is not None:
        c = np.asarray(lg.dropped_obstacle.center)[:2]
        ret["dropped_obstacle_xy"] = c.tolist()
        ret["stopped_distance_to_dropped_obstacle_m"] = float(np.hypot(*(lg.truth[-1, :2] - c)))
    return {
        "scene": lg.scene.name,
        "seed": s.seed,
        "simulated_time_s": float(lg.time[-1]),
        "distance_travelled_m": travelled,
        "control_steps": len(lg.time),
        "pose_error": pose,
        "obstacles": obst,
        "planes": _plane_metrics(lg),
        "room": _room_metrics(lg),
        "obstacle_map_fixes": _fix_stats(lg.map_fixes),
        "path": lg.path_summary,
        "return": ret,
        "timing": timing_table(lg),
    }
