"""The batch engine: serial and LocalCluster runs agree, failures are rows, resume, killed workers."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import pytest

from navkit.batch import (
    DONE_MARKER,
    BatchSettings,
    BatchTask,
    run_batch,
    settings_hash,
    summarize,
    wilson_interval,
)
from navkit.batch.path_record import record_path_job
from navkit.errors import ConfigError
from navkit.path import ApproximatorSettings

TRAJECTORIES = ("freiburg1_xyz-groundtruth.txt", "fr2_desk_ORB.txt", "KITTI_00_gt.txt")


@pytest.fixture
def real_tasks(data_path, tmp_path):
    paths = [data_path(f"trajectories/{name}") for name in TRAJECTORIES]
    bad = tmp_path / "broken.txt"
    bad.write_text("1.0 2.0 three four\n", encoding="utf-8")
    paths.insert(1, bad)
    return [
        BatchTask(
            p.stem,
            record_path_job,
            {"trajectory": str(p), "settings": ApproximatorSettings(tolerance=0.05)},
            settings_hash(p, 0.05),
        )
        for p in paths
    ]


def _manifest(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "batch.jsonl").read_text().splitlines()]


@pytest.mark.parametrize(("k", "n"), [(0, 10), (3, 10), (97, 100), (1000, 1000)])
def test_wilson_bounds_solve_the_score_equation(k, n):
    """At each bound p, the score statistic |k/n - p| / sqrt(p (1-p) / n) equals z = 1.96."""
    r = wilson_interval(k, n)
    assert r.low <= k / n <= r.high
    for p in (r.low, r.high):
        if 0.0 < p < 1.0:
            z = abs(k / n - p) / math.sqrt(p * (1 - p) / n)
            assert z == pytest.approx(1.959963984540054, rel=1e-9)
        else:  # a bound is clipped only where the rate itself is 0 or 1
            assert k in (0, n)


def test_serial_batch_records_a_bad_input_and_completes_the_rest(real_tasks, tmp_path):
    out = tmp_path / "serial"
    res = run_batch(real_tasks, out)
    assert [r["key"] for r in res.rows] == [t.key for t in real_tasks]
    assert res.n_failed == 1 and res.n_ok == 3
    bad = next(r for r in res.rows if r["status"] == "failed")
    assert bad["key"] == "broken" and "broken.txt" in bad["error"] and "expected" in bad["error"]
    assert not (out / "broken" / DONE_MARKER).exists()
    for r in res.rows:
        if r["status"] == "ok":
            # the stored spline keeps every accepted point within the tolerance
            assert r["figures"]["max_deviation_m"] <= 0.05 + 1e-9
            assert (out / r["key"] / "path.json").is_file()
    assert _manifest(out) == [json.loads(json.dumps(r)) for r in res.rows]
    s = summarize(res.rows)
    assert (s["ok"], s["failed"]) == (3, 1)
    assert s["rates"]["within_tolerance"]["successes"] == 3


def test_local_cluster_matches_serial_byte_for_byte(real_tasks, tmp_path):
    pytest.importorskip(
        "distributed", reason="the cluster extra (dask.distributed) is not installed"
    )
    serial = run_batch(real_tasks, tmp_path / "serial")
    dask = run_batch(real_tasks, tmp_path / "dask", BatchSettings(workers=2))
    assert [r["status"] for r in dask.rows] == [r["status"] for r in serial.rows]
    assert [r["figures"] for r in dask.rows] == [r["figures"] for r in serial.rows]
    assert len({r["worker"] for r in dask.rows}) >= 1
    for r in serial.rows:
        if r["status"] == "ok":
            a = (tmp_path / "serial" / r["key"] / "path.json").read_bytes()
            b = (tmp_path / "dask" / r["key"] / "path.json").read_bytes()
            assert a == b


def test_resume_recomputes_only_the_deleted_input(real_tasks, tmp_path):
    out = tmp_path / "b"
    run_batch(real_tasks, out)
    victim = real_tasks[0].key
    (out / victim / "path.json").unlink()
    res = run_batch(real_tasks, out, BatchSettings(resume=True))
    status = {r["key"]: r["status"] for r in res.rows}
    assert status[victim] == "ok"
    assert status["broken"] == "failed"  # failed inputs are tried again
    assert [k for k, s in status.items() if s == "skipped"] == [
        t.key for t in real_tasks if t.key not in (victim, "broken")
    ]
    assert (out / victim / "path.json").is_file()
    # a changed setting invalidates every completed input
    changed = [
        BatchTask(t.key, t.fn, t.kwargs, settings_hash(t.kwargs["trajectory"], 0.1))
        for t in real_tasks
    ]
    res2 = run_batch(changed, out, BatchSettings(resume=True))
    assert not any(r["status"] == "skipped" for r in res2.rows)


def _die_once(out_dir: Path, *, flag: str) -> dict:
    """Kill the worker process the first time it runs (as the OOM killer would)."""
    if not os.path.exists(flag):
        Path(flag).write_text("died", encoding="utf-8")
        os._exit(1)
    (out_dir / "value.txt").write_text("42", encoding="utf-8")
    return {"value": 42}


def test_killed_worker_is_replaced_and_the_batch_completes(tmp_path):
    pytest.importorskip(
        "distributed", reason="the cluster extra (dask.distributed) is not installed"
    )
    import sys

    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    tasks = [
        BatchTask(f"t{i}", _die_once, {"flag": str(tmp_path / f"flag{i}")}, "h") for i in range(3)
    ]
    res = run_batch(tasks, tmp_path / "out", BatchSettings(workers=2))
    assert [r["status"] for r in res.rows] == ["ok", "ok", "ok"]
    assert [r["figures"] for r in res.rows] == [{"value": 42}] * 3
    assert len(_manifest(tmp_path / "out")) == 3


def test_settings_are_checked():
    with pytest.raises(ConfigError, match="workers"):
        BatchSettings(workers=2, scheduler="tcp://127.0.0.1:8786")
    with pytest.raises(ConfigError, match="workers"):
        BatchSettings(workers=0)
    with pytest.raises(ConfigError, match="key"):
        BatchTask("../escape", record_path_job)
    with pytest.raises(ConfigError, match="output names"):
        run_batch([BatchTask("a", record_path_job)] * 2, "/nonexistent-never-created")


def test_an_interrupted_batch_keeps_its_completed_inputs(real_tasks, tmp_path):
    """In a command's output transaction, Ctrl-C after two inputs undoes only the one in flight:
    the completed inputs stay (with their markers), so --resume goes on from there."""
    from navkit.batch import iter_batch
    from navkit.io.atomic import output_transaction

    out = tmp_path / "b"
    good = [t for t in real_tasks if t.key != "broken"]
    with pytest.raises(KeyboardInterrupt), output_transaction(out):
        for i, _ in enumerate(iter_batch(good, out)):
            if i == 1:
                raise KeyboardInterrupt
    done = [t.key for t in good if (out / t.key / DONE_MARKER).is_file()]
    assert done == [good[0].key, good[1].key]
    res = run_batch(good, out, BatchSettings(resume=True))
    assert [r["status"] for r in res.rows] == ["skipped", "skipped", "ok"]


def test_summarize_counts_every_element_of_a_list_figure_as_a_trial():
    # two chunks of simulated runs and a failed task: 3 of 5 runs succeeded
    rows = [
        {
            "key": "a",
            "status": "ok",
            "figures": {"hit": [True, False, True], "err": [1.0, 3.0, 2.0]},
        },
        {"key": "b", "status": "skipped", "figures": {"hit": [True, False], "err": [4.0, 5.0]}},
        {"key": "c", "status": "failed", "error": "x"},
    ]
    s = summarize(rows)
    assert (s["rates"]["hit"]["successes"], s["rates"]["hit"]["trials"]) == (3, 5)
    assert s["rates"]["hit"]["text"] == str(wilson_interval(3, 5))
    assert s["figures"]["err"]["n"] == 5 and s["figures"]["err"]["mean"] == 3.0
