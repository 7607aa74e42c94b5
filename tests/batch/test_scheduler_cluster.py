"""A Dask cluster made of separate processes, as on several machines: ``dask scheduler`` and two
``dask worker`` processes (the command-line tools dask.distributed installs) on localhost, and
``navkit obstacles detect --scheduler tcp://127.0.0.1:PORT`` writing the serial run's files.

The closest this machine gets to a multi-node run: the scheduler and each worker are separate
operating-system processes started by their own CLIs that only share the network address and
the file system, as over SSH or on SLURM (``docs/scale.md``).
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("distributed", reason="the cluster extra (dask.distributed) is not installed")

FRAMES = ("000000", "000001", "000002")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _dask_cli() -> list[str]:
    exe = Path(sys.executable).with_name("dask")
    if exe.is_file():
        return [str(exe)]
    found = shutil.which("dask")
    if found is None:
        pytest.skip("the 'dask' command of dask.distributed is not on PATH")
    return [found]


@pytest.fixture
def dask_processes(tmp_path):
    """``tcp://127.0.0.1:PORT`` of a scheduler and two single-threaded workers (no nanny, so a
    worker's pid is the process started here); yields ``(address, worker pids)``."""
    import distributed

    dask = _dask_cli()
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {
        **os.environ,
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
    }
    logs = tmp_path / "dask-logs"
    logs.mkdir()
    procs: list[subprocess.Popen] = []

    def start(name: str, args: list[str]) -> subprocess.Popen:
        with open(logs / f"{name}.log", "wb") as fh:  # the child keeps its own descriptor
            p = subprocess.Popen([*dask, *args], stdout=fh, stderr=subprocess.STDOUT, env=env)
        procs.append(p)
        return p

    try:
        start(
            "scheduler", ["scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"]
        )
        workers = [
            start(
                f"worker{i}",
                [
                    "worker",
                    address,
                    "--nthreads",
                    "1",
                    "--no-nanny",
                    "--no-dashboard",
                    "--name",
                    f"navkit-test-{i}",
                    "--local-directory",
                    str(tmp_path / f"w{i}"),
                ],
            )
            for i in range(2)
        ]
        deadline = time.monotonic() + 120
        while True:  # the scheduler takes a moment to listen
            try:
                client = distributed.Client(address, timeout=5)
                break
            except OSError:
                if time.monotonic() > deadline or procs[0].poll() is not None:
                    raise
                time.sleep(0.5)
        try:
            client.wait_for_workers(2, timeout=120)
        finally:
            client.close()
        yield address, {p.pid for p in workers}
    finally:  # the workers first (they say goodbye to a live scheduler), then the scheduler
        _stop(procs[1:])
        _stop(procs[:1])


def _stop(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        p.terminate()
    for p in procs:
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def test_obstacles_on_a_cluster_of_separate_processes_equal_serial(
    cli, data_path, tmp_path, dask_processes
):
    address, worker_pids = dask_processes
    src = tmp_path / "in"
    src.mkdir()
    for f in FRAMES:
        shutil.copy(data_path(f"lidar/semantickitti-seq00/{f}.bin"), src / f"{f}.bin")
    a, b = tmp_path / "serial", tmp_path / "cluster"
    common = ("--sensor", "hdl64e-kitti", "--outputs", "labels,obstacles,grid")
    assert cli("obstacles", "detect", src, "-o", a, *common).exit_code == 0
    r = cli("obstacles", "detect", src, "-o", b, *common, "--scheduler", address)
    assert r.exit_code == 0, r.output
    for f in FRAMES:
        for name in ("labels.npy", "obstacles.json", "map.pgm", "map.yaml"):
            assert (a / f / name).read_bytes() == (b / f / name).read_bytes(), (f, name)
    rows = [json.loads(line) for line in (b / "batch.jsonl").read_text().splitlines()]
    assert sorted(r["key"] for r in rows) == list(FRAMES)
    assert all(r["status"] == "ok" for r in rows)
    # every frame ran in one of the worker processes started above, none in this one
    pids = {int(r["worker"].rsplit(":", 1)[1]) for r in rows}
    assert pids <= worker_pids and os.getpid() not in pids
