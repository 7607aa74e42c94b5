"""Correlative matching: known shifts and rotations, exactness vs brute force, ambiguity."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.errors import ConfigError, InputError
from navkit.localization import MatcherSettings, match_scan
from navkit.localization.field import LikelihoodField
from navkit.localization.matcher import analyse_peak, score_poses
from tests.localization.helpers import LSHAPE, RECT, sample_walls, scan_points


@pytest.fixture(scope="module")
def lfield():
    return LikelihoodField.from_points(sample_walls(LSHAPE, 0.01), 0.05, 0.1)


@pytest.mark.parametrize(
    "pose, offset",
    [
        ((2.0, 3.0, 0.7), (0.4, -0.3, 0.15)),
        ((7.0, 1.5, -2.0), (-0.6, 0.5, -0.2)),
        ((3.3, 6.1, 3.0), (0.2, 0.7, 0.3)),
    ],
)
def test_tracking_recovers_known_shift_and_rotation(lfield, rng, pose, offset):
    pose = np.array(pose)
    pts = scan_points(LSHAPE, pose, n=361, noise=0.01, rng=rng)
    fix = match_scan(lfield, pts, pose + np.array(offset))
    # 1 cm range noise over ~300 points: sub-cell refinement reaches a few mm; the field is
    # sampled at 5 cm and interpolated bilinearly, so allow 2 cm and 0.3 deg.
    assert np.hypot(*(fix.pose[:2] - pose[:2])) < 0.02
    assert abs(np.degrees(np.angle(np.exp(1j * (fix.pose[2] - pose[2]))))) < 0.3
    assert fix.ok and not fix.ambiguity.ambiguous
    assert fix.score > 0.8


def test_global_search_without_prior(lfield, rng):
    pose = np.array([7.8, 2.2, 2.5])
    pts = scan_points(LSHAPE, pose, n=361, noise=0.01, rng=rng)
    fix = match_scan(lfield, pts, None)
    assert np.hypot(*(fix.pose[:2] - pose[:2])) < 0.02
    assert fix.ok


def test_branch_and_bound_equals_brute_force(lfield, rng):
    """The discrete optimum found by branch-and-bound is the brute-force maximum of the same grid."""
    from navkit.localization.matcher import _Search, _thin

    # a window reaching 3 m beyond the map's corner: pyramid blocks that start outside the map
    # but reach into it must keep their true maximum (a bound computed only on the map is wrong)
    pose = np.array([1.0, 1.0, 0.3])
    pts = _thin(scan_points(LSHAPE, pose, n=181, noise=0.01, rng=rng), 0.1)
    thetas = 0.3 + np.linspace(-0.1, 0.1, 9)
    base = pose[:2] - 3.0
    n = 121
    search = _Search(lfield, pts, thetas, base, n)
    best, exact = search.run(levels=7, lower=-1.0, cap=10**9)
    assert exact
    K, IX, IY = np.meshgrid(np.arange(len(thetas)), np.arange(n), np.arange(n), indexing="ij")
    brute = search.scores(0, K.ravel(), IX.ravel(), IY.ravel())
    assert best[0] == pytest.approx(brute.max(), abs=1e-12)
    # and the brute-force scores agree with the public scorer (nearest cell, same poses)
    j = int(np.argmax(brute))
    P = search.pose(K.ravel()[j], IX.ravel()[j], IY.ravel()[j])
    assert score_poses(lfield, pts, P[None])[0] == pytest.approx(brute[j], abs=1 / 255 + 1e-6)
    # and it is a sound search: visiting far fewer nodes than the brute force
    assert search.evaluated < 2 * len(brute)


def test_single_straight_wall_is_reported_ambiguous_along_itself():
    wall = np.array([[[-20.0, 2.0], [20.0, 2.0]]])
    fld = LikelihoodField.from_points(sample_walls(wall, 0.01), 0.05, 0.1)
    pose = np.array([0.0, 0.0, 0.0])
    pts = scan_points(wall, pose, n=181, fov=np.radians(90))  # sees 4 m of the wall
    fix = match_scan(fld, pts, pose + np.array([0.3, 0.1, 0.05]))
    amb = fix.ambiguity
    assert amb.ambiguous and "elongated" in amb.reason
    assert not fix.ok
    assert abs(amb.direction[0]) > 0.99  # along the wall (x)
    s = MatcherSettings()
    assert amb.extent >= 2 * s.ambiguity_window  # flat over the whole examined window
    assert amb.extent_minor < 0.3  # but well determined across the wall
    assert abs(fix.pose[1] - pose[1]) < 0.02  # the distance to the wall is right


def test_corner_is_not_ambiguous():
    corner = np.array([[[0.0, 0.0], [6.0, 0.0]], [[0.0, 0.0], [0.0, 6.0]]])
    fld = LikelihoodField.from_points(sample_walls(corner, 0.01), 0.05, 0.1)
    pose = np.array([2.0, 2.0, -2.3])
    pts = scan_points(corner, pose, n=181, fov=np.radians(120))
    _, extent, minor, _, _ = analyse_peak(fld, pts, pose)
    assert extent < 0.3 and minor < 0.3


def test_symmetric_room_reports_a_second_peak(rng):
    # the rectangle looks the same turned by 180 degrees about its centre: a global fix must say so
    fld = LikelihoodField.from_points(sample_walls(RECT, 0.01), 0.05, 0.1)
    pose = np.array([2.0, 2.5, 0.4])
    pts = scan_points(RECT, pose, n=361, noise=0.005, rng=rng)
    fix = match_scan(fld, pts, None)
    amb = fix.ambiguity
    assert "second peak" in amb.reason and not fix.ok
    twin = np.array([8.0 - pose[0], 6.0 - pose[1]])
    found = [fix.pose[:2], amb.second_pose[:2]]
    # one of the two peaks is the truth, the other its mirror image (coarse search: 0.1 m cells)
    d = sorted([min(np.hypot(*(f - pose[:2])), np.hypot(*(f - twin))) for f in found])
    assert d[1] < 0.25


def test_bad_input():
    fld = LikelihoodField.from_points(sample_walls(RECT, 0.05), 0.05, 0.1)
    with pytest.raises(InputError, match="points"):
        match_scan(fld, np.full((5, 2), np.nan))
    with pytest.raises(InputError, match="points"):
        match_scan(fld, np.zeros((5, 3)))
    with pytest.raises(ConfigError, match="peak_tolerance"):
        MatcherSettings(peak_tolerance=2.0)
    with pytest.raises(ConfigError, match="sigma"):
        LikelihoodField.from_points(np.zeros((3, 2)), 0.05, -1.0)


def test_one_pass_collects_every_leaf_near_the_optimum(rng):
    """``keep < 1`` keeps exactly the leaves within that ratio of the optimum (the runner-up
    search of a global fix); checked against brute force on the same discretised score."""
    from navkit.localization.matcher import _Search, _thin

    fld = LikelihoodField.from_points(sample_walls(RECT, 0.01), 0.05, 0.1)
    pose = np.array([2.0, 2.5, 0.4])
    pts = _thin(scan_points(RECT, pose, n=181, noise=0.005, rng=rng), 0.1)
    # the pose and its half-turn twin about the room centre (4, 3) are both in the window
    thetas = np.array([0.4, 0.4 + np.pi])
    base = np.array([1.5, 1.5])
    n = 101  # 5 m x 5 m at 5 cm: covers (2, 2.5) and the twin (6, 3.5)
    search = _Search(fld, pts, thetas, base, n)
    best, exact = search.run(levels=7, lower=-1.0, cap=10**9, keep=0.9)
    assert exact
    K, IX, IY = np.meshgrid(np.arange(len(thetas)), np.arange(n), np.arange(n), indexing="ij")
    brute = search.scores(0, K.ravel(), IX.ravel(), IY.ravel())
    assert best[0] == pytest.approx(brute.max(), abs=1e-12)
    ls, lk, lx, ly = (np.concatenate(a) for a in zip(*search.leaves, strict=True))
    found = {(int(a), int(b), int(c)) for a, b, c in zip(lk, lx, ly, strict=True)}
    want = np.flatnonzero(brute > 0.9 * brute.max())
    assert {(int(K.ravel()[j]), int(IX.ravel()[j]), int(IY.ravel()[j])) for j in want} <= found
    # both peaks of the symmetric room survive: one leaf near each heading
    assert set(lk[ls > 0.9 * best[0]].tolist()) == {0, 1}


def test_scan_far_from_every_wall_is_maximally_ambiguous_not_nan():
    """A scan that touches no wall near the pose scores 0 everywhere: the peak analysis must say
    'ambiguous over the whole window' (finite extents), not divide by zero."""
    fld = LikelihoodField.from_points(sample_walls(RECT, 0.05), 0.05, 0.1)
    far = np.array([[100.0, 100.0], [101.0, 100.0], [100.0, 101.0]])
    s = MatcherSettings()
    _direction, extent, extent_minor, cov, best = analyse_peak(fld, far, [0.0, 0.0, 0.0], s)
    assert best == 0.0
    assert np.all(np.isfinite(cov)) and np.isfinite(extent) and np.isfinite(extent_minor)
    assert extent_minor >= 2 * s.ambiguity_window  # every offset in the window is as good
