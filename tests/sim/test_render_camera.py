"""render_rgbd / render_stereo: depth, colour, disparity against the geometry."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.geometry import R_BODY_FROM_OPTICAL, se3_apply, se3_from_rt
from navkit.sensors import PinholeCamera, StereoRig
from navkit.sim import Box, Ground, Scene, Texture, Wall, render_rgbd, render_stereo
from navkit.sim.scanners import RangeNoise


def _camera_pose(x, y, z, yaw=0.0):
    """Optical frame looking along the world heading ``yaw`` (level)."""
    c, s = np.cos(yaw), np.sin(yaw)
    Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    return se3_from_rt(Rz @ R_BODY_FROM_OPTICAL, [x, y, z])


def _wall_scene():
    return Scene(
        [
            Ground(name="ground"),
            Wall(
                (5.0, 4.0, 0.0),
                (0.0, -8.0, 0.0),
                (0.0, 0.0, 4.0),
                name="wall",
                texture=Texture("bricks", seed=2),
            ),
            Box((3.0, -1.0, 0.4), (0.8, 0.8, 0.8), name="box", texture=Texture("noise", scale=0.2)),
        ]
    )


def test_rgbd_depth_is_along_the_optical_axis():
    cam = PinholeCamera.from_fov(160, 120, 70.0)
    sim = render_rgbd(_wall_scene(), cam, _camera_pose(0.0, 0.0, 1.5))
    wall = sim.hit_index == 1
    assert wall.sum() > 1000
    # a wall facing the camera at x = 5: every pixel on it has depth exactly 5
    np.testing.assert_allclose(sim.frame.depth[wall], 5.0, atol=1e-9)
    # back-projected depth lands on the true surfaces: world z of ground pixels is 0
    pw = se3_apply(sim.T_world_camera, sim.frame.points().reshape(-1, 3)).reshape(120, 160, 3)
    ground = sim.hit_index == 0
    np.testing.assert_allclose(pw[ground][:, 2], 0.0, atol=1e-9)
    np.testing.assert_allclose(pw[wall][:, 0], 5.0, atol=1e-9)
    # sky above the wall: no depth, sky colour
    assert np.all(np.isnan(sim.frame.depth[sim.hit_index < 0]))
    assert sim.frame.color.dtype == np.uint8 and sim.frame.color.shape == (120, 160, 3)


def test_rgbd_noise_and_shading(rng):
    cam = PinholeCamera.from_fov(160, 120, 70.0)
    scene = Scene([Ground(texture=Texture("solid", color=(0.5, 0.5, 0.5)))])
    T = se3_from_rt(np.array([[1, 0, 0], [0, -1, 0], [0, 0, -1.0]]), [0, 0, 2.0])  # looking down
    sim = render_rgbd(scene, cam, T, noise=RangeNoise(relative_sigma=0.01), rng=rng)
    ok = np.isfinite(sim.frame.depth)
    np.testing.assert_allclose(sim.depth_true[ok], 2.0, atol=1e-9)
    rel = sim.frame.depth[ok] / 2.0 - 1.0
    n = rel.size  # relative error ~ N(0, 0.01): std within 5 sigma / sqrt(2n)
    assert abs(rel.std() - 0.01) < 5 * 0.01 / np.sqrt(2 * n)
    # flat, uniformly lit, solid grey ground: one colour = albedo * (ambient + diffuse cos)
    from navkit.sim.render import AMBIENT, SUN_DIRECTION

    expected = 0.5 * (AMBIENT + (1 - AMBIENT) * SUN_DIRECTION[2]) * 255
    np.testing.assert_allclose(sim.frame.color.reshape(-1, 3), expected, atol=0.51)


def test_stereo_disparity_is_geometric_and_photometric(rng):
    cam = PinholeCamera.from_fov(200, 150, 60.0)
    rig = StereoRig(cam, baseline=0.3)
    scene = _wall_scene()
    sim = render_stereo(scene, rig, _camera_pose(0.0, 0.0, 1.5), rng=rng)
    d = sim.disparity
    ok = np.isfinite(d)
    # the true disparity is b f / z, and triangulating it recovers the left-camera points
    np.testing.assert_allclose(d[ok], 0.3 * cam.fx / sim.depth[ok], rtol=1e-12)
    np.testing.assert_allclose(d[sim.hit_index == 1], 0.3 * cam.fx / 5.0, rtol=1e-9)
    # geometric: each left point projects into the right camera at u - d, same row
    P_left = rig.triangulate(d).reshape(-1, 3)
    P_right = P_left - np.array([0.3, 0.0, 0.0])
    uv, _ = cam.project(P_right)
    u, v = np.meshgrid(np.arange(200), np.arange(150))
    np.testing.assert_allclose(uv[ok.ravel(), 0], (u - d)[ok], atol=1e-6)
    np.testing.assert_allclose(uv[ok.ravel(), 1], v[ok], atol=1e-6)
    # photometric: with a baseline giving exactly 10 px on the wall (z = 5), left wall pixels
    # match the right image 10 px to the left far better than at a wrong shift (bricks repeat
    # every 0.25 m ~ 9 px here, so half a brick = 4 px is the least similar shift)
    rig10 = StereoRig(cam, baseline=10.0 * 5.0 / cam.fx)
    sim10 = render_stereo(scene, rig10, _camera_pose(0.0, 0.0, 1.5))
    np.testing.assert_allclose(sim10.disparity[sim10.hit_index == 1], 10.0, rtol=1e-9)
    left = sim10.pair.left.astype(float)
    right = sim10.pair.right.astype(float)
    rows, cols = np.nonzero((sim10.hit_index == 1) & (u >= 20))
    good = np.abs(left[rows, cols] - right[rows, cols - 10]).mean()
    bad = np.abs(left[rows, cols] - right[rows, cols - 14]).mean()
    assert good < 1.0 and good < 0.1 * bad  # measured 0.1 vs 7.2 grey levels


def test_stereo_pixel_noise_level(rng):
    cam = PinholeCamera.from_fov(120, 90, 60.0)
    rig = StereoRig(cam, baseline=0.2)
    scene = _wall_scene()
    clean = render_stereo(scene, rig, _camera_pose(0, 0, 1.5))
    noisy = render_stereo(scene, rig, _camera_pose(0, 0, 1.5), rng=rng, pixel_noise=4.0)
    diff = noisy.pair.left.astype(float) - clean.pair.left.astype(float)
    inner = (clean.pair.left > 20) & (clean.pair.left < 235)  # away from clipping
    # rounding adds uniform(-0.5, 0.5) per image: var = 16 + 2/12; 5 sigma of the std estimate
    sd = np.sqrt(16 + 2 / 12)
    assert abs(diff[inner].std() - sd) < 5 * sd / np.sqrt(2 * inner.sum())


def test_kinect_like_quadratic_depth_noise(rng):
    cam = PinholeCamera.from_fov(120, 90, 60.0)
    scene = Scene([Wall((4.0, -10.0, -10.0), (0.0, 20.0, 0.0), (0.0, 0.0, 20.0))])
    noise = RangeNoise(quadratic_sigma=0.0019)
    sim = render_rgbd(scene, cam, _camera_pose(0.0, 0.0, 1.0), noise=noise, rng=rng)
    err = sim.frame.depth - sim.depth_true  # all at z = 4: sigma = 0.0019 * 16
    sd = 0.0019 * 16
    assert abs(err.std() - sd) < 5 * sd / np.sqrt(2 * err.size)
    np.testing.assert_allclose(noise.sigma(4.0), sd)


def test_stereo_with_principal_point_offset():
    cam = PinholeCamera.from_fov(120, 90, 60.0)
    rig = StereoRig(cam, baseline=0.25, doffs=3.0)
    sim = render_stereo(_wall_scene(), rig, _camera_pose(0.0, 0.0, 1.5), supersample=1)
    ok = np.isfinite(sim.disparity)
    np.testing.assert_allclose(sim.disparity[ok], 0.25 * cam.fx / sim.depth[ok] - 3.0, rtol=1e-12)
    # u_right = u_left - d: project the left points into the right camera (cx + doffs)
    right = PinholeCamera(cam.fx, cam.fy, cam.cx + 3.0, cam.cy, cam.width, cam.height)
    P = cam.backproject(sim.depth).reshape(-1, 3) - np.array([0.25, 0.0, 0.0])
    uv, _ = right.project(P)
    u = np.meshgrid(np.arange(120), np.arange(90))[0]
    np.testing.assert_allclose(uv[ok.ravel(), 0], (u - sim.disparity)[ok], atol=1e-6)
    assert rig.depth_from_disparity(sim.disparity)[ok] == pytest.approx(sim.depth[ok], rel=1e-12)
