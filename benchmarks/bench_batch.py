"""Batch throughput: the same inputs in process, on a LocalCluster of 1 and of 2 workers.

Inputs: ``path record`` over the real trajectories (TUM fr1/xyz and fr2/desk, KITTI 00), each at
four tolerances, so every task is real work of 0.1-0.5 s. Also the scheduler's overhead per task,
from tasks that do nothing: (wall time - time inside the tasks) / tasks, on one worker.
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
