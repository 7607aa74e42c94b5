"""``navkit demo``: pictures of every simulated sensor with the truth, settings and summary."""

from __future__ import annotations

import json

import cv2
import numpy as np
import tomllib

from navkit.viz.sensors import GROUND_COLOR, OBSTACLE_COLOR


def _has_color(img_rgb, rgb, tol=12):
    target = np.array(rgb) * 255
    return int((np.abs(img_rgb.astype(float) - target).max(axis=-1) < tol).sum())


def test_demo_writes_pictures_settings_and_summary(cli, tmp_path):
    out = tmp_path / "demo"
    res = cli("demo", "--out", out, "--small", "--seed", "3")
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "summary.json").read_text())
    settings = tomllib.loads((out / "settings.toml").read_text())
    assert settings["seed"] == 3 and settings["small"] is True and settings["scene"] == "yard"
    assert sorted(summary["outputs"]) == sorted(
        ["world.png", "lidar.png", "tilting_scanner.png", "rgbd.png", "stereo.png"]
    )
    for name in summary["outputs"]:
        img = cv2.imread(str(out / name), cv2.IMREAD_COLOR)
        assert img is not None, f"{name} is not a readable PNG"
        assert img.shape[0] > 200 and img.shape[1] > 200
        assert img.std() > 10, f"{name} looks blank"
        assert not list(out.glob(f".{name}*")), "temporary file left behind"
    # the lidar figure shows ground (green) and obstacle (red) truth colours
    lidar = cv2.cvtColor(cv2.imread(str(out / "lidar.png")), cv2.COLOR_BGR2RGB)
    assert _has_color(lidar, GROUND_COLOR) > 500 and _has_color(lidar, OBSTACLE_COLOR) > 100
    # the summary's counts are consistent: 16 x 512 rays, ground + obstacle = returns
    lid = summary["sensors"]["lidar"]
    assert lid["rays"] == 16 * 512
    assert lid["ground_returns"] + lid["obstacle_returns"] == lid["returns"]
    assert sum(lid["returns_per_primitive"].values()) == lid["returns"]
    # the robot at the yard's start sees crate_1 and the west building with the lidar
    assert lid["returns_per_primitive"].get("crate_1", 0) > 0
    assert lid["returns_per_primitive"].get("building_west", 0) > 0
    # stereo truth: the bottom image row sees the ground nearest. The mission's stereo pair
    # (StereoSettings: 1.0 m high, level, 80 deg horizontal FOV, 0.3 m baseline) at 160 x 120 px:
    # f = 80 / tan(40 deg); the bottom row centre is 59.5 px below the axis, so its rays dip
    # atan(59.5 / f) below the horizon and (no roll) every pixel of that row has depth
    # z = h cos(dip) / sin(dip) on the flat ground under the start pose.
    from navkit.mission.settings import StereoSettings

    st = StereoSettings()
    assert (st.height, st.hfov_deg, st.baseline) == (1.0, 80.0, 0.3)
    f = 80.0 / np.tan(np.radians(40.0))
    a = np.arctan(59.5 / f)
    z = st.height * np.cos(a) / np.sin(a)
    lo, hi = summary["sensors"]["stereo"]["disparity_px"]
    np.testing.assert_allclose(hi, 0.3 * f / z, rtol=1e-9)
    assert 0 < lo < hi
    # the data in standard formats agree with the summary
    from navkit.io.images import read_depth, read_pfm
    from navkit.io.pointcloud import read_pcd

    cloud = read_pcd(out / "data" / "lidar.pcd")
    assert (cloud.height, cloud.width) == (16, 512)
    labels = np.asarray(cloud.fields["label"]).ravel()
    assert (labels == 1).sum() == lid["ground_returns"]
    assert (labels == 2).sum() == lid["obstacle_returns"]
    assert np.isnan(cloud.points[labels == 0]).all() and np.isfinite(cloud.points[labels > 0]).all()
    disp = read_pfm(out / "data" / "stereo_disparity_true.pfm")
    np.testing.assert_allclose(np.nanmax(disp), hi, rtol=1e-6)  # float32 storage
    depth = read_depth(out / "data" / "rgbd_depth.png", 1000.0)
    dmin, dmax = summary["sensors"]["rgbd"]["depth_range_m"]
    # millimetre steps: within half a millimetre of the summary's range
    assert abs(np.nanmin(depth) - dmin) <= 0.0005 + 1e-9
    assert abs(np.nanmax(depth) - dmax) <= 0.0005 + 1e-9


def test_demo_bad_scene_is_a_clean_error(cli, tmp_path):
    res = cli("demo", "--out", tmp_path / "x", "--scene", str(tmp_path / "missing.toml"), "--small")
    assert res.exit_code == 2
    assert "error:" in res.output and "missing.toml" in res.output
    bad = tmp_path / "bad.toml"
    bad.write_text('[[primitive]]\ntype = "sphere"\ncenter = [0, 0, 1]\nradius = -1\n')
    res = cli("demo", "--out", tmp_path / "y", "--scene", str(bad), "--small")
    assert res.exit_code == 2
    assert "bad.toml" in res.output and "radius" in res.output
    assert "Traceback" not in res.output
    assert not (tmp_path / "y" / "summary.json").exists()


def test_demo_out_must_be_a_folder(cli, tmp_path):
    target = tmp_path / "a_file"
    target.write_text("x")
    res = cli("demo", "--out", target, "--small")
    assert res.exit_code == 2 and "is a file" in res.output and "--out" in res.output
    assert target.read_text() == "x"
