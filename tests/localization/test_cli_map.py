"""``navkit map build`` / ``navkit map locate`` on a tiny synthetic CARMEN log and on a real one."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.localization.helpers import LSHAPE, cast


def _write_log(path, poses, bearings, odom_noise=0.0, rng=None):
    rng = rng or np.random.default_rng(0)
    lines = ["# synthetic CARMEN log of the L-shaped room\n"]
    odom = poses + np.cumsum(rng.normal(0, odom_noise, poses.shape), axis=0)
    for k, (p, o) in enumerate(zip(poses, odom, strict=True)):
        r = cast(LSHAPE, p, bearings)
        r = np.where(np.isfinite(r), r, 81.9)
        t = 100.0 + k
        lines.append(
            f"ODOM {o[0]:.5f} {o[1]:.5f} {o[2]:.6f} 0.2 0.0 0.0 {t - 0.05:.6f} host {t - 0.05:.6f}\n"
        )
        lines.append(
            f"FLASER {len(r)} {' '.join(f'{v:.3f}' for v in r)} {p[0]:.5f} {p[1]:.5f} {p[2]:.6f} "
            f"{o[0]:.5f} {o[1]:.5f} {o[2]:.6f} {t:.6f} host {t + 0.001:.6f}\n"
        )
    path.write_text("".join(lines))


@pytest.fixture
def tiny_log(tmp_path):
    # a robot driving round the L: 40 scans
    t = np.linspace(0, 1, 40)
    xs = np.interp(t, [0, 0.35, 0.6, 1.0], [1.5, 8.5, 2.5, 2.5])
    ys = np.interp(t, [0, 0.35, 0.6, 1.0], [1.5, 2.0, 2.0, 6.8])
    th = np.arctan2(np.gradient(ys), np.gradient(xs))
    poses = np.column_stack([xs, ys, th])
    p = tmp_path / "tiny.log"
    _write_log(p, poses, np.linspace(-np.pi / 2, np.pi / 2, 181), odom_noise=0.01)
    return p, poses


def test_build_and_locate_on_a_tiny_log(cli, tiny_log, tmp_path):
    log_path, _ = tiny_log
    res = cli("map", "build", log_path, "--out", tmp_path / "map", "--every", "2")
    assert res.exit_code == 0, res.stderr
    for name in ("map.json", "map.pgm", "map.yaml", "map.png", "summary.json", "settings.toml"):
        assert (tmp_path / "map" / name).is_file(), name
    m = json.loads((tmp_path / "map" / "map.json").read_text())
    assert len(m["walls"]) == 6 and len(m["corners"]) == 6  # the L has 6 walls and 6 corners
    assert (tmp_path / "map" / "map.yaml").read_text().startswith("image: map.pgm")

    for prior in ("none", "odometry"):
        out = tmp_path / f"loc-{prior}"
        res = cli(
            "map",
            "locate",
            tmp_path / "map" / "map.json",
            log_path,
            "--out",
            out,
            "--prior",
            prior,
            "--every",
            "4",
        )
        assert res.exit_code == 0, res.stderr
        s = json.loads((out / "summary.json").read_text())
        assert s["fixes"] == 10
        # noise-free ranges, exact poses: every fix within the 0.3 m / 5 deg success bound, and
        # the median error a fraction of the 5 cm cell
        assert s["success_rate"] == 1.0
        assert s["position_error_m_median"] < 0.02
        assert s["false_fix_rate"] == 0.0
        tum = np.loadtxt(out / "poses.tum")
        assert tum.shape[1] == 8
        np.testing.assert_allclose(tum[:, 0], 100.001 + np.arange(0, 40, 4)[: len(tum)], atol=1e-6)
        np.testing.assert_allclose(tum[:, 3], 0.0)  # z = 0
        header = (out / "fixes.csv").read_text().splitlines()[0]
        assert "score" in header and "ambiguous" in header and "extent_m" in header


def test_locate_rejects_a_bad_map(cli, tiny_log, tmp_path):
    log_path, _ = tiny_log
    bad = tmp_path / "bad.json"
    bad.write_text('{"walls": []}')
    res = cli("map", "locate", bad, log_path, "--out", tmp_path / "o")
    assert res.exit_code == 2
    assert "error:" in res.stderr and "format" in res.stderr
    assert not (tmp_path / "o" / "poses.tum").exists()
    res = cli("map", "build", tmp_path / "absent.log", "--out", tmp_path / "o2")
    assert res.exit_code == 2 and "absent.log" in res.stderr


@pytest.mark.realdata
def test_real_log_build_and_track(cli, data_path, tmp_path):
    log_path = data_path("laser2d/aces-corrected.log.gz")
    assert cli("map", "build", log_path, "--out", tmp_path / "m", "--every", "4").exit_code == 0
    res = cli(
        "map",
        "locate",
        tmp_path / "m" / "map.json",
        log_path,
        "--out",
        tmp_path / "l",
        "--prior",
        "odometry",
        "--every",
        "20",
    )
    assert res.exit_code == 0, res.stderr
    s = json.loads((tmp_path / "l" / "summary.json").read_text())
    # tracking on the real log against its corrected poses (reference quality: cm to dm)
    assert s["success_rate"] >= 0.9
    assert s["position_error_m_median"] < 0.1


def test_locate_refuses_to_overwrite_and_reads_its_settings_back(cli, tiny_log, tmp_path):
    log_path, _ = tiny_log
    assert cli("map", "build", log_path, "-o", tmp_path / "map", "--every", "2").exit_code == 0
    args = ("map", "locate", tmp_path / "map" / "map.json", log_path, "--every", "8")
    assert cli(*args, "-o", tmp_path / "a", "--prior", "odometry", "--refine").exit_code == 0
    first = (tmp_path / "a" / "fixes.csv").read_text()
    res = cli(*args, "-o", tmp_path / "a")
    assert res.exit_code == 2 and "--overwrite" in res.stderr
    assert (tmp_path / "a" / "fixes.csv").read_text() == first  # untouched
    # the [localizer] table of the settings.toml written reproduces the run (refinement on)
    res = cli(
        *args,
        "-o",
        tmp_path / "b",
        "--prior",
        "odometry",
        "--config",
        tmp_path / "a" / "settings.toml",
    )
    assert res.exit_code == 0, res.stderr
    strip = lambda t: [",".join(r.split(",")[:14] + r.split(",")[15:]) for r in t.splitlines()]  # noqa: E731  (drop ms)
    assert strip((tmp_path / "b" / "fixes.csv").read_text()) == strip(first)
    assert "True" in {r.split(",")[15] for r in first.splitlines()[1:]}  # refined
    bad = tmp_path / "bad.toml"
    bad.write_text("[localizer]\nsigmaa = 0.1\n")
    res = cli(*args, "-o", tmp_path / "c", "--config", bad)
    assert res.exit_code == 2 and "sigmaa" in res.stderr


def test_build_reads_map_settings_from_config(cli, tiny_log, tmp_path):
    log_path, _ = tiny_log
    cfg = tmp_path / "map.toml"
    cfg.write_text("[map]\nresolution = 0.1\nmerge_distance = 0.15\n[map.segmentation]\n")
    res = cli("map", "build", log_path, "-o", tmp_path / "m", "--every", "2", "--config", cfg)
    assert res.exit_code == 0, res.stderr
    assert "resolution: 0.1" in (tmp_path / "m" / "map.yaml").read_text()
    m = json.loads((tmp_path / "m" / "map.json").read_text())
    assert len(m["walls"]) == 6  # the L's six walls on the coarser grid too
    assert "merge_distance = 0.15" in (tmp_path / "m" / "settings.toml").read_text()
    cfg.write_text("[map]\nresolution = -1\n")
    res = cli("map", "build", log_path, "-o", tmp_path / "m2", "--config", cfg)
    assert res.exit_code == 2 and "resolution" in res.stderr


def test_locate_says_self_consistency_and_runs_several_logs_as_a_batch(cli, tiny_log, tmp_path):
    """Against the map built from the same log the headline is a self-consistency check; a second
    log of the same room (another drive) is scored against its own poses; a batch of both writes
    what the single runs write."""
    log_path, poses = tiny_log
    other = tmp_path / "other.log"
    _write_log(other, poses[::-1].copy(), np.linspace(-np.pi / 2, np.pi / 2, 181), 0.01)
    assert cli("map", "build", log_path, "-o", tmp_path / "map", "--every", "2").exit_code == 0
    m = tmp_path / "map" / "map.json"
    res = cli("map", "locate", m, log_path, "-o", tmp_path / "same", "--every", "4")
    assert res.exit_code == 0, res.output
    assert "self-consistency" in res.output
    same = json.loads((tmp_path / "same" / "summary.json").read_text())
    assert same["reference"].startswith("self-consistency")
    res = cli("map", "locate", m, other, "-o", tmp_path / "other", "--every", "4")
    assert res.exit_code == 0 and "self-consistency" not in res.output
    assert (
        "corrected poses"
        in json.loads((tmp_path / "other" / "summary.json").read_text())["reference"]
    )
    res = cli("map", "locate", m, log_path, other, "-o", tmp_path / "both", "--every", "4")
    assert res.exit_code == 0, res.output
    for name, single in (("tiny", "same"), ("other", "other")):
        a = (tmp_path / "both" / name / "poses.tum").read_text()
        assert a == (tmp_path / single / "poses.tum").read_text()
    rows = [json.loads(x) for x in (tmp_path / "both" / "batch.jsonl").read_text().splitlines()]
    assert [r["status"] for r in rows] == ["ok", "ok"]
    assert rows[0]["figures"]["success_rate"] == same["success_rate"]
