"""Negative information: walls the map puts in view that the fragment lacks."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.errors import ConfigError, InputError
from navkit.localization import locate_known_heading
from navkit.localization.field import LikelihoodField
from navkit.localization.visibility import ViewModel, check_visibility
from navkit.sensors import PinholeCamera, StereoRig
from tests.localization.helpers import RECT, cast, sample_walls

# The benchmark's stereo view: 320 px, 90 deg, b = 0.2 m, 80 disparities (the front end's
# b f / 0.5 m rounded up to 16), depth cut sqrt(0.25 m * b f / 0.25 px) = 5.66 m.
RIG = StereoRig(PinholeCamera.from_fov(320, 240, 90.0), 0.2)
VIEW = ViewModel.from_stereo(RIG, max_depth=float(np.sqrt(32.0)), num_disparities=80)


def view_scan(pose, view=VIEW, n=529):
    """Body-frame points of the map along ``n`` bearings over the view (0.1 deg apart)."""
    b = np.linspace(view.bearing_min, view.bearing_max, n)
    r = cast(RECT, np.asarray(pose, float), b)
    ok = np.isfinite(r)
    return np.stack([r[ok] * np.cos(b[ok]), r[ok] * np.sin(b[ok])], axis=1), b[ok]


def test_view_from_stereo_is_the_matched_columns():
    # columns [80, 239] of a 320-px image with c_x = 159.5, f_x = 160: atan(79.5 / 160)
    assert VIEW.bearing_max == pytest.approx(np.arctan(79.5 / 160), abs=1e-12)
    assert VIEW.bearing_min == pytest.approx(-VIEW.bearing_max, abs=1e-12)
    assert VIEW.depth_sigma_coefficient == pytest.approx(0.25 / 32.0)
    with pytest.raises(InputError, match="num_disparities"):
        ViewModel.from_stereo(RIG, max_depth=5.0, num_disparities=200)
    with pytest.raises(ConfigError, match="bearing"):
        ViewModel(0.5, -0.5, 5.0)


def test_the_true_pose_sees_every_predicted_wall():
    pose = np.array([6.0, 4.0, np.radians(45.0)])  # the (8, 6) corner, 2.8 m away
    pts, _ = view_scan(pose)
    v = check_visibility(RECT, pts, pose, VIEW)
    assert v.expected.any() and v.unseen_fraction == 0.0
    assert np.isnan(v.unseen_span).all()


def test_a_gap_in_the_fragment_is_reported_with_its_bearings():
    pose = np.array([6.0, 4.0, np.radians(45.0)])
    pts, b = view_scan(pose)
    gap = (b >= np.radians(8.0)) & (b < np.radians(18.0))
    v = check_visibility(RECT, pts[~gap], pose, VIEW)
    # bearings are checked every 1 deg from -26.42 deg and a point counts for the nearest
    # bearing and both its neighbours: the points end at 7.9 deg (nearest bearing 7.58) and
    # resume at 18.0 deg (nearest 17.58), so 9.58 .. 15.58 deg (7 bearings) have no point within
    # one step. They meet the y = 6 wall 2.2-2.5 m away, 0.5-1 m from its corner, 27-37 deg off
    # its normal: all expected.
    assert round(v.unseen_fraction * len(v.bearings)) == 7
    np.testing.assert_allclose(np.degrees(v.unseen_span), [9.58, 15.58], atol=0.01)


def test_a_far_fragment_placed_beside_a_near_wall_is_inconsistent():
    """The benchmark's false fix: the x = 8 wall seen 5 m away (far, noisy points at the edge of
    the range) fits as well 2.5 m to the right, where the map puts the y = 0 wall 1-2 m away in
    the right part of the view - the fragment has nothing there."""
    seen_from = np.array([3.0, 3.0, 0.0])
    pts, _ = view_scan(seen_from)
    assert check_visibility(RECT, pts, seen_from, VIEW).unseen_fraction == 0.0
    wrong = np.array([3.0, 0.5, 0.0])
    v = check_visibility(RECT, pts, wrong, VIEW)
    # from (3, 0.5) a bearing b < 0 meets y = 0 at 0.5 / sin|b| m; it is expected where its
    # incidence 90 - |b| deg is <= 75 deg: b = -26.42 .. -15.42 deg, 12 of the 53 bearings (the
    # fragment's points there lie 5 m away). Bearings toward the x = 8 wall agree with the
    # fragment (same depth, 5 m, from both poses).
    assert round(v.unseen_fraction * len(v.bearings)) == 12
    np.testing.assert_allclose(np.degrees(v.unseen_span), [-26.42, -15.42], atol=0.01)
    assert v.unseen_fraction > 0.15  # the default max_unseen of locate_known_heading


def test_a_wall_beyond_the_usable_depth_is_not_expected():
    pose = np.array([2.0, 3.0, 0.0])  # the x = 8 wall 6 m away: past the 5.66 m depth cut
    v = check_visibility(RECT, np.empty((0, 2)), pose, VIEW)
    # the nearest expected depth: z + 3 k z^2 <= 5.66 m, k = 1 / 128  ->  z <= 5.06 m
    assert not v.expected.any() and v.unseen_fraction == 0.0
    v = check_visibility(RECT, np.empty((0, 2)), np.array([3.0, 3.0, 0.0]), VIEW)
    assert v.expected.all() and v.unseen_fraction == 1.0  # 5 m: expected, and nothing seen


def test_locate_known_heading_refuses_a_fix_that_misses_a_predicted_wall():
    fld = LikelihoodField.from_points(sample_walls(RECT, 0.01), 0.05, 0.1)
    pose = np.array([6.0, 4.0, np.radians(45.0)])
    pts, b = view_scan(pose)
    full = locate_known_heading(fld, pts, pose[2], walls=RECT, view=VIEW)
    assert full.ok and full.unseen_fraction == 0.0
    gap = (b >= 0.0) & (b < np.radians(20.0))  # a 20 deg hole in the y = 6 wall
    plain = locate_known_heading(fld, pts[~gap], pose[2], walls=RECT)
    assert plain.ok and np.isnan(plain.unseen_fraction)  # without the view: confident
    fix = locate_known_heading(fld, pts[~gap], pose[2], walls=RECT, view=VIEW)
    assert not fix.ok and fix.reason == "unseen wall"
    # the position itself is still right (two walls seen); only the confidence is withdrawn
    assert np.hypot(*(fix.position - pose[:2])) < 0.005
    assert fix.visibility is not None and fix.unseen_fraction > 0.15
