"""The folder formats as streams (KITTI, CARMEN, RGB-D, trajectories), the pipeline's topic
mapping and its errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from navkit.errors import ConfigError, InputError
from navkit.runtime import open_source, resolve_pipeline, run_recording

pytest.importorskip("mcap", reason="mcap (extra 'ros') not installed")
pytest.importorskip("rosbags", reason="rosbags (extra 'ros') not installed")


def test_auto_topics_and_errors():
    topics = {"/points": "cloud", "/scan": "scan", "/odom": "pose", "/ground_truth": "pose"}
    p = resolve_pipeline("rec", topics)
    assert p.topics.pose == p.topics.reference == "/ground_truth"
    assert p.topics.odometry == "/odom"
    assert set(p.capabilities) == {"obstacles", "obstacle_map", "wall_map", "path"}
    p = resolve_pipeline("rec", topics, map_path="map.json")
    assert "localization" in p.capabilities and "wall_map" not in p.capabilities
    p = resolve_pipeline(
        "rec", topics, {"topics": {"pose": "/odom"}, "run": {"capabilities": ["path"]}}
    )
    assert p.topics.pose == "/odom" and p.capabilities == ("path",)
    with pytest.raises(ConfigError, match=r"topics\.pose.*'/scan' is scan"):
        resolve_pipeline("rec", topics, {"topics": {"pose": "/scan"}})
    with pytest.raises(ConfigError, match=r"unknown keys \['resolution'\]"):
        resolve_pipeline("rec", topics, {"laser": {"resolution": 1}})
    with pytest.raises(ConfigError, match=r"planes.*no input"):
        resolve_pipeline("rec", topics, {"run": {"capabilities": ["planes"]}})
    with pytest.raises(ConfigError, match=r"laser\.sigma_m.*a number"):
        resolve_pipeline("rec", topics, {"laser": {"sigma_m": "wide"}})


def test_cli_refuses_to_overwrite_and_bad_input(cli, tmp_path):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "x.txt").write_text("earlier result")
    traj = tmp_path / "t.tum"
    traj.write_text("".join(f"{k * 0.1:.1f} {k * 0.1} 0 0 0 0 0 1\n" for k in range(20)))
    r = cli("run", traj, "--out", tmp_path / "out")
    assert r.exit_code == 2 and "--overwrite" in r.output
    assert cli("run", traj, "--out", tmp_path / "out", "--overwrite").exit_code == 0
    r = cli("run", tmp_path / "nothing.xyz", "--out", tmp_path / "o2")
    assert r.exit_code == 2 and "no such recording" in r.output
    (tmp_path / "junk.bin").write_bytes(b"x")
    with pytest.raises(InputError, match="not a recording"):
        open_source(tmp_path / "junk.bin")
    r = cli("run", traj, "--out", tmp_path / "o3", "--resume")
    assert r.exit_code == 2 and "checkpoint" in r.output
    # --map needs laser scans: a recording without any is refused before anything is written
    (tmp_path / "map.json").write_text("{}")
    r = cli("run", traj, "--out", tmp_path / "o4", "--map", tmp_path / "map.json")
    assert r.exit_code == 2 and r.output.count("\n") == 1, r.output
    assert r.output.startswith("error:") and "--map" in r.output and "no laser scans" in r.output
    assert not (tmp_path / "o4").exists() or not any((tmp_path / "o4").iterdir())


def test_trajectory_file_path_memory(data_path, tmp_path):
    """A TUM trajectory streamed pose by pose: path.json is the recorder's result on the same
    points (the online path memory sees them in the same order)."""
    from navkit.io.pathjson import read_path_json
    from navkit.io.trajectory import read_trajectory
    from navkit.path import ApproximatorSettings, OnlineApproximator

    f = data_path("trajectories/freiburg1_xyz-groundtruth.txt")
    s = run_recording(f, tmp_path / "o")
    tr = read_trajectory(f)
    rec = OnlineApproximator(ApproximatorSettings(tolerance=0.05))
    for p in tr.poses[:, :2, 3]:
        rec.update(p)
    want = rec.finish().spline
    got = read_path_json(tmp_path / "o" / "path" / "path.json")
    assert got.n_segments == want.n_segments == s["capabilities"]["path"]["segments"]
    np.testing.assert_allclose(got.total_length, want.total_length, rtol=1e-12)


def test_kitti_folder_equals_obstacles_detect(data_path, tmp_path, cli):
    folder = data_path("lidar/semantickitti-seq00")
    bins = sorted(folder.glob("*.bin"))[:2]
    assert cli("obstacles", "detect", *bins, "--out", tmp_path / "ref").exit_code == 0
    s = run_recording(folder, tmp_path / "run", {"run": {"max_items": 2}})
    assert s["capabilities"]["obstacles"]["messages"] == 2
    for k, b in enumerate(bins):
        np.testing.assert_array_equal(
            np.load(tmp_path / "run" / "obstacles" / f"{k:06d}" / "labels.npy"),
            np.load(tmp_path / "ref" / b.stem / "labels.npy"),
        )


def test_rgbd_folder_plane_odometry(data_path, tmp_path):
    """The slambook RGB-D folder through plane odometry: the same poses as PlaneOdometry on the
    frames read by ``io.rgbd`` (the runtime pairs colour and depth by stamp)."""
    from navkit.io.rgbd import open_rgbd_sequence
    from navkit.io.trajectory import read_tum
    from navkit.planes import ExtractionSettings, OdometrySettings, PlaneOdometry, observe_rgbd

    folder = data_path("rgbd/slambook-ch5")
    cam = {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0}
    s = run_recording(folder, tmp_path / "o", intrinsics=(518.0, 519.0, 325.5, 253.5))
    planes = s["capabilities"]["planes"]
    # one frame per RGB-D pair: 3 depth + 3 colour images and one CameraInfo are 3 frames
    assert planes["frames"] == 3 and planes["messages"] == 7
    assert planes["real_time_factor"] == pytest.approx(
        planes["sensor_period_s"] / (planes["seconds"] / 3), rel=1e-12
    )
    seq = open_rgbd_sequence(folder, cam)
    odo = PlaneOdometry(OdometrySettings())
    want = np.stack(
        [
            odo.update(observe_rgbd(seq.frame(i), ExtractionSettings(cell=20))).T_world_frame
            for i in range(3)
        ]
    )
    got = read_tum(tmp_path / "o" / "planes" / "trajectory.tum").poses
    np.testing.assert_allclose(got, want, atol=1e-6)
    recs = [json.loads(x) for x in (tmp_path / "o" / "frames.jsonl").read_text().splitlines()]
    first = next(r for r in recs if r["capability"] == "planes")
    assert (first["status"], first["source"]) == ("tracked", "first")
    # the TF tree of results.mcap: the folder's ground truth (world -> camera) is the camera's
    # parent, planes_odom hangs (static) where the truth had the camera at the first frame, and
    # world links to map; without a base in the folder the robot's pose is the camera's
    from navkit.io.results_mcap import read_messages
    from tests.runtime.test_runtime_robot import results_tf

    res = tmp_path / "o" / "results.mcap"
    tree, frames = results_tf(res)
    assert tree.parent == {"camera": "world", "planes_odom": "world", "world": "map"}
    assert frames["/navkit/planes/pose"] == frames["/navkit/planes/outlines"] == {"planes_odom"}
    pub = list(read_messages(res, ["/navkit/planes/pose"]))
    xyz = [
        [
            m.message.pose.pose.position.x,
            m.message.pose.pose.position.y,
            m.message.pose.pose.position.z,
        ]
        for m in pub
    ]
    np.testing.assert_allclose(xyz, want[:, :3, 3], atol=1e-6)
    st0 = pub[0].log_time_ns  # at the first frame the odometry's camera is the tree's camera
    np.testing.assert_allclose(
        tree.lookup("world", "planes_odom", st0) @ want[0],
        tree.lookup("world", "camera", st0),
        atol=1e-6,
    )


class _PosesAt10Hz:
    """A source of one TF at stamp 0 (as a ``/tf_static`` often is) then poses every 0.1 s from
    an hour into the recording: the recording's span is an hour, the sensor's period 0.1 s."""

    name = "poses at 10 Hz"
    n_frames = 30
    start_ns = 0
    end_ns = 3600 * 10**9 + (n_frames - 1) * 10**8
    n_items = n_frames + 1

    def __init__(self) -> None:
        self.topics = {"/tf_static": "tf", "/odom": "pose"}

    def messages(self, skip=0):
        from navkit.runtime.messages import Message

        items = [[Message("/tf_static", "tf", 0, "base_link", np.eye(4), "laser")]]
        for k in range(self.n_frames):
            T = np.eye(4)
            T[0, 3] = 0.05 * k
            items.append([Message("/odom", "pose", 3600 * 10**9 + k * 10**8, "odom", T, "laser")])
        yield from list(enumerate(items))[skip:]


def test_real_time_factor_is_the_sensor_period_over_the_work_per_frame(tmp_path):
    """Real-time factor = the frames' stamp spacing / the work per frame, not the recording's
    span (an hour here, because of a static transform at stamp 0) / the work."""
    src = _PosesAt10Hz()
    s = run_recording(src, tmp_path / "o")
    path = s["capabilities"]["path"]
    assert path["frames"] == path["messages"] == src.n_frames
    assert path["sensor_period_s"] == pytest.approx(0.1, abs=1e-12)
    per_frame = path["seconds"] / path["frames"]
    assert path["ms_per_frame"] == pytest.approx(1e3 * per_frame, rel=1e-12)
    assert path["real_time_factor"] == pytest.approx(0.1 / per_frame, rel=1e-12)


@pytest.mark.realdata
def test_a_bag_cut_at_60_percent_streams_up_to_the_cut(data_path, tmp_path):
    """A ROS 1 bag cut at 60 % of its bytes (a crash): the run reads every whole message before
    the cut, and its wall map uses every scan among them."""
    from navkit.io.rosbag import bag_info
    from tests.runtime.bags import write_carmen_bag

    log_gz = data_path("laser2d/freiburg-101-corrected.log.gz")
    whole = tmp_path / "whole.bag"
    n = write_carmen_bag(log_gz, whole, ros1=True, every=4)
    data = whole.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: int(0.6 * len(data))])
    info = bag_info(cut)
    scans = info.topics["/scan"][1]
    assert 0.5 * n < scans < n  # 3 messages per scan time, evenly spread over the bytes
    s = run_recording(cut, tmp_path / "o")
    assert s["messages"] == info.n_messages
    assert s["capabilities"]["wall_map"]["frames"] == scans
