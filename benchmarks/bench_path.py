"""Path memory (paper 4): real-data table, cost per point, peers, loop search, return simulation.

``python -m benchmarks path`` (``--quick`` for a subset). Peers, timed in this process on the same
points: SciPy's ``splprep`` / ``make_splprep`` fitted offline with the smoothing ``s`` tuned (by
bisection) so the maximum point-to-curve distance equals navkit's tolerance; a
Ramer-Douglas-Peucker polyline at the same tolerance (what ArduPilot's SmartRTL stores); and an
O(n^2) pairwise search of polyline pieces for the loop search.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from benchmarks.common import Row, median_time, time_ratio

AREA = "path"
log = logging.getLogger(__name__)

TRAJECTORIES = {
    "KITTI 00 gt": "trajectories/KITTI_00_gt.txt",
    "KITTI 00 ORB": "trajectories/KITTI_00_ORB.txt",
    "KITTI 00 S-PTAM": "trajectories/KITTI_00_SPTAM.txt",
    "TUM fr2_desk gt": "trajectories/fr2_desk_groundtruth.txt",
    "TUM fr1_xyz gt": "trajectories/freiburg1_xyz-groundtruth.txt",
    "MRCLAM R1 odometry": "odometry/mrclam-dataset7/Robot1_Odometry.dat",
}
TOLERANCES = (0.01, 0.05, 0.1, 0.5)


def _load(relative: str) -> np.ndarray:
    from navkit import datasets
    from navkit.io.trajectory import load_planar_track

    _, xy, _, _ = load_planar_track(Path(datasets.find(relative)))
    return xy


def _dedupe(xy: np.ndarray) -> np.ndarray:
    keep = np.r_[True, np.hypot(*np.diff(xy, axis=0).T) > 1e-9]
    return xy[keep]


# --------------------------------------------------------------------------- peers
def rdp(points: np.ndarray, eps: float) -> np.ndarray:
    """Ramer-Douglas-Peucker: indices of the kept vertices (every point within ``eps`` of the
    polyline through them). Stack-based; each split is one vectorised distance pass."""
    keep = np.zeros(len(points), dtype=bool)
    keep[0] = keep[-1] = True
    stack = [(0, len(points) - 1)]
    while stack:
        i, j = stack.pop()
        if j <= i + 1:
            continue
        a, b = points[i], points[j]
        seg = b - a
        q = points[i + 1 : j] - a
        L2 = float(seg @ seg)
        if L2 > 0:
            t = np.clip(q @ seg / L2, 0.0, 1.0)
            d = np.hypot(*(q - t[:, None] * seg).T)
        else:
            d = np.hypot(*q.T)
        k = int(np.argmax(d))
        if d[k] > eps:
            m = i + 1 + k
            keep[m] = True
            stack.extend([(i, m), (m, j)])
    return np.flatnonzero(keep)


def _spline_max_dev(tck_eval, xy: np.ndarray, u_data: np.ndarray) -> float:
    """Largest distance of the points from the curve: each point against 41 curve samples
    spanning its neighbours' parameters (the nearest curve point of a fit that follows the points
    lies there), so the sampling error is ~1/40 of the point spacing."""
    du = np.maximum(np.gradient(u_data), 1e-12)
    U = np.clip(u_data[:, None] + du[:, None] * np.linspace(-1.0, 1.0, 41)[None, :], 0.0, 1.0)
    curve = tck_eval(U.reshape(-1)).reshape(len(xy), 41, 2)
    return float(np.sqrt(((curve - xy[:, None, :]) ** 2).sum(-1)).min(1).max())


def scipy_tuned(
    xy: np.ndarray, eps: float, maker: str = "splprep"
) -> tuple[int, float, float, float]:
    """Smallest spline (largest ``s``) whose points are all within ~eps; returns
    (stored numbers, max deviation, seconds of one fit at that s, s)."""
    from scipy.interpolate import make_splprep, splev, splprep

    x = _dedupe(xy)
    chord = np.r_[0.0, np.cumsum(np.hypot(*np.diff(x, axis=0).T))]
    u_data = chord / chord[-1]  # the chord-length parameter both SciPy functions use by default

    def fit(s: float):
        if maker == "splprep":
            tck, _ = splprep([x[:, 0], x[:, 1]], s=s, k=3)
            return (
                tck,
                (lambda u: np.stack(splev(u, tck), axis=1)),
                len(tck[0]) + 2 * (len(tck[0]) - 4),
            )
        spl, _ = make_splprep([x[:, 0], x[:, 1]], s=s, k=3)
        return (
            spl,
            (lambda u: spl(u).T if spl(u).shape[0] == 2 else spl(u)),
            len(spl.t) + spl.c.size,
        )

    lo, hi = 0.0, len(x) * eps**2  # s = sum of squared residuals; all residuals = eps at most
    best = None
    for _ in range(14):
        mid = 0.5 * (lo + hi) if lo > 0 else (hi / 64.0 if best is None else 0.5 * (lo + hi))
        _, ev, numbers = fit(mid)
        dev = _spline_max_dev(ev, x, u_data)
        if dev <= eps:
            lo, best = mid, (numbers, dev, mid)
        else:
            hi = mid
    if best is None:
        _, ev, numbers = fit(0.0)
        best = (numbers, _spline_max_dev(ev, x, u_data), 0.0)
    seconds = median_time(lambda: fit(best[2]), repeats=3)
    return best[0], best[1], seconds, best[2]


def brute_force_loops(spline, step: float) -> tuple[int, float]:
    """O(n^2) crossing search over the polyline sampled every ``step`` metres: (crossings, s)."""
    t0 = time.perf_counter()
    _, xy = spline.sample(step)
    p, d = xy[:-1], np.diff(xy, axis=0)
    n = len(p)
    count = 0
    for i0 in range(0, n, 128):
        i = np.arange(i0, min(i0 + 128, n))
        r = d[i][:, None, :]
        w = p[None, :, :] - p[i][:, None, :]
        den = r[..., 0] * d[None, :, 1] - r[..., 1] * d[None, :, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (w[..., 0] * d[None, :, 1] - w[..., 1] * d[None, :, 0]) / den
            u = (w[..., 0] * r[..., 1] - w[..., 1] * r[..., 0]) / den
        valid = np.arange(n)[None, :] > i[:, None] + 1
        count += int((valid & (den != 0) & (t >= 0) & (t <= 1) & (u >= 0) & (u <= 1)).sum())
    return count, time.perf_counter() - t0


# --------------------------------------------------------------------------- the benchmark
def run(quick: bool = False) -> list[Row]:
    from navkit.path import ApproximatorSettings, approximate
    from navkit.path.control import PathFollowerSettings
    from navkit.path.loops import find_crossings
    from navkit.sensors import VisualOdometryNoise
    from navkit.sim.return_sim import leg_drive, simulate_returns

    rows: list[Row] = []
    names = ["KITTI 00 gt", "MRCLAM R1 odometry"] if quick else list(TRAJECTORIES)
    tols = (0.05, 0.5) if quick else TOLERANCES

    # 1. real-data table
    for name in names:
        xy = _load(TRAJECTORIES[name])
        approximate(xy[:300], ApproximatorSettings(tolerance=0.05))  # warm-up
        for eps in tols:
            r = approximate(xy, ApproximatorSettings(tolerance=eps))
            s = r.summary()
            note = (
                f"{s['points']} pts, {s['segments_before_loop_removal']} segments "
                f"({s['segments']} after {s['loops_removed']} loops), L {s['raw_length_m']:.1f} m, "
                f"max dev {s['max_deviation_m']:.4f} m, cheap test {100 * s['cheap_test_fraction']:.0f} %, "
                f"wall mean/max {s['mean_us_per_point']:.0f}/{s['max_us_per_point']:.0f} us"
            )
            rows.append(
                Row(
                    AREA,
                    f"{name} eps={eps:g}: CPU us/point mean",
                    "us",
                    s["mean_cpu_us_per_point"],
                    note=note,
                )
            )
            rows.append(
                Row(AREA, f"{name} eps={eps:g}: CPU us/point max", "us", s["max_cpu_us_per_point"])
            )

    # 2. the paper's Table 1 targets on KITTI 00 (eps 0.05 m): mean 1.0 ms, max 3.0 ms
    xy = _load(TRAJECTORIES["KITTI 00 gt"])
    # each point's time is the median over 5 runs (the same work every run): a point's time is
    # then its own cost, not a moment the scheduler gave the CPU to another process
    runs = [approximate(xy, ApproximatorSettings(tolerance=0.05)) for _ in range(3 if quick else 5)]
    wall_pp = np.median([r.seconds_per_point for r in runs], axis=0) * 1e6
    cpu_pp = np.median([r.cpu_seconds_per_point for r in runs], axis=0) * 1e6
    for stat, paper in (("mean", 1000.0), ("max", 3000.0)):
        wall = float(getattr(np, stat)(wall_pp))
        cpu = float(getattr(np, stat)(cpu_pp))
        rows.append(
            Row(
                AREA,
                f"KITTI 00 gt eps=0.05: {stat} time per point (CPU, median of runs)",
                "us",
                cpu,
                paper,
                "paper Table 1 (full cycle)",
                time_ratio(cpu, paper),
                f"wall {wall:.0f} us; p99 CPU {np.percentile(cpu_pp, 99):.0f} us",
            )
        )

    # 3. stored numbers and fit time against SciPy splprep / make_splprep and RDP (same tolerance)
    for eps in (0.5,) if quick else TOLERANCES:
        raw = approximate(xy, ApproximatorSettings(tolerance=eps, remove_loops=False))
        nav_numbers = raw.spline.n_numbers
        nav_time = median_time(
            lambda eps=eps: approximate(
                xy, ApproximatorSettings(tolerance=eps, remove_loops=False), timed=False
            ),
            repeats=3,
        )
        makers = (
            ("splprep", "make_splprep") if eps >= 0.1 else ("splprep",)
        )  # make_splprep: ~5 s/fit
        for maker in makers:
            try:
                numbers, dev, seconds, s_val = scipy_tuned(xy, eps, maker)
            except Exception as exc:  # a peer failing is a result, not a crash of the benchmark
                rows.append(
                    Row(
                        AREA,
                        f"KITTI 00 eps={eps:g}: stored numbers vs {maker}",
                        "numbers",
                        float(nav_numbers),
                        None,
                        maker,
                        None,
                        f"peer failed: {exc!r}"[:120],
                    )
                )
                continue
            rows.append(
                Row(
                    AREA,
                    f"KITTI 00 eps={eps:g}: stored numbers vs {maker}",
                    "numbers",
                    float(nav_numbers),
                    float(numbers),
                    f"scipy {maker} (s={s_val:.3g}, max dev {dev:.3f} m)",
                    numbers / nav_numbers,
                    "ratio = peer / navkit (> 1: navkit stores fewer)",
                )
            )
            rows.append(
                Row(
                    AREA,
                    f"KITTI 00 eps={eps:g}: time, all points vs {maker}",
                    "s",
                    nav_time,
                    seconds,
                    f"scipy {maker} (one fit at the tuned s, offline)",
                    time_ratio(nav_time, seconds),
                    "navkit online point by point incl. refits; peer offline, tuning loop not counted",
                )
            )
        keep = rdp(_dedupe(xy), eps)
        rdp_time = median_time(lambda eps=eps: rdp(_dedupe(xy), eps), repeats=3)
        rows.append(
            Row(
                AREA,
                f"KITTI 00 eps={eps:g}: stored numbers vs RDP",
                "numbers",
                float(nav_numbers),
                float(2 * len(keep)),
                "RDP polyline (SmartRTL-like)",
                2 * len(keep) / nav_numbers,
                f"{raw.spline.n_segments} cubics (7 numbers each + start) vs {len(keep)} vertices; "
                f"RDP offline {rdp_time * 1e3:.0f} ms",
            )
        )

    # 4. loop search: box tree + refinement to 0.1 mm vs O(n^2) pairwise polyline pieces
    raw = approximate(
        xy[: 1200 if quick else 2400], ApproximatorSettings(tolerance=0.05, remove_loops=False)
    ).spline
    tree_s = median_time(lambda: find_crossings(raw), repeats=3)
    n_tree = len({(round(c.s_a, 2), round(c.s_b, 2)) for c in find_crossings(raw)})
    n_brute, brute_s = brute_force_loops(raw, 0.25)
    rows.append(
        Row(
            AREA,
            f"loop search, whole KITTI prefix ({raw.total_length:.0f} m)",
            "s",
            tree_s,
            brute_s,
            "O(n^2) pairwise pieces (0.25 m)",
            time_ratio(tree_s, brute_s),
            f"tree: {n_tree} crossings to 0.1 mm; brute force: {n_brute} crossings to ~mm",
        )
    )

    # 5. return simulation: 40 runs, growth with path length and with VO noise
    runs = 20 if quick else 40
    base = VisualOdometryNoise()
    for legs in (7, 28) if quick else (7, 14, 28, 56):
        poses = leg_drive(legs)
        spl = approximate(poses[:, :2], ApproximatorSettings(tolerance=0.005), timed=False).spline
        sim = simulate_returns(spl, runs=runs, vo=base, rng=7, settings=PathFollowerSettings())
        s = sim.summary()
        rows.append(
            Row(
                AREA,
                f"return, {spl.total_length:.1f} m staircase, default VO: final error mean",
                "% of L",
                s["final_error_mean_pct"],
                16.0,
                "paper: < 16 % of 3.5 m",
                None,
                f"p95 {s['final_error_p95_pct']:.2f} %, {s['final_error_mean_m']:.3f} m; lateral mean "
                f"{s['lateral_error_mean_m']:.3f} m, max {s['lateral_error_max_m']:.3f} m; "
                f"{s['stopped']}/{runs} stopped",
            )
        )
    poses = leg_drive(7)
    spl = approximate(poses[:, :2], ApproximatorSettings(tolerance=0.005), timed=False).spline
    for k in (1.0, 4.0) if quick else (0.0, 0.5, 1.0, 2.0, 4.0):
        vo = VisualOdometryNoise(
            scale_sigma=base.scale_sigma * k, heading_sigma=base.heading_sigma * k
        )
        sim = simulate_returns(spl, runs=runs, vo=vo, rng=7)
        s = sim.summary()
        rows.append(
            Row(
                AREA,
                f"return, 3.5 m, VO noise x{k:g}: final error mean",
                "% of L",
                s["final_error_mean_pct"],
                16.0,
                "paper: < 16 % of 3.5 m",
                None,
                f"p95 {s['final_error_p95_pct']:.2f} %; lateral mean {s['lateral_error_mean_m']:.3f} m",
            )
        )
    # the whole loop: the path itself recorded from VO (outbound drift), return on VO
    rng = np.random.default_rng(11)
    errs = []
    for _ in range(runs):
        est = base.corrupt(poses, rng)
        spl_vo = approximate(est[:, :2], ApproximatorSettings(tolerance=0.005), timed=False).spline
        sim = simulate_returns(
            spl_vo, runs=1, vo=base, rng=rng, initial_true=poses[-1], initial_estimate=est[-1]
        )
        errs.append(float(sim.final_error[0]))
    e = 100 * np.array(errs) / 3.5
    rows.append(
        Row(
            AREA,
            "return, 3.5 m, path recorded from VO too: final error mean",
            "% of L",
            float(e.mean()),
            16.0,
            "paper: < 16 % of 3.5 m",
            None,
            f"p95 {np.percentile(e, 95):.2f} % ({runs} runs)",
        )
    )
    return rows
