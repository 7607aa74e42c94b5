"""``navkit planes extract`` over several real RGB-D inputs: 2 workers write the serial files,
a bad input is a failed row (exit code 3), ``--resume`` recomputes only what is missing."""

from __future__ import annotations

import json

import pytest

INTRINSICS = ("--intrinsics", "518,519,325.5,253.5")  # slambook-ch5's camera (data README)


@pytest.fixture
def rgbd_inputs(data_path):
    """Four cheap real inputs: a CAPE frame, two organised Kinect clouds, a slambook frame."""
    return [
        data_path("rgbd/cape-tunnel"),
        data_path("rgbd/pcl-kinect/capture0001.pcd"),
        data_path("rgbd/pcl-kinect/capture0002.pcd"),
        data_path("rgbd/slambook-ch5"),
    ]


KEYS = ("cape-tunnel", "capture0001", "capture0002", "slambook-ch5")


def _rows(out):
    return {r["key"]: r for r in map(json.loads, (out / "batch.jsonl").read_text().splitlines())}


def _files(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


def test_planes_on_two_workers_write_the_serial_files(cli, rgbd_inputs, tmp_path):
    pytest.importorskip(
        "distributed", reason="the cluster extra (dask.distributed) is not installed"
    )
    a, b = tmp_path / "serial", tmp_path / "dask"
    r = cli("planes", "extract", *rgbd_inputs, "-o", a, *INTRINSICS)
    assert r.exit_code == 0, r.output
    r = cli("planes", "extract", *rgbd_inputs, "-o", b, *INTRINSICS, "--workers", "2")
    assert r.exit_code == 0, r.output
    for key in KEYS:
        fa, fb = _files(a / key), _files(b / key)
        assert "planes.json" in fa and "overlay.png" in fa
        assert sorted(fa) == sorted(fb), key
        for name in fa:
            if name != ".navkit-done.json":
                assert fa[name] == fb[name], (key, name)
    ra, rb = _rows(a), _rows(b)
    assert [ra[k]["figures"] for k in KEYS] == [rb[k]["figures"] for k in KEYS]
    # every plane's normal is a unit vector and the textured inputs have one PNG per plane
    for key in KEYS:
        planes = json.loads((b / key / "planes.json").read_text())["planes"]
        assert len(planes) == rb[key]["figures"]["planes"] >= 2
        assert all(abs(sum(c * c for c in p["normal"]) - 1.0) < 1e-9 for p in planes)
        if rb[key]["figures"]["textures"]:
            assert rb[key]["figures"]["textures"] == len(planes)
            assert all((b / key / p["texture"]).is_file() for p in planes)


def test_one_input_alone_writes_the_batch_files(cli, rgbd_inputs, tmp_path):
    alone, many = tmp_path / "alone", tmp_path / "many"
    assert cli("planes", "extract", rgbd_inputs[1], "-o", alone).exit_code == 0
    assert cli("planes", "extract", *rgbd_inputs[1:3], "-o", many).exit_code == 0
    assert (alone / "planes.json").read_bytes() == (
        many / "capture0001" / "planes.json"
    ).read_bytes()
    assert (alone / "overlay.png").read_bytes() == (
        many / "capture0001" / "overlay.png"
    ).read_bytes()


def test_a_bad_input_is_a_failed_row_and_resume_redoes_only_the_missing(cli, rgbd_inputs, tmp_path):
    bad = tmp_path / "broken.pcd"
    bad.write_bytes(b"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\n")  # header cut short
    inputs = [*rgbd_inputs[:2], bad, rgbd_inputs[3]]
    out = tmp_path / "b"
    r = cli("planes", "extract", *inputs, "-o", out, *INTRINSICS)
    assert r.exit_code == 3, r.output
    rows = _rows(out)
    assert rows["broken"]["status"] == "failed" and "broken.pcd" in rows["broken"]["error"]
    assert len(rows["broken"]["error"].splitlines()) == 1
    assert not (out / "broken" / "planes.json").exists()
    good = [k for k in rows if k != "broken"]
    assert all(rows[k]["status"] == "ok" for k in good)
    before = {k: (out / k / "planes.json").stat().st_mtime_ns for k in good}
    (out / "capture0001" / "planes.json").unlink()
    r = cli(
        "planes", "extract", *rgbd_inputs[:2], rgbd_inputs[3], "-o", out, *INTRINSICS, "--resume"
    )
    assert r.exit_code == 0, r.output
    rows = _rows(out)
    assert {k: v["status"] for k, v in rows.items()} == {
        "cape-tunnel": "skipped",
        "capture0001": "ok",
        "slambook-ch5": "skipped",
    }
    assert (out / "capture0001" / "planes.json").is_file()
    for k in ("cape-tunnel", "slambook-ch5"):  # untouched
        assert (out / k / "planes.json").stat().st_mtime_ns == before[k]
