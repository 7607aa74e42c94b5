"""Texture search on synthetic textures with known shifts and turns (skimage-style known answers)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from navkit.geometry.fitting import Plane
from navkit.planes.align import search_1d, search_2d
from navkit.planes.texture import PlaneTexture

NU = 0.01
PLANE = Plane(np.array([0.0, 0, 1]), 1.0, np.zeros(3))


def blobs(rng, size=400):
    """A smooth random texture (blurred noise, features ~5 pixels)."""
    img = cv2.GaussianBlur(rng.random((size, size)).astype(np.float32), (0, 0), 2.0)
    return (img - img.min()) / (img.max() - img.min())


def texture(img, i0, j0):
    return PlaneTexture(
        img.astype(np.float32),
        np.ones(img.shape, bool),
        np.zeros(3),
        np.eye(3)[:2],
        np.array([i0, j0]),
        NU,
        PLANE,
    )


def crop_metric(big, lam, tx, ty, h=150, w=200):
    """Texture 2 seen through the motion: tex2(q) = tex1(Rot(lam) q + t), sampled at pixel centres."""
    jj, ii = np.mgrid[0:h, 0:w].astype(np.float64)
    q = np.stack([ii + 100, jj + 100], axis=-1) * NU  # tex2 lattice starts at (100, 100)
    c, s = np.cos(lam), np.sin(lam)
    p = q @ np.array([[c, -s], [s, c]]).T + [tx, ty]
    return cv2.remap(
        big,
        (p[..., 0] / NU).astype(np.float32),
        (p[..., 1] / NU).astype(np.float32),
        cv2.INTER_CUBIC,
    )


@pytest.mark.parametrize("shift", [-23.0, 7.4, 31.6])
def test_search_1d_recovers_a_shift(rng, shift):
    big = blobs(rng)
    t1 = texture(big, 0, 0)
    img2 = crop_metric(big, 0.0, shift * NU, 0.0)
    res = search_1d([(t1, texture(img2, 100, 100))], max_shift=40)
    # exhaustive search to the pixel, then the parabola: a few hundredths of a pixel on a smooth texture
    assert res.shift == pytest.approx(shift, abs=0.1)
    assert res.distinctness > 0.3


@pytest.mark.parametrize(
    ("lam_deg", "tx", "ty"), [(0.0, -0.07, 0.12), (14.0, 0.31, -0.22), (-25.0, 0.05, 0.4)]
)
def test_search_2d_recovers_turn_and_shift(rng, lam_deg, tx, ty):
    big = blobs(rng)
    img2 = crop_metric(big, np.radians(lam_deg), tx, ty)
    res = search_2d(
        texture(big, 0, 0), texture(img2, 100, 100), max_angle=np.radians(30), max_shift=0.6
    )
    # texture features are ~5 px: the fine stage reaches ~0.1 px (1 mm) and ~0.05 deg at a 1 m radius
    assert np.degrees(res.lam) == pytest.approx(lam_deg, abs=0.1)
    assert res.t == pytest.approx([tx, ty], abs=0.002)
    assert res.peak > 0.8


def test_flat_texture_has_no_distinct_minimum():
    flat = np.full((100, 100), 0.5, np.float32)
    res = search_1d([(texture(flat, 0, 0), texture(flat, 3, 0))], max_shift=20)
    assert res.distinctness == pytest.approx(0.0, abs=1e-6)
