"""Pinhole projection, RGB-D back-projection and stereo triangulation against the analytic model."""

import numpy as np
import pytest

from navkit.errors import InputError
from navkit.sensors import PinholeCamera, RGBDFrame, StereoPair, StereoRig


@pytest.fixture
def cam():
    return PinholeCamera(500.0, 480.0, 319.5, 239.5, 640, 480)


def test_project_backproject_round_trip(cam, rng):
    depth = rng.uniform(0.5, 8.0, size=(480, 640))
    pts = cam.backproject(depth)
    uv, z = cam.project(pts.reshape(-1, 3))
    u, v = np.meshgrid(np.arange(640), np.arange(480))
    np.testing.assert_allclose(uv[:, 0], u.ravel(), atol=1e-9)
    np.testing.assert_allclose(uv[:, 1], v.ravel(), atol=1e-9)
    np.testing.assert_allclose(z, depth.ravel())


def test_points_behind_camera_do_not_project(cam):
    uv, _ = cam.project(np.array([[0.0, 0.0, -1.0], [0.1, 0.0, 2.0]]))
    assert np.isnan(uv[0]).all() and np.isfinite(uv[1]).all()


def test_from_fov():
    cam = PinholeCamera.from_fov(640, 480, 90.0)
    assert cam.fx == pytest.approx(320.0)


def test_stereo_triangulation_matches_z_equals_bf_over_d(cam):
    rig = StereoRig(cam, baseline=0.12)
    X = np.array([0.4, -0.3, 3.0])
    uvl, _ = cam.project(X[None])
    uvr, _ = cam.project((X - [0.12, 0, 0])[None])  # right camera at +b along x
    d = uvl[0, 0] - uvr[0, 0]
    assert d == pytest.approx(0.12 * 500.0 / 3.0)
    disp = np.full((480, 640), np.nan)
    r, c = round(uvl[0, 1]), round(uvl[0, 0])
    disp[r, c] = d
    P = rig.triangulate(disp)
    assert P[r, c, 2] == pytest.approx(3.0)
    assert np.isnan(P[0, 0]).all()
    np.testing.assert_allclose(rig.disparity_from_depth(rig.depth_from_disparity([[d]])), [[d]])


def test_rgbd_frame_validates_and_marks_invalid_depth(cam):
    color = np.zeros((480, 640, 3), np.uint8)
    depth = np.ones((480, 640))
    depth[0, 0] = 0.0
    f = RGBDFrame(color, depth, cam)
    assert np.isnan(f.depth[0, 0]) and f.points().shape == (480, 640, 3)
    with pytest.raises(InputError, match="depth"):
        RGBDFrame(color, np.ones((10, 10)), cam)
    with pytest.raises(InputError, match="right"):
        StereoPair(
            np.zeros((480, 640), np.uint8), np.zeros((480, 639), np.uint8), StereoRig(cam, 0.1)
        )
    with pytest.raises(InputError, match="baseline"):
        StereoRig(cam, 0.0)
    with pytest.raises(InputError, match="fx"):
        PinholeCamera(0.0, 1.0, 0.0, 0.0, 10, 10)
