"""``navkit obstacles detect``: every output on a simulated scan and a real frame; clear errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from navkit.experiments.obstacles import run_experiment


@pytest.fixture(scope="module")
def four_npz(tmp_path_factory):
    r = run_experiment("four", "tilting", 0.01, 0)
    s = r.sim.scan
    path = tmp_path_factory.mktemp("scans") / "four.npz"
    np.savez(
        path,
        ranges=s.ranges,
        azimuth=s.azimuth,
        elevation=s.elevation,
        sensor_height=s.sensor_height,
    )
    return path, r


def test_detect_on_a_grid_writes_every_output(cli, four_npz, tmp_path):
    from navkit.io.maps import read_occupancy_grid

    path, r = four_npz
    out = tmp_path / "out"
    res = cli(
        "obstacles", "detect", path, "--out", out, "--resolution", "0.1", "--extent", "20",
        "--outputs", "labels,obstacles,grid,png,geojson", "--origin", "48.8584,2.2945,90",
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    frame = out / "four"
    assert sorted(p.name for p in frame.iterdir()) == sorted(
        ["labels.npy", "obstacles.json", "map.pgm", "map.yaml", "map.geojson", "map.png"]
    )
    labels = np.load(frame / "labels.npy")
    assert labels.dtype == np.int8 and labels.shape == r.sim.scan.shape
    # the same classes as the library on the same scan (the .npz is in the scan's own order)
    assert np.array_equal(labels, np.asarray(r.detection.vertex_labels))
    obs = json.loads((frame / "obstacles.json").read_text())["obstacles"]
    assert len(obs) == 4
    for o in obs:
        assert {
            "id",
            "n_points",
            "height",
            "boundary_polygon",
            "shapes",
            "A7",
            "shadow_area",
        } <= set(o)
        assert set(o["shapes"]) == {"A1", "A2", "A3", "A4", "A5", "A6", "MEC", "MVEE"}
        assert all("area" in p for p in o["shapes"].values())
    # the occupancy grid: the box at (6, 2.5) is occupied, the ground in front of the robot free,
    # the region behind the box (its shadow) unknown
    grid = read_occupancy_grid(frame / "map.yaml")

    def cell(x, y):
        r = int((y - grid.origin_xy[1]) / grid.resolution)
        return grid.occupancy[r, int((x - grid.origin_xy[0]) / grid.resolution)]

    assert cell(5.6, 2.5) == 100
    assert cell(3.0, 0.0) == 0
    assert cell(-3.0, 0.0) == -1  # behind the scanner: never seen
    gj = json.loads((frame / "map.geojson").read_text())
    kinds = {f["properties"].get("shape") for f in gj["features"]}
    assert {"A1", "A6"} <= kinds  # the --plot-shapes, georeferenced
    assert gj["properties"]["coordinates"].startswith("WGS84")
    # x points east (heading 90): the box near x = 6 m lies east of the origin, within 20 m
    box = next(o for o in obs if np.mean(np.array(o["boundary_polygon"])[:, 0]) > 4)
    poly = next(
        f for f in gj["features"] if f["properties"].get("obstacle") == box["id"]
        and f["properties"]["kind"] == "boundary"
    )  # fmt: skip
    lon, lat = np.array(poly["geometry"]["coordinates"][0]).mean(axis=0)
    assert 2.2945 + 4 / 73_000 < lon < 2.2945 + 20 / 73_000  # 1 deg of longitude ~ 73 km here
    assert abs(lat - 48.8584) < 10 / 111_000
    summary = json.loads((out / "summary.json").read_text())
    t = summary["frames"][0]["timings_s"]
    assert {"points", "mesh", "classes", "split", "boundaries", "map"} <= set(t)
    assert (out / "settings.toml").is_file()


def test_detect_on_a_kitti_frame(cli, data_path, tmp_path):
    from navkit.io.pointcloud import read_kitti_bin

    src = data_path("lidar/semantickitti-seq00/000000.bin")
    out = tmp_path / "out"
    res = cli(
        "obstacles", "detect", src, "--out", out, "--sensor-height", "1.73", "--shapes", "A1,MEC"
    )
    assert res.exit_code == 0, res.output
    labels = np.load(out / "000000" / "labels.npy")
    assert labels.shape == (len(read_kitti_bin(src)),)  # one label per input point, input order
    assert set(np.unique(labels)) <= {0, -1, -2, -3, -4}
    assert (labels == 0).mean() > 0.4  # about half of an urban scan is road and sidewalk


def test_bad_inputs_give_clear_errors_and_no_partial_outputs(cli, tmp_path, four_npz):
    bad = tmp_path / "cut.bin"
    bad.write_bytes(np.arange(10, dtype=np.float32).tobytes()[:-2])  # not a multiple of 16 bytes
    out = tmp_path / "out"
    res = cli("obstacles", "detect", bad, "--out", out)
    assert res.exit_code == 2
    assert "cut.bin" in res.output
    assert not (out / "cut").exists()
    wrong = tmp_path / "wrong.npz"
    np.savez(wrong, ranges=np.ones((3, 4)), azimuth=np.zeros(2), elevation=np.zeros(4))
    res = cli("obstacles", "detect", wrong, "--out", out)
    assert res.exit_code == 2 and "ranges" in res.output
    res = cli("obstacles", "detect", tmp_path / "nothing_*.bin", "--out", out)
    assert res.exit_code == 2
    depth = tmp_path / "d.png"
    import cv2

    cv2.imwrite(str(depth), np.full((4, 4), 1000, np.uint16))
    res = cli("obstacles", "detect", depth, "--out", out)
    assert res.exit_code == 2 and "--intrinsics" in res.output
    res = cli("obstacles", "detect", four_npz[0], "--out", out, "--shapes", "A1,B2")
    assert res.exit_code == 2 and "shapes" in res.output


def test_a_folder_of_inputs_gives_one_subfolder_each(cli, tmp_path, four_npz):
    src = tmp_path / "scans"
    src.mkdir()
    for name in ("a", "b"):
        (src / f"{name}.npz").write_bytes(four_npz[0].read_bytes())
    out = tmp_path / "out"
    res = cli("obstacles", "detect", src, "--out", out, "--shapes", "A1")
    assert res.exit_code == 0, res.output
    assert (out / "a" / "labels.npy").is_file() and (out / "b" / "labels.npy").is_file()
    assert json.loads((out / "summary.json").read_text())["n_frames"] == 2


def test_detect_on_an_organised_pcd(cli, tmp_path, four_npz):
    from navkit.io.pointcloud import PointCloud, write_pcd

    _, r = four_npz
    P = r.sim.scan.points("sensor")  # (n_az, n_el, 3); stored image-like: rows = elevation
    image = P.transpose(1, 0, 2)[::-1, ::-1]
    h, w = image.shape[:2]
    path = tmp_path / "four.pcd"
    write_pcd(path, PointCloud(image.reshape(-1, 3), width=w, height=h))
    out = tmp_path / "out"
    res = cli("obstacles", "detect", path, "--out", out, "--sensor-height", "2.0", "--shapes", "A1")
    assert res.exit_code == 0, res.output
    labels = np.load(out / "four" / "labels.npy")
    assert labels.shape == (h * w,)
    assert len(json.loads((out / "four" / "obstacles.json").read_text())["obstacles"]) == 4
    # NaN points (no return) of the organised cloud are outside the grid
    assert np.all(labels[~np.all(np.isfinite(image.reshape(-1, 3)), axis=1)] == -1)


KITTI_GROUND = (40, 44, 48)  # SemanticKITTI road, parking, sidewalk
KITTI_SOLID = (10, 50, 51, 70, 71, 80, 81)  # car, building, fence, vegetation, trunk, pole, sign


def test_kitti_sequence_with_the_default_outputs(cli, data_path, tmp_path):
    """Three KITTI frames, nothing but defaults: small per-frame outputs, the height measured
    from the ground, the labels right against SemanticKITTI's, reruns refused."""
    from navkit.io.pointcloud import read_kitti_labels

    folder = data_path("lidar/semantickitti-seq00/000000.bin").parent
    out = tmp_path / "kitti"
    res = cli("obstacles", "detect", folder, "-o", out)
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_frames"] == 3 and summary["outputs"] == ["labels", "obstacles"]
    h = summary["sensor_height"]
    assert h["source"] == "estimated from the ground" and h["estimate"]["plausible"]
    assert abs(h["m"] - 1.73) < 0.05
    for f in summary["frames"]:
        frame = Path(f["output"])
        assert sorted(p.name for p in frame.iterdir()) == ["labels.npy", "obstacles.json"]
        written = sum(p.stat().st_size for p in frame.iterdir())
        assert written == f["bytes_written"] and written < 300_000  # measured ~210 kB (was 4.9 MB)
        labels = np.load(frame / "labels.npy")
        sk = read_kitti_labels(folder / (frame.name + ".label"))[0]
        assert labels.shape == sk.shape
        assert (labels[np.isin(sk, KITTI_GROUND)] == 0).mean() > 0.98  # measured 0.995-0.996
        assert (labels[np.isin(sk, KITTI_SOLID)] == -2).mean() > 0.90  # measured 0.93-0.94
        used = json.loads((frame / "obstacles.json").read_text())["sensor_height"]["m"]
        assert used == pytest.approx(h["m"], abs=5e-4)  # obstacles.json rounds to 1 mm
    again = cli("obstacles", "detect", folder, "-o", out)
    assert again.exit_code == 2 and "--overwrite" in again.output and str(out) in again.output
    assert cli("obstacles", "detect", folder, "-o", out, "--overwrite", "-q").exit_code == 0


