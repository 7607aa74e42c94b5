"""``navkit run`` on the real recordings: real-time factors, and the Rerun logging overhead.

Real-time factor = recording duration / processing time (per capability: that stage's time;
overall: the whole loop's wall time including reading, decoding and writing ``results.mcap``).

Recordings (``../shared/data``): SemanticKITTI seq 00 (3 Velodyne frames + poses: obstacles,
obstacle map, path), the CARMEN log freiburg-101 (LaserScan + odometry: wall map over the whole
log; localization of the second half against a map of the first half), 7-Scenes (RGB-D, plane
odometry; 20 frames with ``--quick``, else 100).

Rerun overhead: the same run with the null logger and with ``RerunLogger(save=...)`` (headless
``.rrd``), alternated, median of the wall times; the ratio is the overhead (the issue's bound:
< 1.10).
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import Row


def _run(
    rec: Any, out: Path, cfg: dict[str, Any] | None = None, **kw: Any
) -> tuple[dict[str, Any], float]:
    from navkit.runtime import run_recording

    shutil.rmtree(out, ignore_errors=True)
    t0 = time.perf_counter()
    s = run_recording(rec, out, cfg, **kw)
    return s, time.perf_counter() - t0


def _rtf_rows(name: str, s: dict[str, Any], wall: float) -> list[Row]:
    rows = [
        Row(
            "runtime",
            f"{name}: whole run",
            "x real time",
            s["recording_seconds"] / wall,
            note=f"{s['messages']} messages, {s['recording_seconds']:.1f} s of recording, {wall:.1f} s",
        )
    ]
    for cap, c in s["capabilities"].items():
        rows.append(
            Row(
                "runtime",
                f"{name}: {cap}",
                "x real time",
                c["real_time_factor"],
                note=f"{c['ms_per_message']:.2f} ms per message, {c['messages']} messages",
            )
        )
    return rows


def _overhead(
    name: str, rec: Any, tmp: Path, cfg: dict[str, Any] | None, repeats: int, **kw: Any
) -> Row:
    from navkit.viz.rerun_logger import RerunLogger

    plain, viewed = [], []
    for k in range(repeats):
        _, t = _run(rec, tmp / "plain", cfg, **kw)
        plain.append(t)
        logger = RerunLogger(save=tmp / f"run{k}.rrd")
        _, t = _run(rec, tmp / "viewed", cfg, logger=logger, **kw)
        viewed.append(t)
    p, v = float(np.median(plain)), float(np.median(viewed))
    size = (tmp / "run0.rrd").stat().st_size / 1e6
    return Row(
        "runtime",
        f"{name}: --rerun-save overhead",
        "s per run",
        v,
        peer=p,
        peer_name="no viewer",
        ratio=v / p,
        note=f"median of {repeats}; .rrd {size:.1f} MB",
    )


def run(quick: bool = False) -> list[Row]:
    from navkit import datasets

    rows: list[Row] = []
    tmp = Path(tempfile.mkdtemp(prefix="bench_runtime_"))
    try:
        kitti = datasets.find("lidar/semantickitti-seq00")
        s, wall = _run(kitti, tmp / "kitti")
        rows += _rtf_rows("SemanticKITTI seq00 (3 frames)", s, wall)

        log_gz = datasets.find("laser2d/freiburg-101-corrected.log.gz")
        s, wall = _run(log_gz, tmp / "wall")
        rows += _rtf_rows("freiburg-101 wall map", s, wall)

        import sys

        sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
        from tests.runtime.bags import split_carmen, write_carmen_bag

        first, second = split_carmen(log_gz, tmp)
        _run(first, tmp / "map")
        bag = tmp / "second.bag"
        write_carmen_bag(second, bag, ros1=True)
        s, wall = _run(bag, tmp / "loc", map_path=tmp / "map" / "wall_map" / "map.json")
        rows += _rtf_rows("freiburg-101 localization (ROS 1 bag)", s, wall)

        seven = datasets.find("rgbd/7scenes-tsdf")
        cfg = {"run": {"max_items": 20 if quick else 100}}
        s, wall = _run(seven, tmp / "seven", cfg)
        rows += _rtf_rows(f"7-Scenes ({cfg['run']['max_items']} frames)", s, wall)

        repeats = 3 if quick else 5
        rows.append(_overhead("SemanticKITTI seq00", kitti, tmp, None, repeats))
        rows.append(
            _overhead(
                "freiburg-101 localization",
                bag,
                tmp,
                None,
                repeats,
                map_path=tmp / "map" / "wall_map" / "map.json",
            )
        )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return rows
