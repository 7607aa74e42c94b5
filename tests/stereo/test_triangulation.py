"""Triangulation against the analytic pinhole stereo model (paper 3, eq. 1) and eq. 2."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from navkit.geometry import se3_apply
from navkit.sensors import PinholeCamera, StereoRig
from navkit.stereo import disparity_to_points
from navkit.stereo.triangulation import camera_to_world, planar_camera_pose, triangulate_pixels


def _project(P, f, cx, cy, b, doffs=0.0):
    """Exact pixel coordinates of points in the left frame seen by both cameras of the rig."""
    uL = f * P[:, 0] / P[:, 2] + cx
    uR = f * (P[:, 0] - b) / P[:, 2] + cx + doffs  # right principal point shifted by doffs
    v = f * P[:, 1] / P[:, 2] + cy
    return uL, uR, v


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.0, 40.0))
def test_triangulation_inverts_projection(seed, doffs):
    rng = np.random.default_rng(seed)
    P = rng.uniform([-3, -2, 0.5], [3, 2, 30], (50, 3))
    f, cx, cy, b = 700.0, 320.0, 240.0, 0.12
    uL, uR, v = _project(P, f, cx, cy, b, doffs)
    left = triangulate_pixels(uL - cx, uR - cx, v - cy, b, f, origin="left", doffs=doffs)
    np.testing.assert_allclose(left, P, rtol=1e-9, atol=1e-9)
    # the paper's origin at the centre of the pair is the left frame shifted by b/2 along x
    centre = triangulate_pixels(uL - cx, uR - cx, v - cy, b, f, origin="centre", doffs=doffs)
    np.testing.assert_allclose(centre, P - [b / 2, 0, 0], rtol=1e-9, atol=1e-9)


def test_depth_is_b_f_over_d():
    z = triangulate_pixels(np.array([10.0]), np.array([-4.0]), np.array([0.0]), 0.5, 800.0)[0, 2]
    assert z == pytest.approx(0.5 * 800.0 / 14.0)
    assert np.isnan(
        triangulate_pixels(np.array([1.0]), np.array([2.0]), np.array([0.0]), 0.5, 800.0)
    ).all()


def test_disparity_image_to_points_matches_the_rig():
    cam = PinholeCamera(500.0, 500.0, 159.5, 119.5, 320, 240)
    rig = StereoRig(cam, 0.2, doffs=3.0)
    depth = np.full((240, 320), 4.0)
    depth[:, :100] = 2.0
    d = rig.disparity_from_depth(depth)
    d[0, 0] = np.nan
    P = disparity_to_points(d, rig)
    np.testing.assert_allclose(P[1:, :, 2], depth[1:], rtol=1e-12)
    np.testing.assert_allclose(P[1:], rig.triangulate(d)[1:], rtol=1e-12)
    assert np.isnan(P[0, 0]).all()


def test_planar_camera_pose_looks_along_the_heading():
    T = planar_camera_pose(1.0, 2.0, np.pi / 2, height=1.5)
    # a point 3 m in front of the camera (optical z) is 3 m along world +y from it
    np.testing.assert_allclose(
        camera_to_world(np.array([0.0, 0.0, 3.0]), T), [1.0, 5.0, 1.5], atol=1e-12
    )
    # facing +y (north), image x (right) is world +x (east) and image y (down) is world -z
    np.testing.assert_allclose(
        se3_apply(T, np.array([[1.0, 1.0, 0.0]]))[0], [2.0, 2.0, 0.5], atol=1e-12
    )
