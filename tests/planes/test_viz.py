"""Pictures: the overlay tints exactly the labelled pixels; textures keep invalid pixels black."""

from __future__ import annotations

import numpy as np

from navkit.viz.planes import extraction_overlay, plot_map, texture_to_uint8


def test_overlay_tints_the_labelled_pixels():
    img = np.full((200, 300, 3), 100, np.uint8)
    labels = -np.ones((200, 300), np.int64)
    labels[25:100, 25:150] = 0
    labels[125:175, 175:275] = 1
    out = extraction_overlay(img, labels)
    assert out.shape == img.shape and out.dtype == np.uint8
    # unlabelled pixels keep the image (except where a plane's number is written, < 2 %)
    assert np.mean(np.all(out[labels < 0] == 100, axis=1)) > 0.98
    assert np.all(np.any(out[labels >= 0] != 100, axis=1))
    # the two planes get different colours
    assert not np.array_equal(out[30, 30], out[130, 180])


def test_texture_image_marks_invalid_black():
    a = np.array([[0.0, 0.5], [1.0, np.nan]])
    t = texture_to_uint8(a)
    assert t[1, 1] == 0 and t[0, 0] >= 1 and t[1, 0] == 255


def test_map_figure_is_written(tmp_path):
    planes = [
        {
            "id": 0,
            "normal": [0, 1, 0],
            "outline_world": [[0, 1, 0], [2, 1, 0], [2, 1, 3], [0, 1, 3]],
        }
    ]
    poses = np.repeat(np.eye(4)[None], 3, axis=0)
    poses[:, 2, 3] = [0, 0.5, 1.0]
    plot_map(tmp_path / "m.png", planes, poses, truth=poses)
    assert (tmp_path / "m.png").stat().st_size > 5000
