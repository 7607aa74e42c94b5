"""The compiled fill, forward warp and left-right check against their NumPy oracles: identical
results on random disparity maps with holes and on the Middlebury pair (both matcher runs)."""

from __future__ import annotations

import numpy as np
import pytest

from navkit import jit
from navkit.stereo.disparity import fill_background, lr_consistency, warp_right_disparity


def _twin(f, *args):  # type: ignore[no-untyped-def]
    """``f(*args)`` on the NumPy twins (navkit.jit.use)."""
    with jit.use("numpy"):
        return f(*args)


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return bool(np.array_equal(a, b, equal_nan=True))


@pytest.mark.twin("fill_background", "lr_consistency", "warp_right")
def test_random_maps(rng):
    for _ in range(5):
        d = rng.uniform(0, 60, (37, 53))
        d[rng.random(d.shape) < 0.3] = np.nan
        d[3] = np.nan  # a row without any valid pixel stays NaN
        d_inf = d.copy()
        d_inf[5, :10] = np.inf  # not finite: filled like NaN
        dr = rng.uniform(0, 60, d.shape)
        dr[rng.random(d.shape) < 0.3] = np.nan
        assert _same(fill_background(d), _twin(fill_background, d))
        assert _same(fill_background(d_inf), _twin(fill_background, d_inf))
        assert _same(warp_right_disparity(d), _twin(warp_right_disparity, d))
        assert _same(warp_right_disparity(d_inf), _twin(warp_right_disparity, d_inf))
        for m in (0.5, 1.0, 3.0):
            assert np.array_equal(lr_consistency(d, dr, m), _twin(lr_consistency, d, dr, m))
    # exact halves: rint rounds half to even in both
    d = np.tile(np.arange(20) + 0.5, (4, 1))
    dr = np.tile(np.arange(20, dtype=float), (4, 1))
    assert np.array_equal(lr_consistency(d, dr, 0.5), _twin(lr_consistency, d, dr, 0.5))
    assert _same(warp_right_disparity(d), _twin(warp_right_disparity, d))
    # collisions: many left pixels on one right pixel, the largest wins in both
    d = np.tile(np.array([1.0, 2.0, 3.0, 2.5, 4.0, np.nan, 6.0, 7.0]), (3, 1))
    assert _same(warp_right_disparity(d), _twin(warp_right_disparity, d))


@pytest.mark.twin("fill_background", "lr_consistency", "warp_right")
def test_middlebury_pair(data_path):
    import cv2

    from navkit.io.images import read_image
    from navkit.stereo import DisparitySettings
    from navkit.stereo.disparity import _matcher, _run

    root = data_path("stereo/middlebury2014-motorcycle-q")
    L, R = read_image(root / "im0.png"), read_image(root / "im1.png")
    g0, g1 = cv2.cvtColor(L, cv2.COLOR_RGB2GRAY), cv2.cvtColor(R, cv2.COLOR_RGB2GRAY)
    s = DisparitySettings(num_disparities=80, block_size=3)
    m = _matcher(s)
    dl = _run(m, g0, g1, s)
    # the right view's disparity as compute_disparity gets it: the mirrored pair
    dr = _run(m, np.ascontiguousarray(g1[:, ::-1]), np.ascontiguousarray(g0[:, ::-1]), s)[:, ::-1]
    assert np.isnan(dl).mean() > 0.05
    assert np.array_equal(lr_consistency(dl, dr), _twin(lr_consistency, dl, dr))
    assert _same(fill_background(dl), _twin(fill_background, dl))
    warped = warp_right_disparity(dl)
    assert _same(warped, _twin(warp_right_disparity, dl))
    assert np.array_equal(lr_consistency(dl, warped), _twin(lr_consistency, dl, warped))
