"""Batch options of the commands on the real SemanticKITTI frames: identical files, failures as
rows (exit code 3), resume recomputes only what is missing."""

from __future__ import annotations

import json
import shutil

import pytest

FRAMES = ("000000", "000001", "000002")


@pytest.fixture
def kitti(data_path, tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    for f in FRAMES:
        shutil.copy(data_path(f"lidar/semantickitti-seq00/{f}.bin"), src / f"{f}.bin")
    return src


def _rows(out):
    return {r["key"]: r for r in map(json.loads, (out / "batch.jsonl").read_text().splitlines())}


def test_obstacles_on_two_workers_write_the_serial_files(cli, kitti, tmp_path):
    pytest.importorskip(
        "distributed", reason="the cluster extra (dask.distributed) is not installed"
    )
    a, b = tmp_path / "serial", tmp_path / "dask"
    common = ("--sensor", "hdl64e-kitti", "--outputs", "labels,obstacles,grid")
    assert cli("obstacles", "detect", kitti, "-o", a, *common).exit_code == 0
    r = cli("obstacles", "detect", kitti, "-o", b, *common, "--workers", "2")
    assert r.exit_code == 0, r.output
    for f in FRAMES:
        for name in ("labels.npy", "obstacles.json", "map.pgm", "map.yaml"):
            assert (a / f / name).read_bytes() == (b / f / name).read_bytes(), (f, name)
    rows = _rows(b)
    assert sorted(rows) == list(FRAMES) and {r["status"] for r in rows.values()} == {"ok"}
    serial = json.loads((a / "summary.json").read_text())
    assert [fr["n_obstacles"] for fr in serial["frames"]] == [
        rows[f]["figures"]["n_obstacles"] for f in FRAMES
    ]


def test_a_bad_frame_is_a_failed_row_and_resume_redoes_only_the_missing(cli, kitti, tmp_path):
    (kitti / "broken.bin").write_bytes(b"\x00" * 10)  # not a multiple of 16 bytes
    out = tmp_path / "b"
    r = cli("obstacles", "detect", kitti, "-o", out, "--sensor", "hdl64e-kitti", "--resume")
    assert r.exit_code == 3, r.output
    rows = _rows(out)
    assert rows["broken"]["status"] == "failed" and "broken.bin" in rows["broken"]["error"]
    assert all(rows[f]["status"] == "ok" for f in FRAMES)
    (out / "000001" / "labels.npy").unlink()
    (kitti / "broken.bin").unlink()
    r = cli("obstacles", "detect", kitti, "-o", out, "--sensor", "hdl64e-kitti", "--resume")
    assert r.exit_code == 0, r.output
    rows = _rows(out)
    assert {k: v["status"] for k, v in rows.items()} == {
        "000000": "skipped",
        "000001": "ok",
        "000002": "skipped",
    }
    assert (out / "000001" / "labels.npy").is_file()


def test_path_record_many_trajectories_in_one_batch(cli, data_path, tmp_path):
    tum = data_path("trajectories/freiburg1_xyz-groundtruth.txt")
    kitti = data_path("trajectories/KITTI_00_gt.txt")
    alone = tmp_path / "alone"
    assert cli("path", "record", tum, "-o", alone).exit_code == 0
    out = tmp_path / "many"
    r = cli("path", "record", tum, kitti, "-o", out)
    assert r.exit_code == 0, r.output
    # the batch writes each input's path.json exactly as the single-input command does
    assert (out / tum.stem / "path.json").read_bytes() == (alone / "path.json").read_bytes()
    rows = _rows(out)
    assert {k: r["status"] for k, r in rows.items()} == {tum.stem: "ok", kitti.stem: "ok"}
    assert all(r["figures"]["max_deviation_m"] <= 0.05 + 1e-12 for r in rows.values())
    summary = json.loads((out / "summary.json").read_text())
    assert summary["rates"]["within_tolerance"]["successes"] == 2
