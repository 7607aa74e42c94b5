"""Stereo room maps and localization in simulated rooms (paper 3).

Simulated rooms: rendered stereo pairs (320 x 240, 90 deg, b = 0.2 m, camera 1.2 m high) of the four
test rooms; the map from the survey views with known poses (wall angle error, corner error); then
random poses: each localization turns the camera through 4 headings 90 deg apart (relative angles
known from the drive's angle sensor, as in paper 3) and matches the combined fragment globally
(success also counted up to the half-turn symmetry of the rectangle-based rooms) and from a coarse
prior (uniform error up to 0.5 m / 10 deg).
"""

from __future__ import annotations

import numpy as np

from benchmarks.bench_localization import SUCCESS_DEG, SUCCESS_M, _err
from benchmarks.common import Row


def sim_rooms(
    n_poses: int = 100, width: int = 320, seed: int = 0, kinds: tuple[str, ...] | None = None
) -> dict[str, dict[str, float]]:
    """Map accuracy and localization statistics in the simulated rooms (see the module docstring)."""
    from navkit.geometry import se2_apply, se2_from_xytheta
    from navkit.localization import build_map, evaluate_map, match_scan
    from navkit.sensors import PinholeCamera, StereoRig
    from navkit.sim import render_stereo, scene_from_dict
    from navkit.stereo import planar_camera_pose, stereo_wall_points
    from navkit.stereo.rooms import ROOM_KINDS, room, sample_poses

    rig = StereoRig(PinholeCamera.from_fov(width, width * 3 // 4, 90.0), 0.2)
    height = 1.2
    out: dict[str, dict[str, float]] = {}
    for kind in kinds or ROOM_KINDS:
        truth = room(kind)
        scene = scene_from_dict(truth.scene)
        rng = np.random.default_rng(seed)

        def render(pose, scene=scene, rng=rng):  # type: ignore[no-untyped-def]
            T = planar_camera_pose(*pose, height)
            return render_stereo(scene, rig, T, rng=rng, pixel_noise=1.0, supersample=1), T

        views = []
        for pose in truth.survey:
            st, T = render(pose)
            views.append(stereo_wall_points(st.pair.left, st.pair.right, rig, T_world_camera=T))
        m = build_map(views)
        acc = evaluate_map(m, truth.walls, truth.corners)
        fld = m.likelihood_field(0.1)
        poses = sample_poses(truth, n_poses, rng)
        pe, he, ok, ms, single = [], [], [], [], []
        twin_ok: list[bool] = []
        tpe: list[float] = []
        the: list[float] = []
        tms: list[float] = []
        for p in poses:
            parts = []
            for k in range(4):
                st, _ = render(p + np.array([0.0, 0.0, k * np.pi / 2]))
                B = stereo_wall_points(st.pair.left, st.pair.right, rig, camera_height=height)
                parts.append(se2_apply(se2_from_xytheta(0.0, 0.0, k * np.pi / 2), B))
                if k == 0 and len(B) >= 3:
                    f1 = match_scan(fld, B, None)
                    single.append(np.hypot(*(f1.pose[:2] - p[:2])))
            frag = np.concatenate(parts)
            fix = match_scan(fld, frag, None)
            e_p, e_h = _err(fix.pose[None], p[None])
            pe.append(e_p[0])
            he.append(e_h[0])
            ok.append(fix.ok)
            ms.append(1e3 * fix.seconds)
            # the half-turn twin of the pose (the rectangle-based rooms are symmetric)
            centre = 0.5 * (truth.outline.min(axis=0) + truth.outline.max(axis=0))
            twin = np.array([*(2 * centre - p[:2]), p[2] + np.pi])
            t_p, t_h = _err(fix.pose[None], twin[None])
            twin_ok.append(bool(t_p[0] <= SUCCESS_M and t_h[0] <= SUCCESS_DEG))
            # tracking from a coarse prior (uniform error up to 0.5 m / 10 deg)
            prior = p + rng.uniform(-1, 1, 3) * np.array([0.5, 0.5, np.radians(10)])
            tf = match_scan(fld, frag, prior)
            k_p, k_h = _err(tf.pose[None], p[None])
            tpe.append(k_p[0])
            the.append(k_h[0])
            tms.append(1e3 * tf.seconds)
        pe_a, he_a, ok_a = np.array(pe), np.array(he), np.array(ok)
        succ = (pe_a <= SUCCESS_M) & (he_a <= SUCCESS_DEG)
        good = pe_a[succ]
        out[kind] = {
            "size_m": float(truth.size),
            **{
                key: float(acc[key])  # type: ignore[arg-type]
                for key in (
                    "walls_found",
                    "walls_true",
                    "walls_in_map",
                    "corners_found",
                    "corners_true",
                    "wall_angle_error_deg_median",
                    "wall_angle_error_deg_max",
                    "corner_error_m_median",
                    "corner_error_m_max",
                )
            },
            "poses": n_poses,
            "success_rate": float(succ.mean()),
            "confident_rate": float(ok_a.mean()),
            "false_confident_rate": float((ok_a & ~succ).mean()),
            "error_m_median": float(np.median(pe_a)),
            "error_m_p95": float(np.percentile(pe_a, 95)),
            "error_m_median_of_successes": float(np.median(good)) if len(good) else float("nan"),
            "error_relative_median": float(np.median(pe_a)) / truth.size,
            "heading_error_deg_median": float(np.median(he_a)),
            "ms_per_fix_median": float(np.median(ms)),
            "single_view_success_rate": float(np.mean(np.array(single) <= SUCCESS_M))
            if single
            else float("nan"),
            "success_rate_up_to_symmetry": float((succ | np.array(twin_ok)).mean()),
            "tracking_success_rate": float(
                ((np.array(tpe) <= SUCCESS_M) & (np.array(the) <= SUCCESS_DEG)).mean()
            ),
            "tracking_error_m_median": float(np.median(tpe)),
            "tracking_error_m_p95": float(np.percentile(tpe, 95)),
            "tracking_error_relative_median": float(np.median(tpe)) / truth.size,
            "tracking_ms_per_fix_median": float(np.median(tms)),
        }
    return out


def run(quick: bool = False) -> list[Row]:
    rows: list[Row] = []
    stats = sim_rooms(
        n_poses=10 if quick else 100, kinds=("rectangle", "lshape") if quick else None
    )
    for kind, s in stats.items():
        rows += [
            Row(
                "localization",
                f"sim {kind}: corner error median / max",
                "m",
                s["corner_error_m_median"],
                None,
                "",
                None,
                f"max {s['corner_error_m_max']:.3f} m; {s['corners_found']:.0f}/{s['corners_true']:.0f} corners, "
                f"{s['walls_found']:.0f}/{s['walls_true']:.0f} walls ({s['walls_in_map']:.0f} in map), "
                f"angle error median {s['wall_angle_error_deg_median']:.2f} deg",
            ),
            Row(
                "localization",
                f"sim {kind}: success (4-view turn, global)",
                "%",
                100 * s["success_rate"],
                None,
                "",
                None,
                f"{s['poses']} poses; single 90-deg view {100 * s['single_view_success_rate']:.0f} %",
            ),
            Row(
                "localization",
                f"sim {kind}: tracking success (prior 0.5 m / 10 deg)",
                "%",
                100 * s["tracking_success_rate"],
                None,
                "",
                None,
                f"median error {100 * s['tracking_error_m_median']:.1f} cm = "
                f"{100 * s['tracking_error_relative_median']:.2f} % of the diagonal, p95 "
                f"{100 * s['tracking_error_m_p95']:.1f} cm; global success up to the room's symmetry "
                f"{100 * s['success_rate_up_to_symmetry']:.0f} %",
            ),
            Row(
                "localization",
                f"sim {kind}: position error median / p95",
                "m",
                s["error_m_median"],
                None,
                "",
                None,
                f"p95 {s['error_m_p95']:.3f} m; median {100 * s['error_relative_median']:.2f} % of the {s['size_m']:.1f} m diagonal; "
                f"{1e0 * s['ms_per_fix_median']:.0f} ms per fix",
            ),
        ]
    return rows
