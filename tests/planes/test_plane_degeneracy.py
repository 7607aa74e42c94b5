"""The degeneracy analysis of the plane constraints (``FrameMotion.plane_free_dof``): which
degrees of freedom the matched planes leave free, from their noise-weighted information."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from navkit.geometry import se3_from_rt
from navkit.planes import FrameMotion, MotionPrior, OdometrySettings, PlaneOdometry, observe_rgbd
from navkit.planes.noise import DepthNoise, fit_plane, plane_pair_information
from navkit.planes.odometry import DenseGates
from navkit.sensors import PinholeCamera, RGBDFrame
from navkit.sim import Box, Ground, Scene, Texture, Wall, render_rgbd
from navkit.sim.scanners import RangeNoise

# camera: optical z along world +x, x right = world -y, y down = world -z
R0 = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
CAM = PinholeCamera(262.5, 262.5, 159.5, 119.5, 320, 240)


def _poses(n: int, step: float) -> list[np.ndarray]:
    """Camera poses ``step`` metres apart along world x (the optical axis), yaw 0.5 deg each."""
    out = []
    for k in range(n):
        R = Rotation.from_euler("z", 0.5 * k, degrees=True).as_matrix() @ R0
        out.append(se3_from_rt(R, [step * k, 0.0, 1.2]))
    return out


def _frames(scene: Scene, poses: list[np.ndarray]) -> list:
    out = []
    for k, T in enumerate(poses):
        f = render_rgbd(scene, CAM, T, noise=RangeNoise(quadratic_sigma=0.0016), rng=k).frame
        out.append(observe_rgbd(RGBDFrame(f.color, f.depth, f.camera, k / 30.0)))
    return out


def _track(scene: Scene) -> list:
    """Three frames 1.5 cm apart."""
    odo = PlaneOdometry()
    return [odo.update(obs) for obs in _frames(scene, _poses(3, 0.015))]


def _corridor() -> Scene:
    tex = Texture("noise", scale=0.3, seed=5)
    return Scene(
        [
            Ground(texture=tex, name="floor"),
            Wall(origin=(-1, 1.2, 0), u=(12, 0, 0), v=(0, 0, 2.8), texture=tex, name="left"),
            Wall(origin=(11, -1.2, 0), u=(-12, 0, 0), v=(0, 0, 2.8), texture=tex, name="right"),
        ]
    )


def test_a_corridor_leaves_the_translation_along_it_free():
    """Floor and two parallel walls along world x: two plane directions, so the planes fix
    the rotation and the translation across the corridor, and leave the translation along it
    (the camera's z) free; the texture / dense step fixes it."""
    res = _track(_corridor())
    moved = [r for r in res[1:] if isinstance(r, FrameMotion)]
    assert moved, res
    for r in moved:
        assert r.plane_free_dof == ("tz",), r.plane_free_dof
        assert r.plane_information.any()


def _corner(y_left: float, x_end: float, end_len: float, box_at, box: float) -> Scene:
    """A floor, a side wall at ``y = y_left`` and an end wall at ``x = x_end`` (``end_len``
    long), and a cube of side ``box``: three plane directions."""
    tex = Texture("noise", scale=0.3, seed=5)
    return Scene(
        [
            Ground(texture=tex, name="floor"),
            Wall(
                origin=(-1, y_left, 0), u=(x_end + 1, 0, 0), v=(0, 0, 2.8), texture=tex, name="left"
            ),
            Wall(
                origin=(x_end, y_left, 0),
                u=(0, -end_len, 0),
                v=(0, 0, 2.8),
                texture=tex,
                name="end",
            ),
            Box(box_at, (box, box, box), texture=tex, name="box"),
        ]
    )


def test_a_room_corner_leaves_nothing_free():
    """Floor, end wall and side wall: three plane directions fix all six."""
    room = _corner(1.5, 5.0, 4.0, (3.0, -0.6, 0.3), 0.6)
    res = _track(room)
    moved = [r for r in res[1:] if isinstance(r, FrameMotion)]
    assert len(moved) == 2, res
    for r in moved:
        assert r.plane_free_dof == (), r.plane_free_dof


def test_the_information_of_a_fit_matches_its_scatter():
    """``plane_pair_information`` of a plane seen head-on at depth z from N points spread over
    a square of side a: the offset along the normal has variance 2 sigma_z^2 / N (two fits),
    checked against the sample variance of the offset over repeated noisy fits."""
    rng = np.random.default_rng(0)
    noise = DepthNoise()
    z, a, n = 2.0, 1.0, 400
    offs = []
    for _ in range(300):
        xy = rng.uniform(-a / 2, a / 2, (n, 2))
        P = np.column_stack([xy, z + rng.normal(0.0, noise.sigma(z), n)])
        offs.append(fit_plane(P, noise).rho - z)
    f = fit_plane(np.column_stack([rng.uniform(-a / 2, a / 2, (n, 2)), np.full(n, z)]), noise)
    H = plane_pair_information(f, f, np.eye(3), np.zeros(3))
    var_tz = np.linalg.pinv(H)[2, 2]  # the camera's z is the normal
    # the two-fit variance is twice one fit's; the sample variance of 300 fits is within 20 %
    assert abs(var_tz / 2 / np.var(offs) - 1) < 0.2, (var_tz / 2, np.var(offs))


def _prior_run(
    poses: list[np.ndarray], monkeypatch, texture_allowed: bool, gates: DenseGates | None = None
) -> tuple[list, list]:
    """Track the corridor with a motion prior (the true step moved by 3 cm along the corridor
    and 0.5 deg, as a visual odometry would give it); counts the texture searches."""
    import navkit.planes.motion as motion

    calls: list[str] = []
    real = motion.solve_two_planes

    def counted(*a, **k):
        calls.append("two planes")
        assert texture_allowed, "a texture search ran where the dense step measures the motion"
        return real(*a, **k)

    monkeypatch.setattr(motion, "solve_two_planes", counted)
    odo = PlaneOdometry(OdometrySettings(gates=gates or DenseGates()))
    obs = _frames(_corridor(), poses)
    out = [odo.update(obs[0])]
    off = se3_from_rt(Rotation.from_euler("y", 0.5, degrees=True).as_matrix(), [0, 0, 0.03])
    for k in range(1, len(obs)):
        step = np.linalg.inv(poses[k - 1]) @ poses[k]
        out.append(odo.update(obs[k], MotionPrior(step @ off, 1.0, 0.03)))
    return out, calls


def test_with_a_prior_the_image_measures_what_the_planes_leave_free(monkeypatch):
    """Two plane directions and a motion prior: no texture search runs; the planes fix their
    degrees of freedom, the prior starts the free one (along the corridor) and the dense step
    measures it - to the accuracy of the dense step, not the prior's 3 cm."""
    poses = _poses(4, 0.015)
    res, calls = _prior_run(poses, monkeypatch, texture_allowed=False)
    assert not calls
    for k in range(1, len(res)):
        r = res[k]
        assert isinstance(r, FrameMotion) and r.source.endswith("+dense"), r
        assert r.plane_free_dof == ("tz",) and r.prior_dof == ()
        step_true = np.linalg.inv(poses[k - 1]) @ poses[k]
        err = np.linalg.norm((np.linalg.inv(step_true) @ r.motion.T)[:3, 3])
        # the dense step on noise-free texture and Kinect-noise depth at 1-3 m: millimetres
        assert err < 0.005, err


def test_the_texture_searches_run_when_the_dense_step_rejects(monkeypatch):
    """When the dense step rejects every start (here: a photometric gate no alignment can
    pass), the frame is measured again with the texture searches."""
    res, calls = _prior_run(
        _poses(3, 0.015), monkeypatch, True, DenseGates(max_photometric_sigmas=1e-6)
    )
    assert calls
    assert all(not isinstance(r, FrameMotion) for r in res[1:])  # still no silent pose


def test_without_a_prior_the_dense_step_measures_a_corridor_walk(monkeypatch):
    """No motion prior (a hand-held sequence): the dense step, started from the
    constant-velocity prediction, measures the corridor's free direction; no texture search
    runs while it succeeds (they cost 0.1-0.6 s a frame at 640 x 480)."""
    import navkit.planes.motion as motion

    calls: list[str] = []
    monkeypatch.setattr(motion, "solve_two_planes", lambda *a, **k: calls.append("2"))
    monkeypatch.setattr(motion, "solve_one_plane", lambda *a, **k: calls.append("1"))
    poses = _poses(5, 0.015)
    odo = PlaneOdometry()
    res = [odo.update(obs) for obs in _frames(_corridor(), poses)]
    assert not calls
    for k in range(1, len(res)):
        r = res[k]
        assert isinstance(r, FrameMotion) and r.source.endswith("+dense"), r
        step_true = np.linalg.inv(poses[k - 1]) @ poses[k]
        assert np.linalg.norm((np.linalg.inv(step_true) @ r.motion.T)[:3, 3]) < 0.005


def test_tracking_restarts_after_the_view_leaves_every_keyframe():
    """With a motion prior (a robot's odometry: the true step moved by 3 cm and 0.5 deg), the
    view changes to one nothing seen before overlaps (frames 0-2 in the corridor, then the
    camera is in a room - a kidnapped robot, or a camera that was covered): that frame is a
    failure, it becomes the new reference at the prior's pose, and the steps after it are
    measured again. Without the restart every later frame failed against the old keyframes."""
    room = _corner(0.9, 2.2, 3.0, (1.5, -0.5, 0.2), 0.4)
    poses = _poses(7, 0.015)
    obs = _frames(_corridor(), poses[:3]) + _frames(room, poses[3:])
    off = se3_from_rt(Rotation.from_euler("y", 0.5, degrees=True).as_matrix(), [0, 0, 0.03])
    odo = PlaneOdometry()
    res = [odo.update(obs[0])]
    for k in range(1, len(obs)):
        step = np.linalg.inv(poses[k - 1]) @ poses[k]
        res.append(odo.update(obs[k], MotionPrior(step @ off, 1.0, 0.03)))
    assert all(isinstance(r, FrameMotion) for r in res[:3])
    assert not isinstance(res[3], FrameMotion) and "restarts" in res[3].reason
    for k in range(4, len(res)):
        r = res[k]
        assert isinstance(r, FrameMotion), r
        step_true = np.linalg.inv(poses[k - 1]) @ poses[k]
        assert np.linalg.norm((np.linalg.inv(step_true) @ r.motion.T)[:3, 3]) < 0.005
