"""Localization: navkit's correlative matcher vs a point-to-point ICP baseline on real laser logs,
and the stereo map + localization evaluation in simulated rooms.

Real logs (``../shared/data/laser2d``): for each log the map is built from every 2nd scan with the
corrected poses; then scans spread over the log are localized (a) *tracking*: from a prior = the
corrected pose disturbed by a uniform error of up to 0.5 m and 10 deg (the same prior for both
methods), navkit ``match_scan`` vs point-to-point ICP (nearest neighbours by ``scipy.spatial.cKDTree``
on the same map points, up to 50 iterations, correspondences beyond a shrinking gate rejected);
(b) *global*: navkit without prior (ICP cannot). Success = within 0.3 m and 5 deg of the corrected
pose. Figures: success %, median error, ms per fix (median).

Simulated rooms: rendered stereo pairs (320 x 240, 90 deg, b = 0.2 m, camera 1.2 m high) of the four
test rooms; the map from the survey views with known poses (wall angle error, corner error); then
random poses: each localization turns the camera through 4 headings 90 deg apart (relative angles
known from the drive's angle sensor, as in paper 3) and matches the combined fragment globally
(success also counted up to the half-turn symmetry of the rectangle-based rooms) and from a coarse
prior (uniform error up to 0.5 m / 10 deg).
"""

from __future__ import annotations

import time

import numpy as np

from benchmarks.common import Row, time_ratio

LOGS = ("intel", "aces", "csail", "freiburg-079", "freiburg-101", "infinite-corridor", "acapulco")
SUCCESS_M, SUCCESS_DEG = 0.3, 5.0


