"""Known motions recovered in the 1-, 2- and >= 3-plane cases; failure objects on degenerate input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from navkit.geometry import se3_from_rt, se3_inverse
from navkit.geometry.fitting import Plane, canonical_plane
from navkit.geometry.rotations import rotation_angle
from navkit.planes import (
    ExtractionSettings,
    MotionEstimate,
    MotionFailure,
    estimate_motion,
    observe_rgbd,
)
from navkit.planes.align import search_1d
from navkit.planes.quaternion import euler_zxy_from_quat
from navkit.planes.solve import SolverSettings, normal_rank, solve_three_planes
from navkit.planes.texture import PlaneTexture

from .conftest import SOLID, render_pair

ES = ExtractionSettings(cell=10)
NU = 0.01  # texture pixel, metres (SolverSettings default)


def errors(est: MotionEstimate, truth: np.ndarray) -> tuple[float, float]:
    """Rotation error (deg) and translation error (m) of an estimate."""
    E = se3_inverse(truth) @ est.T
    return float(np.degrees(rotation_angle(E[:3, :3]))), float(np.linalg.norm(E[:3, 3]))


def solve(pair):
    return estimate_motion(observe_rgbd(pair.f1.frame, ES), observe_rgbd(pair.f2.frame, ES))


def test_three_planes_closed_form(pairs):
    est = solve(pairs[3])
    assert isinstance(est, MotionEstimate) and est.case == 3
    assert est.texture_dof == ()
    rot, tr = errors(est, pairs[3].T_1_2)
    # normals from >= 10^4 points with 0.2 % depth noise are good to ~1e-3 rad and rho to
    # < 1 mm (see test_extract); the closed form inherits them: 0.1 deg and 5 mm
    assert rot < 0.1 and tr < 0.005
    assert est.residuals["normal_deg"] < 0.2
    # the Euler angles reported are the paper's ZXY of the estimate
    assert np.allclose(
        Rotation.from_euler("ZXY", est.euler_zxy).as_matrix(), est.rotation, atol=1e-9
    )


def test_two_planes_texture_fixes_mu(pairs):
    est = solve(pairs[2])
    assert isinstance(est, MotionEstimate) and est.case == 2
    assert est.texture_dof == ("mu",)
    rot, tr = errors(est, pairs[2].T_1_2)
    # rotation from two normals (as in the 3-plane case); mu from the exhaustive search at
    # nu = 1 cm is within nu / 2 = 5 mm before the sub-pixel step
    assert rot < 0.1 and tr < NU / 2
    # the motion along the line really was found by texture: it is not zero
    assert abs(est.residuals["mu_m"]) > 0.1


def test_one_plane_texture_fixes_lambda_mu_eta(pairs):
    est = solve(pairs[1])
    assert isinstance(est, MotionEstimate) and est.case == 1
    assert set(est.texture_dof) == {"lambda", "mu", "eta"}
    rot, tr = errors(est, pairs[1].T_1_2)
    # (mu, eta) to within half a texture pixel (5 mm); lambda to within half a pixel at the
    # texture's radius (~1 m): 0.005 rad = 0.3 deg
    assert tr < NU / 2 and rot < 0.3
    # the turn about the normal is not small: it was recovered, not assumed
    assert abs(est.residuals["lambda_rad"]) > 0.02


def test_one_plane_large_shift_uses_the_global_stage():
    """A 0.45 m slide along the wall (15 bricks' worth of texture) with a 12 deg turn."""
    motion = se3_from_rt(Rotation.from_rotvec([0, 0, 0.2]).as_matrix(), [0.45, -0.2, 0.05])
    pair = render_pair(1, motion=motion, seed=5)
    est = solve(pair)
    assert isinstance(est, MotionEstimate) and est.case == 1
    rot, tr = errors(est, motion)
    assert tr < NU / 2 and rot < 0.3


@pytest.mark.parametrize("n_dirs, free", [(1, {"lambda", "mu", "eta"}), (2, {"mu"})])
def test_uniform_texture_is_a_failure_naming_the_free_dof(n_dirs, free):
    pair = render_pair(n_dirs, texture=SOLID)
    res = solve(pair)
    assert isinstance(res, MotionFailure) and not res.ok
    assert set(res.free_dof) == free
    assert res.case == n_dirs
    assert "uniform" in res.reason or "flat" in res.reason


def test_no_overlap_is_a_failure():
    rng = np.random.default_rng(0)
    plane = Plane(np.array([0.0, 0, 1]), 1.0, np.zeros(3))

    def tex(i0):
        img = rng.random((20, 30)).astype(np.float32)
        return PlaneTexture(
            img, np.ones(img.shape, bool), np.zeros(3), np.eye(3)[:2], np.array([i0, 0]), NU, plane
        )

    res = search_1d([(tex(0), tex(1000))], max_shift=50)
    assert np.isnan(res.shift)


def test_parallel_planes_are_degenerate_for_the_closed_form():
    p = [Plane(np.array([0.0, 0, 1]), r, np.zeros(3), count=100) for r in (1.0, 2.0, 3.0)]
    res = solve_three_planes(p, p)
    assert isinstance(res, MotionFailure) and res.case == 1
    assert set(res.free_dof) == {"lambda", "mu", "eta"}


def test_two_directions_without_camera_are_a_failure(pairs):
    from dataclasses import replace

    o1 = observe_rgbd(pairs[2].f1.frame, ES)
    o2 = observe_rgbd(pairs[2].f2.frame, ES)
    res = estimate_motion(replace(o1, gray=None), replace(o2, gray=None))
    assert isinstance(res, MotionFailure) and res.free_dof == ("mu",)


unit = (
    st.lists(st.floats(-1, 1), min_size=3, max_size=3)
    .map(np.array)
    .filter(lambda v: np.linalg.norm(v) > 0.2)
)


@settings(max_examples=50, deadline=None)
@given(
    st.lists(unit, min_size=3, max_size=6),
    st.lists(st.floats(0.5, 5), min_size=6, max_size=6),
    unit,
    st.floats(0, np.pi),
    st.lists(st.floats(-2, 2), min_size=3, max_size=3),
)
def test_closed_form_recovers_any_motion_exactly(normals, rhos, axis, angle, t):
    """Noise-free planes: the closed form is exact whenever the normals span 3 directions."""
    N = np.array([n / np.linalg.norm(n) for n in normals])
    # The solver's documented criterion: a third direction at least parallel_deg off the plane
    # of the first two. Normals that are all nearly coplanar must give an explicit failure.
    three_directions = normal_rank(N, SolverSettings().parallel_deg)[0] == 3
    R = Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix()
    t = np.array(t)
    p1, p2 = [], []
    for n, rho in zip(N, rhos, strict=False):
        n1, r1 = canonical_plane(n, rho)
        # frame 2 sees N2 = R^T N1, rho2 = rho1 - N1 . t (eqs. 1, 2)
        n2, r2 = R.T @ n1, r1 - n1 @ t
        p1.append(Plane(n1, r1, n1 * r1, count=1000))
        p2.append(Plane(n2, r2, n2 * r2, count=1000))
    res = solve_three_planes(p1, p2)
    if not three_directions:
        assert isinstance(res, MotionFailure) and res.free_dof
        return
    assert isinstance(res, MotionEstimate)
    assert np.allclose(res.rotation, R, atol=1e-8)
    assert np.allclose(res.translation, t, atol=1e-8)
    # the paper's Euler angles (eq. 11) equal SciPy's ZXY modulo 2 pi (away from gimbal lock)
    ref = Rotation.from_matrix(R).as_euler("ZXY")
    if abs(ref[1]) < np.radians(89):
        diff = np.angle(np.exp(1j * (euler_zxy_from_quat(res.quaternion) - ref)))
        assert np.allclose(diff, 0, atol=1e-6)


@settings(max_examples=50, deadline=None)
@given(
    st.floats(30, 150),
    st.lists(st.floats(0.5, 5), min_size=4, max_size=4),
    unit,
    unit,
    st.floats(0, np.pi),
    st.lists(st.floats(-2, 2), min_size=3, max_size=3),
)
def test_two_plane_geometry_fixes_all_but_mu(between_deg, rhos, axis, first, angle, t):
    """Noise-free planes in two directions (plus parallel copies): the rotation is exact and the
    translation is exact across the intersection line; along it (mu) it is left free (t0 . d =
    0), whatever the true shift along the line."""
    from navkit.planes.solve import PartialMotion, two_plane_geometry

    a = first / np.linalg.norm(first)
    perp = np.cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0])
    perp /= np.linalg.norm(perp)
    b = np.cos(np.radians(between_deg)) * a + np.sin(np.radians(between_deg)) * perp
    R = Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix()
    t = np.array(t)
    p1, p2 = [], []
    for n, rho in zip([a, b, a, b], rhos, strict=True):
        n1, r1 = canonical_plane(n, rho)
        n2, r2 = R.T @ n1, r1 - n1 @ t
        p1.append(Plane(n1, r1, n1 * r1, count=1000))
        p2.append(Plane(n2, r2, n2 * r2, count=1000))
    g = two_plane_geometry(p1, p2)
    assert isinstance(g, PartialMotion) and g.free_dof == ("mu",)
    assert np.allclose(g.R, R, atol=1e-8)
    assert abs(g.d @ a) < 1e-9 and abs(g.d @ b) < 1e-9 and abs(g.t0 @ g.d) < 1e-9
    assert np.allclose(g.t0, t - (t @ g.d) * g.d, atol=1e-8)


