"""The stereo front end on rendered rooms: wall points, map accuracy and a fix against the truth."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.localization import build_map, match_scan
from navkit.localization.evaluate import evaluate_map
from navkit.sensors import PinholeCamera, StereoRig
from navkit.stereo import stereo_wall_points
from navkit.stereo.rooms import ROOM_KINDS, room, sample_poses
from navkit.stereo.triangulation import planar_camera_pose

sim = pytest.importorskip("navkit.sim")
scene_io = pytest.importorskip("navkit.sim.scene_io")

RIG = StereoRig(PinholeCamera.from_fov(320, 240, 90.0), 0.2)
HEIGHT = 1.2


def _render(scene, pose, seed):
    T = planar_camera_pose(*pose, HEIGHT)
    st = sim.render_stereo(scene, RIG, T, rng=seed, pixel_noise=1.0, supersample=1)
    return st, T


@pytest.fixture(scope="module")
def rect_map():
    truth = room("rectangle")
    scene = scene_io.scene_from_dict(truth.scene)
    views = []
    for k, pose in enumerate(truth.survey):  # 12 headings, 30 degrees apart, 90 deg field of view
        st, T = _render(scene, pose, k)
        views.append(stereo_wall_points(st.pair.left, st.pair.right, RIG, T_world_camera=T))
    return truth, scene, build_map(views)


def test_wall_points_lie_on_the_walls():
    truth = room("rectangle")
    scene = scene_io.scene_from_dict(truth.scene)
    st, T = _render(scene, (4.0, 3.0, 0.3), 1)
    P = stereo_wall_points(st.pair.left, st.pair.right, RIG, T_world_camera=T)
    assert len(P) > 300
    # distance of each point to the nearest wall line. SGBM's disparity error on these renders
    # has a MAD of ~0.15 px (sigma ~0.22 px); the depth error at 4 m is z^2 / (b f) * sigma =
    # 16 / 32 * 0.22 = 0.11 m, so the median |error| of a N(0, 0.11) is 0.074 m: allow 0.1 m,
    # and 80 % within 0.25 m (> 2 sigma).
    d = np.minimum.reduce(
        [np.abs(P[:, 0]), np.abs(P[:, 0] - 8), np.abs(P[:, 1]), np.abs(P[:, 1] - 6)]
    )
    assert np.median(d) < 0.1
    assert np.mean(d < 0.25) > 0.8


def test_map_of_the_rectangle_against_the_truth(rect_map):
    truth, _, m = rect_map
    acc = evaluate_map(m, truth.walls, truth.corners)
    assert acc["walls_found"] == 4 and acc["corners_found"] == 4
    # ~1000 points per wall with ~0.1 m depth noise: TLS direction error ~ 0.1 / 8 m *
    # sqrt(12/1000) ~ 0.08 deg, plus the matcher's systematic depth bias (~1-3 cm, varying along
    # the wall); allow 1 deg and 6 cm (0.6 % of the 10 m diagonal).
    assert acc["wall_angle_error_deg_max"] < 1.0
    assert acc["corner_error_m_max"] < 0.06


def test_locate_by_turning_the_camera_in_the_stereo_map(rect_map):
    """Paper 3's protocol: the camera turns on its drive (relative headings known) and the fragments
    of 4 views 90 deg apart are matched together, globally (no prior)."""
    from navkit.geometry import se2_apply, se2_from_xytheta

    truth, scene, m = rect_map
    fld = m.likelihood_field(0.1)
    pose = sample_poses(truth, 1, np.random.default_rng(4))[0]
    parts = []
    for k in range(4):
        st, _ = _render(scene, pose + np.array([0.0, 0.0, k * np.pi / 2]), 20 + k)
        B = stereo_wall_points(st.pair.left, st.pair.right, RIG, camera_height=HEIGHT)
        parts.append(se2_apply(se2_from_xytheta(0.0, 0.0, k * np.pi / 2), B))
    fix = match_scan(fld, np.concatenate(parts), None)
    # the rectangle is symmetric under a half turn: the fix is the pose or its twin, and a
    # symmetric room must be reported as ambiguous (second peak)
    twin = np.array([8.0 - pose[0], 6.0 - pose[1]])
    err = min(np.hypot(*(fix.pose[:2] - pose[:2])), np.hypot(*(fix.pose[:2] - twin)))
    # ~4 x 1000 points with ~0.1 m noise and a few cm of bias: measured ~1-3 cm; allow 0.1 m (1 %)
    assert err < 0.1
    assert fix.ambiguity.ambiguous and "second peak" in fix.ambiguity.reason


def test_rooms_are_well_formed():
    for kind in ROOM_KINDS:
        r = room(kind)
        scene_io.scene_from_dict(r.scene)  # the simulator accepts the description
        P = sample_poses(r, 50, np.random.default_rng(0))
        from navkit.geometry.polygons import points_in_polygon

        assert points_in_polygon(P[:, :2], r.outline).all()


def test_single_view_known_heading_in_the_stereo_map(rect_map):
    """Paper 3's own scenario: one 90-deg view, the heading from the camera drive. A view of a
    corner gives a confident fix; a view of one straight wall is reported ambiguous along it."""
    from navkit.localization import locate_known_heading
    from navkit.localization.refine import stereo_range_sigma

    _, scene, m = rect_map
    fld = m.likelihood_field(0.1)
    corner = np.array([5.5, 3.5, np.radians(35.0)])  # looks at the (8, 6) corner, ~3 m away
    wall = np.array([4.0, 3.0, np.radians(-90.0)])  # faces the south wall, 3 m away, head-on
    fixes = {}
    for name, pose in (("corner", corner), ("wall", wall)):
        st, _ = _render(scene, pose, 7)
        B = stereo_wall_points(st.pair.left, st.pair.right, RIG, camera_height=HEIGHT)
        sig = stereo_range_sigma(B, RIG.baseline, RIG.camera.fx)
        fixes[name] = locate_known_heading(
            fld, B, pose[2], walls=m.walls, range_sigma=sig, region=m.outline
        )
    fc, fw = fixes["corner"], fixes["wall"]
    assert fc.ok
    # ~1000 points at 2.5-4 m (depth sigma 5-12 cm after the sub-pixel correction, bias-free)
    # and a map good to ~1-2 cm: measured ~1 cm; allow 4 cm (0.4 % of the 10 m diagonal)
    assert np.hypot(*(fc.position - corner[:2])) < 0.04
    # the 8 m wall seen over ~6 m: the fragment slides ~2 m along it - ambiguous, along x
    assert not fw.ok and fw.ambiguous
    assert abs(fw.peak_direction[0]) > 0.95
    assert abs(fw.position[1] - wall[1]) < 0.04  # across the wall it is determined
