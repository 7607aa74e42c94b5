"""10,000 frames through the run loop with tracemalloc: memory does not grow with the recording."""

from __future__ import annotations

import gc
import json
import tracemalloc
from dataclasses import dataclass, field

import numpy as np
import pytest

pytest.importorskip("mcap", reason="mcap (extra 'ros') not installed")
pytest.importorskip("rosbags", reason="rosbags (extra 'ros') not installed")

from navkit.runtime import Message, ScanData, run_recording

N_ITEMS = 10_000
CLOUD_EVERY = 25  # a tiny lidar cloud every 25th item (detection dominates the test's time)


def _tiny_cloud() -> np.ndarray:
    """A 4-ring x 32-column spinning-lidar cloud 1 m above flat ground, with one box-like
    obstacle (ring by ring, as a Velodyne stores it)."""
    az = np.linspace(-np.pi, np.pi, 32, endpoint=False)
    el = np.radians(np.linspace(-15.0, -2.0, 4))
    A, E = np.meshgrid(az, el)
    d = 1.0 / np.sin(-E)
    d[:, 14:17] = np.minimum(d[:, 14:17], 3.0)  # a wall section 3 m away
    return np.c_[
        (d * np.cos(E) * np.cos(A)).ravel(),
        (d * np.cos(E) * np.sin(A)).ravel(),
        (d * np.sin(E)).ravel(),
    ]


@dataclass
class SyntheticSource:
    """A robot standing still: per item a pose, a laser scan and every 25th item a cloud."""

    name: str = "synthetic"
    topics: dict[str, str] = field(
        default_factory=lambda: {"/pose": "pose", "/scan": "scan", "/points": "cloud"}
    )
    start_ns: int = 0
    end_ns: int = (N_ITEMS - 1) * 10_000_000
    n_items: int = N_ITEMS

    def messages(self, skip: int = 0):
        cloud = _tiny_cloud()
        b = np.linspace(-np.pi / 2, np.pi / 2, 19)
        r = 2.0 / np.maximum(np.cos(b), 0.3)
        T = np.eye(4)
        for k in range(skip, N_ITEMS):
            st = k * 10_000_000
            msgs = [
                Message("/pose", "pose", st, "map", T, "base"),
                Message("/scan", "scan", st, "laser", ScanData(r, b, 30.0)),
            ]
            if k % CLOUD_EVERY == 0:
                msgs.append(Message("/points", "cloud", st, "lidar", cloud))
            yield k, msgs


def test_memory_flat_over_10000_frames(tmp_path):
    cfg = {
        "obstacles": {"sensor_height_m": 1.0, "map_half_extent_m": 10.0, "map_every": 50},
        "laser": {"keyframe_distance_m": 0.5, "keyframe_angle_deg": 10.0},
        "run": {"checkpoint_every": 1000, "write_frames": False},
    }
    marks: dict[int, int] = {}

    def probe(done_s: float, _total: float) -> None:
        k = round(done_s / 0.01)
        if k in (2_000, N_ITEMS - 1):
            gc.collect()  # live memory: garbage in reference cycles is not growth
            marks[k] = tracemalloc.get_traced_memory()[0]

    tracemalloc.start()
    try:
        summary = run_recording(SyntheticSource(), tmp_path / "soak", cfg, on_progress=probe)
    finally:
        tracemalloc.stop()
    caps = summary["capabilities"]
    assert caps["obstacles"]["messages"] == N_ITEMS // CLOUD_EVERY
    assert caps["wall_map"]["messages"] == N_ITEMS and caps["wall_map"]["keyframes"] == 1
    assert caps["path"]["poses"] == N_ITEMS
    growth = marks[N_ITEMS - 1] - marks[2_000]
    # 8,000 items (16,800 messages) later: less than 8 bytes per item
    assert growth < 64_000, f"traced memory grew by {growth} bytes over 8,000 items"
    lines = (tmp_path / "soak" / "frames.jsonl").read_text().splitlines()
    assert len(lines) == N_ITEMS + N_ITEMS // CLOUD_EVERY  # wall map + obstacles records
    assert json.loads(lines[-1])["capability"] in ("wall_map", "obstacles")


# --------------------------------------------------------------------------- plane odometry
N_DISTINCT, N_LOOPS = 5, 3  # 5 rendered frames, streamed 3 times over (as the 7-Scenes soak)


