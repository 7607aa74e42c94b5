"""Plane odometry over sequences: frame-to-map tracking against the truth, the motion prior.

Sequences are rendered from the simulated corridor of ``conftest.py`` (brick wall + textured
floor: the 2-plane case, where the texture fixes the position along the wall-floor line).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from navkit.geometry import se3_from_rt, se3_inverse
from navkit.geometry.fitting import Plane, canonical_plane
from navkit.geometry.rotations import rotation_angle
from navkit.planes import FrameMotion, OdometrySettings, PlaneOdometry, observe_rgbd
from navkit.planes.associate import AssociationSettings
from navkit.planes.frame import PlaneObservation
from navkit.planes.metrics import ate, rpe
from navkit.planes.motion import MotionPrior, MotionSettings, _fill_from_prior, estimate_motion
from navkit.planes.plane_map import MapView
from navkit.planes.solve import MotionEstimate, MotionFailure
from navkit.sensors import RGBDFrame
from navkit.sim import render_rgbd
from navkit.sim.scanners import RangeNoise

from .conftest import CAMERA, SOLID, corridor, render_pair, start_pose

STEP = se3_from_rt(Rotation.from_rotvec([0.0, -0.03, 0.0]).as_matrix(), [0.02, 0.0, 0.12])
"""Per frame: 12 cm forward, 2 cm sideways, 1.7 deg turn (camera frame)."""


@dataclass(frozen=True)
class Sequence:
    obs: list[PlaneObservation]
    truth: np.ndarray  # (N, 4, 4) T_world_frame, world = first frame


def _sequence(
    n: int, depth_sigma: float, image_sigma: float, loop: bool, seed: int = 0
) -> Sequence:
    """Walk ``n // 2`` steps down the corridor and (``loop``) the same steps back, rendering
    depth with ``depth_sigma`` relative noise and adding ``image_sigma`` (of 255) Gaussian noise
    to the colour."""
    scene = corridor(2)
    rng = np.random.default_rng(seed)
    T = start_pose(2)
    poses, obs = [], []
    for k in range(n):
        poses.append(T)
        f = render_rgbd(scene, CAMERA, T, noise=RangeNoise(relative_sigma=depth_sigma), rng=k)
        f = f.frame
        col = np.clip(f.color + rng.normal(0.0, image_sigma, f.color.shape), 0, 255)
        obs.append(observe_rgbd(RGBDFrame(col.astype(np.uint8), f.depth, f.camera, float(k))))
        T = T @ (se3_inverse(STEP) if loop and k >= n // 2 else STEP)
    return Sequence(obs, se3_inverse(poses[0]) @ np.array(poses))


def _run(seq: Sequence, frame_to_map: bool, priors=None) -> PlaneOdometry:
    # the plane stage alone (no dense refinement): these tests measure the planes' own
    # tracking, map and failure handling; the dense step has its own tests (test_dense.py)
    odo = PlaneOdometry(OdometrySettings(frame_to_map=frame_to_map, dense=None))
    for k, o in enumerate(seq.obs):
        odo.update(o, None if priors is None or k == 0 else priors[k])
    return odo


@pytest.fixture(scope="module")
def loop_runs() -> tuple[Sequence, PlaneOdometry, PlaneOdometry]:
    seq = _sequence(16, depth_sigma=0.005, image_sigma=20.0, loop=True)
    return seq, _run(seq, False), _run(seq, True)


def test_frame_to_map_lowers_drift_on_a_corridor_loop(loop_runs):
    """Down the corridor and back (16 frames, 0.9 m out): frame-to-frame chains 15 texture
    steps, each with an independent error along the corridor (~1 mm: sub-pixel parabola at
    nu = 1 cm under 20/255 image noise), so its error grows as a random walk (sqrt(15) ~ 4x one
    step) and is largest when the walk returns. Frame-to-map refers every frame to the same
    fused wall and floor textures: back at the start the frames see the parts of the map laid
    down by the first frames, so the error returns to the size of one step. Measured: ATE
    0.18 vs 0.08 cm, error of the last frame 0.54 vs 0.05 cm. (At 640 x 480 the texture steps
    are finer and neither mode drifts: equal ATE, see docs/benchmarks/planes.md.)"""
    seq, f2f, f2m = loop_runs
    assert all(r.source == "map" for r in f2m.results[1:])
    assert all(r.source == "frame" for r in f2f.results[1:])
    assert all(isinstance(r, FrameMotion) and r.case == 2 for r in f2m.results[1:])
    ate_f, ate_m = ate(f2f.trajectory, seq.truth), ate(f2m.trajectory, seq.truth)
    assert ate_m < 0.7 * ate_f
    # the loop closes: the last frame (back at the second frame's place)
    end_f = np.linalg.norm((se3_inverse(seq.truth[-1]) @ f2f.trajectory[-1])[:3, 3])
    end_m = np.linalg.norm((se3_inverse(seq.truth[-1]) @ f2m.trajectory[-1])[:3, 3])
    assert end_m < 0.5 * end_f
    # and neither leaves the millimetre regime of a textured 2-plane scene: per-step errors of
    # ~1 mm (see test_solve.py's tolerances) over 15 steps, sqrt(15) x 1 mm ~ 4 mm < 1 cm
    assert ate_m < 0.01 and ate_f < 0.01
    assert rpe(f2m.trajectory, seq.truth)[0] < 0.005


def test_frame_to_map_recovers_after_a_failed_frame():
    """The robot slows down (12 -> 6 cm per frame) just as one camera frame is blank (an
    exposure glitch: uniform brightness). That frame's texture step fails, its pose is the
    constant-velocity prediction, 6 cm too far, and it is not merged into the map. Frame-to-
    map measures the next frame against the map laid down before the glitch (the texture
    search covers +-60 cm around the prediction) and is back to the millimetre regime at once
    (one texture step: ~1 mm). Frame-to-frame measures it against the last *tracked* frame
    (4), not the misplaced one: it recovers as well (it used to keep the 6-12 cm for good,
    chained onto the prediction)."""
    scene = corridor(2)
    T = start_pose(2)
    speeds = [0.12, 0.12, 0.12, 0.12, 0.06, 0.06, 0.12, 0.12, 0.12]
    obs, poses = [], []
    for k in range(len(speeds) + 1):
        poses.append(T)
        f = render_rgbd(scene, CAMERA, T, noise=RangeNoise(relative_sigma=0.005), rng=k).frame
        col = f.color if k != 5 else np.full_like(f.color, 128)
        obs.append(observe_rgbd(RGBDFrame(col, f.depth, f.camera, float(k))))
        if k < len(speeds):
            T = T @ se3_from_rt(STEP[:3, :3], [0.02, 0.0, speeds[k]])
    seq = Sequence(obs, se3_inverse(poses[0]) @ np.array(poses))
    f2f, f2m = _run(seq, False), _run(seq, True)
    for odo in (f2f, f2m):
        assert isinstance(odo.results[5], MotionFailure)
        assert all(5 not in mp.observations for mp in odo.map.planes)
    err_f = [_err(f2f.trajectory[k], seq.truth[k])[0] for k in range(len(obs))]
    err_m = [_err(f2m.trajectory[k], seq.truth[k])[0] for k in range(len(obs))]
    assert err_f[5] > 0.05 and err_m[5] > 0.05  # the prediction: 6 cm too far
    assert max(err_f[6:]) < 0.005  # frame-to-frame: measured from frame 4, not the guess
    assert max(err_m[6:]) < 0.005  # frame-to-map: back to a few millimetres
    assert all(r.source == "map" for r in f2m.results[6:])


def test_map_is_one_plane_per_surface_and_textured(loop_runs):
    """Frame-to-map keeps one map plane per physical surface (wall, floor), each seen by every
    frame, with the world geometry of the truth (normals within 0.5 deg, distances within
    1 cm: the 2-plane solution's rotation is exact to ~0.01 deg, the rest is the plane fit)."""
    seq, _, f2m = loop_runs
    planes = f2m.map.planes
    assert len(planes) == 2
    for mp in planes:
        assert mp.observations == list(range(len(seq.obs)))
        assert np.isfinite(mp.texture).mean() > 0.5
    # truth: wall y = -1.5 and floor z = 0 in the world, moved into the first camera frame
    T0 = start_pose(2)
    R0, t0 = T0[:3, :3], T0[:3, 3]
    for n_w, d_w in (([0.0, 1.0, 0.0], -1.5), ([0.0, 0.0, 1.0], 0.0)):
        n_c = R0.T @ np.array(n_w)
        rho_c = d_w - np.array(n_w) @ t0
        n_c, rho_c = (n_c, rho_c) if rho_c >= 0 else (-n_c, -rho_c)
        best = min(planes, key=lambda mp: np.arccos(np.clip(mp.plane.normal @ n_c, -1, 1)))
        assert np.degrees(np.arccos(np.clip(best.plane.normal @ n_c, -1, 1))) < 0.5
        assert abs(best.plane.rho - rho_c) < 0.01


def test_map_view_texture_is_registered_with_the_frame_texture(loop_runs):
    """The map's fused texture, resampled on a frame's own plane lattice from the true pose,
    lines up with that frame's texture: over shifts of -3..3 texture pixels (1 cm) in both
    axes the correlation peaks at zero shift (a misregistration of half a pixel would move the
    peak), and clearly (a one-pixel shift of the brick / noise textures loses > 0.05)."""
    seq, _, f2m = loop_runs
    k = 5
    o = seq.obs[k]
    view: MapView = f2m.map_view(o, seq.truth[k])
    for j, seg in enumerate(o.segments[:2]):
        tf = o.texture(j)
        i = min(
            range(len(view.segments)),
            key=lambda m: np.arccos(np.clip(view.segments[m].normal @ seg.normal, -1, 1)),
        )
        tm = view.texture(i, tf.axes, tf.ref, tf.nu)
        # map texture on the frame texture's window, shifted by (dx, dy) lattice pixels
        corr = np.full((7, 7), np.nan)
        for dy in range(-3, 4):
            for dx in range(-3, 4):
                M = np.full(tf.image.shape, np.nan, np.float32)
                o0 = (
                    tf.index0 + np.array([dx, dy]) - tm.index0
                )  # frame pixel (0, 0) in the map window
                h, w = tf.image.shape
                ys = slice(max(0, -o0[1]), min(h, tm.image.shape[0] - o0[1]))
                xs = slice(max(0, -o0[0]), min(w, tm.image.shape[1] - o0[0]))
                M[ys, xs] = tm.image[
                    ys.start + o0[1] : ys.stop + o0[1], xs.start + o0[0] : xs.stop + o0[0]
                ]
                ok = np.isfinite(M) & np.isfinite(tf.image)
                if ok.sum() > 5000:
                    corr[dy + 3, dx + 3] = np.corrcoef(M[ok], tf.image[ok])[0, 1]
        assert np.nanargmax(corr) == 24  # the centre: zero shift
        # sub-pixel peak (parabola through the centre and its neighbours) within 0.25 px
        # = 2.5 mm: the map is registered to the frame far below the texture pixel
        for lo, c, hi in (
            (corr[3, 2], corr[3, 3], corr[3, 4]),
            (corr[2, 3], corr[3, 3], corr[4, 3]),
        ):
            assert abs(0.5 * (lo - hi) / (lo - 2 * c + hi)) < 0.25


def _err(T: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    E = se3_inverse(T_true) @ T
    return float(np.linalg.norm(E[:3, 3])), float(np.degrees(rotation_angle(E[:3, :3])))


PERTURB = se3_from_rt(Rotation.from_rotvec([0.01, 0.02, -0.01]).as_matrix(), [0.04, -0.03, 0.05])
"""A prior error of 7.1 cm and 1.4 deg."""


def test_prior_fills_the_free_position_along_the_line_and_says_so():
    """Uniform walls and floor (no texture): without a prior the position along the
    wall-floor line is free (a MotionFailure); with a prior it is taken from the prior and
    marked in ``prior_dof``. Rotation and the translation across the line stay measured: the
    rotation error is that of the planes (~0.01 deg), the translation error is the prior's
    error along the line only (its component across the line is corrected)."""
    p = render_pair(2, texture=SOLID)
    o1, o2 = observe_rgbd(p.f1.frame), observe_rgbd(p.f2.frame)
    assert isinstance(estimate_motion(o1, o2), MotionFailure)
    prior = MotionPrior(p.T_1_2 @ PERTURB, sigma_rotation_deg=2.0, sigma_translation=0.05)
    res = estimate_motion(o1, o2, prior)
    assert isinstance(res, MotionEstimate)
    assert res.case == 2 and res.prior_dof == ("mu",) and res.texture_dof == ()
    t_err, r_err = _err(res.T, p.T_1_2)
    assert r_err < 0.05
    # the line direction in frame 1: cross product of the matched normals
    n = [o1.segments[i].normal for i, _ in res.pairs[:2]]
    d = np.cross(n[0], n[1])
    d /= np.linalg.norm(d)
    e = res.T[:3, 3] - p.T_1_2[:3, 3]
    e_prior = prior.T[:3, 3] - p.T_1_2[:3, 3]
    assert np.linalg.norm(e - (e @ d) * d) < 0.005  # across the line: measured (5 mm: planes)
    assert abs(e @ d - e_prior @ d) < 1e-9  # along the line: the prior's value, exactly
    assert t_err < np.linalg.norm(e_prior)


def test_prior_fills_the_in_plane_motion_of_a_uniform_wall():
    p = render_pair(1, texture=SOLID)
    o1, o2 = observe_rgbd(p.f1.frame), observe_rgbd(p.f2.frame)
    prior = MotionPrior(p.T_1_2 @ PERTURB, 2.0, 0.05)
    res = estimate_motion(o1, o2, prior)
    assert isinstance(res, MotionEstimate)
    assert res.case == 1 and set(res.prior_dof) == {"lambda", "mu", "eta"}
    # the wall's normal and distance are measured: the normal agrees with the truth's
    n1 = o1.segments[res.pairs[0][0]].normal
    n2_true = p.T_1_2[:3, :3] @ o2.segments[res.pairs[0][1]].normal
    n2_est = res.T[:3, :3] @ o2.segments[res.pairs[0][1]].normal
    assert np.degrees(np.arccos(np.clip(n1 @ n2_est, -1, 1))) < 0.05
    assert np.degrees(np.arccos(np.clip(n1 @ n2_true, -1, 1))) < 0.1


@pytest.mark.parametrize("n_dirs", [1, 2])
def test_prior_starts_the_texture_search_and_texture_still_decides(n_dirs):
    """With textures, a prior 7 cm / 1.4 deg off only starts the search: the texture fixes the
    DoF (``prior_dof`` empty) to the accuracy of the prior-free solver (sub-millimetre, see
    test_solve.py: 3 mm / 0.05 deg)."""
    p = render_pair(n_dirs)
    o1, o2 = observe_rgbd(p.f1.frame), observe_rgbd(p.f2.frame)
    res = estimate_motion(o1, o2, MotionPrior(p.T_1_2 @ PERTURB, 2.0, 0.05))
    assert isinstance(res, MotionEstimate)
    assert res.case == n_dirs and res.prior_dof == () and res.texture_dof
    t_err, r_err = _err(res.T, p.T_1_2)
    assert t_err < 0.003 and r_err < 0.05


def test_prior_uncertainty_sets_the_association_gate():
    """A prior whose rotation is 12 deg off about the axis that moves all three normals alike
    (their normalised sum: each normal turns by 12 deg x sqrt(2/3) = 9.8 deg): a confident
    prior (sigma 1 deg: gate 3 x 1 + 3 = 6 deg) matches no plane (a MotionFailure), an honest
    one (sigma 3 deg: gate 12 deg) matches them and the planes correct the rotation."""
    p = render_pair(3)
    o1, o2 = observe_rgbd(p.f1.frame), observe_rgbd(p.f2.frame)
    axis = np.sum([s.normal for s in o2.segments[:3]], axis=0)
    axis /= np.linalg.norm(axis)
    off = p.T_1_2 @ se3_from_rt(
        Rotation.from_rotvec(np.radians(12.0) * axis).as_matrix(), [0, 0, 0]
    )
    assert MotionPrior(off, 1.0, 0.02).association(AssociationSettings()).max_angle_deg == 6.0
    tight = estimate_motion(o1, o2, MotionPrior(off, 1.0, 0.02))
    assert isinstance(tight, MotionFailure) and tight.case == 0
    loose = estimate_motion(o1, o2, MotionPrior(off, 3.0, 0.02))
    assert isinstance(loose, MotionEstimate) and loose.case == 3 and not loose.prior_dof
    assert _err(loose.T, p.T_1_2)[1] < 0.1


def test_update_with_a_prior_tracks_where_texture_fails():
    """Heavy image noise (40/255) flattens D(mu): the texture steps fail. Without a prior the
    frames are failures and the trajectory is the (identity) prediction - decimetres off after
    a few frames; with a visual-odometry-like prior (the true step perturbed by 1 cm / 0.3 deg
    per frame) every frame is ``ok`` with ``mu`` from the prior, rotation and the translation
    across the line measured, and none of those frames is merged into the map."""
    seq = _sequence(5, depth_sigma=0.005, image_sigma=40.0, loop=False, seed=1)
    rng = np.random.default_rng(7)
    priors = []
    for k in range(len(seq.obs)):
        true_step = se3_inverse(seq.truth[k - 1]) @ seq.truth[k] if k else np.eye(4)
        noise = se3_from_rt(
            Rotation.from_rotvec(rng.normal(0, np.radians(0.3), 3)).as_matrix(),
            rng.normal(0, 0.01, 3),
        )
        priors.append(MotionPrior(true_step @ noise, 0.5, 0.02))
    bare = _run(seq, True)
    # without a prior the texture steps fail (the last frame may match the map, seen from a
    # prediction that by then is 49 cm / 7 deg off, with one plane only)
    assert all(isinstance(r, MotionFailure) for r in bare.results[1:4])
    odo = _run(seq, True, priors)
    filled = []
    for k, r in enumerate(odo.results[1:], start=1):
        assert isinstance(r, FrameMotion) and isinstance(r.motion, MotionEstimate)
        # mu is either measured (a texture step against the map can succeed: the map texture
        # is fused) or filled from the prior and then named
        assert (r.motion.prior_dof, r.motion.texture_dof) in ((("mu",), ()), ((), ("mu",)))
        if r.motion.prior_dof:
            assert r.prior_dof == ("mu",) and r.dof_sources["mu"] == "prior"
            filled.append(k)
        # rotation measured by the planes (0.01 deg class) although the prior is 0.3-0.9 off
        assert _err(r.T_world_frame, seq.truth[k])[1] < 0.05
    assert filled  # the heavy noise leaves some frames to the prior
    for mp in odo.map.planes:
        assert not set(filled) & set(mp.observations)  # prior-filled frames are not merged
    # translation: across the line measured, along it the prior's ~1 cm per frame
    assert ate(odo.trajectory, seq.truth) < 0.02 < ate(bare.trajectory, seq.truth)


def test_slambook_sequence_is_flagged_and_recovers_the_second_motion(data_path):
    """The 3 real slambook frames through PlaneOdometry: 1 -> 2 (25 deg, 41 cm, one carpet
    plane in common) is a flagged failure, not a silent guess (the depth check rejects the
    texture step, the dense step finds no motion the pixels support). Frame 3 is then
    measured against frame 1, the last *tracked* frame (1 -> 3: 1.1 m, 20 deg), not chained
    onto frame 2's predicted pose (that gave a 52 cm / 28 deg error reported as tracked): it is
    tracked within 5 cm / 2 deg or an explicit failure (measured: a failure). The pair 2 -> 3
    alone (73 cm / 5.6 deg, >= 3 planes, global association, then the dense step from the
    plane solution) is within 5 cm / 2 deg (measured 2.5 cm / 0.73 deg; planes alone 9.3 cm /
    2.96 deg)."""
    from navkit.geometry import se3_from_xyz_quat
    from navkit.io.rgbd import read_simple_rgbd

    root = data_path("rgbd/slambook-ch5")
    seq = read_simple_rgbd(
        root, {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0}
    )
    Q = np.array([se3_from_xyz_quat(p[:3], p[3:]) for p in np.loadtxt(root / "pose.txt")])
    obs = [observe_rgbd(seq.frame(k)) for k in range(len(seq))]
    odo = PlaneOdometry()
    res = [odo.update(o) for o in obs]
    assert isinstance(res[1], MotionFailure) and res[1].reason and res[1].free_dof
    for k in (1, 2):
        if isinstance(res[k], FrameMotion):
            t_err, r_err = _err(res[k].T_world_frame, se3_inverse(Q[0]) @ Q[k])
            assert t_err < 0.05 and r_err < 2.0
        else:
            assert res[k].reason and not odo.tracked[k]
    pair = PlaneOdometry()
    pair.update(obs[1])
    r = pair.update(obs[2])
    assert isinstance(r, FrameMotion) and r.source.endswith("+dense") and r.case == 3
    t_err, r_err = _err(r.motion.T, se3_inverse(Q[1]) @ Q[2])
    assert t_err < 0.05 and r_err < 2.0


rotvec = st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3)
vec = st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3)


