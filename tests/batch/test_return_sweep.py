"""``navkit path return`` as a sweep: runs in chunks of tasks, every run its own random stream, so
2 workers, the serial loop, other chunk sizes, the runs made one by one and a shorter sweep all
agree run for run."""

from __future__ import annotations

import json

import numpy as np
import pytest

from navkit.batch.path_return import ERROR_RATE_PCT, run_rng
from navkit.batch.summary import wilson_interval


@pytest.fixture(scope="module")
def path_json(tmp_path_factory):
    """A path recorded from a simulated 3-leg VO drive (1.5 m): cheap returns."""
    from typer.testing import CliRunner

    from navkit.cli.main import app

    root = tmp_path_factory.mktemp("ret")
    run = CliRunner().invoke
    assert (
        run(
            app, ["path", "simulate", "--legs", "3", "--seed", "2", "-o", str(root / "s")]
        ).exit_code
        == 0
    )
    r = run(
        app, ["path", "record", str(root / "s" / "vo.tum"), "-e", "0.01", "-o", str(root / "r")]
    )
    assert r.exit_code == 0, r.output
    return root / "r" / "path.json"


def _rows(out):
    return [json.loads(line) for line in (out / "batch.jsonl").read_text().splitlines()]


def _detail(out):
    return json.loads((out / "returns.json").read_text())["runs_detail"]


def test_two_workers_equal_the_runs_made_one_by_one(cli, path_json, tmp_path):
    pytest.importorskip(
        "distributed", reason="the cluster extra (dask.distributed) is not installed"
    )
    from navkit.io.pathjson import read_path_json
    from navkit.path.control import PathFollowerSettings
    from navkit.sensors import VisualOdometryNoise
    from navkit.sim.return_sim import simulate_returns

    a, b, c = tmp_path / "serial", tmp_path / "dask", tmp_path / "one-task"
    args = ("path", "return", path_json, "--runs", "4", "--seed", "7")
    r = cli(*args, "-o", a, "--runs-per-task", "2")
    assert r.exit_code == 0, r.output
    r = cli(*args, "-o", b, "--workers", "2", "--runs-per-task", "2")
    assert r.exit_code == 0, r.output
    r = cli(*args, "-o", c)  # the default chunk: all 4 runs in one lock-step task
    assert r.exit_code == 0, r.output
    assert _detail(a) == _detail(b) == _detail(c)
    assert [x["key"] for x in _rows(b)] == ["runs-0000-0001", "runs-0002-0003"]
    for key in ("runs-0000-0001", "runs-0002-0003"):
        ta = (a / key / "true_xy.npy").read_bytes()
        assert ta == (b / key / "true_xy.npy").read_bytes()
    # each run made alone, straight from the simulator with its own stream (7, i)
    spline = read_path_json(path_json)
    for i, d in enumerate(_detail(b)):
        alone = simulate_returns(
            spline,
            runs=1,
            settings=PathFollowerSettings(),
            vo=VisualOdometryNoise(),
            rng=run_rng(7, i),
        )
        assert d["run"] == i and d["seed"] == [7, i]
        assert d["final_error_m"] == float(alone.final_error[0])
        assert d["final_xy"] == [float(v) for v in alone.final_true[0]]
        assert d["stopped"] == bool(alone.stopped[0])
        # ground truth: the error is the true final position's distance from the path's start
        assert d["final_error_m"] == pytest.approx(
            np.hypot(*(np.array(d["final_xy"]) - spline.start))
        )


def test_summary_rates_count_the_runs_and_a_shorter_sweep_is_a_prefix(cli, path_json, tmp_path):
    out, short = tmp_path / "a", tmp_path / "b"
    assert cli("path", "return", path_json, "--runs", "5", "-o", out).exit_code == 0
    assert cli("path", "return", path_json, "--runs", "2", "-o", short).exit_code == 0
    assert _detail(short) == _detail(out)[:2]  # run i does not depend on how many runs there are
    detail = _detail(out)
    summary = json.loads((out / "batch_summary.json").read_text())
    stopped = sum(d["stopped"] for d in detail)
    within = sum(d["final_error_pct"] <= ERROR_RATE_PCT for d in detail)
    rate = summary["rates"]["stopped_within_the_stop_radius"]
    assert (rate["successes"], rate["trials"]) == (stopped, 5)
    assert rate["text"] == str(wilson_interval(stopped, 5))
    assert summary["rates"]["final_error_within_1_percent_of_L"]["successes"] == within
    ret = json.loads((out / "returns.json").read_text())
    assert ret["stopped"] == stopped and ret["runs"] == 5
    assert (out / "returns.png").stat().st_size > 0


def test_resume_recomputes_only_the_deleted_run(cli, path_json, tmp_path):
    out = tmp_path / "r"
    args = ("path", "return", path_json, "--runs", "3", "--runs-per-task", "1", "-o", out)
    assert cli(*args).exit_code == 0
    before = _detail(out)
    (out / "runs-0001-0001" / "runs.json").unlink()
    r = cli(*args, "--resume")
    assert r.exit_code == 0, r.output
    assert [x["status"] for x in _rows(out)] == ["skipped", "ok", "skipped"]
    assert _detail(out) == before