@dataclass
class RGBDLoopSource:
    """Simulated RGB-D frames down a corridor (depth, colour, camera info), the same
    ``N_DISTINCT`` frames again and again at 30 Hz: the stream never ends the odometry's work."""

    frames: list = field(default_factory=list)
    name: str = "rgbd-loop"
    topics: dict[str, str] = field(
        default_factory=lambda: {"/depth": "depth", "/color": "color", "/info": "camera_info"}
    )
    start_ns: int = 0
    end_ns: int = (N_DISTINCT * N_LOOPS - 1) * 33_333_333
    n_items: int = N_DISTINCT * N_LOOPS

    def messages(self, skip: int = 0):
        from navkit.runtime import CameraData

        for k in range(skip, self.n_items):
            f = self.frames[k % N_DISTINCT]
            st = k * 33_333_333
            c = f.camera
            msgs = (
                [
                    Message(
                        "/info",
                        "camera_info",
                        st,
                        "cam",
                        CameraData(c.fx, c.fy, c.cx, c.cy, c.width, c.height),
                    )
                ]
                if k == 0
                else []
            )
            msgs += [
                Message("/depth", "depth", st, "cam", f.depth),
                Message("/color", "color", st, "cam", f.color),
            ]
            yield k, msgs


def _corridor_frames():
    from navkit.geometry import se3_from_rt
    from navkit.sensors import PinholeCamera
    from navkit.sim import render_rgbd
    from tests.planes.conftest import corridor, start_pose

    camera = PinholeCamera(131.25, 131.25, 79.5, 59.5, 160, 120)
    scene, T = corridor(3), start_pose(3)
    step = se3_from_rt(np.eye(3), [0.0, 0.0, 0.08])
    out = []
    for k in range(N_DISTINCT):
        out.append(render_rgbd(scene, camera, T, rng=k).frame)
        T = T @ step
    return out


def test_plane_odometry_memory_is_bounded(tmp_path):
    """The runtime's plane stage keeps at most ``max_history`` poses / results / observation
    numbers, ``max_keyframes`` keyframes and ``max_map_planes`` planes, however long the
    stream; the trajectory is streamed to ``trajectory.tum`` (one line per frame, equal to the
    published poses); bounding the history changes no pose (same frames, unbounded object)."""
    from navkit.io.results_mcap import read_messages
    from navkit.io.trajectory import read_tum
    from navkit.planes import OdometrySettings, PlaneOdometry, observe_rgbd
    from navkit.planes.motion import MotionSettings
    from navkit.planes.solve import SolverSettings
    from navkit.runtime.planes_stage import PlanesStage
    from navkit.sensors import RGBDFrame

    frames = _corridor_frames()
    bounds = {"max_history": 3, "max_keyframes": 2, "max_map_planes": 4}
    cfg = {"planes": bounds, "run": {"checkpoint_every": 1000}}
    sizes = []
    original = PlanesStage._frame

    def spy(self, d, c, poses):  # the stage's structures after every frame
        res = original(self, d, c, poses)
        o = self.odo
        sizes.append(
            (
                len(o.poses),
                len(o.results),
                len(o._keyframes),
                len(o.map.planes),
                max((len(mp.observations) for mp in o.map.planes), default=0),
            )
        )
        return res

    PlanesStage._frame = spy
    try:
        summary = run_recording(RGBDLoopSource(frames), tmp_path / "run", cfg)
    finally:
        PlanesStage._frame = original
    n = N_DISTINCT * N_LOOPS
    assert summary["capabilities"]["planes"]["frames"] == n == len(sizes)
    # real tracking, not failures: the 0.08 m steps, and the jumps back to the first frame
    assert summary["capabilities"]["planes"]["tracked"] >= n - N_LOOPS
    S = np.array(sizes)
    assert S[:, 0].max() == S[:, 1].max() == 3 and S[-1, 0] == 3
    assert 1 <= S[:, 2].max() <= 2
    assert 1 <= S[:, 3].max() <= 4 and S[:, 4].max() <= 3
    # the streamed trajectory: every frame, equal to the published poses
    traj = read_tum(tmp_path / "run" / "planes" / "trajectory.tum")
    assert len(traj.timestamps) == n
    pub = [
        r.message.pose.position
        for r in read_messages(tmp_path / "run" / "results.mcap", ["/navkit/planes/sensor_pose"])
    ]
    np.testing.assert_allclose(traj.poses[:, :3, 3], [[p.x, p.y, p.z] for p in pub], atol=1e-9)
    # the same frames through an object that keeps everything (only max_history differs)
    odo = PlaneOdometry(
        OdometrySettings(
            motion=MotionSettings(solver=SolverSettings(nu=0.01)),
            max_keyframes=2,
            max_map_planes=4,
        )
    )
    for k in range(n):
        f = frames[k % N_DISTINCT]
        odo.update(observe_rgbd(RGBDFrame(f.color, f.depth, f.camera, k / 30)))
    assert len(odo.poses) == n
    np.testing.assert_allclose(traj.poses, odo.trajectory, atol=1e-6)
