"""``navkit obstacles detect``: every output on a simulated scan and a real frame; clear errors."""

from __future__ import annotations

import json

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
    res = cli("obstacles", "detect", path, "--out", out, "--resolution", "0.1", "--extent", "20")
    assert res.exit_code == 0, res.output
    frame = out / "four"
    for name in ("labels.npy", "obstacles.json", "map.pgm", "map.yaml", "map.geojson", "map.png"):
        assert (frame / name).is_file(), name
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
    assert {"A1", "A6", "MVEE", "A7:A1"} <= kinds
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
    assert res.exit_code == 2 and "--camera" in res.output
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
