"""RGB-D readers on real and broken folders."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from navkit.errors import DataNotFoundError, FormatError, InputError
from navkit.io.rgbd import (
    open_rgbd_sequence,
    read_camera_yaml,
    read_cape_calibration,
    read_cape_frame,
    read_simple_rgbd,
    read_tum_rgbd,
)

SLAMBOOK_CAMERA = {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0}


def write_simple(root, n=3, stems=None, yaml=True, scale=1000.0):
    (root / "color").mkdir(parents=True)
    (root / "depth").mkdir()
    stems = stems or [str(i) for i in range(n)]
    for k, s in enumerate(stems):
        cv2.imwrite(str(root / "color" / f"{s}.png"), np.full((8, 10, 3), 10 * k, np.uint8))
        d = np.full((8, 10), int(1.5 * scale), np.uint16)
        d[0, 0] = 0
        cv2.imwrite(str(root / "depth" / f"{s}.png"), d)
    if yaml:
        (root / "camera.yaml").write_text(
            f"fx: 5\nfy: 5\ncx: 4.5\ncy: 3.5  # centre\ndepth_scale: {scale}\n"
        )


def test_simple_layout_round_trip(tmp_path):
    write_simple(tmp_path, stems=["1.5", "2.5", "10"])
    seq = read_simple_rgbd(tmp_path)
    assert len(seq) == 3
    assert np.allclose(seq.timestamps, [1.5, 2.5, 10.0])  # numeric stems, numeric order
    f = seq.frame(2)
    assert f.color.shape == (8, 10, 3) and f.color[0, 0, 0] == 20
    assert np.isnan(f.depth[0, 0]) and np.allclose(f.depth[1:, 1:], 1.5)
    assert seq.camera.width == 10 and seq.camera.fx == 5


def test_simple_layout_stems_not_numbers_give_indices(tmp_path):
    write_simple(tmp_path, stems=["a", "b"])
    assert np.allclose(read_simple_rgbd(tmp_path).timestamps, [0, 1])


def test_simple_layout_errors(tmp_path):
    write_simple(tmp_path / "a", yaml=False)
    with pytest.raises(FormatError, match="fx"):
        read_simple_rgbd(tmp_path / "a")
    write_simple(tmp_path / "b")
    (tmp_path / "b" / "depth" / "2.png").unlink()
    with pytest.raises(FormatError, match="3 colour images but 2 depth"):
        read_simple_rgbd(tmp_path / "b")
    with pytest.raises(DataNotFoundError):
        read_simple_rgbd(tmp_path / "nothing")


def test_broken_camera_yaml(tmp_path):
    p = tmp_path / "camera.yaml"
    p.write_text("fx: five\n")
    with pytest.raises(FormatError, match="fx"):
        read_camera_yaml(p)
    p.write_text("fx 5\n")
    with pytest.raises(FormatError, match="line 1"):
        read_camera_yaml(p)


def test_tum_folder(tmp_path):
    (tmp_path / "rgb").mkdir()
    (tmp_path / "depth").mkdir()
    rgb, dep = ["# color"], ["# depth"]
    for k, t in enumerate([1.0, 1.033, 1.066]):
        cv2.imwrite(str(tmp_path / "rgb" / f"{t:.3f}.png"), np.zeros((480, 640, 3), np.uint8))
        cv2.imwrite(
            str(tmp_path / "depth" / f"{t + 0.004:.3f}.png"),
            np.full((480, 640), 5000 * (k + 1), np.uint16),
        )
        rgb.append(f"{t:.6f} rgb/{t:.3f}.png")
        dep.append(f"{t + 0.004:.6f} depth/{t + 0.004:.3f}.png")
    (tmp_path / "rgb.txt").write_text("\n".join(rgb))
    (tmp_path / "depth.txt").write_text("\n".join(dep))
    seq = open_rgbd_sequence(tmp_path)
    assert len(seq) == 3 and seq.depth_scale == 5000 and seq.camera.fx == 525
    assert np.allclose(seq.frame(1).depth, 2.0)  # raw 10000 / 5000
    (tmp_path / "depth.txt").write_text("1.5 depth/x.png\n")
    with pytest.raises(FormatError, match="no colour / depth pair"):
        read_tum_rgbd(tmp_path)


def test_unknown_folder(tmp_path):
    with pytest.raises(InputError, match=r"rgb\.txt, color/ nor frame-NNNNNN"):
        open_rgbd_sequence(tmp_path)


def test_slambook_reads(data_path):
    seq = read_simple_rgbd(data_path("rgbd/slambook-ch5"), SLAMBOOK_CAMERA)
    assert len(seq) == 3
    f = seq.frame(0)
    # a dining room seen by a Kinect: depths between ~0.5 and ~10 m, mostly valid
    d = f.depth[np.isfinite(f.depth)]
    assert 0.4 < d.min() and d.max() < 12 and len(d) > 0.5 * f.depth.size


def test_cape_calibration_and_frame(data_path, tmp_path):
    root = data_path("rgbd/cape-tunnel")
    cal = read_cape_calibration(root / "calib_params.xml")
    assert np.isclose(cal.K_rgb[0, 0], 548.867, atol=1e-3)
    assert np.isclose(cal.T_rgb_ir[0, 3], 0.0114975, atol=1e-6)  # 11.50 mm -> metres
    f = read_cape_frame(root)
    assert f.points.shape == (480, 640, 3) and f.color_registered.shape == (480, 640, 3)
    z = f.points[..., 2]
    assert np.nanmedian(z) == pytest.approx(1.829, abs=0.01)  # the raw depth median, in metres
    bad = tmp_path / "calib.xml"
    bad.write_text(
        (root / "calib_params.xml")
        .read_text()
        .replace("<Rotation", "<Rot")
        .replace("</Rotation>", "</Rot>")
    )
    with pytest.raises(FormatError, match="Rotation"):
        read_cape_calibration(bad)
    bad.write_text("not xml at all")
    with pytest.raises(FormatError):
        read_cape_calibration(bad)


# ------------------------------------------------------------------------------------------------
# 7-Scenes layout


def write_seven_scenes(root, n=3, pose=True, intrinsics=True):
    root.mkdir(parents=True, exist_ok=True)
    for k in range(n):
        cv2.imwrite(str(root / f"frame-{k:06d}.color.png"), np.full((8, 10, 3), 10 * k, np.uint8))
        d = np.full((8, 10), 1500, np.uint16)
        d[0, 0] = 0
        d[0, 1] = 65535
        cv2.imwrite(str(root / f"frame-{k:06d}.depth.png"), d)
        if pose:
            T = np.eye(4)
            T[0, 3] = 0.1 * k
            np.savetxt(root / f"frame-{k:06d}.pose.txt", T)
    if intrinsics:
        np.savetxt(root / "camera-intrinsics.txt", [[5.0, 0, 4.5], [0, 6.0, 3.5], [0, 0, 1]])


def test_seven_scenes_layout(tmp_path):
    write_seven_scenes(tmp_path)
    seq = open_rgbd_sequence(tmp_path)
    assert len(seq) == 3
    assert (seq.camera.fx, seq.camera.fy, seq.camera.cx, seq.camera.cy) == (5.0, 6.0, 4.5, 3.5)
    np.testing.assert_allclose(seq.timestamps, [0, 1 / 30, 2 / 30])
    assert seq.reference is not None
    np.testing.assert_allclose(seq.reference[:, 0, 3], [0.0, 0.1, 0.2])
    f = seq.frame(1)
    assert np.isnan(f.depth[0, 0]) and np.isnan(f.depth[0, 1])  # 0 and 65535: no measurement
    assert f.depth[1, 1] == pytest.approx(1.5)


def test_seven_scenes_without_intrinsics_or_poses(tmp_path):
    write_seven_scenes(tmp_path, pose=False, intrinsics=False)
    with pytest.raises(DataNotFoundError, match="intrinsics"):
        open_rgbd_sequence(tmp_path)
    seq = open_rgbd_sequence(tmp_path, {"fx": 5, "fy": 5, "cx": 4.5, "cy": 3.5})
    assert seq.reference is None


def test_seven_scenes_broken_pose(tmp_path):
    write_seven_scenes(tmp_path)
    (tmp_path / "frame-000001.pose.txt").write_text("1 0 0\n0 1 0\n")
    with pytest.raises(FormatError) as exc:
        open_rgbd_sequence(tmp_path)
    assert "frame-000001.pose.txt" in str(exc.value)


def test_seven_scenes_real(data_path):
    root = data_path("rgbd/7scenes-tsdf")
    seq = open_rgbd_sequence(root)
    assert len(seq) == 100
    assert seq.camera.fx == 585.0 and seq.camera.cx == 320.0
    assert seq.reference is not None and seq.reference.shape == (100, 4, 4)
    f = seq.frame(0)
    valid = np.isfinite(f.depth)
    assert 0.8 < valid.mean() < 0.95  # 10.8 % of frame 0 has no depth
    assert 0.7 < np.nanmin(f.depth) and np.nanmax(f.depth) < 4.0


def test_seven_scenes_reference_is_orthonormal(data_path):
    seq = open_rgbd_sequence(data_path("rgbd/7scenes-tsdf"))
    R = seq.reference[:, :3, :3]
    np.testing.assert_allclose(
        np.einsum("nji,njk->nik", R, R), np.broadcast_to(np.eye(3), R.shape), atol=1e-12
    )
    raw = np.loadtxt(data_path("rgbd/7scenes-tsdf/frame-000050.pose.txt"))
    np.testing.assert_allclose(seq.reference[50], raw, atol=2e-4)  # the projection moves < 2e-4
