"""Paper 3's correlation localization: 1D slide, the position formula, 2D with known heading."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from navkit.errors import InputError
from navkit.geometry import se2_apply, se2_from_xytheta
from navkit.localization import (
    LikelihoodField,
    correlate_profiles,
    locate_known_heading,
    robot_position,
)
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
