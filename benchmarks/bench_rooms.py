"""Stereo room maps and localization in simulated rooms (paper 3).

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

from benchmarks.bench_localization import SUCCESS_DEG, SUCCESS_M, _err
from benchmarks.common import Row


def sim_rooms(
    n_poses: int = 100,
    width: int = 320,
    seed: int = 0,
    kinds: tuple[str, ...] | None = None,
    weighted_map: bool = True,
    negative_information: bool = True,
) -> dict[str, dict[str, float]]:
    """Map accuracy and localization statistics in the simulated rooms (see the module docstring).

    ``weighted_map``: the map's walls refitted by inverse-variance weighted TLS (stereo depth
    error along the rays; False = plain TLS, the figures before). ``negative_information``: the
    single-view known-heading fixes are checked for walls the map puts in view that the
    fragment lacks (False = the figures before).
    """
    from navkit.geometry import se2_apply, se2_from_xytheta
    from navkit.geometry.polygons import points_in_polygon
    from navkit.localization import (
        Localizer,
        LocalizerSettings,
        MatcherSettings,
        WallMapSettings,
        build_map,
        match_scan,
    )
    from navkit.localization.correlation import KnownHeadingFix, KnownHeadingSettings
    from navkit.localization.evaluate import evaluate_map
    from navkit.localization.evaluation import reported_poses
    from navkit.localization.refine import occluded_fraction, refine_pose, stereo_range_sigma
    from navkit.localization.visibility import ViewModel, check_visibility
    from navkit.sensors import PinholeCamera, StereoRig
    from navkit.sim import render_stereo
    from navkit.sim.scene_io import scene_from_dict
    from navkit.stereo import stereo_wall_points
    from navkit.stereo.floorplan import FloorplanSettings, default_num_disparities, usable_depth
    from navkit.stereo.rooms import ROOM_KINDS, room, sample_poses
    from navkit.stereo.triangulation import planar_camera_pose

    rig = StereoRig(PinholeCamera.from_fov(width, width * 3 // 4, 90.0), 0.2)
    height = 1.2
    # the single view's usable bearings and depth, from the front end's own settings
    # (stereo_wall_points: disparity range b f / min_depth, depth cut at the error budget)
    fp = FloorplanSettings()
    view = ViewModel.from_stereo(
        rig,
        max_depth=usable_depth(rig, fp),
        num_disparities=default_num_disparities(rig, fp),
        disparity_sigma=fp.disparity_sigma,
    )
    max_unseen = KnownHeadingSettings().max_unseen
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
        survey_xy = np.asarray(truth.survey, dtype=np.float64)[:, :2]  # the cameras' positions
        map_settings = WallMapSettings(
            range_sigma_coefficient=fp.disparity_sigma / (rig.baseline * rig.camera.fx)
            if weighted_map
            else 0.0
        )
        m = build_map(views, settings=map_settings, origins=survey_xy)
        acc = evaluate_map(m, truth.walls, truth.corners)
        loc = Localizer(m)  # 4-view fragments: global and tracking fixes
        fld = loc.field
        # single views at the known heading (paper 3): refined against the walls (weights from
        # the stereo depth error), in the map's outline, negative information with the view
        kh_settings = LocalizerSettings(
            refine=True,
            range_sigma_coefficient=fp.disparity_sigma / (rig.baseline * rig.camera.fx),
        )
        kh_loc = Localizer(m, kh_settings, field=fld, view=view if negative_information else None)
        poses = sample_poses(truth, n_poses, rng)
        pe, he, ok, ms, single = [], [], [], [], []
        # the paper's scenario: one 90-deg view, heading known (paper's correlation / 2D search)
        kh: dict[str, list[float]] = {
            k: []
            for k in (
                "paper_ok",
                "paper_unseen",
                "paper_succ",
                "paper_err",
                "paper_err_corr",
                "paper_ms",
                "search_ok",
                "search_succ",
                "search_err",
                "search_err_raw",
                "search_ms",
                "line_ok",
            )
        }
        rpe: list[float] = []
        rtpe: list[float] = []
        half_diag = 0.5 * truth.size + 0.5
        centre0 = 0.5 * (truth.outline.min(axis=0) + truth.outline.max(axis=0))
        search_settings = MatcherSettings(
            linear_window=half_diag, angular_window_deg=0.01, angular_step_deg=0.01
        )
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
                    f1 = reported_poses([loc.update(B)])[0]  # global, one view
                    single.append(np.hypot(*(f1[:2] - p[:2])))
                    sig1 = stereo_range_sigma(B, rig.baseline, rig.camera.fx)
                    # (a) the paper's method: correlation at the known heading + refinement
                    t0 = time.process_time()
                    kf = kh_loc.update(B, heading=p[2]).match
                    assert isinstance(kf, KnownHeadingFix)
                    kh["paper_ms"].append(1e3 * (time.process_time() - t0))
                    e_k = float(np.hypot(*(kf.position - p[:2])))
                    kh["paper_ok"].append(kf.ok)
                    kh["paper_unseen"].append(kf.reason == "unseen wall")
                    kh["paper_succ"].append(e_k <= SUCCESS_M)
                    kh["paper_err"].append(e_k)
                    kh["paper_err_corr"].append(float(np.hypot(*(kf.correlation_position - p[:2]))))
                    if kf.ambiguous and "elongated peak" in kf.reason:
                        # an honest "along this wall": the truth lies on the reported line
                        off = p[:2] - kf.position
                        across = abs(off @ np.array([-kf.peak_direction[1], kf.peak_direction[0]]))
                        kh["line_ok"].append(across <= SUCCESS_M)
                    # (b) 2D (x, y) correlative search at the known heading + refinement
                    t0 = time.process_time()
                    sf = match_scan(fld, B, np.array([*centre0, p[2]]), search_settings)
                    rf = refine_pose(m.walls, B, sf.pose, range_sigma=sig1, known_heading=True)
                    kh["search_ms"].append(1e3 * (time.process_time() - t0))
                    pos_s = rf.pose[:2] if rf.converged else sf.pose[:2]
                    e_s = float(np.hypot(*(pos_s - p[:2])))
                    # a fix outside the map's room outline is no fix (the field is symmetric
                    # about each wall: a fragment also fits the wall's far side)
                    inside = m.outline is None or bool(points_in_polygon(pos_s[None], m.outline)[0])
                    occl = occluded_fraction(
                        m.walls, B, np.array([*pos_s, p[2]]), margin=np.maximum(0.15, 3 * sig1)
                    )
                    unseen = check_visibility(m.walls, B, np.array([*pos_s, p[2]]), view)
                    kh["search_ok"].append(
                        sf.ok
                        and not rf.degenerate
                        and inside
                        and occl <= 0.05
                        and (not negative_information or unseen.unseen_fraction <= max_unseen)
                    )
                    kh["search_succ"].append(e_s <= SUCCESS_M)
                    kh["search_err"].append(e_s)
                    kh["search_err_raw"].append(float(np.hypot(*(sf.pose[:2] - p[:2]))))
            frag = np.concatenate(parts)
            sig4 = stereo_range_sigma(frag, rig.baseline, rig.camera.fx)
            fix = loc.update(frag)  # no odometry: a global search
            fix_pose = reported_poses([fix])[0]
            rg = refine_pose(m.walls, frag, fix_pose, range_sigma=sig4)
            rpe.append(float(np.hypot(*((rg.pose if rg.converged else fix_pose)[:2] - p[:2]))))
            e_p, e_h = _err(fix_pose[None], p[None])
            pe.append(e_p[0])
            he.append(e_h[0])
            ok.append(fix.ok)
            ms.append(1e3 * fix.seconds)
            # the half-turn twin of the pose (the rectangle-based rooms are symmetric)
            centre = 0.5 * (truth.outline.min(axis=0) + truth.outline.max(axis=0))
            twin = np.array([*(2 * centre - p[:2]), p[2] + np.pi])
            t_p, t_h = _err(fix_pose[None], twin[None])
            twin_ok.append(bool(t_p[0] <= SUCCESS_M and t_h[0] <= SUCCESS_DEG))
            # tracking from a coarse prior (uniform error up to 0.5 m / 10 deg)
            prior = p + rng.uniform(-1, 1, 3) * np.array([0.5, 0.5, np.radians(10)])
            tf = loc.update(frag, prior=prior)
            tf_pose = reported_poses([tf])[0]
            rt = refine_pose(m.walls, frag, tf_pose, range_sigma=sig4)
            rtpe.append(float(np.hypot(*((rt.pose if rt.converged else tf_pose)[:2] - p[:2]))))
            k_p, k_h = _err(tf_pose[None], p[None])
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
            # point-to-line refinement of the 4-view fixes (weighted by the stereo depth error)
            "refined_error_m_median": float(np.median(rpe)),
            "refined_error_m_p95": float(np.percentile(rpe, 95)),
            "refined_success_rate": float(
                ((np.array(rpe) <= SUCCESS_M) & (he_a <= SUCCESS_DEG)).mean()
            ),
            "tracking_refined_error_m_median": float(np.median(rtpe)),
            "tracking_refined_error_m_p95": float(np.percentile(rtpe, 95)),
            "tracking_refined_error_relative_median": float(np.median(rtpe)) / truth.size,
            "tracking_refined_success_rate": float(
                ((np.array(rtpe) <= SUCCESS_M) & (np.array(the) <= SUCCESS_DEG)).mean()
            ),
            **_known_heading_stats(kh, truth.size),
        }
    return out


def disparity_bias(
    n_views: int = 10,
    width: int = 320,
    seed: int = 0,
    kinds: tuple[str, ...] = ("rectangle", "column"),
) -> dict[str, dict[str, float]]:
    """SGBM's sub-pixel bias ("pixel locking") on the simulated rooms, with and without the
    Lucas-Kanade correction: wall pixels (rows above the horizon) of ``n_views`` random views per
    room against the renderer's true disparity (errors within 1 px)."""
    from navkit.sensors import PinholeCamera, StereoRig
    from navkit.sim import render_stereo
    from navkit.sim.scene_io import scene_from_dict
    from navkit.stereo import DisparitySettings, compute_disparity
    from navkit.stereo.rooms import room, sample_poses
    from navkit.stereo.triangulation import planar_camera_pose

    rig = StereoRig(PinholeCamera.from_fov(width, width * 3 // 4, 90.0), 0.2)
    out: dict[str, dict[str, float]] = {}
    for kind in kinds:
        truth = room(kind)
        scene = scene_from_dict(truth.scene)
        poses = sample_poses(truth, n_views, np.random.default_rng(seed))
        for sp in ("parabola", "lk"):
            errs, gts = [], []
            for k, p in enumerate(poses):
                st = render_stereo(
                    scene, rig, planar_camera_pose(*p, 1.2), rng=k, pixel_noise=1.0, supersample=1
                )
                d = compute_disparity(
                    st.pair.left, st.pair.right, DisparitySettings(num_disparities=64, subpixel=sp)
                ).disparity
                ok = np.isfinite(d) & np.isfinite(st.disparity)
                ok[int(rig.camera.cy) - 10 :] = False  # wall pixels: above the horizon
                errs.append((d - st.disparity)[ok])
                gts.append(st.disparity[ok])
            e, g = np.concatenate(errs), np.concatenate(gts)
            keep = np.abs(e) < 1.0
            e, g = e[keep], g[keep]
            frac = g - np.floor(g)
            per = [float(e[(frac >= j / 8) & (frac < (j + 1) / 8)].mean()) for j in range(8)]
            out[f"{kind}/{sp}"] = {
                "bias_px": float(e.mean()),
                "max_abs_bias_per_fraction_px": float(np.max(np.abs(per))),
                "spread_px": float(1.4826 * np.median(np.abs(e - np.median(e)))),
                "pixels": float(len(e)),
            }
    return out


def _known_heading_stats(kh: dict[str, list[float]], size: float) -> dict[str, float]:
    """Single-view known-heading statistics: confident rate, success among confident fixes,
    false-confident rate (confident and wrong), errors of the confident fixes."""
    out: dict[str, float] = {"single_views": float(len(kh["paper_ok"]))}
    for m in ("paper", "search"):
        ok = np.array(kh[f"{m}_ok"], dtype=bool)
        succ = np.array(kh[f"{m}_succ"], dtype=bool)
        err = np.array(kh[f"{m}_err"], dtype=np.float64)
        good = err[ok & succ]
        out[f"kh_{m}_confident_rate"] = float(ok.mean()) if len(ok) else float("nan")
        out[f"kh_{m}_success_among_confident"] = (
            float(succ[ok].mean()) if ok.any() else float("nan")
        )
        out[f"kh_{m}_false_confident_rate"] = (
            float((ok & ~succ).mean()) if len(ok) else float("nan")
        )
        out[f"kh_{m}_success_rate_all"] = float(succ.mean()) if len(succ) else float("nan")
        out[f"kh_{m}_error_m_median_confident"] = (
            float(np.median(good)) if len(good) else float("nan")
        )
        out[f"kh_{m}_error_m_p95_confident"] = (
            float(np.percentile(good, 95)) if len(good) else float("nan")
        )
        out[f"kh_{m}_error_relative_median_confident"] = (
            float(np.median(good)) / size if len(good) else float("nan")
        )
        out[f"kh_{m}_ms_median"] = (
            float(np.median(kh[f"{m}_ms"])) if kh[f"{m}_ms"] else float("nan")
        )
    ok = np.array(kh["paper_ok"], dtype=bool)
    succ = np.array(kh["paper_succ"], dtype=bool)
    corr = np.array(kh["paper_err_corr"], dtype=np.float64)
    good = corr[ok & succ]
    out["kh_paper_correlation_only_error_m_median_confident"] = (
        float(np.median(good)) if len(good) else float("nan")
    )
    sok = np.array(kh["search_ok"], dtype=bool)
    raw = np.array(kh["search_err_raw"], dtype=np.float64)
    ssucc = np.array(kh["search_succ"], dtype=bool)
    out["kh_search_unrefined_error_m_median_confident"] = (
        float(np.median(raw[sok & ssucc])) if (sok & ssucc).any() else float("nan")
    )
    # fixes refused by the negative-information check alone (confident without it)
    out["kh_paper_unseen_only_rate"] = (
        float(np.mean(kh["paper_unseen"])) if kh["paper_unseen"] else float("nan")
    )
    out["kh_line_reports"] = float(len(kh["line_ok"]))
    out["kh_line_truth_on_line_rate"] = (
        float(np.mean(kh["line_ok"])) if kh["line_ok"] else float("nan")
    )
    return out


def run(quick: bool = False) -> list[Row]:
    rows: list[Row] = []
    stats = sim_rooms(
        n_poses=10 if quick else 100, kinds=("rectangle", "lshape") if quick else None
    )
    for key, b in disparity_bias(n_views=3 if quick else 10).items():
        rows.append(
            Row(
                "localization",
                f"sim {key}: disparity bias per fractional disparity (max)",
                "px",
                b["max_abs_bias_per_fraction_px"],
                None,
                "",
                None,
                f"robust spread {b['spread_px']:.3f} px, mean bias {b['bias_px']:+.3f} px, "
                f"{b['pixels']:.0f} wall pixels",
            )
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
                f"sim {kind}: single view, known heading (paper's correlation + refinement)",
                "%",
                100 * s["kh_paper_success_among_confident"],
                None,
                "",
                None,
                f"success among confident fixes; confident {100 * s['kh_paper_confident_rate']:.0f} %, "
                f"false confident {100 * s['kh_paper_false_confident_rate']:.0f} % (refused as "
                f"unseen wall {100 * s['kh_paper_unseen_only_rate']:.0f} %), median error "
                f"{100 * s['kh_paper_error_m_median_confident']:.1f} cm; 2D search: confident "
                f"{100 * s['kh_search_confident_rate']:.0f} %, success among them "
                f"{100 * s['kh_search_success_among_confident']:.0f} %, false confident "
                f"{100 * s['kh_search_false_confident_rate']:.0f} %",
            ),
            Row(
                "localization",
                f"sim {kind}: tracking error after point-to-line refinement",
                "m",
                s["tracking_refined_error_m_median"],
                None,
                "",
                None,
                f"p95 {100 * s['tracking_refined_error_m_p95']:.1f} cm; median "
                f"{100 * s['tracking_refined_error_relative_median']:.2f} % of the diagonal "
                f"(before: {100 * s['tracking_error_relative_median']:.2f} %); global refined "
                f"median {100 * s['refined_error_m_median']:.1f} cm",
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
