"""Batch throughput: the same inputs in process, on a LocalCluster of 1 and of 2 workers.

Inputs: real SemanticKITTI frames (``obstacles detect``), the real RGB-D inputs (``planes
extract``: a CAPE frame, two Kinect clouds, a slambook frame), a few seeds of ``mission sweep
yard --small``, the runs of a ``path return`` sweep over a path recorded from a simulated 7-leg
drive, and ``path record`` over the real trajectories (TUM fr1/xyz and fr2/desk, KITTI 00), each
at four tolerances. Also the scheduler's overhead per task, from tasks that do nothing: (wall
time - time inside the tasks) / tasks, on one worker.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from benchmarks.common import Row


def _noop(out_dir: Path) -> dict:
    return {}


def _tasks(quick: bool):  # type: ignore[no-untyped-def]
    from navkit import datasets
    from navkit.batch import BatchTask, settings_hash
    from navkit.batch.path_record import record_path_job
    from navkit.path import ApproximatorSettings

    names = ("freiburg1_xyz-groundtruth.txt", "fr2_desk_ORB.txt", "KITTI_00_gt.txt")
    tols = (0.05, 0.1) if quick else (0.02, 0.05, 0.1, 0.2)
    tasks = []
    for name in names:
        p = datasets.find(f"trajectories/{name}")
        for tol in tols:
            tasks.append(
                BatchTask(
                    f"{p.stem}-{tol:g}",
                    record_path_job,
                    {"trajectory": str(p), "settings": ApproximatorSettings(tolerance=tol)},
                    settings_hash(p, tol),
                )
            )
    return tasks


def _obstacle_tasks(quick: bool):  # type: ignore[no-untyped-def]
    """The 3 SemanticKITTI frames, each 4 times (2 when quick): one task per frame."""
    from navkit import datasets
    from navkit.batch import BatchTask
    from navkit.batch.obstacle_frames import InputOptions, MapOptions, obstacles_frame_job
    from navkit.obstacles import ObstacleSettings
    from navkit.obstacles.mounting import SensorHeight

    height = SensorHeight(1.73, "given")
    tasks = []
    for copy in range(2 if quick else 4):
        for f in ("000000", "000001", "000002"):
            p = datasets.find(f"lidar/semantickitti-seq00/{f}.bin")
            kwargs = {"path": str(p), "settings": ObstacleSettings(), "opts": InputOptions(),
                      "mopts": MapOptions(), "height": height}  # fmt: skip
            tasks.append(BatchTask(f"{f}-{copy}", obstacles_frame_job, kwargs, ""))
    return tasks


def _planes_tasks(quick: bool):  # type: ignore[no-untyped-def]
    """The 4 real RGB-D inputs of tests/batch/test_planes_batch.py, each 3 times (1 when quick)."""
    from navkit import datasets
    from navkit.batch import BatchTask
    from navkit.batch.planes_extract import CameraOverride, input_key, planes_extract_job

    cam = CameraOverride(fx=518.0, fy=519.0, cx=325.5, cy=253.5)  # slambook-ch5's camera
    names = ("cape-tunnel", "pcl-kinect/capture0001.pcd", "pcl-kinect/capture0002.pcd",
             "slambook-ch5")  # fmt: skip
    tasks = []
    for copy in range(1 if quick else 3):
        for name in names:
            src = str(datasets.find(f"rgbd/{name}"))
            kwargs = {"source": src, "camera": cam}
            tasks.append(BatchTask(f"{input_key(src)}-{copy}", planes_extract_job, kwargs, ""))
    return tasks


def _return_tasks(quick: bool, tmp: Path):  # type: ignore[no-untyped-def]
    """The tasks of a ``path return`` sweep (default VO and controller) over a 3.5 m path recorded
    from a simulated 7-leg drive (``path simulate --legs 7``): 8 tasks of 10 runs (4 when quick);
    the rows' "inputs" are these tasks, so runs/s is 10x the figure."""
    import numpy as np

    from navkit.batch.path_return import ReturnSweepSpec, return_sweep_tasks
    from navkit.io.pathjson import write_path_json
    from navkit.path import ApproximatorSettings, approximate
    from navkit.path.control import PathFollowerSettings
    from navkit.sensors import VisualOdometryNoise
    from navkit.sim.return_sim import leg_drive

    rng = np.random.default_rng(0)
    vo = VisualOdometryNoise()
    est = vo.corrupt(leg_drive(7, 0.5, 90.0, rng=rng, rate_hz=vo.rate_hz), rng)
    spline = approximate(est[:, :2], ApproximatorSettings(tolerance=0.05)).spline
    write_path_json(tmp / "path.json", spline)
    sweep = ReturnSweepSpec(vo=vo, controller=PathFollowerSettings(), seed=0)
    return return_sweep_tasks(str(tmp / "path.json"), 40 if quick else 80, sweep, 10)


