"""navkit.viz.sensors: figures are valid PNGs, written atomically, showing the truth."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from navkit.geometry import R_BODY_FROM_OPTICAL, se3_from_rt
from navkit.sensors import PinholeCamera, StereoRig
from navkit.sim import (
    Box,
    Ground,
    Scene,
    SpinningLidar,
    Wall,
    render_rgbd,
    render_scan,
    render_stereo,
)
from navkit.viz import sensors as viz


@pytest.fixture(scope="module")
def scene():
    return Scene(
        [
            Ground(name="ground"),
            Box((4.0, 0.0, 0.5), (1.0, 1.0, 1.0), name="box"),
            Wall((8.0, -4.0, 0.0), (0.0, 8.0, 0.0), (0.0, 0.0, 3.0), name="wall"),
        ]
    )


def _read(path):
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    assert img is not None
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def _count(img, rgb, tol=12):
    return int((np.abs(img.astype(float) - np.array(rgb) * 255).max(axis=-1) < tol).sum())


def test_scan_figure_colours_follow_truth(scene, tmp_path):
    T = se3_from_rt(np.eye(3), [0.0, 0.0, 1.5])
    sim = render_scan(scene, SpinningLidar(n_beams=16, n_columns=256), T)
    path = viz.plot_scan(sim, scene, tmp_path / "scan.png")
    img = _read(path)
    assert _count(img, viz.GROUND_COLOR) > 1000 and _count(img, viz.OBSTACLE_COLOR) > 200
    # an all-ground scene has (almost) no obstacle-red pixels: the colouring follows the labels
    only_ground = Scene([Ground()])
    sim2 = render_scan(only_ground, SpinningLidar(n_beams=16, n_columns=256), T)
    img2 = _read(viz.plot_scan(sim2, only_ground, tmp_path / "ground.png"))
    assert _count(img2, viz.OBSTACLE_COLOR) < 0.02 * _count(img, viz.OBSTACLE_COLOR) + 50


def test_camera_figures_and_world(scene, tmp_path):
    cam = PinholeCamera.from_fov(96, 72, 70.0)
    T = se3_from_rt(R_BODY_FROM_OPTICAL, [0.0, 0.0, 1.0])
    viz.plot_rgbd(render_rgbd(scene, cam, T), tmp_path / "rgbd.png")
    viz.plot_stereo(render_stereo(scene, StereoRig(cam, 0.1), T), tmp_path / "stereo.png")
    viz.plot_world(scene, tmp_path / "world.png", poses=[(0, 0, 0)], pose_labels=["robot"])
    for name in ("rgbd.png", "stereo.png", "world.png"):
        img = _read(tmp_path / name)
        assert img.std() > 10
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rgbd.png", "stereo.png", "world.png"]


def test_failed_save_leaves_no_file(scene, tmp_path):
    fig = viz.new_figure(3, 3)
    fig.add_subplot().plot([0, 1], [0, 1])
    with pytest.raises(ValueError):
        viz.save_figure(fig, tmp_path / "bad.unknownformat")
    assert list(tmp_path.iterdir()) == []
