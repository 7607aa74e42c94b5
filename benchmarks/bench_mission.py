"""The integrated mission against its peer: the same robot returning on visual odometry alone.

Paper 4 returns the robot on its VO; the mission corrects the VO with plane-based motion
(paper 2) and room-map fixes (paper 3). Both runs use the same world, route, seed and sensor
noise; the "VO only" run has every correction weight set to zero (plane motions, room fixes,
obstacle-map fixes; the planes and the room are still computed, so the time figures compare). Figures per seed: final distance of the
robot to the operator, mean position error, obstacle recall and phantoms, wall time.

``python -m benchmarks mission`` (``--quick``: seed 0 only).
"""

from __future__ import annotations

import dataclasses
import time

from benchmarks.common import Row

AREA = "mission"


def _run(seed: int, corrected: bool) -> tuple[dict, float]:
    from navkit.mission import (
        MissionSettings,
        builtin_route_path,
        load_route,
        mission_metrics,
        run_mission,
    )
    from navkit.sim import load_scene

    route, overrides = load_route(builtin_route_path("yard"))
    s = MissionSettings(seed=seed).with_overrides(overrides)
    if not corrected:
        f = dataclasses.replace(
            s.fusion,
            weight_xy_geometry=0.0,
            weight_heading_geometry=0.0,
            weight_xy_texture=0.0,
            weight_heading_texture=0.0,
            fix_weight=0.0,
            map_fix_weight=0.0,
        )
        s = dataclasses.replace(s, fusion=f)
    t0 = time.perf_counter()
    lg = run_mission(load_scene("yard"), route, s)
    return mission_metrics(lg), time.perf_counter() - t0


def run(quick: bool = False) -> list[Row]:
    rows: list[Row] = []
    for seed in (0,) if quick else (0, 1, 2):
        m, wall = _run(seed, True)
        p, wall_p = _run(seed, False)
        peer = "same robot, VO only (paper 4)"
        d, dp = (
            m["return"]["final_distance_to_operator_m"],
            p["return"]["final_distance_to_operator_m"],
        )
        rows.append(
            Row(
                AREA,
                f"yard seed {seed}: final distance to operator",
                "m",
                d,
                dp,
                peer,
                d / dp if dp else None,
                f"outcomes {m['return']['outcome']} / {p['return']['outcome']}; "
                f"route {m['return']['outbound_length_m']:.1f} m",
            )
        )
        e, ep = m["pose_error"]["corrected_m"]["mean"], p["pose_error"]["corrected_m"]["mean"]
        rows.append(
            Row(
                AREA,
                f"yard seed {seed}: mean position error",
                "m",
                e,
                ep,
                peer,
                e / ep if ep else None,
            )
        )
        h, hp = (
            m["pose_error"]["corrected_heading_deg"]["mean"],
            p["pose_error"]["corrected_heading_deg"]["mean"],
        )
        rows.append(
            Row(
                AREA,
                f"yard seed {seed}: mean heading error",
                "deg",
                h,
                hp,
                peer,
                h / hp if hp else None,
            )
        )
        ob, obp = m["obstacles"], p["obstacles"]
        rows.append(
            Row(
                AREA,
                f"yard seed {seed}: obstacle recall (larger than robot)",
                "",
                ob["recall_larger_than_robot"],
                obp["recall_larger_than_robot"],
                peer,
            )
        )
        rows.append(
            Row(
                AREA,
                f"yard seed {seed}: phantom obstacles",
                "count",
                float(ob["phantoms"]),
                float(obp["phantoms"]),
                peer,
            )
        )
        rows.append(
            Row(
                AREA,
                f"yard seed {seed}: wall time of the mission",
                "s",
                wall,
                wall_p,
                peer,
                wall / wall_p if wall_p else None,
                "same process, same machine load",
            )
        )
    return rows
