"""The online Localizer: simulated L-shaped room against truth, its failures and gates, and on a
real CARMEN log the same fixes as ``navkit map locate`` (which is a loop over it)."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from navkit.errors import ConfigError, InputError
from navkit.geometry import se2_compose, se2_from_xytheta, se2_inverse, se2_to_xytheta, wrap_angle
from navkit.localization import (
    Fix,
    KnownHeadingFix,
    LocalizationFailure,
    Localizer,
    LocalizerSettings,
    MatcherSettings,
    ScanMatch,
    build_map_from_scans,
    evaluate_fixes,
)
from navkit.localization.evaluation import reported_poses
from navkit.localization.localizer import stack_views
from tests.localization.helpers import LSHAPE, cast, scan_points

BEARINGS = np.linspace(-np.pi / 2, np.pi / 2, 181)


def _route(n: int = 60) -> np.ndarray:
    """A drive round the L-shaped room: (n, 3) poses."""
    t = np.linspace(0, 1, n)
    xs = np.interp(t, [0, 0.35, 0.6, 1.0], [1.5, 8.5, 2.5, 2.5])
    ys = np.interp(t, [0, 0.35, 0.6, 1.0], [1.5, 2.0, 2.0, 6.8])
    return np.column_stack([xs, ys, np.arctan2(np.gradient(ys), np.gradient(xs))])


def _delta(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return se2_to_xytheta(se2_compose(se2_inverse(se2_from_xytheta(*a)), se2_from_xytheta(*b)))


@pytest.fixture(scope="module")
def room():
    """The L-shaped room's wall map from exact scans at every 3rd pose of the route."""
    truth = _route()
    ranges = np.array([cast(LSHAPE, p, BEARINGS) for p in truth[::3]])
    return build_map_from_scans(ranges, BEARINGS, truth[::3]), truth


