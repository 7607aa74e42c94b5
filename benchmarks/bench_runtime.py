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

Obstacles in ``run`` against the detector alone (:func:`obstacles_cost`; the bound: 1.2): the
SemanticKITTI clouds looped to 10 Hz frames with their poses (obstacles + obstacle map, the
per-frame files on), beside ``cloud_to_grid`` + ``detect_obstacles_in_grid`` on the same clouds
with the run's mounting, alternated in one process. Printed: the capability's work per cloud
(handling + serialising and writing its outputs) / the detector's, and the whole loop's wall
time per cloud (reading, decoding, path, TF, the files' writer thread) / the detector's. CPU
times: the stage's and the detector's are their thread's CPU; the whole run's is the process's
plus its children's (the per-frame files' writer process: reaped children's, and the kept
writer's from ``/proc``).
``python -m benchmarks.bench_runtime`` prints the ratios alone.
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


def _files_cpu(pid: int | None) -> float:
    """CPU seconds of the per-frame files' writer process ``pid`` (kept between runs, so not
    in ``RUSAGE_CHILDREN`` until it stops): ``/proc/<pid>/stat``'s utime + stime; 0 without."""
    import os

    if pid is None:
        return 0.0
    with open(f"/proc/{pid}/stat") as fh:
        fields = fh.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class _LoopedClouds:
    """A KITTI folder's clouds and poses repeated ``loops`` times at 10 Hz (a Source)."""

    def __init__(self, folder: Path, loops: int) -> None:
        from navkit.runtime.sources import open_source

        src = open_source(folder)
        self.items = [msgs for _, msgs in src.messages()]
        self.loops = loops
        self.name = f"{folder} x{loops}"
        self.topics = dict(src.topics)
        self.start_ns = 0
        self.n_items = len(self.items) * loops
        self.end_ns = (self.n_items - 1) * 100_000_000

    def messages(self, skip: int = 0) -> Any:
        from dataclasses import replace

        for k in range(skip, self.n_items):
            st = k * 100_000_000
            yield k, [replace(m, stamp_ns=st) for m in self.items[k % len(self.items)]]


def obstacles_cost(loops: int = 10, repeats: int = 3) -> tuple[list[Row], dict[str, float]]:
    """``navkit run``'s obstacles per cloud against the detector alone (module docstring)."""
    from navkit import datasets
    from navkit.obstacles import detect_obstacles_in_grid
    from navkit.obstacles.grids import cloud_to_grid
    from navkit.obstacles.mounting import Mounting, choose_sensor_height

    kitti = datasets.find("lidar/semantickitti-seq00")
    src = _LoopedClouds(kitti, loops)
    clouds = [m.data for msgs in src.items for m in msgs if m.kind == "cloud"]
    tmp = Path(tempfile.mkdtemp(prefix="bench_runtime_obst_"))
    cfg = {"run": {"capabilities": ["obstacles", "obstacle_map", "path"]}}
    det_ms, stage_ms, loop_ms = [], [], []
    det_cpu, stage_cpu, loop_cpu, files_cpu = [], [], [], []
    try:
        for _ in range(repeats):
            import resource

            from navkit.runtime.files import idle_writer_pid

            ch0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            pid0 = idle_writer_pid()
            w0 = _files_cpu(pid0)
            c0 = time.process_time()
            s, wall = _run(src, tmp / "run", cfg)
            cpu = time.process_time() - c0
            ch1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            pid1 = idle_writer_pid()
            w1 = _files_cpu(pid1) - (w0 if pid1 == pid0 else 0.0)
            o = s["capabilities"]["obstacles"]
            stage_ms.append(o["ms_per_frame"])
            stage_cpu.append(o["cpu_ms_per_frame"])
            loop_ms.append(1e3 * wall / o["frames"])
            loop_cpu.append(1e3 * cpu / o["frames"])
            files_cpu.append(
                1e3 * (ch1.ru_utime + ch1.ru_stime - ch0.ru_utime - ch0.ru_stime + w1) / o["frames"]
            )
            # the calling thread's CPU, as the stage's cpu_ms_per_frame (the process's would
            # also count other threads: a BLAS pool's spinning, the run's leftovers)
            t0, c0 = time.perf_counter(), time.thread_time()
            # as navkit obstacles detect: the height measured once, on the first cloud
            g = cloud_to_grid(clouds[0])
            h = choose_sensor_height(g.points, np.eye(3), given_m=None, source="bench")
            mounting = Mounting(height_m=h.height_m)
            for _ in range(loops):
                for P in clouds:
                    detect_obstacles_in_grid(cloud_to_grid(P), mounting)
            det_ms.append(1e3 * (time.perf_counter() - t0) / (loops * len(clouds)))
            det_cpu.append(1e3 * (time.thread_time() - c0) / (loops * len(clouds)))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    d, st, lp = (float(np.median(x)) for x in (det_ms, stage_ms, loop_ms))
    dc, sc, lc, fc = (float(np.median(x)) for x in (det_cpu, stage_cpu, loop_cpu, files_cpu))
    figs = {
        "detector_cpu_ms": dc,
        "stage_cpu_ms": sc,
        "loop_cpu_ms": lc,
        "files_cpu_ms": fc,
        "stage_cpu_ratio": sc / dc,
        "loop_cpu_ratio": (lc + fc) / dc,
        "detector_ms": d,
        "stage_ms": st,
        "loop_ms": lp,
        "stage_ratio": st / d,
        "loop_ratio": lp / d,
    }
    note = f"SemanticKITTI seq00, {len(clouds)} clouds x {loops} at 10 Hz, median of {repeats}"
    rows = [
        Row(
            "runtime",
            "obstacles in run / detector alone (per cloud)",
            "ms per cloud",
            st,
            peer=d,
            peer_name="detector alone",
            ratio=st / d,
            note=note + "; bound 1.2",
        ),
        Row(
            "runtime",
            "whole run loop / detector alone (per cloud)",
            "ms per cloud",
            lp,
            peer=d,
            peer_name="detector alone",
            ratio=lp / d,
            note=note,
        ),
    ]
    return rows, figs


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
    rows += obstacles_cost(loops=5 if quick else 10, repeats=2 if quick else 3)[0]
    return rows


if __name__ == "__main__":
    import os

    from navkit.jit import implementation

    _, f = obstacles_cost()
    print(f"kernels: {implementation()} (NAVKIT_JIT={os.environ.get('NAVKIT_JIT', '')})")
    print(
        f"CPU: detector alone {f['detector_cpu_ms']:.1f} ms per cloud; obstacles in run "
        f"{f['stage_cpu_ms']:.1f} ms (ratio {f['stage_cpu_ratio']:.2f}); whole run "
        f"{f['loop_cpu_ms']:.1f} ms + files process {f['files_cpu_ms']:.1f} ms "
        f"(ratio {f['loop_cpu_ratio']:.2f})"
    )
    print(
        f"wall: detector alone {f['detector_ms']:.1f} ms per cloud; obstacles in run "
        f"{f['stage_ms']:.1f} ms (ratio {f['stage_ratio']:.2f}); whole run loop "
        f"{f['loop_ms']:.1f} ms (ratio {f['loop_ratio']:.2f})"
    )
