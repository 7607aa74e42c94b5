"""Real-time table: each capability's CPU time per frame on recorded data against
its sensor's frame period, on one core.

| capability | work per frame | sensor, period |
|---|---|---|
| obstacles (paper 1) | SemanticKITTI scan: ``cloud_to_grid`` + ``detect_obstacles_in_grid`` (the public entry for a recorded lidar cloud; ``detect_obstacles`` takes a ``RangeScan``, which is the same stages after the grid) - all 8 stages, default shapes | lidar 10 Hz, 100 ms |
| planes (paper 2) | 640 x 480 slambook frame: plane extraction alone, and ``observe_rgbd`` + ``estimate_motion`` against the previous frame; TUM fr3 stream: ``observe_rgbd`` + ``PlaneOdometry.update`` | RGB-D 30 Hz, 33.3 ms |
| localization (paper 3) | CARMEN Intel scan: tracking fix (``match_scan`` with a prior) | laser 40 Hz, 25 ms |
| stereo (paper 3) | Middlebury Q pair: ``compute_disparity`` | VO camera 10 Hz, 100 ms |
| path (paper 4) | KITTI 00 ground truth, eps 0.05 m: ``OnlineApproximator.update`` per point, mean and worst | VO 10 Hz, 100 ms |

One core: OpenCV is told to use one thread and the time is the process's CPU time
(``time.process_time``, all threads), so it is what one core spends. The figure is the median
over the frames (each frame's own median over repeats); the row's ratio is period / time (> 1:
faster than the sensor), the note gives the fraction of the period.

Run: ``python -m benchmarks realtime`` (``--quick``: fewer frames and repeats).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from benchmarks.common import Row

AREA = "realtime"


def _cpu(fn: Callable[[], Any], repeats: int) -> float:
    """Median CPU seconds of ``fn()`` after one warm-up call."""
    fn()
    t = []
    for _ in range(repeats):
        c0 = time.process_time()
        fn()
        t.append(time.process_time() - c0)
    return float(np.median(t))


def _row(capability: str, what: str, seconds: float, hz: float, sensor: str, note: str) -> Row:
    period = 1.0 / hz
    return Row(
        AREA,
        f"{capability}: {what}",
        "ms",
        1e3 * seconds,
        1e3 * period,
        f"{sensor} period ({hz:g} Hz)",
        period / seconds if seconds > 0 else None,
        f"{100 * seconds / period:.1f} % of the period, one core; {note}",
    )


def _obstacles(quick: bool) -> list[Row]:
    from navkit.experiments.obstacles import KITTI_FRAMES, SENSOR_HEIGHT_KITTI, kitti_frame
    from navkit.obstacles import Mounting, detect_obstacles_in_grid
    from navkit.obstacles.grids import cloud_to_grid

    times = []
    for name in KITTI_FRAMES[:1] if quick else KITTI_FRAMES:
        pts, _ = kitti_frame(name)

        def one(pts: np.ndarray = pts) -> None:
            detect_obstacles_in_grid(cloud_to_grid(pts), Mounting(SENSOR_HEIGHT_KITTI))

        times.append(_cpu(one, 1 if quick else 3))
    return [
        _row(
            "obstacles",
            "SemanticKITTI scan, cloud -> grid + 8 stages",
            float(np.median(times)),
            10.0,
            "lidar",
            f"median of {len(times)} frames",
        )
    ]


def _planes(quick: bool) -> list[Row]:
    from navkit.datasets import find
    from navkit.io.rgbd import read_simple_rgbd
    from navkit.planes import estimate_motion, extract_planes_organized, observe_rgbd

    seq = read_simple_rgbd(
        find("rgbd/slambook-ch5"),
        {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0},
    )
    frames = [seq.frame(i) for i in range(len(seq))]
    reps = 3 if quick else 10
    ext = [_cpu(lambda f=f: extract_planes_organized(f.points()), reps) for f in frames]
    obs = [observe_rgbd(f) for f in frames]
    odo = []
    for k in range(1, len(frames)):

        def one(k: int = k) -> None:
            estimate_motion(obs[k - 1], observe_rgbd(frames[k]))

        odo.append(_cpu(one, reps))
    return [
        _row(
            "planes",
            "640x480 slambook frame, plane extraction",
            float(np.median(ext)),
            30.0,
            "RGB-D",
            f"median of {len(ext)} frames (back-projection included)",
        ),
        _row(
            "planes",
            "640x480 slambook frame, observe + motion against the previous frame",
            float(np.median(odo)),
            30.0,
            "RGB-D",
            f"median of {len(odo)} frame pairs (0.4-0.7 m apart: the global search)",
        ),
        *_plane_odometry(quick),
    ]


def _plane_odometry(quick: bool) -> list[Row]:
    """``observe_rgbd`` + ``PlaneOdometry.update`` over the TUM fr3 frames as a 30 Hz stream
    (frame-to-map tracking, the dense refinement and verification, the map update)."""
    from navkit.datasets import find
    from navkit.errors import DataNotFoundError
    from navkit.io.rgbd import open_rgbd_sequence
    from navkit.planes import PlaneOdometry, observe_rgbd

    try:
        seq = open_rgbd_sequence(find("rgbd/tum-fr3-structure-notexture-far"))
    except DataNotFoundError:
        return []
    frames = [seq.frame(i) for i in range(30 if quick else len(seq))]
    odo = PlaneOdometry()
    odo.update(observe_rgbd(frames[0]))
    cpu = []
    for f in frames[1:]:
        t0 = time.process_time()
        odo.update(observe_rgbd(f))
        cpu.append(time.process_time() - t0)
    return [
        _row(
            "planes",
            "640x480 TUM fr3 stream, observe + PlaneOdometry.update",
            float(np.median(cpu)),
            30.0,
            "RGB-D",
            f"median of {len(cpu)} frames (p90 {1000 * np.percentile(cpu, 90):.1f} ms)",
        )
    ]


def _localization(quick: bool) -> list[Row]:
    from navkit import datasets
    from navkit.io.carmen import read_carmen
    from navkit.localization import build_map_from_scans, match_scan

    lg = read_carmen(datasets.find("laser2d/intel-corrected.log.gz"))
    every = max(2, len(lg) // 1200)
    m = build_map_from_scans(lg.ranges[::every], lg.bearings, lg.poses[::every], max_range=30.0)
    fld = m.likelihood_field(0.1)
    rng = np.random.default_rng(0)
    idx = np.linspace(0, len(lg) - 1, 10 if quick else 40).astype(int)
    prior = lg.poses[idx] + rng.uniform(-1, 1, (len(idx), 3)) * [0.5, 0.5, np.radians(10)]
    match_scan(fld, lg.points(int(idx[0]), 30.0), prior[0])  # the map's caches
    times = []
    for k, p in zip(idx, prior, strict=True):
        pts = lg.points(int(k), 30.0)
        c0 = time.process_time()
        match_scan(fld, pts, p)
        times.append(time.process_time() - c0)
    return [
        _row(
            "localization",
            "Intel scan, tracking fix (prior 0.5 m / 10 deg)",
            float(np.median(times)),
            40.0,
            "laser",
            f"median of {len(times)} scans",
        )
    ]


def _stereo(quick: bool) -> list[Row]:
    from navkit import datasets
    from navkit.io.images import read_image
    from navkit.stereo import DisparitySettings, compute_disparity

    root = datasets.find("stereo/middlebury2014-motorcycle-q")
    L, R = read_image(root / "im0.png"), read_image(root / "im1.png")
    settings = DisparitySettings(num_disparities=80, block_size=3, fill="background")
    t = _cpu(lambda: compute_disparity(L, R, settings), 2 if quick else 5)
    return [
        _row(
            "stereo",
            f"Middlebury Q pair ({L.shape[1]}x{L.shape[0]}), disparity",
            t,
            10.0,
            "VO camera",
            "the benchmark's settings (80 disparities, 3 px window, background fill)",
        )
    ]


def _path(quick: bool) -> list[Row]:
    from navkit import datasets
    from navkit.io.trajectory import load_planar_track
    from navkit.path import ApproximatorSettings, approximate

    _, xy, _, _ = load_planar_track(datasets.find("trajectories/KITTI_00_gt.txt"))
    # the approximator's own thread-CPU clock around each add (as benchmarks/bench_path.py)
    runs = [
        approximate(xy, ApproximatorSettings(tolerance=0.05)).cpu_seconds_per_point
        for _ in range(3 if quick else 5)
    ]
    per_point = np.median(runs, axis=0)  # each point's own cost, not a scheduler hiccup
    return [
        _row(
            "path",
            "KITTI 00 gt point, eps 0.05 m, mean",
            float(per_point.mean()),
            10.0,
            "VO",
            f"{len(xy)} points, each the median of {len(runs)} runs",
        ),
        _row(
            "path",
            "KITTI 00 gt point, eps 0.05 m, worst",
            float(per_point.max()),
            10.0,
            "VO",
            "the point that closes a loop (refit + loop search + cut)",
        ),
    ]


def run(quick: bool = False) -> list[Row]:
    import logging

    import cv2

    from navkit.errors import DataNotFoundError

    log = logging.getLogger(__name__)
    cv2.setNumThreads(1)  # one core
    rows: list[Row] = []
    for part in (_obstacles, _planes, _localization, _stereo, _path):
        try:
            rows += part(quick)
        except DataNotFoundError as exc:  # recorded data absent: the other rows still stand
            log.warning("%s skipped: %s", part.__name__, exc)
    return rows
