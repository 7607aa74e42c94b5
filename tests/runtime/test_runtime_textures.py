"""Planes with their textures for the viewer: each plane of an RGB-D frame as a
mesh on its fit, textured with the colour pixels of its region."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from navkit.geometry import se3_from_rt
from navkit.runtime.planes_stage import textured_planes


@pytest.fixture(scope="module")
def frame():
    from navkit.planes import observe_rgbd
    from navkit.sensors import PinholeCamera, RGBDFrame
    from navkit.sim import render_rgbd
    from tests.planes.conftest import corridor, start_pose

    camera = PinholeCamera(131.25, 131.25, 79.5, 59.5, 160, 120)
    f = render_rgbd(corridor(3), camera, start_pose(3), rng=0).frame
    return f, observe_rgbd(RGBDFrame(f.color, f.depth, f.camera, 0.0))


def _texel(p, uv):
    h, w = p.texture.shape[:2]
    j = np.minimum((uv[:, 0] * w).astype(int), w - 1)
    i = np.minimum((uv[:, 1] * h).astype(int), h - 1)
    return p.texture[i, j]


@pytest.mark.parametrize("max_px", [1000, 32])
def test_vertices_on_their_plane_and_texture_is_the_region_colour(frame, max_px):
    f, obs = frame
    T = se3_from_rt(np.eye(3), [1.0, -2.0, 0.5])  # a world frame shifted from the camera
    planes = textured_planes(obs, f.color, T, step=4, max_texture_px=max_px)
    assert len(planes) >= 3  # the corridor's floor and walls
    cam = f.camera
    W = cam.width
    for p in planes:
        seg = obs.segments[p.id]
        X = p.vertices - T[:3, 3]  # back in the camera frame
        np.testing.assert_allclose(X @ seg.plane.normal, seg.plane.rho, atol=1e-9)
        assert p.triangles.min() >= 0 and p.triangles.max() < len(X)
        assert np.all((p.texcoords > 0) & (p.texcoords < 1))
        # each vertex projects into its plane's region, onto the pixel it was made from
        u = cam.fx * X[:, 0] / X[:, 2] + cam.cx
        v = cam.fy * X[:, 1] / X[:, 2] + cam.cy
        col, row = np.rint(u).astype(int), np.rint(v).astype(int)
        region = np.zeros(cam.height * W, bool)
        region[seg.inliers] = True
        assert region[row * W + col].mean() == 1.0
        # the texture at a vertex's texcoords is the colour image there (decimated: the
        # texel's first pixel)
        h, w = p.texture.shape[:2]
        du = (p.texcoords[:, 0].max() - p.texcoords[:, 0].min()) * w
        dec = max(round((col.max() - col.min()) / du), 1) if du > 0 else 1
        c0 = col.min() - col.min() % 4
        r0 = row.min() - row.min() % 4
        want = f.color[r0 + (row - r0) // dec * dec, c0 + (col - c0) // dec * dec]
        np.testing.assert_array_equal(_texel(p, p.texcoords), want)
        if max_px == 32:
            assert max(h, w) <= 32


def test_textured_planes_in_rerun_load_back(frame, tmp_path):
    pytest.importorskip("rerun")
    from navkit.runtime import Output
    from navkit.viz.rerun_logger import RerunLogger

    f, obs = frame
    planes = textured_planes(obs, f.color, np.eye(4))
    logger = RerunLogger(save=tmp_path / "planes.rrd")
    logger.set_time(0)
    logger.log_output(
        Output("/navkit/planes/textured", "textured_planes", 0, "planes_odom", planes)
    )
    logger.close()
    res = subprocess.run(
        [sys.executable, "-m", "rerun", "rrd", "verify", str(tmp_path / "planes.rrd")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
