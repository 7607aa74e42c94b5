"""The mission's own parts: the operator's driver, the obstacle map, pose algebra, settings."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from navkit.errors import ConfigError, FormatError
from navkit.mission import CameraSettings, MissionSettings, PurePursuit, load_route
from navkit.mission.driver import polyline_point
from navkit.mission.pose2d import blend, compose, relative
from navkit.obstacles import ObstacleMapper, ObstacleMapperSettings
from navkit.obstacles.evaluate import distance_to_polygon as _distance_to_polygon
from navkit.obstacles.evaluate import score_obstacle_map
from navkit.sim.footprints import true_footprints
from navkit.sim.unicycle import unicycle_step

from .conftest import small_scene


def test_pure_pursuit_follows_an_l_shaped_route_to_its_end():
    W = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 5.0]])
    drv = PurePursuit(W, v_max=0.6, omega_max=0.8, lookahead=1.0, goal_tolerance=0.3)
    pose = np.zeros(3)
    track = [pose]
    for _ in range(600):
        if drv.done(pose):
            break
        v, om = drv.command(pose)
        pose = unicycle_step(pose, v, om, 0.1)
        track.append(pose)
    assert drv.done(pose)
    P = np.array(track)[:, :2]
    # pure pursuit cuts corners by at most about the look-ahead distance
    s = np.linspace(0, 11, 2201)
    ref = polyline_point(W, s)
    d = np.min(np.hypot(*(P[:, None, :] - ref[None]).transpose(2, 0, 1)), axis=1)
    assert d.max() <= 1.0


@settings(max_examples=50, deadline=None)
@given(
    st.floats(-20, 20),
    st.floats(-20, 20),
    st.floats(-3.1, 3.1),
    st.floats(-2, 2),
    st.floats(-2, 2),
    st.floats(-1, 1),
)
def test_relative_inverts_compose(x, y, th, dx, dy, dth):
    a = np.array([x, y, th])
    inc = np.array([dx, dy, dth])
    np.testing.assert_allclose(relative(a, compose(a, inc)), inc, atol=1e-9)


def test_blend_wraps_the_heading():
    a, b = np.array([0.0, 0.0, np.pi - 0.1]), np.array([2.0, 0.0, -np.pi + 0.1])
    out = blend(a, b, 0.5)
    np.testing.assert_allclose(out, [1.0, 0.0, np.pi], atol=1e-12)


def _box_cells(c, half, step=0.05):
    g = np.arange(-half, half + 1e-9, step)
    X, Y = np.meshgrid(g, g)
    return np.c_[X.ravel(), Y.ravel()] + c


def test_obstacle_grid_confirms_repeated_obstacles_and_scores_them():
    scene = small_scene()
    fps = true_footprints(scene)
    crate = next(f for f in fps if f.name == "crate")
    grid = ObstacleMapper((-2, -5), (15, 5), ObstacleMapperSettings(0.1, min_hits=2, min_ratio=0.3))
    ground = np.random.default_rng(0).uniform([-2, -5], [8, 5], (4000, 2))
    crate_pts = _box_cells(np.array([3.0, 1.6]), 0.45)
    for k in range(3):
        extra = np.array([[0.0, -3.0]]) if k == 0 else np.zeros((0, 2))  # one-scan noise
        phantom = np.array([[1.0, 3.5]]) if k >= 1 else np.zeros((0, 2))  # seen twice: a phantom
        grid.add_points(np.vstack([crate_pts, extra, phantom]), ground)
    seen = {crate.index}
    sc = score_obstacle_map(grid.grid(), fps, seen, min_height=0.2, robot_width=0.5, tolerance=0.3)
    assert sc["seen_obstacles"] == 1 and sc["recall"] == 1.0
    assert sc["phantoms"] == 1 and sc["components"] == 2
    assert sc["precision"] == 0.5
    # cells of the crate lie inside its true footprint (error 0)
    assert sc["cell_error_p95_m"] == pytest.approx(0.0, abs=1e-9)


def test_blocked_corridor_matches_brute_force(np_rng):
    grid = ObstacleMapper(
        (0, 0), (10, 10), ObstacleMapperSettings(0.1, min_hits=1, min_ratio=0.0, recent_scans=1)
    )
    pts = np_rng.uniform(0, 10, (40, 2))
    grid.add_points(pts, pts)
    path = np.c_[np.linspace(0.5, 9.5, 50), np.linspace(5, 6, 50)]
    got = grid.blocked(path, 0.4)
    rows, cols = np.nonzero(grid.recent_occupied)
    C = grid.centres(rows, cols)
    # brute force: the nearest point of each occupied cell (a 0.1 m square) to each path point
    lo, hi = C - 0.05, C + 0.05
    nearest = np.clip(path[:, None, :], lo[None], hi[None])
    d = np.hypot(*(nearest - path[:, None, :]).transpose(2, 0, 1)).min(axis=1)
    # the grid test uses centre distance minus half a diagonal: never misses a cell within the
    # corridor, and over-reports only within the half-diagonal (0.0707 m) band
    assert np.all(got[d <= 0.4])
    assert not np.any(got[d > 0.4 + 0.0708])


def test_known_obstacles_do_not_block_the_way_back_new_ones_do():
    grid = ObstacleMapper(
        (0, 0), (10, 10), ObstacleMapperSettings(0.1, min_hits=1, min_ratio=0.0, recent_scans=1)
    )
    jamb = np.c_[np.full(20, 5.0), np.linspace(5.6, 7.5, 20)]  # a door jamb 0.6 m from the path
    grid.add_points(jamb, jamb)
    grid.freeze_known(0.6)
    path = np.c_[np.linspace(4.0, 6.0, 21), np.full(21, 5.0)]
    # seen again on the way back with the estimate 0.35 m off: the jamb now touches the corridor
    grid.add_points(jamb - [0.0, 0.35], jamb)
    assert not grid.blocked(path, 0.3).any()
    # without the memory of the way out, the same cells would stop the robot
    known, grid.known = grid.known, None
    assert grid.blocked(path, 0.3).any()
    grid.known = known
    # a new box on the path blocks
    box = np.c_[np.full(5, 6.0), np.linspace(4.6, 5.0, 5)]  # 1 m from the jamb
    grid.add_points(np.vstack([jamb - [0.0, 0.35], box]), jamb)
    hit = grid.blocked(path, 0.3)
    assert hit.any() and np.all(np.abs(path[hit, 0] - 6.0) <= 0.3 + 0.08)


def test_true_footprints_of_the_primitives():
    fps = {f.name: f for f in true_footprints(small_scene())}
    from navkit.geometry.polygons import polygon_area

    assert polygon_area(fps["crate"].polygon) == pytest.approx(1.0)
    assert fps["crate"].height == pytest.approx(1.0)
    assert polygon_area(fps["rock"].polygon) == pytest.approx(np.pi * 0.55**2, rel=0.01)
    assert fps["post"].extent == pytest.approx(0.2, rel=0.01)
    assert polygon_area(fps["room_south"].polygon) == pytest.approx(5.0 * 0.1)
    assert _distance_to_polygon(
        np.array([[3.0, 1.6], [3.0, 3.1]]), fps["crate"].polygon
    ) == pytest.approx([0.0, 1.0])


def test_settings_reject_bad_rates_and_keys(tmp_path):
    with pytest.raises(ConfigError, match=r"camera\.rate_hz"):
        MissionSettings(camera=CameraSettings(rate_hz=3.0))
    with pytest.raises(ConfigError, match="lidarr"):
        MissionSettings().with_overrides({"lidarr": {}})
    s = MissionSettings().with_overrides({"lidar": {"n_beams": 16}, "seed": 9})
    assert s.lidar.n_beams == 16 and s.seed == 9
    bad = tmp_path / "bad.toml"
    bad.write_text("[route\n")
    with pytest.raises(FormatError, match=r"bad\.toml"):
        load_route(bad)
    nowp = tmp_path / "nowp.toml"
    nowp.write_text("[route]\nroom = [0, 0, 1, 1]\n")
    with pytest.raises(ConfigError, match="waypoints"):
        load_route(nowp)
    badroom = tmp_path / "badroom.toml"
    badroom.write_text("[route]\nwaypoints = [[0, 0], [3, 0]]\nroom = [5, 0, 1, 1]\n")
    with pytest.raises(ConfigError, match=r"route\.room"):
        load_route(badroom)


def test_detour_on_the_obstacle_map_avoids_known_and_new_obstacles():
    """The return's planning step (``Return._plan``) on an ObstacleMapper: the confirmed cells of
    the way out and the recent cells of a new box are both avoided, the rejoin lies on the
    stored path beyond the box, and the controller on the detour starts at the robot."""
    from navkit.mission.run import _return_settings
    from navkit.path import Return, approximate

    s = MissionSettings()
    grid = ObstacleMapper(
        (-2, -5), (14, 5), ObstacleMapperSettings(0.1, min_hits=1, min_ratio=0.0, recent_scans=2)
    )
    wall = np.c_[np.linspace(0.0, 12.0, 121), np.full(121, 1.3)]  # mapped on the way out
    grid.add_points(wall, wall)
    xx, yy = np.meshgrid(np.arange(5.6, 6.45, 0.05), np.arange(-0.4, 0.45, 0.05))
    box = np.c_[xx.ravel(), yy.ravel()]  # a new 0.8 m box on the path, seen on the way back
    grid.add_points(np.vstack([wall, box]), wall)
    # the stored path: recorded from the operator at x = 0 to x = 12 (the robot is at x = 9)
    path = approximate(np.c_[np.linspace(0.0, 12.0, 241), np.zeros(241)]).spline
    s_now = 9.0
    half = 0.5 * s.robot.width + s.block.clearance
    ret = Return(path, _return_settings(s))
    got = ret._plan(grid, np.array([9.0, 0.0, np.pi]), s_now, 2.6)
    assert got.ok, got
    d = got.detour
    inflation = half + s.block.detour_margin
    rows, cols = np.nonzero(grid.occupied | grid.recent_occupied)
    C = grid.centres(rows, cols)
    P = np.vstack(
        [
            a + np.linspace(0, 1, 50)[:, None] * (b - a)
            for a, b in zip(d.points[:-1], d.points[1:], strict=True)
        ]
    )
    clear = np.hypot(*(P[:, None, :] - C[None]).transpose(2, 0, 1)).min(axis=1)
    # every point keeps the inflation radius from the cells, up to half a cell diagonal
    assert clear.min() >= inflation - 0.5 * np.sqrt(2) * 0.1 - 1e-9
    # the box lies between y = -0.4 and 0.4 and the wall at y = 1.3: the gap (0.9 m) is narrower
    # than twice the inflation (1.0 m), so the detour goes south of the box
    assert P[:, 1].min() < -0.4 - inflation + 0.1
    # rejoins the stored path beyond the box (x < 5.6 - inflation), at s_rejoin on the path
    assert abs(d.rejoin[1]) < 0.05 and d.rejoin[0] < 5.6 - inflation
    np.testing.assert_allclose(path.position(np.array([got.s_rejoin]))[0], d.rejoin, atol=0.05)
    np.testing.assert_allclose(
        got.controller.path.position(np.array([got.controller.path.total_length]))[0],
        [9.0, 0.0],
        atol=1e-9,
    )
    # a closed way (the box grown to the wall and far south) -> the planner's reason
    south = np.c_[np.full(90, 6.0), np.linspace(-5.0, 1.3, 90)]
    grid.add_points(np.vstack([wall, box, south]), wall)
    fail = ret._plan(grid, np.array([9.0, 0.0, np.pi]), s_now, 2.6)
    assert not fail.ok and "no detour" in str(fail)


def _wall_view(pose, walls, max_range=6.0, step=0.05):
    """Body-frame points of the wall segments ``[(x0, y0, x1, y1)]`` seen from ``pose``."""
    pts = []
    for x0, y0, x1, y1 in walls:
        n = int(np.hypot(x1 - x0, y1 - y0) / step) + 1
        s = np.linspace(0.0, 1.0, n)[:, None]
        pts.append(np.array([x0, y0]) + s * np.array([x1 - x0, y1 - y0]))
    W = np.vstack(pts) - pose[:2]
    c, s_ = np.cos(pose[2]), np.sin(pose[2])
    B = W @ np.array([[c, -s_], [s_, c]])  # world offsets -> body frame
    return B[np.hypot(B[:, 0], B[:, 1]) <= max_range]


def test_mission_localizer_fixes_through_the_localizer():
    """The room's Localizer (built from first-visit views at true poses) pulls a wrong estimate
    by the fix weight towards the truth; a view of one straight wall is refused (elongated peak)
    and leaves the estimate."""
    from navkit.mission.localize import MissionLocalizer, RoomRecord
    from navkit.mission.settings import FusionSettings, Route

    room = [(0.0, 0.0, 6.0, 0.0), (6.0, 0.0, 6.0, 4.0), (6.0, 4.0, 0.0, 4.0), (0.0, 4.0, 0.0, 0.0)]
    route = Route(waypoints=((0.0, 0.0), (6.0, 4.0)), room=(0.0, 0.0, 6.0, 4.0))
    F = FusionSettings(room_map_views=4)
    rec = RoomRecord()
    loc = MissionLocalizer(route, F, 0.1, rec)
    for x in (1.5, 2.5, 3.5, 4.5):  # the first visit: views at the true poses
        p = np.array([x, 2.0, 0.3 * x])
        est = loc.room_view(_wall_view(p, room), p, p, 0.0, outbound=True, may_fix=True)
        np.testing.assert_array_equal(est, p)  # collecting, no fix yet
    loc.finish_room()
    assert rec.room_map is not None and len(rec.room_map.walls) >= 4
    truth = np.array([3.0, 1.8, 0.5])
    wrong = truth + np.array([0.2, -0.15, np.radians(3.0)])
    est = loc.room_view(_wall_view(truth, room), wrong, truth, 1.0, outbound=False, may_fix=True)
    fx = rec.fixes[-1]
    assert fx.ok and fx.used and fx.reason == ""
    assert np.hypot(*(fx.pose[:2] - truth[:2])) < 0.05 and abs(fx.pose[2] - truth[2]) < 0.02
    # blended by fix_weight: the estimate moved 70 % of the way to the fix
    np.testing.assert_allclose(est, wrong + F.fix_weight * (fx.pose - wrong), atol=1e-12)
    # one straight wall only: slides along it -> refused, the estimate stays
    loc2 = MissionLocalizer(route, FusionSettings(room_map_views=4, fragment_views=1), 0.1, rec)
    loc2.room, loc2.done = loc.room, True
    one_wall = _wall_view(truth, room[:1], max_range=2.5)
    est2 = loc2.room_view(one_wall, wrong, truth, 2.0, outbound=False, may_fix=True)
    assert not rec.fixes[-1].ok and "elongated peak" in rec.fixes[-1].reason
    np.testing.assert_array_equal(est2, wrong)