def test_geojson_needs_an_origin_and_presets_fill_the_layout(cli, data_path, tmp_path):
    src = data_path("lidar/semantickitti-seq00/000000.bin")
    res = cli("obstacles", "detect", src, "-o", tmp_path / "a", "--outputs", "labels,geojson")
    assert res.exit_code == 2 and "--origin" in res.output
    res = cli("obstacles", "detect", src, "-o", tmp_path / "b", "--sensor", "hdl64e-kitti")
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "b" / "summary.json").read_text())
    assert summary["frames"][0]["grid_shape"][1] == 64  # the preset's 64 beams
    assert abs(summary["sensor_height"]["m"] - 1.73) < 0.05
    res = cli("obstacles", "detect", src, "-o", tmp_path / "c", "--sensor", "hdl-65")
    assert res.exit_code == 2 and "vlp16" in res.output


@pytest.mark.parametrize("batch", [(), ("--resume",)])
def test_a_failed_frame_is_reported_and_the_sequence_goes_on(cli, tmp_path, four_npz, batch):
    """One bad frame of three: the others are done, the bad one has no folder, exit code 3
    (the same with ``--resume``, which runs the frames as a batch)."""
    src = tmp_path / "seq"
    src.mkdir()
    (src / "a.npz").write_bytes(four_npz[0].read_bytes())
    np.savez(src / "b.npz", ranges=np.ones((3, 4)), azimuth=np.zeros(2), elevation=np.zeros(4))
    (src / "c.npz").write_bytes(four_npz[0].read_bytes())
    out = tmp_path / "out"
    res = cli("obstacles", "detect", src, "-o", out, *batch)
    assert res.exit_code == 3, res.output
    assert "1 failed" in res.stdout
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == ["a", "c"]  # nothing for b
    if batch:
        return
    rows = (out / "frames.csv").read_text().splitlines()
    assert rows[0] == "frame,input,status,n_obstacles,reason"
    assert rows[1].startswith("a,") and rows[1].split(",")[2:4] == ["ok", "4"]
    assert rows[2].startswith("b,") and ",failed,," in rows[2] and "ranges" in rows[2]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["n_frames"] == 2 and [f["input"] for f in summary["failed"]] == [
        str(src / "b.npz")
    ]
    assert summary["reference"].startswith("none")


def test_settings_toml_of_a_run_reproduces_it(cli, tmp_path, four_npz):
    out1, out2 = tmp_path / "one", tmp_path / "two"
    args = ("--resolution", "0.2", "--outputs", "labels,grid", "--c0-deg", "15")
    assert cli("obstacles", "detect", four_npz[0], "-o", out1, *args).exit_code == 0
    res = cli("obstacles", "detect", four_npz[0], "-o", out2, "--config", out1 / "settings.toml")
    assert res.exit_code == 0, res.output
    assert (out2 / "settings.toml").read_text() == (out1 / "settings.toml").read_text()
    assert (out2 / "four" / "map.pgm").read_bytes() == (out1 / "four" / "map.pgm").read_bytes()
    assert np.array_equal(
        np.load(out2 / "four" / "labels.npy"), np.load(out1 / "four" / "labels.npy")
    )
