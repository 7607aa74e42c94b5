"""Degenerate but realistic inputs read as data (with a warning), lying ones refused early."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from navkit.errors import FormatError, InputError
from navkit.io.carmen import read_carmen
from navkit.io.images import read_depth, write_image
from navkit.io.lzf import LZFError, lzf_compress, lzf_decompress, max_lzf_output
from navkit.io.pathjson import read_path_json, write_path_json
from navkit.io.textfiles import load_json_file, load_toml_file


def _flaser(ranges, stamp):
    r = " ".join(f"{v:.2f}" for v in ranges)
    return f"FLASER {len(ranges)} {r} 1.0 2.0 0.1 1.0 2.0 0.1 {stamp} host {stamp}\n"


def test_carmen_all_zero_timestamps_use_scan_order(tmp_path, caplog):
    """A Radish log with every timestamp 0 (orebro): scan k at k s, and a warning says so."""
    log = tmp_path / "orebro.log"
    log.write_text("".join(_flaser([1.0, 2.0, 3.0], 0) for _ in range(5)))
    with caplog.at_level(logging.WARNING, logger="navkit.io.carmen"):
        lg = read_carmen(log)
    np.testing.assert_array_equal(lg.timestamps, np.arange(5.0))
    assert "scan order" in caplog.text


def test_carmen_increasing_timestamps_are_kept(tmp_path):
    log = tmp_path / "ok.log"
    log.write_text("".join(_flaser([1.0, 2.0], 10.5 + k) for k in range(4)))
    np.testing.assert_allclose(read_carmen(log).timestamps, 10.5 + np.arange(4))


def test_8bit_depth_png_is_refused_unless_allowed(tmp_path):
    p = tmp_path / "depth8.png"
    raw = np.full((4, 5, 3), 100, np.uint8)
    write_image(p, raw)
    with pytest.raises(FormatError, match=r"depth8\.png.*single-channel"):
        read_depth(p, 1000.0)
    gray = tmp_path / "gray.png"
    import cv2

    cv2.imwrite(str(gray), np.full((4, 5), 100, np.uint8))
    with pytest.raises(FormatError, match="8-bit"):
        read_depth(gray, 1000.0)
    np.testing.assert_allclose(read_depth(gray, 1000.0, allow_8bit=True), 0.1)
    with pytest.raises(InputError, match="scale"):
        read_depth(gray, float("inf"), allow_8bit=True)


def test_lzf_declared_size_is_bounded_before_allocation():
    data = lzf_compress(bytes(10_000))
    assert lzf_decompress(data, 10_000) == bytes(10_000)
    assert max_lzf_output(len(data)) >= 10_000  # the bound holds for the best compression
    with pytest.raises(LZFError, match="cannot hold"):
        lzf_decompress(data, 4 * 2**30)  # a 4 GB claim from ~120 bytes: refused, nothing allocated


def test_path_json_version_format_and_tolerance(tmp_path):
    from navkit.path.approximator import approximate

    s = np.linspace(0, 2, 30)
    good = tmp_path / "path.json"
    write_path_json(good, approximate(np.c_[s, 0.2 * s**2], timed=False).spline)
    data = load_json_file(good)
    import json

    for key, value, match in (
        ("version", 99, "version"),
        ("format", "other-path", "format"),
        ("tolerance", -0.05, "tolerance"),
        ("tolerance", None, None),
    ):
        bad = tmp_path / f"bad-{key}.json"
        bad.write_text(json.dumps({**data, key: value}))
        if match is None:
            read_path_json(bad)  # null tolerance: absent, still a path
            continue
        with pytest.raises(FormatError, match=rf"bad-{key}\.json.*{match}"):
            read_path_json(bad)


@pytest.mark.parametrize(
    ("content", "match"),
    [
        (b"\xff\xfe not utf-8", "not UTF-8"),
        (b"[" * 100_000, "nested too deeply|not valid JSON"),
        (b"{", "not valid JSON"),
    ],
)
def test_json_file_errors_name_the_file(tmp_path, content, match):
    p = tmp_path / "user.json"
    p.write_bytes(content)
    with pytest.raises(FormatError, match=rf"user\.json.*({match})"):
        load_json_file(p)


@pytest.mark.parametrize(
    ("content", "match"),
    [(b"a = \xff", "not UTF-8"), (b"a = " + b"[" * 50_000, "nested too deeply|not valid TOML")],
)
def test_toml_file_errors_name_the_file(tmp_path, content, match):
    p = tmp_path / "user.toml"
    p.write_bytes(content)
    with pytest.raises(FormatError, match=rf"user\.toml.*({match})"):
        load_toml_file(p)


def test_generic_yaml_calib_takes_the_size_from_the_images(tmp_path):
    from navkit.io.stereo import read_stereo_calib

    p = tmp_path / "calib.yaml"
    p.write_text("K: [500, 0, 320, 0, 500, 240, 0, 0, 1]\nbaseline: 0.12\n")
    rig = read_stereo_calib(p, image_size=(640, 480))
    assert (rig.camera.width, rig.camera.height, rig.baseline) == (640, 480, 0.12)
    with pytest.raises(FormatError, match="width"):
        read_stereo_calib(p)  # no images, no size: the file must say
    p.write_text(
        "K: [500, 0, 320, 0, 500, 240, 0, 0, 1]\nbaseline: 0.12\nwidth: 800\nheight: 480\n"
    )
    with pytest.raises(FormatError, match=r"calib\.yaml.*width.*is 800 but the images are 640"):
        read_stereo_calib(p, image_size=(640, 480))
    p.write_text("K: [500, 0, 320, 0, 500, 240, 0, 0, 1]\nbaseline: nan\n")
    with pytest.raises(FormatError, match="baseline"):
        read_stereo_calib(p, image_size=(640, 480))


def test_camera_yaml_that_is_not_utf8_names_the_file(tmp_path):
    from navkit.io.rgbd import read_camera_yaml

    p = tmp_path / "camera.yaml"
    p.write_bytes(b"fx: 500\n# \xff\xfe\nfy: 500\n")
    with pytest.raises(FormatError, match=r"camera\.yaml.*not UTF-8"):
        read_camera_yaml(p)