def _planes_in_both(R, t, normals2, rhos2):
    """Frame-2 planes and the same planes in frame 1 (``X1 = R X2 + t``), rho >= 0 in both."""
    p1, p2 = [], []
    for n2, r2 in zip(normals2, rhos2, strict=True):
        n2 = np.asarray(n2) / np.linalg.norm(n2)
        a, ra = canonical_plane(n2, r2)
        b, rb = canonical_plane(R @ a, ra + (R @ a) @ t)
        p2.append(Plane(a, ra, ra * a, 0.0, 5000))
        p1.append(Plane(b, rb, rb * b, 0.0, 5000))
    return p1, p2


def _assert_maps(T: np.ndarray, a: Plane, b: Plane) -> None:
    """Eqs. 1 and 2: ``T`` maps plane ``b`` (frame 2) onto plane ``a`` (frame 1), up to the
    sign convention rho >= 0 (the sensor may cross the plane)."""
    n = T[:3, :3] @ b.normal
    sg = 1.0 if n @ a.normal > 0 else -1.0
    assert np.allclose(sg * n, a.normal, atol=1e-9)  # eq. 1
    assert abs(sg * (b.rho + n @ T[:3, 3]) - a.rho) < 1e-9  # eq. 2


@settings(max_examples=60, deadline=None)
@given(rotvec, vec, rotvec, vec, st.floats(0.5, 4.0), st.floats(0.5, 4.0))
def test_prior_fill_keeps_the_measured_dof_and_the_priors_free_ones(rv, t, drv, dt, ra, rb):
    """Property of the fill (2 planes, floor + wall type, normals 90 deg apart): whatever the
    prior's error, the filled motion satisfies eqs. 1 and 2 for both planes exactly (rotation
    and translation across the line measured), and its position along the line ``d`` is the
    prior's."""
    R = Rotation.from_rotvec(rv).as_matrix()
    T_true = se3_from_rt(R, np.asarray(t))
    p1, p2 = _planes_in_both(R, np.asarray(t), [[0, 1, 0.0], [0, 0, 1.0]], [ra, rb])
    Tp = T_true @ se3_from_rt(Rotation.from_rotvec(np.asarray(drv) * 0.2).as_matrix(), dt)
    T, geo = _fill_from_prior(p1, p2, 2, Tp, MotionSettings())
    assert geo == ("rotation", "translation across the line")
    for a, b in zip(p1, p2, strict=True):
        _assert_maps(T, a, b)
    d = np.cross(p1[0].normal, p1[1].normal)
    assert abs(T[:3, 3] @ d - Tp[:3, 3] @ d) < 1e-9  # along the line: the prior's
    # so the whole error is the prior's error along the line
    assert np.allclose(T[:3, 3] - T_true[:3, 3], ((Tp - T_true)[:3, 3] @ d) * d, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(rotvec, vec, rotvec, vec, st.floats(0.5, 4.0))
def test_prior_fill_one_plane_aligns_the_normal_and_keeps_the_in_plane_motion(rv, t, drv, dt, ra):
    """Property of the 1-plane fill: the normal and the distance are measured (eqs. 1, 2 hold
    exactly), the in-plane translation is the prior's, and the rotation differs from the
    prior's only by the smallest turn that aligns the normals (eq. 8: its axis lies in the
    plane)."""
    R = Rotation.from_rotvec(rv).as_matrix()
    p1, p2 = _planes_in_both(R, np.asarray(t), [[0.3, 0.2, 1.0]], [ra])
    Tp = se3_from_rt(R, np.asarray(t)) @ se3_from_rt(
        Rotation.from_rotvec(np.asarray(drv) * 0.2).as_matrix(), dt
    )
    T, _ = _fill_from_prior(p1, p2, 1, Tp, MotionSettings())
    n1 = p1[0].normal
    _assert_maps(T, p1[0], p2[0])
    e = T[:3, 3] - Tp[:3, 3]
    assert np.allclose(e, (e @ n1) * n1, atol=1e-9)  # in-plane: the prior's
    axis = Rotation.from_matrix(T[:3, :3] @ Tp[:3, :3].T).as_rotvec()
    assert abs(axis @ n1) < 1e-9
