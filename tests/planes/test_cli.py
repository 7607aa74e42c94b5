"""``navkit planes extract`` / ``navkit planes odometry`` on simulated folders and real frames."""

from __future__ import annotations

import json

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from navkit.geometry import se3_from_rt, se3_inverse
from navkit.geometry.rotations import rotation_angle
from navkit.io.trajectory import read_tum
from navkit.sim import render_rgbd

from .conftest import CAMERA, DEPTH_NOISE, corridor, start_pose


def write_sequence(root, n_dirs=2, n=4):
    """A simulated RGB-D sequence in the simple layout; returns the true T_world_camera poses."""
    (root / "color").mkdir(parents=True)
    (root / "depth").mkdir()
    scene = corridor(n_dirs)
    step = se3_from_rt(
        Rotation.from_rotvec([0, -0.04, 0]).as_matrix(), [0.0, 0.0, 0.15]
    )  # forward + turn
    T = start_pose(n_dirs)
    poses = []
    for k in range(n):
        f = render_rgbd(scene, CAMERA, T, noise=DEPTH_NOISE, rng=k).frame
        cv2.imwrite(str(root / "color" / f"{k:04d}.png"), f.color[..., ::-1])
        cv2.imwrite(
            str(root / "depth" / f"{k:04d}.png"),
            np.nan_to_num(f.depth * 1000).round().astype(np.uint16),
        )
        poses.append(T)
        T = T @ step
    (root / "camera.yaml").write_text(
        f"fx: {CAMERA.fx}\nfy: {CAMERA.fy}\ncx: {CAMERA.cx}\ncy: {CAMERA.cy}\ndepth_scale: 1000\n"
    )
    return np.array(poses)


def test_extract_cli(tmp_path, cli):
    write_sequence(tmp_path / "seq", n_dirs=3, n=1)
    out = tmp_path / "out"
    res = cli("planes", "extract", tmp_path / "seq", "--out", out, "--cell", "10")
    assert res.exit_code == 0, res.output
    data = json.loads((out / "planes.json").read_text())
    assert len(data["planes"]) == 3
    for p in data["planes"]:
        assert np.isclose(np.linalg.norm(p["normal"]), 1.0)
        assert (out / p["texture"]).is_file()
    assert (out / "overlay.png").is_file() and (out / "settings.toml").is_file()
    assert json.loads((out / "summary.json").read_text())["planes"] == 3


def test_odometry_cli_two_planes(tmp_path, cli):
    truth = write_sequence(tmp_path / "seq", n_dirs=2, n=4)
    out = tmp_path / "odo"
    res = cli("planes", "odometry", tmp_path / "seq", "--out", out, "--cell", "10")
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["tracked"] == 4 and summary["failed"] == 0 and summary["cases"]["2"] == 3
    rows = (out / "frames.csv").read_text().splitlines()
    assert rows[0] == "index,timestamp,status,source,reason" and len(rows) == 5
    assert all(r.split(",")[2] == "tracked" for r in rows[1:])
    traj = read_tum(out / "trajectory.tum")
    ref = se3_inverse(truth[0]) @ truth
    E = se3_inverse(ref[-1]) @ traj.poses[-1]
    # three 2-plane steps, each within 0.1 deg / 5 mm (test_solve), depth quantised to 1 mm:
    # the chained error stays below 3 x those
    assert np.degrees(rotation_angle(E[:3, :3])) < 0.3 and np.linalg.norm(E[:3, 3]) < 0.015
    mp = json.loads((out / "map.json").read_text())
    assert len(mp["planes"]) == 2  # wall and floor, merged over the four frames
    assert all(len(p["observations"]) == 4 for p in mp["planes"])
    assert (out / "map.ply").stat().st_size > 1000 and (out / "map.png").is_file()


def test_bad_input_exits_2(tmp_path, cli):
    res = cli("planes", "extract", tmp_path, "--out", tmp_path / "o")
    assert res.exit_code == 2
    assert "rgb.txt, color/ nor frame-NNNNNN" in res.output


def test_extract_cape_and_pcd(cli, data_path, tmp_path):
    res = cli("planes", "extract", data_path("rgbd/cape-tunnel"), "--out", tmp_path / "cape")
    assert res.exit_code == 0, res.output
    planes = json.loads((tmp_path / "cape" / "planes.json").read_text())["planes"]
    assert len(planes) >= 2 and all("texture" in p for p in planes)
    pcd = data_path("rgbd/pcl-kinect/capture0001.pcd")
    res = cli("planes", "extract", pcd, "--out", tmp_path / "pcd")
    assert res.exit_code == 0, res.output
    # each of the four largest planes agrees with an independent least-squares fit of the raw
    # cloud's points near it (within 3 rms of the plane, within 1.5 equal-area radii of its
    # centroid); measured: 0.06-0.41 deg, 1.4-2.5 mm, 0.87-1.24x the reported inliers
    from navkit.io.pointcloud import read_pcd

    P = read_pcd(pcd).points[:, :3].astype(np.float64)
    P = P[np.all(np.isfinite(P), axis=1)]
    found = json.loads((tmp_path / "pcd" / "planes.json").read_text())["planes"]
    assert len(found) >= 4
    for p in sorted(found, key=lambda p: -p["inliers"])[:4]:
        n, rho, c0 = np.array(p["normal"]), p["rho"], np.array(p["centroid"])
        near = P[
            (np.abs(P @ n - rho) < 3 * p["rms"])
            & (np.linalg.norm(P - c0, axis=1) < 1.5 * np.sqrt(p["area_m2"] / np.pi))
        ]
        assert 0.6 * p["inliers"] < len(near) < 1.6 * p["inliers"]
        m = np.linalg.svd(near - near.mean(axis=0), full_matrices=False)[2][-1]
        assert np.degrees(np.arccos(min(1.0, abs(float(m @ n))))) < 1.5
        assert abs(abs(float(m @ near.mean(axis=0))) - rho) < 0.01


