"""Trajectory readers and writers: real files, round trips, broken files."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from navkit.errors import FormatError, InputError
from navkit.io.trajectory import (
    Trajectory,
    read_euroc,
    read_kitti_poses,
    read_odometry_log,
    read_trajectory,
    read_tum,
    write_kitti_poses,
    write_tum,
)

TRAJ = "trajectories"


# --------------------------------------------------------------------------- real files
@pytest.mark.realdata
def test_kitti_00_gt(data_path):
    traj = read_kitti_poses(
        data_path(f"{TRAJ}/KITTI_00_gt.txt"), data_path(f"{TRAJ}/KITTI_00_gt_times.txt")
    )
    assert len(traj) == 4541
    np.testing.assert_allclose(traj.poses[0], np.eye(4), atol=1e-9)
    # timestamps come from the times file (10 Hz camera: 4541 frames in ~470 s)
    assert traj.timestamps[0] == 0.0 and 465.0 < traj.timestamps[-1] < 475.0
    # KITTI 00 is about 3.7 km long (README); rotations are orthonormal to the file's 1e-6 digits
    assert 3650.0 < traj.path_length < 3750.0
    R = traj.rotations
    np.testing.assert_allclose(
        R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), atol=1e-5
    )
    # the car drives on a road: camera y (down) varies by metres, x/z by hundreds of metres
    span = np.ptp(traj.positions, axis=0)
    assert span[1] < 0.1 * min(span[0], span[2])
    # without a times file: the frame index
    auto = read_trajectory(data_path(f"{TRAJ}/KITTI_00_gt.txt"))
    np.testing.assert_array_equal(auto.timestamps, np.arange(4541.0))
    np.testing.assert_array_equal(auto.poses, traj.poses)


@pytest.mark.realdata
def test_tum_fr1_xyz_against_scipy(data_path):
    path = data_path(f"{TRAJ}/freiburg1_xyz-groundtruth.txt")
    traj = read_trajectory(path)
    assert len(traj) == 3000
    ref = np.loadtxt(path)  # independent parse: numpy + scipy
    np.testing.assert_array_equal(traj.timestamps, ref[:, 0])
    np.testing.assert_allclose(traj.positions, ref[:, 1:4], atol=1e-12)
    # the file rounds quaternions to 4 decimals: scipy normalises the same way we do
    np.testing.assert_allclose(
        traj.rotations, Rotation.from_quat(ref[:, 4:8]).as_matrix(), atol=1e-12
    )
    # the xyz sequence moves the camera back and forth by decimetres around a fixed spot
    assert np.all(np.ptp(traj.positions, axis=0) < 1.0)


@pytest.mark.realdata
def test_tum_fr2_desk_duplicate_timestamp(data_path):
    path = data_path(f"{TRAJ}/fr2_desk_groundtruth.txt")
    traj = read_tum(path)
    # 20957 poses, one of which repeats the previous timestamp (line 10863) and is dropped
    assert len(traj) == 20956
    assert np.all(np.diff(traj.timestamps) > 0)
    with pytest.raises(FormatError, match=r"fr2_desk_groundtruth\.txt.*line 10863.*repeats"):
        read_tum(path, duplicates="error")


@pytest.mark.realdata
def test_mrclam_odometry(data_path):
    t, v, omega = read_odometry_log(data_path("odometry/mrclam-dataset7/Robot1_Odometry.dat"))
    assert len(t) == len(v) == len(omega) == 58598
    assert np.all(np.diff(t) > 0)
    assert 880.0 < t[-1] - t[0] < 910.0  # "900 s"
    # an iRobot Create: under 0.5 m/s and a few rad/s
    assert np.abs(v).max() < 0.5 and np.abs(omega).max() < 3.0


# --------------------------------------------------------------------------- round trips
def _random_trajectory(rng, n=50) -> Trajectory:
    t = 1.3e9 + np.cumsum(rng.uniform(0.01, 0.1, n))
    t = np.round(t, 6)
    R = Rotation.random(n, random_state=7).as_matrix()
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = rng.normal(scale=10.0, size=(n, 3))
    return Trajectory(t, T)


def test_tum_roundtrip(tmp_path, rng):
    traj = _random_trajectory(rng)
    write_tum(tmp_path / "t.txt", traj)
    back = read_trajectory(tmp_path / "t.txt")
    # timestamps written with 9 decimals: exact for these 6-decimal values (float64 ulp ~2e-7 s)
    np.testing.assert_allclose(back.timestamps, traj.timestamps, rtol=0, atol=1e-6)
    # 12 significant digits: 1e-11 relative on positions of ~10 m, quaternions ~1e-12
    np.testing.assert_allclose(back.poses, traj.poses, atol=1e-9)


def test_kitti_roundtrip(tmp_path, rng):
    traj = _random_trajectory(rng)
    write_kitti_poses(tmp_path / "k.txt", traj, times_path=tmp_path / "times.txt")
    back = read_kitti_poses(tmp_path / "k.txt", tmp_path / "times.txt")
    np.testing.assert_allclose(back.poses, traj.poses, atol=1e-9)
    np.testing.assert_allclose(back.timestamps, traj.timestamps, rtol=1e-9)
    assert read_trajectory(tmp_path / "k.txt", format="kitti").poses.shape == (50, 4, 4)


def test_euroc_w_first_and_nanoseconds(tmp_path):
    header = (
        "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],"
        "q_RS_y [],q_RS_z [],v_RS_R_x [m s^-1],v_RS_R_y [m s^-1],v_RS_R_z [m s^-1],"
        "b_w_RS_S_x,b_w_RS_S_y,b_w_RS_S_z,b_a_RS_S_x,b_a_RS_S_y,b_a_RS_S_z\n"
    )
    c = np.cos(np.pi / 4)
    rows = [
        f"1403715273262142976,1.0,2.0,3.0,{c},0.0,0.0,{c}" + ",0" * 9,  # 90 deg about z
        "1403715273267142912,1.5,2.0,3.0,1.0,0.0,0.0,0.0" + ",0" * 9,
    ]
    p = tmp_path / "data.csv"
    p.write_text(header + "\n".join(rows) + "\n")
    traj = read_trajectory(p)
    # 4.999936 ms apart as the integer nanoseconds say; seconds near 1.4e9 in float64 have an
    # ulp of 2.4e-7 s, so the difference is exact to two roundings (< 5e-7 s)
    assert traj.timestamps[1] - traj.timestamps[0] == pytest.approx(0.004999936, abs=5e-7)
    assert traj.timestamps[0] == pytest.approx(1403715273.262142976, abs=1e-6)
    # w first: the first pose turns x into y
    np.testing.assert_allclose(traj.rotations[0] @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(traj.positions[1], [1.5, 2, 3])
    np.testing.assert_allclose(read_euroc(p).poses, traj.poses)


# --------------------------------------------------------------------------- broken files
def _tum(tmp_path, lines: list[str], name="bad.txt"):
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


GOOD = ["# header", "1.0 0 0 0 0 0 0 1", "", "2.0 1 0 0 0 0 0 1", "3.0 2 0 0 0 0 0 1"]


def test_tum_nan(tmp_path):
    lines = [*GOOD]
    lines[3] = "2.0 nan 0 0 0 0 0 1"
    with pytest.raises(FormatError, match=r"bad\.txt.*line 4.*non-finite"):
        read_tum(_tum(tmp_path, lines))


def test_tum_backwards(tmp_path):
    lines = [*GOOD]
    lines[4] = "1.5 2 0 0 0 0 0 1"
    with pytest.raises(FormatError, match=r"bad\.txt.*line 5.*before the previous one.*line 4"):
        read_tum(_tum(tmp_path, lines))


def test_wrong_columns(tmp_path):
    lines = [*GOOD]
    lines[4] = "3.0 2 0 0 0 0 1"
    with pytest.raises(FormatError, match=r"bad\.txt.*line 5 has 7 columns.*expected 8"):
        read_tum(_tum(tmp_path, lines))
    with pytest.raises(FormatError, match=r"odo\.dat.*line 2 has 2 columns"):
        read_odometry_log(_tum(tmp_path, ["1 0.1 0.0", "2 0.1"], "odo.dat"))
    with pytest.raises(FormatError, match=r"k\.txt.*line 1 has 11 columns"):
        read_kitti_poses(_tum(tmp_path, [" ".join(["0"] * 11)], "k.txt"))
    with pytest.raises(FormatError, match=r"x\.txt.*first data line has 5 columns"):
        read_trajectory(_tum(tmp_path, ["1 2 3 4 5"], "x.txt"))


def test_non_numeric_and_zero_quaternion(tmp_path):
    lines = [*GOOD]
    lines[1] = "1.0 0 0 zero 0 0 0 1"
    with pytest.raises(FormatError, match=r"bad\.txt.*line 2 is not numeric"):
        read_tum(_tum(tmp_path, lines))
    lines = [*GOOD]
    lines[1] = "1.0 0 0 0 0 0 0 0"
    with pytest.raises(FormatError, match=r"bad\.txt.*line 2.*zero quaternion"):
        read_tum(_tum(tmp_path, lines))


def test_kitti_broken(tmp_path):
    eye = "1 0 0 0 0 1 0 0 0 0 1 0"
    skew = "1 0 0 0 0 1 0 0 0 0 2 0"
    with pytest.raises(FormatError, match=r"k\.txt.*line 2.*not orthonormal"):
        read_kitti_poses(_tum(tmp_path, [eye, skew], "k.txt"))
    with pytest.raises(FormatError, match=r"times\.txt.*3 timestamps for 2 poses"):
        read_kitti_poses(
            _tum(tmp_path, [eye, eye], "k.txt"), _tum(tmp_path, ["0", "1", "2"], "times.txt")
        )
    with pytest.raises(FormatError, match=r"times\.txt.*line 2.*before"):
        read_kitti_poses(
            _tum(tmp_path, [eye, eye], "k.txt"), _tum(tmp_path, ["1", "0.5"], "times.txt")
        )


def test_trajectory_validation():
    T = np.tile(np.eye(4), (3, 1, 1))
    with pytest.raises(InputError, match="timestamp 2"):
        Trajectory(np.array([0.0, 1.0, 1.0]), T)
    bad = T.copy()
    bad[1, 0, 3] = np.nan
    with pytest.raises(InputError, match="pose 1"):
        Trajectory(np.arange(3.0), bad)
    with pytest.raises(InputError, match="poses"):
        Trajectory(np.arange(3.0), T[:2])
    sub = Trajectory(np.arange(3.0), T)[1:]
    assert len(sub) == 2 and sub.timestamps[0] == 1.0
