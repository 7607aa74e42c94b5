"""The detour planner (going round a blocked stretch of the stored path) against its peer.

Peer: the textbook grid A* in pure Python (``heapq``, 8-connected, octile heuristic, no corner
cutting - the PythonRobotics ``a_star.py`` algorithm) on the *same inflated grid*, from the same
start cell to the rejoin cell navkit chose (so the peer is spared the distance transform and the
rejoin search). Figures: CPU time per plan (``time.process_time`` medians, same process, same
inputs), the detour length against the 8-connected optimum and against the continuous optimum
(the analytic way round a disc: tangent - arc - tangent). Without ``--quick``, also the yard
mission with a box dropped on the way back (outcome, final distance to the operator, closest
approach of the true robot to the box).

``python -m benchmarks detour`` (``--quick``: the planner only).
"""

from __future__ import annotations

import heapq
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from benchmarks.common import Row

AREA = "detour"
RES = 0.1
SQRT2 = float(np.sqrt(2.0))


def _cpu_median(fn: Callable[[], Any], repeats: int = 7) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        times.append(time.process_time() - t0)
    return float(np.median(times))


def _world(clutter: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 24 x 14 m grid (0.1 m cells), a straight 16 m path, a disc of radius 0.6 m on it at
    x = 8 and (optionally) a wall across at x = 8 with a 1.6 m gap beside the path, and up to 60
    random boxes, 0.2-1 m, off the path (fixed seed)."""
    origin = np.array([-4.0, -7.0])
    H, W = 140, 240
    rr, cc = np.mgrid[0:H, 0:W]
    X, Y = origin[0] + (cc + 0.5) * RES, origin[1] + (rr + 0.5) * RES
    occ = np.hypot(X - 8.0, Y) <= 0.6
    if clutter:
        # a wall across the whole grid at x = 8, with a 1.6 m gap 2-3.6 m off the path, and
        # random boxes off the path
        occ |= (np.abs(X - 8.0) <= 0.1) & ~((Y >= 2.0) & (Y <= 3.6))
        rng = np.random.default_rng(1)
        for _ in range(60):
            cx, cy = rng.uniform(-3, 19), rng.uniform(-6.5, 6.5)
            h = rng.uniform(0.1, 0.5)
            if abs(cy) - h < 0.6 or (abs(cx - 8.0) < 1.5 + h and cy > -0.5):
                continue  # the stored path and the way to the gap stay clear
            occ |= (np.abs(X - cx) <= h) & (np.abs(Y - cy) <= h)
    path = np.c_[np.linspace(0.0, 16.0, 161), np.zeros(161)]
    return occ, origin, path


def _astar(allowed: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> float:
    """Pure-Python A* (the peer): length of the shortest 8-connected path in cells."""
    H, W = allowed.shape
    g = {start: 0.0}
    gr, gc = goal

    def h(r: int, c: int) -> float:
        dr, dc = abs(r - gr), abs(c - gc)
        return float(max(dr, dc) + (SQRT2 - 1.0) * min(dr, dc))

    heap = [(h(*start), 0.0, start)]
    closed = set()
    steps = [(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc]
    while heap:
        _, d, (r, c) = heapq.heappop(heap)
        if (r, c) == goal:
            return d
        if (r, c) in closed:
            continue
        closed.add((r, c))
        for dr, dc in steps:
            r2, c2 = r + dr, c + dc
            if not (0 <= r2 < H and 0 <= c2 < W and allowed[r2, c2]):
                continue
            if dr and dc and not (allowed[r + dr, c] and allowed[r, c + dc]):
                continue
            nd = d + (SQRT2 if dr and dc else 1.0)
            if nd < g.get((r2, c2), np.inf):
                g[(r2, c2)] = nd
                heapq.heappush(heap, (nd + h(r2, c2), nd, (r2, c2)))
    return float("inf")


def _way_round_disc(a: np.ndarray, b: np.ndarray, c: np.ndarray, rho: float) -> float:
    da, db = np.hypot(*(a - c)), np.hypot(*(b - c))
    angle = np.arccos(np.clip(((a - c) / da) @ ((b - c) / db), -1.0, 1.0))
    return float(
        np.sqrt(da**2 - rho**2)
        + np.sqrt(db**2 - rho**2)
        + rho * (angle - np.arccos(rho / da) - np.arccos(rho / db))
    )


def _planner_rows() -> list[Row]:
    from navkit.path.detour import DetourFailure, DetourSettings, clearance_map, plan_detour

    rows = []
    cfg = DetourSettings(robot_radius=0.3, margin=0.2, search_length=12.0)
    for clutter in (False, True):
        occ, origin, path = _world(clutter)
        start = np.array([0.0, 0.0])
        d = plan_detour(occ, RES, origin, start, path, cfg)
        if isinstance(d, DetourFailure):
            raise RuntimeError(f"benchmark world has no detour: {d}")
        allowed = clearance_map(occ, RES) >= cfg.inflation
        s_cell = tuple(int(v) for v in np.floor((start - origin) / RES).astype(int)[::-1])
        g_cell = tuple(int(v) for v in np.floor((d.rejoin - origin) / RES).astype(int)[::-1])
        args = (occ, RES, origin, start, path, cfg)
        t_nav = _cpu_median(lambda a=args: plan_detour(*a))
        t_peer = _cpu_median(lambda a=(allowed, s_cell, g_cell): _astar(*a), repeats=5)
        L8 = _astar(allowed, s_cell, g_cell) * RES
        label = "wall with a gap + boxes" if clutter else "single disc"
        rows.append(
            Row(
                AREA,
                f"plan one detour, 24 x 14 m grid, {label} (CPU, median)",
                "ms",
                1e3 * t_nav,
                1e3 * t_peer,
                "pure-Python A* (search only)",
                t_peer / t_nav if t_nav > 0 else None,
                "navkit also inflates (EDT), finds the rejoin point and smooths",
            )
        )
        rows.append(
            Row(
                AREA,
                f"detour length / 8-connected optimum, {label}",
                "ratio",
                d.length / L8,
                d.raw_length / L8,
                "unsmoothed grid path",
                None,
                f"8-connected optimum {L8:.2f} m; navkit smoothed {d.length:.2f} m",
            )
        )
        if not clutter:
            rho = 0.6 + cfg.inflation
            Lc = _way_round_disc(start, d.rejoin, np.array([8.0, 0.0]), rho)
            rows.append(
                Row(
                    AREA,
                    "detour length / continuous optimum round the inflated disc",
                    "ratio",
                    d.length / Lc,
                    L8 / Lc,
                    "8-connected optimum",
                    None,
                    f"tangent-arc-tangent {Lc:.2f} m (bound of an 8-connected path: 1.082)",
                )
            )
    return rows


def _mission_rows() -> list[Row]:
    import dataclasses

    from navkit.mission import (
        MissionSettings,
        builtin_route_path,
        load_route,
        mission_metrics,
        run_mission,
    )
    from navkit.obstacles.evaluate import distance_to_polygon as _distance_to_polygon
    from navkit.sim import load_scene
    from navkit.sim.footprints import footprint

    route, overrides = load_route(builtin_route_path("yard"))
    route = dataclasses.replace(route, block_at=5.0)
    rows = []
    for seed in (0, 1):
        s = MissionSettings(seed=seed).with_overrides(overrides)
        lg = run_mission(load_scene("yard"), route, s)
        m = mission_metrics(lg)["return"]
        box = lg.dropped_obstacle
        poly = footprint(box).polygon
        d_box = float(_distance_to_polygon(lg.truth[lg.phase == 1, :2], poly).min())
        rows.append(
            Row(
                AREA,
                f"yard, box dropped 5 m from the operator, seed {seed}: final distance",
                "m",
                m["final_distance_to_operator_m"],
                None,
                "",
                None,
                f"outcome {m['outcome']}; detours {m['detours']} ({m['detour_length_m']:.1f} m);"
                f" closest approach of the robot's centre to the box {d_box:.2f} m",
            )
        )
    return rows


def run(quick: bool = False) -> list[Row]:
    rows = _planner_rows()
    if not quick:
        rows += _mission_rows()
    return rows