def icp_2d(
    map_points: np.ndarray, tree, scan: np.ndarray, prior: np.ndarray, iterations: int = 50
) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Point-to-point ICP (Besl & McKay; closed-form 2D Kabsch step), gate shrinking 1.0 -> 0.2 m."""
    x, y, th = prior
    gate = 1.0
    for _ in range(iterations):
        c, s = np.cos(th), np.sin(th)
        W = scan @ np.array([[c, -s], [s, c]]).T + [x, y]
        d, j = tree.query(W, distance_upper_bound=gate)
        ok = np.isfinite(d)
        if ok.sum() < 3:
            break
        P, Q = W[ok], map_points[j[ok]]
        mp, mq = P.mean(0), Q.mean(0)
        H = (P - mp).T @ (Q - mq)
        dth = np.arctan2(H[0, 1] - H[1, 0], H[0, 0] + H[1, 1])
        cd, sd = np.cos(dth), np.sin(dth)
        Rd = np.array([[cd, -sd], [sd, cd]])
        t = mq - Rd @ mp
        x, y = Rd @ np.array([x, y]) + t
        th = th + dth
        gate = max(0.2, gate * 0.8)
        if abs(dth) < 1e-5 and np.hypot(*t) < 1e-4:
            break
    return np.array([x, y, th])


def _err(est: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pe = np.hypot(est[:, 0] - ref[:, 0], est[:, 1] - ref[:, 1])
    he = np.degrees(np.abs((est[:, 2] - ref[:, 2] + np.pi) % (2 * np.pi) - np.pi))
    return pe, he


def _real_logs(quick: bool) -> list[Row]:
    from scipy.spatial import cKDTree

    from navkit import datasets
    from navkit.io.carmen import read_carmen
    from navkit.localization import build_map_from_scans, match_scan

    rows: list[Row] = []
    logs = LOGS[:2] if quick else LOGS
    n_track, n_global = (20, 5) if quick else (100, 25)
    totals: dict[str, list[float]] = {
        "nk": [],
        "icp": [],
        "glob": [],
        "t_nk": [],
        "t_icp": [],
        "t_glob": [],
    }
    for name in logs:
        lg = read_carmen(datasets.find(f"laser2d/{name}-corrected.log.gz"))
        every = max(2, len(lg) // 1200)
        m = build_map_from_scans(lg.ranges[::every], lg.bearings, lg.poses[::every], max_range=30.0)
        fld = m.likelihood_field(0.1)
        assert fld.points is not None  # built from points
        tree = cKDTree(fld.points)
        rng = np.random.default_rng(0)
        idx = np.linspace(0, len(lg) - 1, n_track).astype(int)
        ref = lg.poses[idx]
        prior = ref + rng.uniform(-1, 1, (len(idx), 3)) * [0.5, 0.5, np.radians(10)]
        est_nk, est_icp, t_nk, t_icp, c_nk = [], [], [], [], []
        for k, p in zip(idx, prior, strict=True):
            pts = lg.points(int(k), 30.0)
            c0, t0 = time.process_time(), time.perf_counter()
            est_nk.append(match_scan(fld, pts, p).pose)
            t1, c1 = time.perf_counter(), time.process_time()
            c_nk.append(c1 - c0)
            est_icp.append(icp_2d(fld.points, tree, pts, p))
            t2 = time.perf_counter()
            t_nk.append(t1 - t0)
            t_icp.append(t2 - t1)
        pe_n, he_n = _err(np.array(est_nk), ref)
        pe_i, he_i = _err(np.array(est_icp), ref)
        ok_n = (pe_n <= SUCCESS_M) & (he_n <= SUCCESS_DEG)
        ok_i = (pe_i <= SUCCESS_M) & (he_i <= SUCCESS_DEG)
        gidx = idx[:: max(1, len(idx) // n_global)][:n_global]
        est_g, t_g, c_g, ok_flag = [], [], [], []
        for k in gidx:
            c0, t0 = time.process_time(), time.perf_counter()
            fix = match_scan(fld, lg.points(int(k), 30.0), None)
            t_g.append(time.perf_counter() - t0)
            c_g.append(time.process_time() - c0)
            est_g.append(fix.pose)
            ok_flag.append(fix.ok)
        pe_g, he_g = _err(np.array(est_g), lg.poses[gidx])
        ok_g = (pe_g <= SUCCESS_M) & (he_g <= SUCCESS_DEG)
        false_fix = float(np.mean(np.array(ok_flag) & ~ok_g))
        rows += [
            Row(
                "localization",
                f"{name}: tracking success (prior 0.5 m / 10 deg)",
                "%",
                100 * ok_n.mean(),
                100 * ok_i.mean(),
                "ICP point-to-point (cKDTree)",
                None,
                f"{len(idx)} scans; map from {len(lg) // every} scans",
            ),
            Row(
                "localization",
                f"{name}: tracking median error",
                "m",
                float(np.median(pe_n)),
                float(np.median(pe_i)),
                "ICP point-to-point (cKDTree)",
                None,
                "vs the log's corrected pose",
            ),
            Row(
                "localization",
                f"{name}: tracking ms per fix",
                "ms",
                1e3 * float(np.median(t_nk)),
                1e3 * float(np.median(t_icp)),
                "ICP point-to-point (cKDTree)",
                time_ratio(float(np.median(t_nk)), float(np.median(t_icp))),
                f"wall time; navkit CPU (process_time) median {1e3 * np.median(c_nk):.1f} ms",
            ),
            Row(
                "localization",
                f"{name}: global success (no prior)",
                "%",
                100 * ok_g.mean(),
                None,
                "",
                None,
                f"{len(gidx)} scans, median {1e3 * np.median(t_g):.0f} ms per fix (CPU {1e3 * np.median(c_g):.0f} ms), false confident fixes {100 * false_fix:.0f} %",
            ),
        ]
        totals["nk"].append(ok_n.mean())
        totals["icp"].append(ok_i.mean())
        totals["glob"].append(ok_g.mean())
        totals["t_nk"].append(np.median(t_nk))
        totals["t_icp"].append(np.median(t_icp))
        totals["t_glob"].append(np.median(t_g))
    rows.append(
        Row(
            "localization",
            "all logs: tracking success (mean)",
            "%",
            100 * float(np.mean(totals["nk"])),
            100 * float(np.mean(totals["icp"])),
            "ICP point-to-point (cKDTree)",
            None,
            f"{len(logs)} logs",
        )
    )
    rows.append(
        Row(
            "localization",
            "all logs: tracking ms per fix (mean of medians)",
            "ms",
            1e3 * float(np.mean(totals["t_nk"])),
            1e3 * float(np.mean(totals["t_icp"])),
            "ICP point-to-point (cKDTree)",
            time_ratio(float(np.mean(totals["t_nk"])), float(np.mean(totals["t_icp"]))),
            "",
        )
    )
    rows.append(
        Row(
            "localization",
            "all logs: global success (mean)",
            "%",
            100 * float(np.mean(totals["glob"])),
            None,
            "",
            None,
            f"median {1e3 * float(np.mean(totals['t_glob'])):.0f} ms per global fix",
        )
    )
    return rows


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
    rows = _real_logs(quick)
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