def test_two_plane_geometry_needs_two_directions():
    from navkit.planes.solve import two_plane_geometry

    n = np.array([0.0, 0.0, 1.0])
    p = [Plane(n, 1.0, n), Plane(n, 2.0, 2 * n)]
    res = two_plane_geometry(p, p)
    assert isinstance(res, MotionFailure) and res.case == 1
    assert res.free_dof == ("lambda", "mu", "eta")


def _seen_from_2(n1, r1, c1, R, t):
    """Frame 2's view of the frame-1 plane ``(n1, r1)`` through a frame-1 point ``c1`` on it."""
    return Plane(R.T @ n1, r1 - n1 @ t, R.T @ (c1 - t), count=1000)


@settings(max_examples=40, deadline=None)
@given(
    st.lists(st.floats(0.5, 5), min_size=4, max_size=4),
    st.lists(st.floats(-3, 3), min_size=16, max_size=16),
    unit,
    st.floats(0, np.pi),
    st.lists(st.floats(-2, 2), min_size=3, max_size=3),
    st.sampled_from(["centroid", "rho"]),
)
def test_plane_translation_is_exact_wherever_the_centroids_lie(rhos, offs, axis, angle, t, method):
    """Noise-free planes: both forms of eq. 2 give the true translation, whatever in-plane points
    the two frames' centroids are (different parts of each plane seen from each frame)."""
    from navkit.planes.solve import plane_translation

    N = np.array([[1.0, 0.2, 0.0], [0.0, 1.0, 0.3], [0.2, 0.0, 1.0], [1.0, 1.0, 1.0]])
    N /= np.linalg.norm(N, axis=1)[:, None]
    R = Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix()
    t = np.array(t)
    off = np.array(offs).reshape(4, 2, 2)
    p1, p2 = [], []
    for k, (n, rho) in enumerate(zip(N, rhos, strict=True)):
        ax = Plane(n, rho, n * rho).basis()
        c1 = rho * n + off[k, 0] @ ax  # where frame 1 saw the plane
        c2 = rho * n + off[k, 1] @ ax  # where frame 2 saw it (frame-1 coordinates)
        p1.append(Plane(n, rho, c1, count=1000))
        p2.append(_seen_from_2(n, rho, c2, R, t))
    est = plane_translation(R, p1, p2, np.ones(4), method)
    assert np.allclose(est, t, atol=1e-8)