def test_out_dir_is_not_overwritten_silently(tmp_path, cli):
    write_sequence(tmp_path / "seq", n_dirs=3, n=1)
    out = tmp_path / "out"
    assert cli("planes", "extract", tmp_path / "seq", "-o", out, "--cell", "10").exit_code == 0
    res = cli("planes", "extract", tmp_path / "seq", "-o", out, "--cell", "10")
    assert res.exit_code == 2 and "--overwrite" in res.output
    res = cli("planes", "extract", tmp_path / "seq", "-o", out, "--cell", "10", "--overwrite")
    assert res.exit_code == 0, res.output


def test_missing_camera_yaml_says_how_to_give_intrinsics(tmp_path, cli):
    write_sequence(tmp_path / "seq", n_dirs=3, n=1)
    (tmp_path / "seq" / "camera.yaml").unlink()
    res = cli("planes", "extract", tmp_path / "seq", "-o", tmp_path / "o")
    assert res.exit_code == 2
    assert "camera.yaml: not found" in res.output and "--intrinsics" in res.output
    assert "field fx" not in res.output
    c = CAMERA
    res = cli(
        "planes",
        "extract",
        tmp_path / "seq",
        "-o",
        tmp_path / "o2",
        "--cell",
        "10",
        "--intrinsics",
        f"{c.fx},{c.fy},{c.cx},{c.cy}",
    )  # depth scale: the default 1000 (the folder's depth is in millimetres)
    assert res.exit_code == 0, res.output
    assert json.loads((tmp_path / "o2" / "summary.json").read_text())["planes"] == 3
    res = cli("planes", "extract", tmp_path / "seq", "-o", tmp_path / "o3", "--intrinsics", "1,2")
    assert res.exit_code == 2 and "FX,FY,CX,CY" in res.output


def test_config_file_sets_options(tmp_path, cli):
    write_sequence(tmp_path / "seq", n_dirs=3, n=1)
    (tmp_path / "c.toml").write_text("[planes]\ncell = 10\nnu = 0.02\n")
    res = cli(
        "planes", "extract", tmp_path / "seq", "-o", tmp_path / "o", "--config", tmp_path / "c.toml"
    )
    assert res.exit_code == 0, res.output
    settings = (tmp_path / "o" / "settings.toml").read_text()
    assert "cell = 10" in settings and "nu = 0.02" in settings


def test_odometry_on_7scenes_writes_only_tracked_poses(cli, data_path, tmp_path):
    """The 7-Scenes folder as it is (intrinsics and reference picked up): 6 frames."""
    out = tmp_path / "o"
    res = cli("planes", "odometry", data_path("rgbd/7scenes-tsdf"), "-o", out, "--max-frames", "6")
    assert res.exit_code == 0, res.output
    summary = json.loads((out / "summary.json").read_text())
    rows = (out / "frames.csv").read_text().splitlines()[1:]
    tracked = [r for r in rows if r.split(",")[2] == "tracked"]
    assert len(rows) == 6 and summary["tracked"] == len(tracked)
    assert len(read_tum(out / "trajectory.tum").poses) == len(tracked)
    assert summary["ate_m"] < 0.01  # measured 0.1-0.2 cm over 6 frames
    assert "7scenes-tsdf" in (out / "settings.toml").read_text()


def test_odometry_on_a_tum_folder_uses_its_truth_at_the_frame_times(cli, data_path, tmp_path):
    """A TUM RGB-D folder is read at its format's depth scale (5000) with the intrinsics of the
    Kinect its name names (fr3), and its ``groundtruth.txt`` (100 Hz motion capture, starting
    after the camera) is interpolated at the frames' times: frames it does not cover are left out
    of the figures, never paired with another frame's pose.

    Bounds: the Kinect's depth noise sigma_z = 1.6e-3 z^2 (Khoshelham & Elberink 2012) is 1.0 cm
    at the structure's mean depth (~2.5 m) and 3.0 cm at its far end (~4.3 m); a frame-to-frame
    motion within the former and a trajectory within the latter is right at the sensor's own
    noise."""
    folder = data_path("rgbd/tum-fr3-structure-notexture-far")
    out = tmp_path / "tum"
    res = cli("planes", "odometry", folder, "-o", out, "--max-frames", "12")
    assert res.exit_code == 0, res.output
    s = json.loads((out / "summary.json").read_text())
    assert s["tracked"] == s["frames"] == 12
    # the reference starts after the camera: some, not all, frames are covered
    assert 2 <= s["reference_frames"] < 12
    assert s["rpe_trans_m"] <= 1.6e-3 * 2.5**2
    assert s["ate_m"] <= 1.6e-3 * 4.3**2
    settings = (out / "settings.toml").read_text()
    assert "groundtruth.txt" in settings


def test_tum_folders_get_their_kinects_intrinsics(tmp_path):
    from navkit.io.rgbd import TUM_CAMERAS, TUM_DEFAULT, tum_camera

    assert tum_camera(tmp_path / "rgbd_dataset_freiburg3_long_office") == TUM_CAMERAS["fr3"]
    assert tum_camera(tmp_path / "tum-fr1-xyz") == TUM_CAMERAS["fr1"]
    assert tum_camera(tmp_path / "rgbd_dataset_freiburg2_desk") == TUM_CAMERAS["fr2"]
    assert tum_camera(tmp_path / "my_frames") == TUM_DEFAULT
    assert tum_camera(tmp_path / "fr30") == TUM_DEFAULT
