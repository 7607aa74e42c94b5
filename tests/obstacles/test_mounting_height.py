"""The sensor height measured from the ground: KITTI (1.73 m nominal), simulated scans, no ground."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.errors import ConfigError
from navkit.obstacles.mounting import choose_sensor_height, estimate_sensor_height


@pytest.mark.parametrize("frame", ["000000", "000001", "000002"])
def test_kitti_height_within_5_cm_of_the_setup_and_of_the_labelled_road(data_path, frame):
    from navkit.io.pointcloud import read_kitti_bin, read_kitti_labels

    pts = read_kitti_bin(data_path(f"lidar/semantickitti-seq00/{frame}.bin"))[:, :3]
    est = estimate_sensor_height(pts)
    assert est.plausible and est.reason == ""
    assert abs(est.height_m - 1.73) < 0.05  # KITTI set-up: Velodyne 1.73 m above the ground
    # the labelled road (SemanticKITTI class 40) 3-10 m away, fitted by least squares: the data's
    # own ground truth, 1.78-1.80 m in these frames
    sk = read_kitti_labels(data_path(f"lidar/semantickitti-seq00/{frame}.label"))[0]
    r = np.hypot(pts[:, 0], pts[:, 1])
    road = pts[(sk == 40) & (r > 3) & (r < 10)].astype(np.float64)
    c = road.mean(axis=0)
    n = np.linalg.svd(road - c, full_matrices=False)[2][-1]
    road_height = abs(float(n @ c))
    assert abs(est.height_m - road_height) < 0.05


def _flat_ground_scan(height, rng, tilt_deg=0.0, n=20000):
    """Returns of a level plane ``height`` below the sensor plus a few boxes, sensor tilted."""
    az = rng.uniform(-np.pi, np.pi, n)
    rng_m = rng.uniform(2.0, 25.0, n)
    ground = np.column_stack([rng_m * np.cos(az), rng_m * np.sin(az), np.full(n, -height)])
    ground[:, 2] += rng.normal(0.0, 0.02, n)
    box = rng.uniform([5, -2, -height], [7, 2, 1.0], (3000, 3))  # a wall-like obstacle
    P = np.vstack([ground, box])
    t = np.radians(tilt_deg)  # the sensor pitched: points seen in its frame
    R = np.array([[np.cos(t), 0, np.sin(t)], [0, 1, 0], [-np.sin(t), 0, np.cos(t)]])
    return P @ R, R  # sensor frame = R^T body; R_body_sensor = R


@pytest.mark.parametrize("height", [0.35, 1.2, 2.4])
def test_simulated_heights_recovered_to_a_centimetre(height):
    rng = np.random.default_rng(7)
    P, R = _flat_ground_scan(height, rng, tilt_deg=5.0)
    est = estimate_sensor_height(P, R)
    assert abs(est.height_m - height) < 0.01 and est.tilt_deg < 0.5
    # without the mounting rotation the ground is seen 5 deg tilted: measured, still plausible
    assert abs(estimate_sensor_height(P).tilt_deg - 5.0) < 0.5


def test_no_ground_is_never_a_silent_zero(caplog):
    rng = np.random.default_rng(1)
    wall = np.column_stack([np.full(5000, 4.0), rng.uniform(-5, 5, 5000), rng.uniform(-2, 2, 5000)])
    est = estimate_sensor_height(wall)
    assert not est.plausible and np.isnan(est.height_m) and est.reason
    with pytest.raises(ConfigError, match="--sensor-height"):
        choose_sensor_height(wall, source="wall.bin")
    used = choose_sensor_height(wall, typical_m=0.7)
    assert used.height_m == 0.7 and used.warning and "typical" in used.source
    assert choose_sensor_height(wall, given_m=1.1).source == "given"


def test_implausible_height_warns(caplog):
    P, _ = _flat_ground_scan(3.0, np.random.default_rng(2))
    used = choose_sensor_height(P, plausible_m=(0.1, 2.5))
    assert abs(used.height_m - 3.0) < 0.01 and "implausible" in used.warning
    assert any("implausible" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize(("preset", "height"), [("vlp16", 0.9), ("os1-64", 0.45), ("os1-128", 1.6)])
def test_presets_recover_the_layout_and_the_height_of_a_shuffled_cloud(
    cli, tmp_path, preset, height
):
    """A simulated cloud of each lidar, stored in random order (no ring information): the preset
    gives the beams and columns, the height is measured from the ground, the box is found and
    the flat ground holds no obstacle."""
    import json

    from navkit.geometry import se3_from_rt
    from navkit.sensors.presets import get_preset
    from navkit.sim import Box, Ground, Scene, SpinningLidar, render_scan

    p = get_preset(preset)
    lidar = SpinningLidar(p.rings, p.columns, *p.elevation_deg)
    scene = Scene([Ground(name="ground"), Box((6.0, 1.0, 0.6), (1.0, 1.0, 1.2), name="box")])
    sim = render_scan(scene, lidar, se3_from_rt(np.eye(3), [0.0, 0.0, height]), rng=0)
    pts = sim.scan.points("sensor").reshape(-1, 3)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    path = tmp_path / f"{preset}.npy"
    np.save(path, pts[np.random.default_rng(3).permutation(len(pts))])
    res = cli("obstacles", "detect", path, "-o", tmp_path / "out", "--sensor", preset)
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    frame = summary["frames"][0]
    assert frame["grid_shape"] == [p.columns, p.rings]
    assert abs(summary["sensor_height"]["m"] - height) < 0.01
    obs = json.loads((tmp_path / "out" / preset / "obstacles.json").read_text())["obstacles"]
    centres = np.array([np.mean(o["boundary_polygon"], axis=0) for o in obs])
    assert len(obs) >= 1 and np.all(np.linalg.norm(centres - [6.0, 1.0], axis=1) < 1.0)
    # the box and nothing else (seen from 1.6 m above, 128 beams cut it into fragments)
