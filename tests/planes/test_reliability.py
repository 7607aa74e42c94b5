"""The texture solution is checked against the rest of the scene: a wrong texture match is
reported as a MotionFailure naming the texture's degrees of freedom, never returned silently."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.geometry import se3_inverse
from navkit.geometry.rotations import rotation_angle
from navkit.planes import (
    ExtractionSettings,
    MotionEstimate,
    MotionFailure,
    estimate_motion,
    observe_rgbd,
)
from navkit.planes.motion import depth_consistency
from navkit.sim import Scene, Sphere, Texture, Wall, render_rgbd

from .conftest import BRICKS, CAMERA, DEPTH_NOISE, MOTION, start_pose

ES = ExtractionSettings(cell=10)
BALL = Sphere(center=(0.2, -0.8, 1.1), radius=0.3, texture=Texture("noise", scale=0.1, seed=1))


def wall(texture_shift: float = 0.0) -> Wall:
    """The brick wall y = -1.5; ``texture_shift`` slides its bricks along x, not its geometry."""
    return Wall(
        origin=(-5 + texture_shift, -1.5, 0), u=(30, 0, 0), v=(0, 0, 3), texture=BRICKS, name="wall"
    )


@pytest.fixture(scope="module")
def ball_pair():
    """One textured wall (one plane direction) and a ball 0.7 m in front of it (off-plane)."""
    T1 = start_pose(1)
    f1 = render_rgbd(Scene([wall(), BALL]), CAMERA, T1, noise=DEPTH_NOISE, rng=1)
    f2 = render_rgbd(Scene([wall(), BALL]), CAMERA, T1 @ MOTION, noise=DEPTH_NOISE, rng=2)
    return observe_rgbd(f1.frame, ES), observe_rgbd(f2.frame, ES)


def test_depth_consistency_separates_true_and_wrong_motions(ball_pair):
    o1, o2 = ball_pair
    assert len(o1.segments) == 1 and len(o2.segments) == 1  # the ball is not a plane
    good = depth_consistency(o1, o2, MOTION, [0])
    # the ball's points (the only off-plane ones) are tested: ~1.7e4 of them
    assert good.tested > 5000
    # true motion: depth noise 0.2 % x 1.2 m = 2.4 mm << tolerance 3 cm + 2 %; only pixels at
    # the ball's silhouette (rounding to a pixel across the depth edge) can violate: < 5 %
    assert good.violation < 0.05
    for axis in (0, 1):  # 20 cm along the wall's two in-plane directions (2/3 of the radius)
        S = np.eye(4)
        S[axis, 3] = 0.2
        bad = depth_consistency(o1, o2, S @ MOTION, [0])
        # two thirds of the ball's radius off: most of its points sit in front of the wall
        # where frame 1 sees the wall (measured 0.68-0.78)
        assert bad.violation > 0.5


def test_one_plane_solution_confirmed_by_off_plane_points(ball_pair):
    est = estimate_motion(*ball_pair)
    assert isinstance(est, MotionEstimate) and est.case == 1
    assert est.residuals["depth_tested"] > 5000
    assert est.residuals["depth_violation"] < 0.05
    E = se3_inverse(MOTION) @ est.T
    # as test_solve's 1-plane case: texture pixel 1 cm, sub-pixel refinement: < 1 cm, 0.5 deg
    assert np.linalg.norm(E[:3, 3]) < 0.01
    assert np.degrees(rotation_angle(E[:3, :3])) < 0.5


def test_texture_contradicting_the_scene_is_a_failure():
    """Frame 2's bricks are slid 25 cm along the wall (geometry unchanged): the texture match
    moves the sensor by 25 cm, the ball says otherwise -> MotionFailure naming the free DoF."""
    T1 = start_pose(1)
    f1 = render_rgbd(Scene([wall(), BALL]), CAMERA, T1, noise=DEPTH_NOISE, rng=1)
    f2 = render_rgbd(Scene([wall(0.25), BALL]), CAMERA, T1 @ MOTION, noise=DEPTH_NOISE, rng=2)
    est = estimate_motion(observe_rgbd(f1.frame, ES), observe_rgbd(f2.frame, ES))
    assert isinstance(est, MotionFailure)
    assert est.case == 1 and est.free_dof == ("lambda", "mu", "eta")
    assert "not confirmed" in est.reason


def test_one_plane_large_turn_about_the_normal():
    """A 40 deg turn about the wall's normal (beyond a +-30 deg coarse grid, which reports no
    match) is found by the default +-90 deg coarse stage."""
    from scipy.spatial.transform import Rotation

    from navkit.geometry import se3_from_rt

    from .conftest import render_pair

    M = se3_from_rt(
        Rotation.from_rotvec([0.0, 0.0, np.radians(40.0)]).as_matrix(), [0.12, -0.05, 0.2]
    )
    p = render_pair(1, motion=M)
    est = estimate_motion(observe_rgbd(p.f1.frame, ES), observe_rgbd(p.f2.frame, ES))
    assert isinstance(est, MotionEstimate) and est.case == 1
    E = se3_inverse(M) @ est.T
    # as the small-motion 1-plane case (measured 0.02 deg, 1 mm): < 0.5 deg, 1 cm
    assert np.degrees(rotation_angle(E[:3, :3])) < 0.5 and np.linalg.norm(E[:3, 3]) < 0.01
