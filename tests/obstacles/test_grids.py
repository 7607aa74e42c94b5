"""Stage 1 inputs: spinning-lidar clouds to grids (any order, any beam count), organised clouds,
depth images, mounting."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navkit.errors import ConfigError, InputError
from navkit.experiments.obstacles import paper_scenes
from navkit.geometry import R_BODY_FROM_OPTICAL, se3_from_rt
from navkit.obstacles import Mounting, detect_obstacles_in_grid
from navkit.obstacles.grids import cloud_to_grid, depth_to_grid, organized_to_grid
from navkit.obstacles.rules import OBSTACLE
from navkit.sensors import PinholeCamera
from navkit.sim import SpinningLidar, render_rgbd, render_scan


def _lidar_cloud(n_beams, n_columns, height=1.73):
    scene = paper_scenes()["four"]
    sim = render_scan(
        scene,
        SpinningLidar(n_beams=n_beams, n_columns=n_columns),
        se3_from_rt(np.eye(3), [0, 0, height]),
        max_range=60,
    )
    P = sim.scan.points("sensor")  # (n_az, n_el, 3), NaN = no return
    return sim, P


@pytest.mark.parametrize("n_beams, n_columns", [(16, 900), (32, 1024), (64, 2048)])
def test_rings_and_columns_recovered_from_a_shuffled_cloud(n_beams, n_columns, rng):
    _, P = _lidar_cloud(n_beams, n_columns)
    n_az, n_el = P.shape[:2]
    ii, jj = np.indices((n_az, n_el))
    flat = P.reshape(-1, 3)
    ok = np.all(np.isfinite(flat), axis=1)
    cloud, true_i, true_j = flat[ok], ii.ravel()[ok], jj.ravel()[ok]
    # add no-returns stored as (0, 0, 0), as several datasets do, then shuffle the storage order
    cloud = np.vstack([cloud, np.zeros((100, 3))])
    true_i = np.r_[true_i, -np.ones(100, int)]
    true_j = np.r_[true_j, -np.ones(100, int)]
    perm = rng.permutation(len(cloud))
    cloud, true_i, true_j = cloud[perm], true_i[perm], true_j[perm]
    grid = cloud_to_grid(cloud)
    assert grid.method == "elevation"  # a shuffled cloud is not a sweep
    # beams that hit nothing within range (pointing up into the sky) are absent from the cloud
    present = np.unique(true_j[true_j >= 0])
    assert grid.shape == (n_columns, len(present))
    got = grid.cell_of_point
    assert np.all(got[true_i < 0] == -1)  # the (0, 0, 0) no-returns are outside the grid
    gi, gj = got[true_i >= 0] // grid.shape[1], got[true_i >= 0] % grid.shape[1]
    # every point lands in its own ring and column (the columns start at -pi like the sensor)
    assert np.array_equal(present[gj], true_j[true_i >= 0])
    assert np.array_equal(gi, true_i[true_i >= 0])
    # and the grid holds the points themselves
    back = grid.points.reshape(-1, 3)[got[true_i >= 0]]
    assert np.allclose(back, cloud[true_i >= 0])


def test_storage_order_sweep_and_detection_on_a_lidar_cloud():
    _, P = _lidar_cloud(64, 2048)
    # store ring by ring (each ring a full sweep), as KITTI does
    cloud = P.transpose(1, 0, 2).reshape(-1, 3)
    cloud = cloud[np.all(np.isfinite(cloud), axis=1)]
    grid = cloud_to_grid(cloud)
    assert grid.method == "order" and grid.wraps
    det = detect_obstacles_in_grid(grid, Mounting(1.73))
    assert len(det.obstacles) == 4
    labels = grid.per_point(det.vertex_labels)
    assert labels.shape == (len(cloud),) and labels.dtype == np.int8


def test_kitti_frame_rings_by_storage_order(data_path):
    from navkit.io.pointcloud import read_kitti_bin

    pts = read_kitti_bin(data_path("lidar/semantickitti-seq00/000000.bin"))
    grid = cloud_to_grid(pts)
    assert grid.method == "order"
    n_cols, n_rings = grid.shape
    assert n_rings == 64  # the HDL-64E's beams
    assert 1950 <= n_cols <= 2150  # ~0.17 deg azimuth steps
    assert np.all(grid.cell_of_point >= 0)
    # rings come out in rising elevation: the median elevation per ring increases
    P = grid.points
    el = np.degrees(np.arctan2(P[..., 2], np.hypot(P[..., 0], P[..., 1])))
    med = np.nanmedian(el, axis=0)
    assert np.all(np.diff(med) > 0)


def test_organized_cloud_any_layout():
    _, P = _lidar_cloud(16, 360)
    # an image-like layout: rows = beams top to bottom, columns = azimuth clockwise
    image = P.transpose(1, 0, 2)[::-1, ::-1]
    grid = organized_to_grid(image)
    assert grid.shape == P.shape[:2]
    assert np.allclose(grid.points, P, equal_nan=True)
    # point k of the image (row-major) sits in its grid cell
    k = 5 * 360 + 17
    r, c = divmod(k, 360)
    assert np.allclose(
        grid.points.reshape(-1, 3)[grid.cell_of_point[k]], image[r, c], equal_nan=True
    )


def test_depth_image_of_a_box_on_the_floor():
    scene = paper_scenes()["box"]
    cam = PinholeCamera.from_fov(160, 120, 70.0)
    # camera 1.0 m above the floor, looking forward (+x) and 20 deg down
    pitch = math.radians(20)
    R_body_cam = (
        np.array(
            [
                [math.cos(pitch), 0, math.sin(pitch)],
                [0, 1, 0],
                [-math.sin(pitch), 0, math.cos(pitch)],
            ]
        )
        @ R_BODY_FROM_OPTICAL
    )
    frame = render_rgbd(scene, cam, se3_from_rt(R_body_cam, [3.5, 0.0, 1.0])).frame
    grid = depth_to_grid(frame.depth, cam)
    det = detect_obstacles_in_grid(grid, Mounting(1.0, pitch_deg=20.0))
    assert len(det.obstacles) == 1
    ob = det.obstacles[0]
    assert ob.height == pytest.approx(1.0, abs=0.1)
    # the box centre is 2.5 m ahead of the camera
    c = ob.shapes["A1"]
    assert c.xmin == pytest.approx(2.0, abs=0.15)
    labels = grid.per_point(det.vertex_labels).reshape(cam.height, cam.width)
    assert labels[cam.height // 2, cam.width // 2] == OBSTACLE


def test_mounting_from_gravity_equals_tilt():
    m = Mounting(1.2, roll_deg=3.0, pitch_deg=-7.0)
    g_sensor = m.R_body_sensor.T @ np.array([0.0, 0.0, -9.81])
    m2 = Mounting(1.2, gravity=tuple(g_sensor))
    # the gravity gives the same vertical (heading may differ by the shortest-arc choice)
    assert np.allclose(m2.R_body_sensor.T @ [0, 0, 1], m.R_body_sensor.T @ [0, 0, 1], atol=1e-9)
    with pytest.raises(ConfigError):
        Mounting(1.0, gravity=(0.0, 0.0, 0.0))


def test_bad_clouds_are_refused():
    with pytest.raises(InputError, match="points"):
        cloud_to_grid(np.zeros((10, 2)))
    with pytest.raises(InputError):
        cloud_to_grid(np.array([["a", "b", "c"]]))
    with pytest.raises(InputError):
        cloud_to_grid(np.zeros((0, 3)))
    with pytest.raises(InputError, match="valid points"):
        cloud_to_grid(np.zeros((50, 3)))  # every point a no-return
    with pytest.raises(InputError):
        organized_to_grid(np.full((4, 5, 3), np.nan))
    with pytest.raises(InputError):
        depth_to_grid(np.ones((3, 3)), PinholeCamera.from_fov(4, 4, 60))
