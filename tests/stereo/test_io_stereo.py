"""Stereo calibration readers and the frame-folder format."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.errors import DataNotFoundError, FormatError
from navkit.io.stereo import (
    read_kitti_stereo_calib,
    read_middlebury_calib,
    read_stereo_calib,
    read_stereo_frames,
    write_generic_yaml_calib,
    write_stereo_frames,
)
from navkit.sensors import PinholeCamera, StereoRig


@pytest.mark.realdata
def test_middlebury_calib(data_path):
    rig, extra = read_middlebury_calib(data_path("stereo/middlebury2014-motorcycle-q/calib.txt"))
    assert rig.camera.fx == pytest.approx(999.421)
    assert rig.baseline == pytest.approx(0.193001)  # millimetres in the file
    assert rig.doffs == pytest.approx(32.778)
    assert (rig.camera.width, rig.camera.height) == (741, 497)
    assert extra["ndisp"] == 70
    # the README's depth formula Z[mm] = baseline * f / (d + doffs)
    assert rig.depth_from_disparity(np.array([30.0]))[0] == pytest.approx(
        193.001 * 999.421 / (30 + 32.778) / 1000
    )


def test_kitti_calib(tmp_path):
    f, cx, cy = 721.5377, 609.5593, 172.854
    p = tmp_path / "calib.txt"
    p.write_text(
        f"P0: {f} 0 {cx} 0 0 {f} {cy} 0 0 0 1 0\n"
        f"P2: {f} 0 {cx} 44.85728 0 {f} {cy} 0.2163791 0 0 1 0.002745884\n"
        f"P3: {f} 0 {cx} -339.5242 0 {f} {cy} 2.199936 0 0 1 0.002729905\n"
    )
    rig = read_kitti_stereo_calib(p, image_size=(1242, 375))
    assert rig.baseline == pytest.approx((44.85728 + 339.5242) / f)  # about 0.53 m
    assert rig.camera.cx == pytest.approx(cx) and rig.camera.width == 1242
    with pytest.raises(FormatError, match="image size"):
        read_kitti_stereo_calib(p)
    assert read_stereo_calib(p, image_size=(1242, 375)).baseline == pytest.approx(rig.baseline)


def test_yaml_round_trip_and_errors(tmp_path):
    rig = StereoRig(PinholeCamera(400.0, 401.0, 160.0, 120.0, 320, 240), 0.15, 1.5)
    write_generic_yaml_calib(tmp_path / "calib.yaml", rig)
    assert read_stereo_calib(tmp_path / "calib.yaml") == rig
    (tmp_path / "bad.yaml").write_text("K: [1, 2, 3]\nbaseline: 0.1\nwidth: 10\nheight: 10\n")
    with pytest.raises(FormatError, match="'K'"):
        read_stereo_calib(tmp_path / "bad.yaml")
    (tmp_path / "other.txt").write_text("hello\n")
    with pytest.raises(FormatError, match="unknown calibration"):
        read_stereo_calib(tmp_path / "other.txt")
    with pytest.raises(DataNotFoundError):
        read_stereo_calib(tmp_path / "absent.yaml")


def test_frame_folder_round_trip(tmp_path, rng):
    rig = StereoRig(PinholeCamera(100.0, 100.0, 31.5, 23.5, 64, 48), 0.1)
    imgs = [rng.integers(0, 255, (48, 64, 3), dtype=np.uint8) for _ in range(3)]
    poses = np.repeat(np.eye(4)[None], 3, axis=0)
    poses[:, 0, 3] = [0.0, 1.0, 2.0]
    write_stereo_frames(tmp_path / "f", rig, imgs, imgs, poses, np.array([1.0, 2.0, 3.0]))
    fr = read_stereo_frames(tmp_path / "f")
    assert len(fr) == 3 and fr.rig == rig
    np.testing.assert_allclose(fr.poses[:, 0, 3], [0, 1, 2])
    (tmp_path / "f" / "right" / "000002.png").unlink()
    with pytest.raises(FormatError, match="left"):
        read_stereo_frames(tmp_path / "f")
