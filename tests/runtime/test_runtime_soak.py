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
