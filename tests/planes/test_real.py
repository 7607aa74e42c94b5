"""Real recorded frames: the CAPE tunnel through the 2-plane path, slambook against pose.txt."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from navkit.geometry import rotation_angle, se3_from_rt, se3_from_xyz_quat, se3_inverse
from navkit.planes import MotionEstimate, estimate_motion, observe_rgbd
from navkit.planes.frame import reproject_rgbd


def test_cape_tunnel_two_plane_path(data_path):
    """The tunnel frame (tiled wall + floor) given a known motion by view synthesis."""
    from navkit.io.rgbd import read_cape_frame

    f = read_cape_frame(data_path("rgbd/cape-tunnel"))
    T12 = se3_from_rt(Rotation.from_rotvec([0.02, -0.05, 0.03]).as_matrix(), [0.05, -0.03, 0.25])
    a = reproject_rgbd(f.points, f.color_registered, f.ir_camera, np.eye(4))
    b = reproject_rgbd(f.points, f.color_registered, f.ir_camera, se3_inverse(T12))
    est = estimate_motion(observe_rgbd(a), observe_rgbd(b))
    assert isinstance(est, MotionEstimate)
    assert est.case == 2 and est.texture_dof == ("mu",)
    E = se3_inverse(T12) @ est.T
    rot = np.degrees(rotation_angle(E[:3, :3]))
    # the tunnel wall is curved: the fitted "plane" depends on which part of it is visible, and
    # the normal residual after the motion measures that; the rotation error is of that order
    # (x 2 for two planes) and the translation error of (residual x distance ~ 2 m) + nu
    assert rot < 2 * est.residuals["normal_deg"] + 0.1
    assert np.linalg.norm(E[:3, 3]) < np.radians(est.residuals["normal_deg"]) * 2.0 + 0.01
    # the texture moved the sensor 0.25 m along the tunnel: found, not assumed
    assert abs(est.residuals["mu_m"]) > 0.15


def test_slambook_floor_agrees_with_reference_poses(data_path):
    """The floor extracted in each frame, taken to the world by pose.txt, is one plane."""
    from navkit.io.rgbd import read_simple_rgbd

    root = data_path("rgbd/slambook-ch5")
    seq = read_simple_rgbd(
        root, {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0}
    )
    poses = np.loadtxt(root / "pose.txt")
    normals, rhos = [], []
    for k in range(len(seq)):
        obs = observe_rgbd(seq.frame(k))
        # the floor: the largest plane whose normal is within 30 deg of the camera's "down"
        floor = next(s for s in obs.segments if s.normal[1] > np.cos(np.radians(30)))
        T = se3_from_xyz_quat(poses[k, :3], poses[k, 3:])
        n = T[:3, :3] @ floor.normal
        normals.append(n)
        rhos.append(floor.rho + n @ T[:3, 3])
    normals = np.array(normals)
    ang = np.degrees(np.arccos(np.clip(normals @ normals[0], -1, 1)))
    # reference poses "not metrology grade" (from a SLAM run over 1.3 m of travel: a few cm,
    # ~1 deg) and Kinect depth bias at 3 m (~1 %, 3 cm): the floor stays within 3 deg and
    # 10 cm across the frames (measured: 7 cm spread of its height)
    assert ang.max() < 3.0
    assert np.ptp(rhos) < 0.10


@pytest.mark.parametrize("use_prior", [True, False])
def test_slambook_relative_pose(data_path, use_prior):
    """Frames 2 -> 3 (>= 3 plane directions), with the reference as the association prior and
    without a prior (then the global association, verified by the points, finds the matches)."""
    from navkit.io.rgbd import read_simple_rgbd

    root = data_path("rgbd/slambook-ch5")
    seq = read_simple_rgbd(
        root, {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0}
    )
    P = np.loadtxt(root / "pose.txt")
    Tw = [se3_from_xyz_quat(p[:3], p[3:]) for p in P]
    a, b = 1, 2
    truth = se3_inverse(Tw[a]) @ Tw[b]
    prior = truth if use_prior else None
    est = estimate_motion(observe_rgbd(seq.frame(a)), observe_rgbd(seq.frame(b)), prior)
    assert isinstance(est, MotionEstimate) and est.case == 3
    E = se3_inverse(truth) @ est.T
    # measured: 1.7-3 deg and ~16-17 cm on a 0.73 m, 5.6 deg motion - planes far away (3-5 m walls)
    # and Kinect depth bias; the bound records the current quality, not a target
    assert np.degrees(rotation_angle(E[:3, :3])) < 5.0
    assert np.linalg.norm(E[:3, 3]) < 0.3


def test_slambook_one_plane_pair_is_not_a_silent_guess(data_path):
    """Frames 1 -> 2 (25 deg, 41 cm): only the low-contrast carpet is common. Either solved to
    the reference's accuracy or a MotionFailure naming the texture's DoF - never the former
    silent 41 cm / 10.5 deg answer."""
    from navkit.io.rgbd import read_simple_rgbd

    root = data_path("rgbd/slambook-ch5")
    seq = read_simple_rgbd(
        root, {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0}
    )
    P = np.loadtxt(root / "pose.txt")
    Tw = [se3_from_xyz_quat(p[:3], p[3:]) for p in P]
    truth = se3_inverse(Tw[0]) @ Tw[1]
    est = estimate_motion(observe_rgbd(seq.frame(0)), observe_rgbd(seq.frame(1)))
    if isinstance(est, MotionEstimate):
        E = se3_inverse(truth) @ est.T
        # reference poses from a SLAM run: a few cm / ~1 deg; 10 cm / 3 deg = "solved"
        assert np.linalg.norm(E[:3, 3]) < 0.10 and np.degrees(rotation_angle(E[:3, :3])) < 3.0
    else:
        assert est.case in (1, 2) and len(est.free_dof) >= 1
        assert set(est.free_dof) <= {"lambda", "mu", "eta"}


def test_depth_check_accepts_reference_motions(data_path):
    """Under the reference poses the off-plane points agree with the other frame (measured
    0.12-0.16 violation: Kinect noise, edges, reference error), below the 0.35 limit; the
    identity (no motion) is rejected on every pair."""
    from navkit.io.rgbd import read_simple_rgbd
    from navkit.planes.motion import MotionSettings, depth_consistency

    root = data_path("rgbd/slambook-ch5")
    seq = read_simple_rgbd(
        root, {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0}
    )
    P = np.loadtxt(root / "pose.txt")
    Tw = [se3_from_xyz_quat(p[:3], p[3:]) for p in P]
    obs = [observe_rgbd(seq.frame(k)) for k in range(3)]
    limit = MotionSettings().max_depth_violation
    for a, b in [(0, 1), (1, 2), (0, 2)]:
        ok = depth_consistency(obs[a], obs[b], se3_inverse(Tw[a]) @ Tw[b])
        assert ok.tested > 10_000 and ok.violation < limit
        assert depth_consistency(obs[a], obs[b], np.eye(4)).violation > limit


def test_slambook_one_plane_texture_step_stays_in_the_coarse_basin(data_path):
    """With the depth check switched off, the 1-plane texture solution of frames 1 -> 2 is near
    the reference: the coarse stage's best candidate is 2 cm / 0.1 deg from it, and the bounded
    fine stage no longer slides into the basin 40 cm / 11 deg away (measured now: 13 cm, 1.3 deg).
    Bound: the floor normal itself differs by 1.2 deg between the frames under the reference
    poses (Kinect / reference error) - at 3-5 m that is 6-10 cm - plus a few cm of reference
    error: 20 cm / 3 deg."""
    from navkit.io.rgbd import read_simple_rgbd
    from navkit.planes.motion import MotionSettings

    root = data_path("rgbd/slambook-ch5")
    seq = read_simple_rgbd(
        root, {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0}
    )
    P = np.loadtxt(root / "pose.txt")
    Tw = [se3_from_xyz_quat(p[:3], p[3:]) for p in P]
    truth = se3_inverse(Tw[0]) @ Tw[1]
    est = estimate_motion(
        observe_rgbd(seq.frame(0)),
        observe_rgbd(seq.frame(1)),
        settings=MotionSettings(max_depth_violation=1.0),
    )
    assert isinstance(est, MotionEstimate) and est.case == 1
    E = se3_inverse(truth) @ est.T
    assert np.linalg.norm(E[:3, 3]) < 0.20
    assert np.degrees(rotation_angle(E[:3, :3])) < 3.0
