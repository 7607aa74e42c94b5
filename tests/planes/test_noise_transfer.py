"""Thresholds in the sensor's noise units (navkit.planes.noise) and the dense step on the TUM
frames, a recording nothing in the project was tuned on."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from navkit.geometry import se3_from_rt, se3_inverse
from navkit.planes import FrameMotion, OdometrySettings, PlaneOdometry, observe_rgbd
from navkit.planes.dense import DenseFrame, dense_align
from navkit.planes.metrics import poses_at
from navkit.planes.noise import KINECT_V1_K, DepthNoise, brightness_sigma
from navkit.planes.odometry import DenseGates
from navkit.planes.texture import to_gray

TUM = "rgbd/tum-fr3-structure-notexture-far"


def _err(T_est, T_true) -> tuple[float, float]:
    E = se3_inverse(T_true) @ T_est
    return float(np.linalg.norm(E[:3, 3])), float(
        np.degrees(Rotation.from_matrix(E[:3, :3]).magnitude())
    )


def test_depth_noise_grows_with_the_square_of_the_distance():
    n = DepthNoise()
    assert n.k == KINECT_V1_K
    np.testing.assert_allclose(n.sigma([1.0, 2.0, 5.0]), KINECT_V1_K * np.array([1, 4, 25]))
    assert n.sigma(5.0) == pytest.approx(0.04)  # Khoshelham and Elberink: 4 cm at 5 m
    np.testing.assert_allclose(n.point_to_plane(2.0), np.sqrt(2) * n.sigma(2.0))


def test_brightness_sigma_recovers_added_noise_on_a_smooth_image():
    """Immerkaer's estimate on a brightness ramp plus Gaussian noise of known sigma: the ramp
    cancels, the estimate is within 5 % (the mean of |N * I| over 300k pixels)."""
    rng = np.random.default_rng(0)
    y, x = np.mgrid[0:480, 0:640].astype(np.float32)
    ramp = 0.2 + 0.5 * x / 640 + 0.2 * y / 480
    for sigma in (0.01, 0.03):
        img = ramp + rng.normal(0, sigma, ramp.shape).astype(np.float32)
        assert brightness_sigma(img) == pytest.approx(sigma, rel=0.05)
    assert brightness_sigma(ramp) == pytest.approx(1 / 255)  # noiseless: the 8-bit floor


def test_poses_at_interpolates_and_leaves_uncovered_times_nan():
    t_ref = np.arange(0.0, 1.0, 0.01)
    T = np.tile(np.eye(4), (len(t_ref), 1, 1))
    T[:, 0, 3] = t_ref  # 1 m/s along x
    T[:, :3, :3] = Rotation.from_rotvec(np.outer(t_ref, [0, 0, 1.0])).as_matrix()
    P = poses_at([-0.1, 0.255, 0.5, 2.0], t_ref, T)
    assert np.isnan(P[0]).all() and np.isnan(P[3]).all()
    assert P[1, 0, 3] == pytest.approx(0.255)
    assert Rotation.from_matrix(P[1, :3, :3]).as_rotvec()[2] == pytest.approx(0.255)
    gap = np.delete(t_ref, [50, 51, 52])  # a 40 ms hole: no pose there
    assert np.isnan(poses_at([0.51], gap, np.delete(T, [50, 51, 52], axis=0))).all()


@pytest.fixture
def tum(data_path):
    from navkit.io.rgbd import open_rgbd_sequence
    from navkit.io.trajectory import read_tum

    root = data_path(TUM)
    seq = open_rgbd_sequence(root)
    tr = read_tum(root / "groundtruth.txt")
    return seq, poses_at(seq.timestamps, tr.timestamps, tr.poses)


def test_dense_step_engages_on_the_tum_frames(tum):
    """The TUM frames (depth x 5000 as the format says, Kinect at 1.3-4.3 m): every frame is
    refined and verified by the dense step with a real overlap, and every motion is right.
    Measured (frames 10-24): overlap 0.87-0.96, 0.6-0.9 depth sigmas, errors <= 0.4 cm /
    0.3 deg per frame."""
    seq, G = tum
    idx = list(range(10, 25))
    odo = PlaneOdometry(OdometrySettings())
    res = [odo.update(observe_rgbd(seq.frame(i))) for i in idx]
    for k in range(1, len(idx)):
        r = res[k]
        assert isinstance(r, FrameMotion) and r.source.endswith("+dense"), (idx[k], r)
        assert r.dense is not None
        assert 0.5 < r.dense.overlap <= 1.0
        assert np.isfinite(r.dense.geometric_sigmas) and np.isfinite(r.dense.photometric_sigmas)
        et, er = _err(odo.relative(k - 1, k), se3_inverse(G[idx[k - 1]]) @ G[idx[k]])
        assert et < 0.01 and er < 1.0, (idx[k], et, er)


def test_dense_step_engages_on_a_far_scene(tum):
    """The same frames with every depth x 5 (a scene at 6-21 m; also what reading TUM depth
    with a scale of 1000 instead of 5000 gives): the dense step works in the depth noise's
    units, so it still overlaps, passes its gates and finds the (5 x larger) motion. A fixed
    0.3-4 m window left no point at all here (overlap 0.00, residuals NaN)."""
    seq, G = tum
    a, b = 40, 41
    frames = {}
    for i in (a, b):
        f = seq.frame(i)
        frames[i] = DenseFrame.build(to_gray(f.color), 5.0 * f.depth, f.camera)
    truth = se3_inverse(G[a]) @ G[b]
    truth[:3, 3] *= 5.0
    r = dense_align(frames[a], frames[b], np.eye(4))
    assert r.overlap > 0.8
    assert DenseGates().check(r) == ""
    et, er = _err(r.T, truth)
    assert et < 5 * 0.01 and er < 1.0  # the 1 cm / 1 deg of the true scale, scaled


def test_a_start_far_off_in_a_repetitive_scene_is_rejected_or_right(tum):
    """Started 40 cm / 10 deg from the motion-capture motion, the dense step on the TUM frames
    either finds it (within 5 cm / 2 deg) or fails the gates (7-Scenes' calibration,
    unchanged)."""
    seq, G = tum
    rng = np.random.default_rng(3)
    outcomes = []
    for a, b in ((20, 21), (50, 60)):
        fa, fb = seq.frame(a), seq.frame(b)
        Da = DenseFrame.build(to_gray(fa.color), fa.depth, fa.camera)
        Db = DenseFrame.build(to_gray(fb.color), fb.depth, fb.camera)
        truth = se3_inverse(G[a]) @ G[b]
        for _ in range(2):
            d, w = rng.normal(size=3), rng.normal(size=3)
            P = se3_from_rt(
                Rotation.from_rotvec(np.radians(10) * w / np.linalg.norm(w)).as_matrix(),
                0.4 * d / np.linalg.norm(d),
            )
            r = dense_align(Da, Db, truth @ P)
            passed = DenseGates().check(r) == ""
            et, er = _err(r.T, truth)
            outcomes.append(passed)
            if passed:
                assert et < 0.05 and er < 2.0, (a, b, et, er)


def _wall(rng, n_normal, rho, size=1.0, n=3000, noise=None):
    """Points of a plane patch (normal ``n_normal``, distance ``rho``) with Kinect depth noise
    along the normal."""
    noise = noise or DepthNoise()
    nn = np.asarray(n_normal, float) / np.linalg.norm(n_normal)
    a = np.cross(nn, [0.0, 0.0, 1.0] if abs(nn[2]) < 0.9 else [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(nn, a)
    uv = rng.uniform(-size, size, (n, 2))
    X = rho * nn + uv[:, :1] * a + uv[:, 1:] * b
    return X + rng.normal(size=(n, 1)) * noise.sigma(X[:, 2])[:, None] * nn


def test_fit_plane_covariance_matches_monte_carlo():
    """The predicted tilt and offset sigmas of a noise-weighted fit agree with the scatter over
    300 noisy draws of a wall at 2.5 m (within 15 %: 300 samples give ~4 % on a sigma)."""
    from navkit.planes.noise import fit_plane

    rng = np.random.default_rng(0)
    n0 = np.array([0.2, -0.1, -1.0])
    n0 /= np.linalg.norm(n0)
    fits = [fit_plane(_wall(rng, n0, 2.5)) for _ in range(300)]
    f = fits[0]
    tilt = np.array([[(g.normal * np.sign(g.normal @ f.normal)) @ e for e in f.axes] for g in fits])
    off = np.array([g.normal @ f.centroid - g.rho for g in fits])
    pred = np.sqrt(np.diag(np.mean([g.cov for g in fits], axis=0)))
    assert tilt[:, 0].std() == pytest.approx(pred[0], rel=0.15)
    assert tilt[:, 1].std() == pytest.approx(pred[1], rel=0.15)
    assert off.std() == pytest.approx(pred[2], rel=0.15)


def test_information_names_what_the_planes_leave_free():
    """Two walls (a corridor seen at 2-3 m) fix everything but the translation along their
    intersection line: that direction - and only it - is named free; a third wall fixes it."""
    from navkit.planes.noise import fit_plane, free_directions, plane_pair_information

    rng = np.random.default_rng(1)
    walls = [([1.0, 0.0, -0.3], 2.0), ([-1.0, 0.0, -0.3], 2.0), ([0.0, 1.0, -0.2], 1.2)]
    H = np.zeros((6, 6))
    for n, rho in walls[:2]:
        f1, f2 = fit_plane(_wall(rng, n, rho)), fit_plane(_wall(rng, n, rho))
        H += plane_pair_information(f1, f2, np.eye(3), np.zeros(3))
    free, sig_t, sig_r = free_directions(H, 0.05, 2.0)
    # the two walls' normals are (+-1, 0, -0.3): their intersection line is along y
    assert free == ("ty",), (free, sig_t, sig_r)
    f1, f2 = fit_plane(_wall(rng, *walls[2])), fit_plane(_wall(rng, *walls[2]))
    H += plane_pair_information(f1, f2, np.eye(3), np.zeros(3))
    free, sig_t, sig_r = free_directions(H, 0.05, 2.0)
    assert free == () and sig_t.max() < 0.005 and sig_r.max() < 0.2
