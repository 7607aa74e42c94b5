"""Paper 3's correlation localization: 1D slide, the position formula, 2D with known heading."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from navkit.errors import InputError
from navkit.geometry import se2_apply, se2_from_xytheta
from navkit.localization import locate_known_heading
from navkit.localization.correlation import correlate_profiles, robot_position
from navkit.localization.field import LikelihoodField
from tests.localization.helpers import LSHAPE, RECT, sample_walls, scan_points


@pytest.mark.parametrize("shift", [0, 17, 123, 160])
def test_profile_correlation_recovers_the_fragment_offset(shift):
    rng = np.random.default_rng(shift)
    profile = np.cumsum(rng.normal(size=200))  # a wall profile (depth along the wall)
    frag = profile[shift : shift + 40] + rng.normal(0, 0.05, 40)
    assert int(np.argmax(correlate_profiles(profile, frag))) == shift


def test_raw_sum_is_the_papers_formula():
    A = np.array([1.0, 2.0, 3.0, 4.0])
    B = np.array([1.0, -1.0])
    # R_i = sum_j A_{i+j} B_j
    np.testing.assert_allclose(correlate_profiles(A, B, normalized=False), [-1.0, -1.0, -1.0])
    with pytest.raises(InputError, match="fragment"):
        correlate_profiles(A, np.ones(5))


@settings(max_examples=50, deadline=None)
@given(
    st.floats(-50, 50),
    st.floats(-50, 50),
    st.floats(-np.pi, np.pi),
    st.floats(-10, 10),
    st.floats(-10, 10),
)
def test_position_formula_inverts_the_pose(x, y, theta, cx, cy):
    """``robot_position`` undoes the camera -> world motion (paper eq. 2) exactly."""
    world = se2_apply(se2_from_xytheta(x, y, theta), np.array([[cx, cy]]))[0]
    np.testing.assert_allclose(robot_position(world, [cx, cy], theta), [x, y], atol=1e-9)


@pytest.mark.parametrize("pose", [(2.0, 3.0, 0.7), (7.5, 1.0, -2.5), (1.2, 6.8, 3.0)])
def test_known_heading_correlation_locates_the_robot(pose, rng):
    pose = np.array(pose)
    fld = LikelihoodField.from_points(sample_walls(LSHAPE, 0.01), 0.05, 0.1)
    pts = scan_points(LSHAPE, pose, n=361, noise=0.01, rng=rng)
    fix = locate_known_heading(fld, pts, pose[2])
    # the peak is found to a cell and refined by a parabola: well inside one 5 cm cell
    assert np.hypot(*(fix.position - pose[:2])) < 0.025
    assert fix.peak_extent < 0.3


def test_known_heading_on_a_single_wall_reports_an_elongated_peak():
    wall = np.array([[[-20.0, 2.0], [20.0, 2.0]]])
    fld = LikelihoodField.from_points(sample_walls(wall, 0.01), 0.05, 0.1)
    pts = scan_points(wall, np.array([0.0, 0.0, 0.0]), n=91, fov=np.radians(60))
    fix = locate_known_heading(fld, pts, 0.0)
    assert fix.peak_extent > 10.0  # the fragment fits anywhere along the 40 m wall
    assert abs(fix.peak_direction[0]) > 0.99
    assert abs(fix.position[1]) < 0.03  # across the wall it is determined


def test_rectangle_known_heading_breaks_the_symmetry(rng):
    # with the heading known, the 180-degree twin of the rectangle is not a candidate
    fld = LikelihoodField.from_points(sample_walls(RECT, 0.01), 0.05, 0.1)
    pose = np.array([2.0, 2.5, 0.4])
    fix = locate_known_heading(fld, scan_points(RECT, pose, n=361, noise=0.005, rng=rng), pose[2])
    assert np.hypot(*(fix.position - pose[:2])) < 0.025


def test_known_heading_corner_view_localizes_confidently(rng):
    """Paper 3's scenario: one 90-deg view of a corner, heading known -> a confident fix, refined
    by point-to-line least squares well below the field's 5 cm cells."""
    fld = LikelihoodField.from_points(sample_walls(RECT, 0.01), 0.05, 0.1)
    pose = np.array([6.0, 4.0, np.radians(35.0)])
    pts = scan_points(RECT, pose, n=121, fov=np.radians(90), noise=0.01, rng=rng)
    fix = locate_known_heading(fld, pts, pose[2], walls=RECT)
    assert fix.ok and not fix.ambiguous
    # ~120 points with 1 cm noise on two walls: standard error ~1.3 mm per axis; allow 5 mm
    assert np.hypot(*(fix.position - pose[:2])) < 0.005
    assert fix.refinement is not None and not fix.refinement.degenerate


def test_known_heading_single_wall_is_ambiguous_not_a_fix():
    wall = np.array([[[-20.0, 2.0], [20.0, 2.0]]])
    fld = LikelihoodField.from_points(sample_walls(wall, 0.01), 0.05, 0.1)
    pts = scan_points(wall, np.array([0.0, 0.0, 0.0]), n=91, fov=np.radians(60))
    fix = locate_known_heading(fld, pts, 0.0, walls=wall)
    assert not fix.ok and fix.ambiguous
    assert "elongated peak" in fix.reason and "degenerate" in fix.reason
    assert abs(fix.peak_direction[0]) > 0.99 and fix.peak_extent > 10.0
    assert abs(fix.position[1]) < 0.01  # the offset across the wall is still reported


def test_known_heading_twin_corners_report_a_second_peak():
    """The L-shaped room has two identical north-east corners ((10, 4) and (5, 8)): a view of
    one of them fits both, and must be reported, not given as a fix."""
    fld = LikelihoodField.from_points(sample_walls(LSHAPE, 0.01), 0.05, 0.1)
    pose = np.array([8.5, 2.5, np.radians(45.0)])
    pts = scan_points(LSHAPE, pose, n=61, fov=np.radians(60))
    fix = locate_known_heading(fld, pts, pose[2], walls=LSHAPE)
    assert not fix.ok and "second peak" in fix.reason
    twin = pose[:2] + np.array([5.0 - 10.0, 8.0 - 4.0])
    found = {tuple(np.round(fix.position, 1)), tuple(np.round(fix.second_position, 1))}
    assert found == {tuple(np.round(pose[:2], 1)), tuple(np.round(twin, 1))}


def test_region_excludes_the_far_side_of_a_wall():
    """A field is symmetric about a wall: the fragment of the south wall seen from (4, 3) also
    fits the north wall seen from outside, at (4, 9). The room outline rules that out."""
    fld = LikelihoodField.from_points(sample_walls(RECT, 0.01), 0.05, 0.1)
    pose = np.array([4.0, 3.0, -np.pi / 2])
    pts = scan_points(RECT, pose, n=31, fov=np.radians(30))  # only the south wall
    outline = np.array([[0.0, 0.0], [8.0, 0.0], [8.0, 6.0], [0.0, 6.0]])
    plain = locate_known_heading(fld, pts, pose[2])
    ys = {round(float(plain.position[1])), round(float(plain.second_position[1]))}
    assert ys == {3, 9}  # the inside fix and its outside twin are the two peaks
    inside = locate_known_heading(fld, pts, pose[2], region=outline)
    assert abs(inside.position[1] - 3.0) < 0.03
    assert not (np.isfinite(inside.second_position).all() and inside.second_position[1] > 6.0)
    assert inside.ambiguous and "elongated peak" in inside.reason  # still along the wall