def _throughput(name: str, tasks: list, rows: list[Row]) -> None:  # type: ignore[type-arg]
    """Inputs per second in process, on 1 and on 2 workers (clusters started beforehand)."""
    import distributed

    from navkit.batch import BatchSettings, local_cluster, run_batch

    def timed(settings: BatchSettings) -> float:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            res = run_batch(tasks, tmp, settings)
            wall = time.perf_counter() - t0
            assert res.n_failed == 0, res.rows
        return wall

    walls = {"in process": timed(BatchSettings())}
    for n in (1, 2):
        with local_cluster(n) as cluster, distributed.Client(cluster):
            timed(BatchSettings(scheduler=cluster.scheduler_address))  # warm the workers
            walls[f"{n} worker{'s' * (n > 1)}"] = timed(
                BatchSettings(scheduler=cluster.scheduler_address)
            )
    for label, wall in walls.items():
        rows.append(
            Row("batch", f"{name} x{len(tasks)}: {label}", "inputs/s", len(tasks) / wall,
                note="cluster running, workers warm")
        )  # fmt: skip
    rows.append(
        Row("batch", f"{name}: speed-up, 2 workers vs 1", "x",
            walls["1 worker"] / walls["2 workers"], note="2-core machine; ideal 2.0")
    )  # fmt: skip
    rows.append(
        Row("batch", f"{name}: seconds per input, in process", "s",
            walls["in process"] / len(tasks), note="the per-input cost of docs/scale.md")
    )  # fmt: skip


def run(quick: bool = False) -> list[Row]:
    import cloudpickle

    from navkit.batch import BatchSettings, BatchTask, run_batch

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    tasks = _tasks(quick)
    rows: list[Row] = []
    _throughput("obstacles detect, KITTI frames", _obstacle_tasks(quick), rows)
    _throughput("planes extract, real RGB-D inputs", _planes_tasks(quick), rows)
    with tempfile.TemporaryDirectory() as tmp:
        _throughput(
            "path return sweep (tasks of 10 runs), 7-leg path",
            _return_tasks(quick, Path(tmp)),
            rows,
        )
    from navkit.batch import mission_sweep_tasks

    _throughput(
        "mission sweep, yard --small",
        mission_sweep_tasks("yard", list(range(2 if quick else 4)), small=True),
        rows,
    )
    walls: dict[str, float] = {}
    import distributed

    from navkit.batch import local_cluster

    def timed(settings: BatchSettings) -> float:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            res = run_batch(tasks, tmp, settings)
            wall = time.perf_counter() - t0
            assert res.n_failed == 0, res.rows
        return wall

    walls["in process"] = timed(BatchSettings())
    for n in (1, 2):
        t0 = time.perf_counter()
        with local_cluster(n) as cluster, distributed.Client(cluster):
            start = time.perf_counter() - t0
            walls[f"{n} worker{'s' * (n > 1)}"] = timed(
                BatchSettings(scheduler=cluster.scheduler_address)
            )
        rows.append(Row("batch", f"LocalCluster start, {n} worker(s)", "s", start))
    for label, wall in walls.items():
        rows.append(
            Row(
                "batch",
                f"path record x{len(tasks)}: {label}",
                "inputs/s",
                len(tasks) / wall,
                note="cluster already running",
            )
        )
    rows.append(
        Row(
            "batch",
            "speed-up, 2 workers vs 1",
            "x",
            walls["1 worker"] / walls["2 workers"],
            note="2-core machine; ideal 2.0",
        )
    )
    n = 20 if quick else 100
    noop = [BatchTask(f"n{i}", _noop, {}, "") for i in range(n)]
    with tempfile.TemporaryDirectory() as tmp:
        with local_cluster(1) as cluster, distributed.Client(cluster) as client:
            t0 = time.perf_counter()
            res = run_batch(noop, tmp, BatchSettings(scheduler=cluster.scheduler_address))
            wall = time.perf_counter() - t0
            inside = sum(r["seconds"] for r in res.rows)
            client.close()
    rows.append(
        Row(
            "batch",
            "scheduler overhead per task (1 worker, existing cluster)",
            "ms",
            1e3 * (wall - inside) / n,
            note=f"{n} no-op tasks; includes connecting a client once",
        )
    )
    return rows
