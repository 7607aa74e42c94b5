"""Images, depth images and PFM: real files, round trips, broken files."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from navkit.errors import FormatError, InputError
from navkit.io.images import read_depth, read_image, read_pfm, write_depth, write_image, write_pfm

MIDDLEBURY = "stereo/middlebury2014-motorcycle-q"
SLAMBOOK = "rgbd/slambook-ch5"


@pytest.mark.realdata
def test_slambook_color_is_rgb(data_path):
    path = data_path(f"{SLAMBOOK}/color/1.png")
    rgb = read_image(path)
    bgr = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert rgb.shape == (480, 640, 3) and rgb.dtype == np.uint8
    np.testing.assert_array_equal(rgb, bgr[:, :, ::-1])


@pytest.mark.realdata
def test_slambook_depth_pgm(data_path):
    path = data_path(f"{SLAMBOOK}/depth/1.pgm")
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert raw.dtype == np.uint16
    depth = read_depth(path, scale=1000.0)
    assert depth.shape == (480, 640) and depth.dtype == np.float64
    np.testing.assert_array_equal(np.isnan(depth), raw == 0)
    np.testing.assert_array_equal(depth[raw > 0], raw[raw > 0] / 1000.0)
    # a Kinect-type sensor in a dining room: 0.5 m .. 10 m
    assert 0.3 < np.nanmin(depth) and np.nanmax(depth) < 10.5
    # 16-bit kept by read_image
    assert read_image(path).dtype == np.uint16


@pytest.mark.realdata
def test_middlebury_pfm_orientation(data_path):
    disp = read_pfm(data_path(f"{MIDDLEBURY}/disp0GT.pfm"))
    assert disp.shape == (497, 741) and disp.dtype == np.float32
    mask = read_image(data_path(f"{MIDDLEBURY}/mask0nocc.png"))
    # unknown disparity (inf) is exactly where the mask is 0: only with rows returned top-down
    np.testing.assert_array_equal(np.isinf(disp), mask == 0)
    assert np.isinf(disp).any()
    finite = disp[np.isfinite(disp)]
    # quarter-size Motorcycle: ndisp in calib.txt bounds the disparities
    assert finite.min() > 0 and finite.max() < 300


def test_pfm_roundtrip(tmp_path, rng):
    gray = rng.normal(size=(5, 7)).astype(np.float32)
    gray[0, 0], gray[1, 1], gray[2, 2] = np.inf, -np.inf, np.nan
    color = rng.normal(size=(4, 6, 3)).astype(np.float32)
    for little in (True, False):
        write_pfm(tmp_path / "g.pfm", gray, little_endian=little)
        np.testing.assert_array_equal(read_pfm(tmp_path / "g.pfm"), gray)
        write_pfm(tmp_path / "c.pfm", color, little_endian=little)
        np.testing.assert_array_equal(read_pfm(tmp_path / "c.pfm"), color)
    # the file really stores rows bottom-up, little-endian under a negative scale
    write_pfm(tmp_path / "g.pfm", gray)
    raw = (tmp_path / "g.pfm").read_bytes()
    assert raw.startswith(b"Pf\n7 5\n-1.0\n")
    np.testing.assert_array_equal(np.frombuffer(raw[-28:], "<f4"), gray[0])


def test_pfm_broken(tmp_path):
    p = tmp_path / "bad.pfm"
    p.write_bytes(b"Pf\n4 3\n-1.0\n" + b"\x00" * 20)
    with pytest.raises(FormatError, match=r"bad\.pfm.*truncated.*48 bytes"):
        read_pfm(p)
    p.write_bytes(b"P6\n4 3\n255\n")
    with pytest.raises(FormatError, match=r"bad\.pfm.*header"):
        read_pfm(p)


def test_image_roundtrip(tmp_path, rng):
    rgb = rng.integers(0, 256, (9, 11, 3)).astype(np.uint8)
    write_image(tmp_path / "a.png", rgb)
    np.testing.assert_array_equal(read_image(tmp_path / "a.png"), rgb)
    # the file is standard BGR for other OpenCV users
    np.testing.assert_array_equal(cv2.imread(str(tmp_path / "a.png"))[:, :, ::-1], rgb)
    g16 = rng.integers(0, 65536, (9, 11)).astype(np.uint16)
    for suffix in (".png", ".pgm"):
        write_image(tmp_path / f"b{suffix}", g16)
        np.testing.assert_array_equal(read_image(tmp_path / f"b{suffix}"), g16)
    rgba = rng.integers(0, 256, (4, 5, 4)).astype(np.uint8)
    write_image(tmp_path / "c.png", rgba)
    np.testing.assert_array_equal(read_image(tmp_path / "c.png"), rgba)


def test_depth_roundtrip(tmp_path, rng):
    depth = np.round(rng.uniform(0.4, 8.0, (6, 8)), 3)
    depth[2, 3] = np.nan
    write_depth(tmp_path / "d.png", depth, scale=1000.0)
    back = read_depth(tmp_path / "d.png", scale=1000.0)
    np.testing.assert_array_equal(np.isnan(back), np.isnan(depth))
    # millimetre quantisation: |error| <= 0.5 mm
    np.testing.assert_allclose(back, depth, atol=5e-4 + 1e-12)
    with pytest.raises(InputError, match="depth"):
        write_depth(tmp_path / "e.png", np.full((2, 2), 70.0), scale=1000.0)
    assert not (tmp_path / "e.png").exists()


def test_image_broken(tmp_path):
    p = tmp_path / "junk.png"
    p.write_bytes(b"not an image at all")
    with pytest.raises(FormatError, match=r"junk\.png.*cannot be decoded"):
        read_image(p)
    with pytest.raises(FormatError, match=r"junk\.png"):
        read_depth(p, 1000.0)
    write_image(tmp_path / "rgb.png", np.zeros((2, 2, 3), np.uint8))
    with pytest.raises(FormatError, match=r"rgb\.png.*single-channel"):
        read_depth(tmp_path / "rgb.png", 1000.0)
    with pytest.raises(InputError, match="scale"):
        read_depth(tmp_path / "rgb.png", 0.0)
    with pytest.raises(InputError, match="float64"):
        write_image(tmp_path / "f.png", np.zeros((2, 2)))
