"""Point-to-line pose refinement: known poses, degenerate walls, outliers, stereo weights."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.errors import ConfigError, InputError
from navkit.localization.refine import RefineSettings, refine_pose, stereo_range_sigma
from tests.localization.helpers import LSHAPE, RECT, scan_points


@pytest.mark.parametrize("pose", [(2.0, 3.0, 0.7), (7.5, 1.0, -2.5), (1.2, 6.8, 3.0)])
def test_refinement_recovers_the_pose_from_a_perturbed_start(pose, rng):
    pose = np.array(pose)
    pts = scan_points(LSHAPE, pose, n=361, noise=0.01, rng=rng)
    start = pose + np.array([0.12, -0.09, np.radians(2.0)])
    res = refine_pose(LSHAPE, pts, start)
    # ~360 points with 1 cm range noise on >= 2 non-parallel walls: the position's standard
    # error is about 0.01 / sqrt(180) < 1 mm per axis; allow 3 mm and 0.05 deg
    assert np.hypot(*(res.pose[:2] - pose[:2])) < 0.003
    assert abs(res.pose[2] - pose[2]) < np.radians(0.05)
    assert res.converged and not res.degenerate
    # the reported covariance is of the right size (sigma ~ 1 mm, not 1 cm)
    assert np.sqrt(np.trace(res.covariance[:2, :2])) < 0.003


def test_covariance_matches_the_monte_carlo_spread():
    pose = np.array([3.0, 2.0, 0.4])
    est = []
    sig = []
    for seed in range(40):
        pts = scan_points(RECT, pose, n=181, noise=0.02, rng=np.random.default_rng(seed))
        r = refine_pose(RECT, pts, pose + np.array([0.05, 0.05, 0.01]))
        est.append(r.pose[:2])
        sig.append(np.sqrt(np.diag(r.covariance)[:2]))
    spread = np.std(np.array(est), axis=0)
    predicted = np.mean(np.array(sig), axis=0)
    # 40 samples: the sample std is within about +-35 % (3 sigma of sqrt(1/(2*40)) ~ 11 %) of the
    # truth; the first-order covariance should agree to that
    np.testing.assert_allclose(spread, predicted, rtol=0.4)


def test_a_single_straight_wall_is_degenerate_along_itself(rng):
    wall = np.array([[[-20.0, 2.0], [20.0, 2.0]]])
    pose = np.array([0.0, 0.0, 0.0])
    pts = scan_points(wall, pose, n=91, fov=np.radians(60), noise=0.01, rng=rng)
    res = refine_pose(wall, pts, np.array([0.7, 0.1, 0.0]), known_heading=True)
    assert res.degenerate
    assert abs(res.weak_direction[0]) > 0.99  # along the wall
    assert res.information_ratio < 1e-6
    assert abs(res.pose[1]) < 0.005  # across it, determined (91 points, 1 cm noise)
    assert res.pose[2] == 0.0  # the known heading is kept


def test_a_corner_is_not_degenerate_with_a_known_heading(rng):
    pose = np.array([6.5, 4.5, np.radians(40.0)])
    pts = scan_points(RECT, pose, n=121, fov=np.radians(90), noise=0.01, rng=rng)
    res = refine_pose(RECT, pts, pose + np.array([0.1, -0.1, 0.0]), known_heading=True)
    assert not res.degenerate
    assert np.hypot(*(res.pose[:2] - pose[:2])) < 0.003


def test_outliers_do_not_pull_the_pose(rng):
    pose = np.array([5.0, 3.0, 0.0])
    pts = scan_points(RECT, pose, n=361, noise=0.01, rng=rng)
    # clutter in front of the east wall only: half as many points again, 0.10-0.25 m in front
    # (inside the first association gate of 0.3 m)
    east = np.flatnonzero(pts[:, 0] > 2.9)
    idx = rng.choice(east, len(east) // 2, replace=False)
    r = np.linalg.norm(pts[idx], axis=1, keepdims=True)
    bad = pts[idx] * (1.0 - rng.uniform(0.10, 0.25, (len(idx), 1)) / r)
    res = refine_pose(RECT, np.concatenate([pts, bad]), pose + np.array([0.05, 0.05, 0.0]))
    # a plain least-squares fit is pulled by (clutter count x mean offset) / (points on the two
    # walls across x) ~ 46 x 0.175 / 200 ~ 4 cm; Huber weights and the shrinking gate keep the
    # fix within 1 mm-scale noise: allow 5 mm
    assert np.hypot(*(res.pose[:2] - pose[:2])) < 0.005


def test_stereo_weights_follow_the_depth_error():
    # on the optical axis: sigma_z = z^2 sigma_d / (b f); 4 m, b f = 0.2 * 160, 0.25 px
    s = stereo_range_sigma(np.array([[4.0, 0.0], [2.0, 0.0]]), 0.2, 160.0, 0.25)
    np.testing.assert_allclose(s, [16 * 0.25 / 32, 4 * 0.25 / 32])
    with pytest.raises(InputError, match="baseline"):
        stereo_range_sigma(np.zeros((1, 2)), 0.0, 160.0)


def test_weighted_refinement_beats_uniform_weights_on_stereo_like_noise():
    """Points with range noise ~ r^2 (stereo): inverse-variance weights give smaller errors."""
    pose = np.array([2.0, 2.0, 0.5])
    e_w, e_u = [], []
    for seed in range(20):
        rng = np.random.default_rng(seed)
        b = np.linspace(-np.pi, np.pi, 720, endpoint=False)
        from tests.localization.helpers import cast

        r = cast(RECT, pose, b)
        ok = np.isfinite(r)
        r, b = r[ok], b[ok]
        sig = 0.004 * r**2
        r = r + rng.normal(0, 1, len(r)) * sig
        pts = np.stack([r * np.cos(b), r * np.sin(b)], axis=1)
        w = refine_pose(RECT, pts, pose + np.array([0.05, -0.05, 0.01]), range_sigma=sig)
        u = refine_pose(RECT, pts, pose + np.array([0.05, -0.05, 0.01]))
        e_w.append(np.hypot(*(w.pose[:2] - pose[:2])))
        e_u.append(np.hypot(*(u.pose[:2] - pose[:2])))
    # ranges 2-6 m: sigma 1.6-14 cm; the weighted fit's mean error is clearly smaller
    assert np.mean(e_w) < 0.8 * np.mean(e_u)


def test_bad_input():
    with pytest.raises(InputError, match="walls"):
        refine_pose(np.zeros((0, 2, 2)), np.ones((5, 2)), np.zeros(3))
    with pytest.raises(InputError, match="points"):
        refine_pose(RECT, np.full((5, 2), np.nan), np.zeros(3))
    with pytest.raises(InputError, match="range_sigma"):
        refine_pose(RECT, np.ones((5, 2)), np.zeros(3), range_sigma=np.ones(3))
    with pytest.raises(ConfigError, match="max_distance"):
        RefineSettings(max_distance=0.0)


def test_occluded_fraction_flags_a_pose_that_sees_through_walls():
    from navkit.localization.refine import occluded_fraction

    column = np.array(
        [
            [[3.7, 2.7], [4.3, 2.7]],
            [[4.3, 2.7], [4.3, 3.3]],
            [[4.3, 3.3], [3.7, 3.3]],
            [[3.7, 3.3], [3.7, 2.7]],
        ]
    )
    walls = np.concatenate([RECT, column])
    pose = np.array([1.5, 3.0, 0.0])  # west of the column, looking east at its west face
    pts = scan_points(walls, pose, n=181, fov=np.radians(90))
    assert occluded_fraction(walls, pts, pose) == 0.0  # the true pose sees nothing through walls
    # 0.6 m east (the column's width): the west-face points land on the east face, seen through
    # the column (and the east wall's points, moved 0.6 m past x = 8, through the east wall)
    shifted = pose + np.array([0.6, 0.0, 0.0])
    face = np.mean(np.abs(pts[:, 0] - 2.2) < 0.05)  # share of points on the west face
    frac = occluded_fraction(walls, pts, shifted)
    assert frac >= 0.9 * face > 0.05
    # points 0.1 m behind their wall are within the default 0.15 m margin; 0.3 m needs a margin
    behind = pts * (1 + 0.3 / np.linalg.norm(pts, axis=1))[:, None]
    assert occluded_fraction(walls, behind, pose) > 0.5
    assert occluded_fraction(walls, behind, pose, margin=0.4) == 0.0