def _odometry(truth: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Dead reckoning from noisy increments (3 cm, 3 cm, 0.01 rad per step)."""
    odo = [truth[0].copy()]
    for k in range(1, len(truth)):
        d = _delta(truth[k - 1], truth[k]) + rng.normal(0.0, [0.03, 0.03, 0.01])
        odo.append(se2_to_xytheta(se2_compose(se2_from_xytheta(*odo[-1]), se2_from_xytheta(*d))))
    return np.array(odo)


@pytest.mark.parametrize(
    ("refine", "median_m", "max_m"), [(False, 0.01, 0.03), (True, 0.006, 0.015)]
)
def test_tracking_in_the_simulated_room(room, refine, median_m, max_m):
    # measured (seed 3, 2 cm range noise): median / max 3.6 / 12.9 mm unrefined, 2.5 / 5.8 mm
    # refined; the bounds leave about 2.5x
    wall_map, truth = room
    rng = np.random.default_rng(3)
    odo = _odometry(truth, rng)
    loc = Localizer(wall_map, LocalizerSettings(refine=refine))
    results = []
    for k in range(len(truth)):
        pts = scan_points(LSHAPE, truth[k], n=181, fov=np.pi, noise=0.02, rng=rng)
        d = None if k == 0 else _delta(odo[k - 1], odo[k])
        results.append(loc.update(pts, odometry_delta=d))
    assert all(isinstance(r, Fix) for r in results)
    assert results[0].method == "global" and {r.method for r in results[1:]} == {"tracking"}
    assert all(r.refined == refine for r in results)
    stats = evaluate_fixes(results, truth, success_m=0.05, success_deg=1.0)
    assert stats["success_rate"] == 1.0
    assert stats["position_error_m_median"] < median_m
    pe = np.hypot(*(np.array([r.pose[:2] for r in results]) - truth[:, :2]).T)
    assert pe.max() < max_m
    # the odometry alone drifts far beyond that
    assert np.hypot(*(odo[:, :2] - truth[:, :2]).T).max() > 5 * max_m
    np.testing.assert_allclose(loc.pose, results[-1].pose)


def test_known_heading_in_the_simulated_room(room):
    # paper 3's correlation at the true heading, refined: measured max 3.9 mm (seed 4)
    wall_map, truth = room
    rng = np.random.default_rng(4)
    loc = Localizer(wall_map, LocalizerSettings(refine=True))
    for p in truth[::5]:
        r = loc.update(scan_points(LSHAPE, p, n=181, fov=np.pi, noise=0.02, rng=rng), heading=p[2])
        assert isinstance(r, Fix) and r.method == "known heading"
        assert r.pose[2] == p[2]  # the heading is kept
        assert np.hypot(*(r.pose[:2] - p[:2])) < 0.01
        assert r.covariance is not None and r.covariance.shape == (3, 3)
        assert isinstance(r.match, KnownHeadingFix) and r.match.ok  # the paper's own report


def test_a_straight_wall_is_a_failure_along_it(room):
    wall_map, _ = room
    # 2 m of the room's 10 m bottom wall (y = 0), seen from (5, 1) looking along +x
    wall = np.column_stack([np.linspace(-1.0, 1.0, 60), np.full(60, -1.0)])
    # (a tracking window narrower than the exclusion radius: no distinct second peak in it)
    s = LocalizerSettings(matcher=MatcherSettings(linear_window=0.4, angular_window_deg=5.0))
    r = Localizer(wall_map, s).update(wall, prior=np.array([5.0, 1.0, 0.0]))
    assert isinstance(r, LocalizationFailure) and not r.ok and r.ambiguous
    assert r.reason == "elongated peak" and r.free_dof == ("along",)
    assert abs(r.direction[0]) > 0.99  # along the wall (x)
    assert abs(r.candidate[1] - 1.0) < 0.02  # right across the wall
    assert isinstance(r.match, ScanMatch) and r.match.ambiguity.reason == r.reason
    assert r.method == "tracking"


def test_too_few_points_keep_the_odometry_for_the_next_scan(room):
    wall_map, truth = room
    loc = Localizer(wall_map)
    assert isinstance(loc.update(scan_points(LSHAPE, truth[10], n=181, fov=np.pi)), Fix)
    r = loc.update(
        np.array([[1.0, 0.0], [np.nan, 1.0]]), odometry_delta=_delta(truth[10], truth[11])
    )
    assert isinstance(r, LocalizationFailure) and r.reason == "too few points"
    assert r.free_dof == ("x", "y", "theta") and np.all(np.isnan(r.candidate))
    # the next scan is tracked from the increments of both steps
    r2 = loc.update(
        scan_points(LSHAPE, truth[12], n=181, fov=np.pi),
        odometry_delta=_delta(truth[11], truth[12]),
    )
    assert isinstance(r2, Fix) and r2.method == "tracking"
    np.testing.assert_allclose(r2.prediction, r2.pose, atol=0.02)


def test_blending_and_gate(room):
    # the mission's use: its own estimate as the prior, a fix pulls it by fix_weight within gate_m
    wall_map, truth = room
    p = truth[20]
    pts = scan_points(LSHAPE, p, n=181, fov=np.pi)
    s = LocalizerSettings(fix_weight=0.5, gate_m=0.4, matcher=MatcherSettings(linear_window=0.4))
    loc = Localizer(wall_map, s)
    est = p + np.array([0.2, -0.1, 0.02])
    r = loc.update(pts, prior=est)
    assert isinstance(r, Fix) and r.used
    np.testing.assert_allclose(r.estimate[:2], 0.5 * (est[:2] + r.pose[:2]))
    assert abs(wrap_angle(r.estimate[2] - 0.5 * (est[2] + r.pose[2]))) < 1e-12
    # an estimate 0.35 m off: the fix (inside the 0.5 m window) lies outside a 0.3 m gate
    loc = Localizer(
        wall_map, LocalizerSettings(gate_m=0.3, matcher=MatcherSettings(linear_window=0.5))
    )
    far = p + np.array([0.35, 0.0, 0.0])
    r = loc.update(pts, prior=far)
    assert isinstance(r, Fix) and not r.used
    np.testing.assert_allclose(r.estimate, far)


def test_settings_are_validated():
    with pytest.raises(ConfigError, match="fix_weight"):
        LocalizerSettings(fix_weight=0.0)
    with pytest.raises(ConfigError, match="sigma"):
        LocalizerSettings(sigma=float("nan"))
    with pytest.raises(ConfigError, match="gate_m"):
        LocalizerSettings(gate_m=-1.0)
    with pytest.raises(ConfigError, match="unknown keys"):
        LocalizerSettings.from_dict({"sigmaa": 0.1})
    s = LocalizerSettings.from_dict({"refine": True, "matcher": {"linear_window": 0.5}})
    assert s.refine and s.matcher.linear_window == 0.5
    with pytest.raises(InputError):
        Localizer()


def test_stack_views_brings_views_into_one_frame():
    rng = np.random.default_rng(0)
    world = rng.uniform(-5, 5, (30, 2))
    poses = np.array([[1.0, 2.0, 0.3], [1.5, 2.5, 1.9], [0.0, -1.0, -2.5]])
    # the same world points seen from each pose: body = R^T (world - t)
    views = [(world - p[:2]) @ se2_from_xytheta(*p)[:2, :2] for p in poses]
    frag = stack_views(views, poses, poses[1])
    expect = (np.vstack([world] * 3) - poses[1, :2]) @ se2_from_xytheta(*poses[1])[:2, :2]
    np.testing.assert_allclose(frag, expect, atol=1e-12)


# ``navkit map locate`` on aces-corrected (map from every 4th scan), recorded with the
# implementation that preceded the Localizer (2026-11-22): fixes.csv rows (index, x, y, theta, ok) of every 20th scan.
PRE_LOCALIZER = {
    "odometry": [
        (0, 0.9024, -0.1895, -0.45299, True),
        (20, 0.558, 0.0258, -0.04022, True),
        (40, 20.2728, -0.2899, 0.08141, True),
        (60, 23.1507, -15.492, -1.68327, True),
        (80, 22.3849, -29.912, -1.55208, True),
        (100, 22.0698, -38.4775, -1.15066, True),
        (120, 10.0326, -39.5317, 3.00466, True),
        (140, -0.5622, -38.3142, 0.92992, True),
        (160, -15.272, -38.3492, -3.13248, True),
        (180, -19.8676, -26.9542, 1.58339, True),
        (200, -19.5894, -15.8093, 1.29871, True),
        (220, -19.2559, 0.12, 1.23616, True),
        (240, -11.6803, 0.0422, 0.02571, True),
        (260, -0.2652, 0.2204, 0.76394, True),
        (280, -0.6677, -13.2492, -1.61303, True),
        (300, -0.8153, -29.9121, -1.61191, True),
        (320, -0.7815, -31.7833, 1.5803, True),
        (340, -5.3269, -18.5941, -3.11536, True),
        (360, -19.2633, -18.3119, -0.47966, True),
        (380, -0.4353, -19.2733, -1.53608, True),
        (400, 6.6511, -18.9927, 0.04529, True),
        (420, 23.058, -19.4221, 0.97977, True),
    ],
    "none": [
        (0, 0.9024, -0.1895, -0.45299, True),
        (20, 0.558, 0.0258, -0.04022, True),
        (40, 20.2728, -0.2899, 0.08142, True),
        (60, 23.1507, -15.492, -1.68327, True),
        (80, 22.3848, -29.912, -1.55208, True),
        (100, 22.0698, -38.4775, -1.15066, True),
        (120, 10.0078, -39.5571, 2.98606, True),
        (140, -0.5622, -38.3142, 0.92992, True),
        (160, -15.272, -38.3492, -3.13248, True),
        (180, -19.866, -26.9532, 1.58305, False),
        (200, -19.5894, -15.8093, 1.29871, True),
        (220, -19.2559, 0.12, 1.23616, True),
        (240, -11.6807, 0.0416, 0.02576, True),
        (260, -0.2654, 0.2204, 0.76385, True),
        (280, -0.6677, -13.2492, -1.61303, False),
        (300, -0.8153, -29.9121, -1.61191, True),
        (320, -0.7815, -31.7834, 1.5803, True),
        (340, -5.3269, -18.5941, -3.11536, False),
        (360, -19.2625, -18.3125, -0.48007, True),
        (380, -0.4353, -19.2733, -1.53608, True),
        (400, 6.6511, -18.9927, 0.04529, True),
        (420, 23.058, -19.4221, 0.97977, True),
    ],
}


def _read_fixes(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.realdata
@pytest.mark.parametrize("prior", ["odometry", "none"])
def test_map_locate_is_a_loop_over_the_localizer(cli, data_path, tmp_path, prior):
    """The command's fixes equal a direct Localizer loop on the real log (poses within 1e-9,
    the same accepted / rejected scans), and both equal what ``map locate`` gave before the
    Localizer (``PRE_LOCALIZER``, 4 decimals)."""
    every = 20
    from navkit.io.carmen import read_carmen
    from navkit.io.trajectory import read_tum
    from navkit.io.wallmap import write_wall_map

    log_path = data_path("laser2d/aces-corrected.log.gz")
    lg = read_carmen(log_path)
    wall_map = build_map_from_scans(lg.ranges[::4], lg.bearings, lg.poses[::4], max_range=30.0)
    write_wall_map(tmp_path / "m", wall_map)
    out = tmp_path / "loc"
    args = ("map", "locate", tmp_path / "m" / "map.json", log_path, "-o", out)
    res = cli(*args, "--prior", prior, "--every", every)
    assert res.exit_code == 0, res.stderr

    from navkit.io.wallmap import read_wall_map

    loc = Localizer(read_wall_map(tmp_path / "m" / "map.json"))
    sel = np.arange(0, len(lg), every)
    results = []
    for j, k in enumerate(sel):
        d = (
            _delta(lg.odom_poses[sel[j - 1]], lg.odom_poses[k])
            if j and prior == "odometry"
            else None
        )
        results.append(loc.update(lg.points(int(k), 30.0), odometry_delta=d))
    rows = _read_fixes(out / "fixes.csv")
    assert [int(r["index"]) for r in rows] == sel.tolist()
    assert [r["ok"] == "True" for r in rows] == [r.ok for r in results]
    ok = np.array([r.ok for r in results])
    tum = read_tum(out / "poses.tum")
    np.testing.assert_allclose(tum.timestamps, lg.timestamps[sel][ok], atol=1e-9)
    P = np.array([r.pose for r in results if r.ok])
    np.testing.assert_allclose(tum.poses[:, :2, 3], P[:, :2], atol=1e-9)
    yaw = np.arctan2(tum.poses[:, 1, 0], tum.poses[:, 0, 0])
    assert np.abs(wrap_angle(yaw - P[:, 2])).max() < 1e-9
    # the rejected candidates are reported (4 decimals in the CSV), never in poses.tum
    for row, r in zip(rows, results, strict=True):
        if not r.ok:
            assert row["reason"] == r.reason != ""
            np.testing.assert_allclose(
                [float(row[c]) for c in ("x", "y", "theta")], r.candidate, atol=6e-5
            )
    # unchanged from before the Localizer: the same accepted set, the same poses
    pre = np.array(PRE_LOCALIZER[prior], dtype=float)
    assert pre[:, 0].astype(int).tolist() == sel.tolist()
    assert pre[:, 4].astype(bool).tolist() == ok.tolist()
    np.testing.assert_allclose(reported_poses(results), pre[:, 1:4], atol=1e-4)
    # accuracy against the log's corrected poses (measured: median 8 mm both ways)
    stats = evaluate_fixes(results, lg.poses[sel])
    assert stats["success_rate_of_ok"] == 1.0
    assert stats["position_error_m_median"] < 0.02
    assert stats["ok_rate"] >= (0.99 if prior == "odometry" else 0.8)


def test_from_views_and_from_points_cover_the_missions_use(room):
    # the mission's room: a map from a few views at (estimated) poses, then fragments of the
    # last views located around the estimate, blended by fix_weight within gate_m
    _, truth = room
    rng = np.random.default_rng(5)
    poses = truth[:12:2]
    views = [scan_points(LSHAPE, p, n=121, fov=np.radians(80), noise=0.02, rng=rng) for p in poses]
    s = LocalizerSettings(
        resolution=0.05,
        matcher=MatcherSettings(linear_window=0.4, angular_window_deg=10.0),
        fix_weight=0.7,
        gate_m=0.4,
        recentre_on_rejected=False,
    )
    loc = Localizer.from_views(views, poses, s)
    assert loc.map is not None and len(loc.map.walls) >= 2
    recent = truth[5:8]  # facing the walls the map saw (east), with fresh range noise
    frag = stack_views(
        [scan_points(LSHAPE, p, n=121, fov=np.radians(80), noise=0.02, rng=rng) for p in recent],
        recent,
        recent[-1],
    )
    est = recent[-1] + np.array([0.15, -0.1, 0.03])
    r = loc.update(frag, prior=est)
    assert isinstance(r, Fix) and r.used and r.method == "tracking"
    assert np.hypot(*(r.pose[:2] - recent[-1, :2])) < 0.03
    np.testing.assert_allclose(r.estimate, est + 0.7 * (r.pose - est), atol=1e-12)
    # the obstacle-map variant: a map of occupied points, no walls
    pts = np.concatenate(
        [stack_views([v], [p], np.zeros(3)) for v, p in zip(views, poses, strict=True)]
    )
    loc2 = Localizer.from_points(pts, s)
    assert loc2.map is None
    r2 = loc2.update(views[0], prior=poses[0] + np.array([0.1, 0.1, 0.0]))
    assert r2.ok and np.hypot(*(r2.pose[:2] - poses[0, :2])) < 0.03
    with pytest.raises(InputError):
        Localizer.from_views([], np.zeros((0, 3)))