def test_centroid_form_removes_the_lever_arm_of_a_normal_error():
    """A plane fitted with a tilted normal still passes through its points' centroid ``c``;
    its rho (the distance extrapolated to the origin) is off by ``c . dN``. Three orthogonal
    planes, frame 1's x-plane tilted by 3 deg (towards -z) about its centroid 3 m ahead (a side
    wall at grazing incidence, as on slambook 2 -> 3), true rotation:

    - eq. 2 as ``rho1 - rho2``: the equation of the tilted plane is off by
      ``(c - t) . dN`` = (3.0 - 0.7) m x sin 3 deg = 12.0 cm (frame 2's distance is measured
      from its own origin ``t``), the other planes keep y and z: error ~12 cm (> 10 cm);
    - at the centroids the lever is the distance between the two views' centroids, here 0.5 m
      in the plane: one of the pair's two equations is off by at most 0.5 m x sin 3 deg =
      2.6 cm, the other (frame 2's normal) is exact, the orthogonal normals keep the axes
      apart: < 2.7 cm (least squares of the two: ~1.3 cm).
    """
    from navkit.planes.solve import plane_translation

    R = Rotation.from_rotvec([0.0, 0.0, 0.1]).as_matrix()
    t = np.array([0.3, -0.2, 0.7])
    tilt = Rotation.from_rotvec([0.0, np.radians(3.0), 0.0]).as_matrix()  # x towards -z
    p1, p2 = [], []
    for n, rho, c in (
        ([1.0, 0.0, 0.0], 0.5, [0.5, 0.3, 3.0]),  # side wall, centroid 3 m ahead
        ([0.0, 1.0, 0.0], 1.4, [0.2, 1.4, 2.0]),  # floor
        ([0.0, 0.0, 1.0], 4.0, [0.1, -0.2, 4.0]),  # far wall
    ):
        n, c = np.array(n), np.array(c)
        c2 = c + (np.array([0.0, 0.0, -0.5]) if n[0] else 0.0)  # frame 2 saw 0.5 m nearer part
        p2.append(_seen_from_2(n, rho, c2, R, t))
        nt = tilt @ n if n[0] else n
        p1.append(Plane(nt, float(nt @ c), c, count=1000))
    e_rho = np.linalg.norm(plane_translation(R, p1, p2, np.ones(3), "rho") - t)
    e_c = np.linalg.norm(plane_translation(R, p1, p2, np.ones(3), "centroid") - t)
    assert e_rho > 0.10
    assert e_c < 0.027


def test_unknown_translation_method_is_a_config_error():
    from navkit.errors import ConfigError
    from navkit.planes.solve import plane_translation

    p = [Plane(np.array([0.0, 0, 1]), 1.0, np.zeros(3))]
    with pytest.raises(ConfigError, match="translation"):
        plane_translation(np.eye(3), p, p, np.ones(1), "normal")
