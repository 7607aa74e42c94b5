"""The TF tree in the runtime: ``/tf_static`` + time-interpolated ``/tf`` carry a pose
topic's child frame to the sensor frame, so a ``PointCloud2`` in ``velodyne`` with odometry of
the base is placed where the obstacles are.

The synthetic bag (``rosbags``' ROS 2 writer, mcap storage): a simulated world (flat ground, two
boxes at known places), the base driving and turning (``nav_msgs/Odometry`` odom ->
base_footprint at 20 Hz), a turret turning on it (``/tf`` base_footprint -> base_link at 50 Hz),
the lidar mounted off-centre and turned on the turret (``/tf_static`` base_link -> velodyne), and
16-beam clouds rendered at the true sensor pose at 5 Hz, between the pose samples.
"""

from __future__ import annotations

import numpy as np
import pytest

from navkit.geometry import se3_from_rt
from navkit.runtime.tf import TransformTree

BOXES = (((7.0, 3.0), (1.0, 1.2)), ((6.0, -3.5), (1.4, 0.8)))  # centre, size (x, y)


def _rz(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def T_odom_footprint(t: float) -> np.ndarray:
    return se3_from_rt(_rz(0.15 * t), [0.8 * t, 0.1 * t + 0.05 * t * t, 0.0])


def T_footprint_link(t: float) -> np.ndarray:
    return se3_from_rt(_rz(0.3 * np.sin(1.5 * t)), [0.1, 0.0, 0.3])


T_LINK_VELODYNE = se3_from_rt(_rz(np.radians(25.0)), [0.4, -0.2, 1.2])


def T_odom_velodyne(t: float) -> np.ndarray:
    return T_odom_footprint(t) @ T_footprint_link(t) @ T_LINK_VELODYNE


# --------------------------------------------------------------------------- the tree itself
def test_lookup_static_dynamic_interpolated_and_inverse():
    tree = TransformTree(maxlen=8)
    tree.add("base_link", "velodyne", 0, T_LINK_VELODYNE, static=True)
    for k in range(20):  # 50 Hz, only the last 8 kept
        t = 0.02 * k
        tree.add("base_footprint", "base_link", round(t * 1e9), T_footprint_link(t), static=False)
    assert len(tree.dynamic["base_link"]) == 8  # bounded
    for t in (0.25, 0.301, 0.37):  # between samples: slerp + linear, vs the smooth truth
        got = tree.lookup("base_footprint", "velodyne", round(t * 1e9))
        want = T_footprint_link(t) @ T_LINK_VELODYNE
        np.testing.assert_allclose(got, want, atol=2e-5)
        back = tree.lookup("velodyne", "base_footprint", round(t * 1e9))
        np.testing.assert_allclose(back @ got, np.eye(4), atol=1e-12)
    # siblings through their common parent
    tree.add("base_link", "camera", 0, se3_from_rt(_rz(-0.5), [0.2, 0.1, 0.9]), static=True)
    T_vc = tree.lookup("velodyne", "camera", 0)
    want = np.linalg.inv(T_LINK_VELODYNE) @ se3_from_rt(_rz(-0.5), [0.2, 0.1, 0.9])
    np.testing.assert_allclose(T_vc, want, atol=1e-12)
    # the chain has data up to the dynamic edge's last stamp; unconnected frames: None
    assert tree.latest_stamp("base_footprint", "velodyne") == round(0.38 * 1e9)
    assert tree.latest_stamp("base_link", "velodyne") == 2**63 - 1
    assert tree.lookup("odom", "velodyne", 0) is None and tree.latest_stamp("odom", "x") is None


# --------------------------------------------------------------------------- a bag through navkit run
def _scene():
    from navkit.sim import Box, Ground, Scene

    boxes = [
        Box(center=(cx, cy, 0.6), size=(sx, sy, 1.2), name=f"box{k}")
        for k, ((cx, cy), (sx, sy)) in enumerate(BOXES)
    ]
    return Scene([Ground(name="ground"), *boxes], name="tf-test")


def _transform(w, stamp_ns: int, parent: str, child: str, T: np.ndarray):
    from scipy.spatial.transform import Rotation

    M = w.ts.types
    q = Rotation.from_matrix(T[:3, :3]).as_quat()
    return M["geometry_msgs/msg/TransformStamped"](
        header=w.header(stamp_ns, parent),
        child_frame_id=child,
        transform=M["geometry_msgs/msg/Transform"](
            translation=M["geometry_msgs/msg/Vector3"](x=T[0, 3], y=T[1, 3], z=T[2, 3]),
            rotation=M["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
        ),
    )


def _write_bag(path, with_tf: bool) -> None:
    from navkit.sim import SpinningLidar, render_scan
    from tests.runtime.bags import _BagWriter

    scene, lidar = _scene(), SpinningLidar(n_beams=16, n_columns=900)
    t0 = 1_000_000_000
    events = [(0.05 * k, "odom") for k in range(41)]
    events += [(0.01 + 0.02 * k, "tf") for k in range(100)]
    events += [(0.025 + 0.2 * k, "cloud") for k in range(10)]
    with _BagWriter(path, ros1=False) as w:
        M = w.ts.types
        TF = M["tf2_msgs/msg/TFMessage"]
        if with_tf:
            w.write(
                "/tf_static",
                t0,
                TF(transforms=[_transform(w, t0, "base_link", "velodyne", T_LINK_VELODYNE)]),
            )
        PF = M["sensor_msgs/msg/PointField"]
        fields = [PF(name=c, offset=4 * i, datatype=7, count=1) for i, c in enumerate("xyz")]
        for t, kind in sorted(events):
            st = t0 + round(t * 1e9)
            if kind == "odom":
                w.write("/odom", st, w.odometry(st, "odom", "base_footprint", T_odom_footprint(t)))
            elif kind == "tf" and with_tf:
                msg = TF(
                    transforms=[
                        _transform(w, st, "base_footprint", "base_link", T_footprint_link(t))
                    ]
                )
                w.write("/tf", st, msg)
            elif kind == "cloud":
                sim = render_scan(scene, lidar, T_odom_velodyne(t), max_range=30.0)
                P = sim.scan.points("sensor").transpose(1, 0, 2).reshape(-1, 3)  # ring by ring
                P = P[np.all(np.isfinite(P), axis=1)].astype("<f4")
                cloud = M["sensor_msgs/msg/PointCloud2"](
                    header=w.header(st, "velodyne"),
                    height=1,
                    width=len(P),
                    fields=fields,
                    is_bigendian=False,
                    point_step=12,
                    row_step=12 * len(P),
                    data=P.view(np.uint8).reshape(-1),
                    is_dense=True,
                )
                w.write("/velodyne_points", st, cloud)


def _occupied_centres(bag, out):
    from navkit.io.results_mcap import read_messages
    from navkit.runtime import run_recording

    cfg = {
        "run": {"capabilities": ["obstacles", "obstacle_map"], "write_frames": False},
        "obstacles": {"map_resolution_m": 0.1, "map_half_extent_m": 15.0},
    }
    summary = run_recording(bag, out, cfg)
    assert summary["capabilities"]["obstacles"]["messages"] == 10
    grid = [r.message for r in read_messages(out / "results.mcap", ["/navkit/obstacle_map"])][-1]
    occ = np.asarray(grid.data, np.int8).reshape(grid.info.height, grid.info.width)
    rows, cols = np.nonzero(occ == 100)
    res, o = grid.info.resolution, grid.info.origin.position
    return np.c_[o.x + (cols + 0.5) * res, o.y + (rows + 0.5) * res], summary


def _inside(xy, margin):
    hit = np.zeros(len(xy), bool)
    for (cx, cy), (sx, sy) in BOXES:
        hit |= (np.abs(xy[:, 0] - cx) <= sx / 2 + margin) & (
            np.abs(xy[:, 1] - cy) <= sy / 2 + margin
        )
    return hit


def test_cloud_in_velodyne_with_odometry_of_the_base_is_placed_by_tf(tmp_path):
    pytest.importorskip("rosbags")
    pytest.importorskip("mcap")
    bag = tmp_path / "tf_bag"
    _write_bag(bag, with_tf=True)
    xy, summary = _occupied_centres(bag, tmp_path / "run")
    # the height measured on the first cloud's ground is the static + turret offset: 1.5 m
    h = summary["capabilities"]["obstacles"]["sensor_height"]["m"]
    assert abs(h - 1.5) < 0.02
    # every occupied cell lies on a box (one cell of margin: cells straddling a face), and both
    # boxes are found, each where it is: the centroid of its cells within 0.6 m of the centre
    # (the lidar sees the near faces only, so the cells' centroid sits towards the robot)
    assert len(xy) > 20
    assert _inside(xy, 0.1).all(), xy[~_inside(xy, 0.1)]
    for (cx, cy), (sx, sy) in BOXES:
        mine = xy[(np.abs(xy[:, 0] - cx) <= sx) & (np.abs(xy[:, 1] - cy) <= sy)]
        assert len(mine) >= 8
        assert np.hypot(*(mine.mean(0) - (cx, cy))) < 0.6


def test_results_mcap_carries_the_tf_tree(tmp_path):
    """results.mcap passes the bag's /tf and /tf_static through and publishes the odometry's
    odom -> base_footprint: the points and shapes (velodyne) and the obstacle map (odom) link to
    map (no localization: map = odom, a static identity), and the tree read back places the
    lidar where it was (interpolated between 20 Hz odometry and 50 Hz turret samples: 1 mm)."""
    pytest.importorskip("rosbags")
    pytest.importorskip("mcap")
    from tests.runtime.test_runtime_robot import results_tf

    bag = tmp_path / "tf_bag"
    _write_bag(bag, with_tf=True)
    _occupied_centres(bag, tmp_path / "run")
    tree, frames = results_tf(tmp_path / "run" / "results.mcap")
    assert frames["/navkit/obstacles/points"] == {"velodyne"}
    assert frames["/navkit/obstacles/shapes"] == {"velodyne"}
    assert frames["/navkit/obstacle_map"] == {"odom"}
    used = set().union(*frames.values()) | set(tree.parent) | set(tree.parent.values())
    for f in used:
        assert tree.can_transform("map", f), (f, tree.parent)
    assert tree.parent == {
        "velodyne": "base_link",
        "base_link": "base_footprint",
        "base_footprint": "odom",
        "odom": "map",
    }
    np.testing.assert_allclose(tree.lookup("map", "odom", 0), np.eye(4))
    for k in range(10):
        t = 0.025 + 0.2 * k
        got = tree.lookup("odom", "velodyne", 1_000_000_000 + round(t * 1e9))
        np.testing.assert_allclose(got, T_odom_velodyne(t), atol=1e-3)


def test_without_tf_the_same_clouds_are_misplaced(tmp_path):
    """The control: the same bag without /tf and /tf_static puts the odometry's base_footprint
    where the sensor is (warned), and the boxes land off their places."""
    pytest.importorskip("rosbags")
    pytest.importorskip("mcap")
    bag = tmp_path / "no_tf_bag"
    _write_bag(bag, with_tf=False)
    xy, _ = _occupied_centres(bag, tmp_path / "run")
    assert len(xy) > 0
    assert _inside(xy, 0.1).mean() < 0.5


_INTERRUPT = r"""
import os, signal, sys
from navkit.runtime import run_recording
from navkit.runtime.run import RunInterrupted
from navkit.runtime.sources import open_source

bag, out, k = sys.argv[1], sys.argv[2], int(sys.argv[3])
src = open_source(bag)
messages = src.messages


def interrupted(skip=0):
    for item, msgs in messages(skip):
        if item == k:  # Ctrl-C in a terminal: SIGINT to the whole process group
            os.killpg(0, signal.SIGINT)
        yield item, msgs


src.messages = interrupted
cfg = {"run": {"checkpoint_every": 1000}, "obstacles": {"map_half_extent_m": 15.0}}
try:
    run_recording(src, out, cfg)
except RunInterrupted:
    sys.exit(130)
"""


def test_ctrl_c_with_the_obstacles_writer_and_resume(tmp_path):
    """Ctrl-C reaches the run and its per-frame file writer (one process group): the writer
    ignores it, the run drains it into its checkpoint, and --resume gives the files, records
    and results of an uninterrupted run."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    pytest.importorskip("rosbags")
    pytest.importorskip("mcap")
    from navkit.io.results_mcap import read_messages
    from navkit.runtime import run_recording

    repo = Path(__file__).resolve().parents[2]
    bag = tmp_path / "tf_bag"
    _write_bag(bag, with_tf=True)
    cfg = {"run": {"checkpoint_every": 1000}, "obstacles": {"map_half_extent_m": 15.0}}
    run_recording(bag, tmp_path / "full", cfg)
    out = tmp_path / "interrupted"
    env = {**os.environ, "PYTHONPATH": f"{repo / 'src'}{os.pathsep}{repo}"}
    r = subprocess.run(
        [sys.executable, "-c", _INTERRUPT, str(bag), str(out), "80"],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        start_new_session=True,  # its own process group: the SIGINT stays in it
    )
    assert r.returncode == 130, r.stderr
    recs = [json.loads(x) for x in (out / "frames.jsonl").read_text().splitlines()]
    done = [x for x in recs if x["capability"] == "obstacles"]
    assert 1 <= len(done) < 10
    for x in done:  # the checkpoint waited for the writer: every frame's files are there
        d = out / "obstacles" / f"{x['seq']:06d}"
        assert (d / "labels.npy").is_file() and (d / "obstacles.json").is_file()
    run_recording(bag, out, cfg, resume=True)

    def strip(rec):
        return {k: v for k, v in rec.items() if k not in ("ms", "item")}

    def records(folder):
        return [strip(json.loads(x)) for x in (folder / "frames.jsonl").read_text().splitlines()]

    assert records(out) == records(tmp_path / "full")
    for k in range(10):
        for name in ("labels.npy", "obstacles.json"):
            a = (out / "obstacles" / f"{k:06d}" / name).read_bytes()
            assert a == (tmp_path / "full" / "obstacles" / f"{k:06d}" / name).read_bytes()
    raw = [(m.topic, m.log_time_ns) for m in read_messages(out / "results.mcap")]
    assert raw == [
        (m.topic, m.log_time_ns) for m in read_messages(tmp_path / "full" / "results.mcap")
    ]
