"""Localization: navkit's correlative matcher vs a point-to-point ICP baseline on real laser logs,
and the stereo map + localization evaluation in simulated rooms.

Real logs (``../shared/data/laser2d``): for each log the map is built from every 2nd scan with the
corrected poses; then scans spread over the log are localized (a) *tracking*: from a prior = the
corrected pose disturbed by a uniform error of up to 0.5 m and 10 deg (the same prior for both
methods), navkit's ``Localizer`` (correlative matching around the prior) vs point-to-point ICP
(nearest neighbours by ``scipy.spatial.cKDTree`` on the same map points, up to 50 iterations,
correspondences beyond a shrinking gate rejected);
(b) *global*: navkit without prior (ICP cannot). Success = within 0.3 m and 5 deg of the corrected
pose. Figures: success %, median error, CPU ms per fix (median of `time.process_time`; the peer
is timed in the same loop on the same scan and prior).

The simulated stereo rooms are in :mod:`benchmarks.bench_rooms`.
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
    from navkit.localization import Localizer, build_map_from_scans
    from navkit.localization.evaluation import reported_poses

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
        loc = Localizer(m)  # the likelihood field (sigma 0.1 m) on the map's grid
        fld = loc.field
        assert fld.points is not None  # built from points
        tree = cKDTree(fld.points)
        rng = np.random.default_rng(0)
        idx = np.linspace(0, len(lg) - 1, n_track).astype(int)
        ref = lg.poses[idx]
        prior = ref + rng.uniform(-1, 1, (len(idx), 3)) * [0.5, 0.5, np.radians(10)]
        est_nk, est_icp, t_nk, t_icp, c_nk, c_icp = [], [], [], [], [], []
        for k, p in zip(idx, prior, strict=True):
            pts = lg.points(int(k), 30.0)
            c0, t0 = time.process_time(), time.perf_counter()
            est_nk.append(reported_poses([loc.update(pts, prior=p)])[0])
            t1, c1 = time.perf_counter(), time.process_time()
            est_icp.append(icp_2d(fld.points, tree, pts, p))
            t2, c2 = time.perf_counter(), time.process_time()
            c_nk.append(c1 - c0)
            c_icp.append(c2 - c1)
            t_nk.append(t1 - t0)
            t_icp.append(t2 - t1)
        # the first fix on a map builds its per-map caches (padded pyramid): reported apart,
        # the medians are those of the 100 fixes (the first included)
        first_ms = 1e3 * c_nk[0]
        pe_n, he_n = _err(np.array(est_nk), ref)
        pe_i, he_i = _err(np.array(est_icp), ref)
        ok_n = (pe_n <= SUCCESS_M) & (he_n <= SUCCESS_DEG)
        ok_i = (pe_i <= SUCCESS_M) & (he_i <= SUCCESS_DEG)
        gidx = idx[:: max(1, len(idx) // n_global)][:n_global]
        est_g, t_g, c_g, ok_flag = [], [], [], []
        c0 = time.process_time()
        loc.update(
            lg.points(int(gidx[0]), 30.0)
        )  # no odometry: global; builds the coarse field's caches
        first_g = 1e3 * (time.process_time() - c0)
        for k in gidx:
            c0, t0 = time.process_time(), time.perf_counter()
            fix = loc.update(lg.points(int(k), 30.0))
            t_g.append(time.perf_counter() - t0)
            c_g.append(time.process_time() - c0)
            est_g.append(reported_poses([fix])[0])
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
                1e3 * float(np.median(c_nk)),
                1e3 * float(np.median(c_icp)),
                "ICP point-to-point (cKDTree)",
                time_ratio(float(np.median(c_nk)), float(np.median(c_icp))),
                f"CPU (process_time) medians; wall {1e3 * np.median(t_nk):.1f} vs "
                f"{1e3 * np.median(t_icp):.1f} ms; first fix {first_ms:.0f} ms (map caches)",
            ),
            Row(
                "localization",
                f"{name}: global success (no prior)",
                "%",
                100 * ok_g.mean(),
                None,
                "",
                None,
                f"{len(gidx)} scans, median {1e3 * np.median(t_g):.0f} ms per fix (CPU {1e3 * np.median(c_g):.0f} ms), false confident fixes {100 * false_fix:.0f} %; first global fix on the map {first_g:.0f} ms CPU (coarse field and pyramid, cached)",
            ),
        ]
        totals["nk"].append(ok_n.mean())
        totals["icp"].append(ok_i.mean())
        totals["glob"].append(ok_g.mean())
        totals["t_nk"].append(np.median(c_nk))
        totals["t_icp"].append(np.median(c_icp))
        totals["t_glob"].append(np.median(c_g))
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
            "all logs: tracking ms per fix (mean of CPU medians)",
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
            f"mean of the logs' CPU medians {1e3 * float(np.mean(totals['t_glob'])):.0f} ms per global fix",
        )
    )
    return rows


def run(quick: bool = False) -> list[Row]:
    return _real_logs(quick)
