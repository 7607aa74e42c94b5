"""The detour planner on synthetic grids, against ground truth.

Truth: a brute-force Dijkstra (heapq) on the same inflated grid for the 8-connected optimum, the
analytic shortest way round a disc (tangent - arc - tangent) for the continuous optimum, and a
KD-tree over the occupied cell centres for the clearance of every point of the detour.
"""

from __future__ import annotations

import heapq
import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from navkit.errors import ConfigError, InputError
from navkit.path.control import PathFollowerSettings, ReturnController
from navkit.path.detour import (
    DetourFailure,
    DetourSettings,
    clearance_map,
    grid_shortest_path,
    plan_detour,
    polyline_spline,
)
from navkit.sim.unicycle import unicycle_step

RES = 0.1
ORIGIN = np.array([-2.0, -5.0])
SHAPE = (100, 160)  # 10 m x 16 m
SQRT2 = np.sqrt(2.0)


def centres() -> tuple[np.ndarray, np.ndarray]:
    rr, cc = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]]
    return ORIGIN[0] + (cc + 0.5) * RES, ORIGIN[1] + (rr + 0.5) * RES


def straight_path(x0: float = 0.0, x1: float = 12.0) -> np.ndarray:
    return np.c_[np.linspace(x0, x1, 121), np.zeros(121)]


def disc(cx: float, cy: float, r: float) -> np.ndarray:
    X, Y = centres()
    return np.hypot(X - cx, Y - cy) <= r


def samples(P: np.ndarray, step: float = 0.01) -> np.ndarray:
    """Points every ``step`` metres along a polyline."""
    out = [P[:1]]
    for a, b in itertools.pairwise(P):
        n = max(int(np.ceil(np.hypot(*(b - a)) / step)), 1)
        out.append(a + np.linspace(0.0, 1.0, n + 1)[1:, None] * (b - a))
    return np.vstack(out)


def occupied_distance(occ: np.ndarray, P: np.ndarray) -> np.ndarray:
    X, Y = centres()
    return cKDTree(np.c_[X[occ], Y[occ]]).query(P)[0]


def length(P: np.ndarray) -> float:
    return float(np.hypot(*np.diff(P, axis=0).T).sum())


def reference_dijkstra(allowed: np.ndarray, start: tuple[int, int]) -> np.ndarray:
    """Brute-force 8-connected Dijkstra (no corner cutting), distances in cells."""
    H, W = allowed.shape
    dist = np.full((H, W), np.inf)
    dist[start] = 0.0
    heap = [(0.0, start)]
    steps = [(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1) if dr or dc]
    while heap:
        d, (r, c) = heapq.heappop(heap)
        if d > dist[r, c]:
            continue
        for dr, dc in steps:
            r2, c2 = r + dr, c + dc
            if not (0 <= r2 < H and 0 <= c2 < W and allowed[r2, c2]):
                continue
            if dr and dc and not (allowed[r + dr, c] and allowed[r, c + dc]):
                continue
            nd = d + (SQRT2 if dr and dc else 1.0)
            if nd < dist[r2, c2] - 1e-12:
                dist[r2, c2] = nd
                heapq.heappush(heap, (nd, (r2, c2)))
    return dist


def way_round_disc(a: np.ndarray, b: np.ndarray, c: np.ndarray, rho: float) -> float:
    """Shortest length from a to b round a disc (centre c, radius rho) that blocks the chord:
    tangent from a, arc, tangent to b."""
    da, db = np.hypot(*(a - c)), np.hypot(*(b - c))
    ua, ub = (a - c) / da, (b - c) / db
    angle = np.arccos(np.clip(ua @ ub, -1.0, 1.0))
    return float(
        np.sqrt(da**2 - rho**2)
        + np.sqrt(db**2 - rho**2)
        + rho * (angle - np.arccos(rho / da) - np.arccos(rho / db))
    )


def test_grid_dijkstra_matches_brute_force():
    rng = np.random.default_rng(3)
    allowed = rng.random((30, 40)) > 0.3
    allowed[5, 7] = True
    dist, pred = grid_shortest_path(allowed, (5, 7))
    ref = reference_dijkstra(allowed, (5, 7))
    assert np.array_equal(np.isinf(dist), np.isinf(ref))
    np.testing.assert_allclose(dist[np.isfinite(ref)], ref[np.isfinite(ref)], atol=1e-9)
    # the predecessor chain of a reachable cell has exactly that length
    goal = np.unravel_index(np.argmax(np.where(np.isfinite(ref), ref, -1)), ref.shape)
    chain = [int(goal[0] * 40 + goal[1])]
    while chain[-1] != 5 * 40 + 7:
        chain.append(int(pred[chain[-1]]))
    rc = np.c_[np.array(chain) // 40, np.array(chain) % 40]
    assert length(rc.astype(float)) == pytest.approx(ref[goal])
    assert allowed[rc[:, 0], rc[:, 1]].all()


def test_clearance_map_is_the_distance_to_the_nearest_occupied_centre():
    occ = disc(4.0, 0.0, 0.4) | disc(9.0, 2.0, 0.2)
    X, Y = centres()
    clear = clearance_map(occ, RES)
    brute = occupied_distance(occ, np.c_[X.ravel(), Y.ravel()]).reshape(SHAPE)
    np.testing.assert_allclose(clear, brute, atol=1e-9)
    assert np.isinf(clearance_map(np.zeros((3, 3), bool), RES)).all()


def test_detour_round_a_disc_is_free_and_near_the_optimum():
    R0 = 0.5
    occ = disc(5.0, 0.0, R0)
    cfg = DetourSettings(robot_radius=0.3, margin=0.1)
    start = np.array([1.0, 0.0])
    path = straight_path(1.0, 12.0)
    d = plan_detour(occ, RES, ORIGIN, start, path, cfg)
    r_inf = cfg.inflation
    # ends: at the robot, and on the stored path beyond the disc (the inflated disc ends at
    # x = 5 + R0 + r_inf; the rejoin is at least rejoin_offset further, within half a cell + one)
    np.testing.assert_allclose(d.points[0], start)
    assert abs(d.rejoin[1]) < 1e-9
    assert 5.0 + R0 + r_inf + cfg.rejoin_offset - RES <= d.rejoin[0] <= 5.0 + R0 + r_inf + 1.0
    # free: the grid path runs on cells whose centres keep the inflation radius from every
    # occupied centre (exact); the smoothed path's points lie in such cells, so they keep it up
    # to half a cell diagonal
    raw_cells = d.raw_points[1:-1]  # the grid path's cells (its ends are the robot and rejoin)
    assert occupied_distance(occ, raw_cells).min() >= r_inf - 1e-9
    clear = occupied_distance(occ, samples(d.points))
    assert clear.min() >= r_inf - 0.5 * SQRT2 * RES - 1e-9
    assert d.min_clearance >= r_inf - 0.5 * SQRT2 * RES - 1e-9
    # the reported clearance is the same distance on samples a quarter cell apart; the distance
    # is 1-Lipschitz, so each sampled minimum is within half its spacing of the true one
    assert clear.min() - 0.005 - 1e-9 <= d.min_clearance <= clear.min() + 0.125 * RES + 1e-9
    # it does not touch the true disc: robot radius kept from its outline, up to one cell
    assert (np.hypot(*(samples(d.points) - [5.0, 0.0]).T) - R0).min() >= cfg.robot_radius - RES
    # length against the 8-connected optimum (brute force on the same inflated grid): the grid
    # path is that optimum (plus the two end links, at most a half cell diagonal each), and
    # shortcutting only shortens it
    allowed = clearance_map(occ, RES) >= r_inf
    s_cell = tuple(np.floor((start - ORIGIN) / RES).astype(int)[::-1])
    g_cell = tuple(np.floor((d.rejoin - ORIGIN) / RES).astype(int)[::-1])
    L8 = reference_dijkstra(allowed, s_cell)[g_cell] * RES
    cell_centre = lambda rc: ORIGIN + (np.array(rc[::-1]) + 0.5) * RES  # noqa: E731
    grid_path = np.vstack([cell_centre(s_cell), raw_cells, cell_centre(g_cell)])
    assert abs(length(grid_path) - L8) < 1e-9
    assert d.length <= d.raw_length + 1e-9
    assert d.raw_length <= L8 + SQRT2 * RES + 1e-9
    # against the continuous optimum round the inflated disc: the free cells' boundary lies
    # within one cell of radius R0 + r_inf (occupied centres cover the disc to half a cell
    # diagonal; the free test is on cell centres), so no collision-free path can be shorter
    # than the way round radius R0 + r_inf - RES; and an 8-connected path is at most
    # 1 / cos(22.5 deg) = 1.0824 times a straight line, applied to the way round R0 + r_inf +
    # RES (its cells are all free), plus the two end cells
    c = np.array([5.0, 0.0])
    lo = way_round_disc(start, d.rejoin, c, R0 + r_inf - RES)
    hi = way_round_disc(start, d.rejoin, c, R0 + r_inf + RES)
    assert lo - 1e-9 <= d.length
    assert L8 <= 1.0824 * hi + 2 * SQRT2 * RES
    # the shortcut path is close to the continuous optimum: within the 8 % grid factor
    assert d.length <= 1.0824 * hi


def test_no_detour_when_a_wall_closes_the_corridor():
    X, Y = centres()
    corridor = (np.abs(np.abs(Y) - 1.1) < 0.06) & (X > -1.5)  # two walls along the path
    end = (np.abs(X + 1.5) < 0.06) & (np.abs(Y) <= 1.1)  # closed behind the operator
    across = (np.abs(X - 5.0) < 0.15) & (np.abs(Y) <= 1.1)  # a wall across the corridor
    occ = corridor | end | across
    path = straight_path(9.0, 0.0)  # the way home, from x = 9 towards the operator at 0
    exc = plan_detour(occ, RES, ORIGIN, [7.0, 0.0], path, DetourSettings(search_length=10.0))
    assert isinstance(exc, DetourFailure) and not exc.ok
    assert exc.reason == "no path to the rejoin"
    assert "no detour" in str(exc)
    # the same corridor with a box instead of the wall: the 2.2 m corridor leaves room
    box = (np.abs(X - 5.0) < 0.3) & (np.abs(Y) <= 0.3)
    d = plan_detour(corridor | end | box, RES, ORIGIN, [7.0, 0.0], path)
    assert d.rejoin[0] < 5.0 - 0.3 - 0.4
    assert occupied_distance(corridor | end | box, samples(d.points)).min() >= 0.4 - 0.071


def test_enclosed_rejoin_and_enclosed_start_fail():
    X, Y = centres()
    # everything beyond the block is enclosed by a ring: the path is reachable nowhere
    ring = np.abs(np.hypot(X - 9.0, Y) - 3.0) < 0.1
    occ = ring | disc(6.5, 0.0, 0.3)
    exc = plan_detour(occ, RES, ORIGIN, [1.0, 0.0], straight_path(1.0, 12.0))
    assert isinstance(exc, DetourFailure) and not exc.ok
    assert exc.reason == "no path to the rejoin"
    # the robot itself in a small ring
    small = np.abs(np.hypot(X - 1.0, Y) - 1.2) < 0.1
    exc = plan_detour(
        small | disc(5.0, 0.0, 0.4), RES, ORIGIN, [1.0, 0.0], straight_path(1.0, 12.0)
    )
    assert isinstance(exc, DetourFailure) and not exc.ok
    assert exc.reason in {"no path to the rejoin", "start enclosed"}
    # the path is clear: nothing to go round
    exc = plan_detour(disc(5.0, 3.0, 0.4), RES, ORIGIN, [1.0, 0.0], straight_path())
    assert isinstance(exc, DetourFailure) and not exc.ok
    assert exc.reason == "path not blocked"


def test_robot_standing_in_the_inflated_zone_escapes_it():
    occ = disc(5.0, 0.0, 0.5) | disc(1.0, 0.75, 0.2)  # a post 0.75 m beside the robot
    cfg = DetourSettings(robot_radius=0.3, margin=0.3)  # inflation 0.6 > 0.75 - 0.2
    start = np.array([1.0, 0.0])
    d = plan_detour(occ, RES, ORIGIN, start, straight_path(1.0, 12.0), cfg)
    clear = occupied_distance(occ, samples(d.points))
    # it never comes closer than the robot radius (the escape zone's floor), and it is out of
    # the inflated zone within the escape radius
    assert clear.min() >= cfg.robot_radius - 0.5 * SQRT2 * RES
    far = np.hypot(*(samples(d.points) - start).T) > cfg.escape_radius + RES
    assert clear[far].min() >= cfg.inflation - 0.5 * SQRT2 * RES


@settings(max_examples=25, deadline=None)
@given(
    cx=st.floats(3.0, 6.0),
    cy=st.floats(-0.4, 0.4),
    half=st.floats(0.2, 1.2),
    margin=st.floats(0.0, 0.3),
)
def test_any_detour_found_keeps_its_clearance(cx, cy, half, margin):
    X, Y = centres()
    occ = (np.abs(X - cx) <= half) & (np.abs(Y - cy) <= half)
    cfg = DetourSettings(robot_radius=0.3, margin=margin)
    d = plan_detour(occ, RES, ORIGIN, [0.0, 0.0], straight_path(), cfg)
    if isinstance(d, DetourFailure):
        exc = d
        # only possible when the box does not reach the path at all
        assert exc.reason == "path not blocked"
        # (clearances are measured between cell centres: up to a cell on each side)
        assert abs(cy) - half > cfg.robot_radius - 2 * RES
        return
    assert occupied_distance(occ, d.raw_points[1:-1]).min() >= cfg.inflation - 1e-9
    assert occupied_distance(occ, samples(d.points)).min() >= cfg.inflation - 0.5 * SQRT2 * RES
    assert d.length <= d.raw_length + 1e-9
    # the rejoin point is on the path, beyond the inflated box
    assert abs(d.rejoin[1]) < 1e-9 and d.rejoin[0] >= cx + half + cfg.inflation - RES


def test_return_controller_follows_a_polyline_spline():
    P = np.array([[0.0, 0.0], [2.0, 0.0], [3.0, 1.0], [5.0, 1.0]])
    spl = polyline_spline(P)
    assert spl.total_length == pytest.approx(length(P))
    np.testing.assert_allclose(spl.position(np.array([0.0, 2.0, 2.0 + SQRT2])), P[:3], atol=1e-12)
    # the controller drives from the end back to the start; noise-free, it stops inside the
    # stop radius and stays within the look-ahead of the polyline (corner cutting < delta)
    cfg = PathFollowerSettings(delta=0.3, stop_radius=0.1)
    ctrl = ReturnController(spl, cfg)
    pose = np.array([[5.0, 1.0, np.pi]])
    lateral = []
    for _ in range(600):
        cmd = ctrl.command(pose)
        if cmd.done[0]:
            break
        pose = unicycle_step(pose, cmd.v, cmd.omega, 0.1)
        lateral.append(spl.nearest(pose[:, :2])[1][0])
    assert cmd.done[0]
    assert np.hypot(*pose[0, :2]) <= cfg.stop_radius
    assert max(lateral) < cfg.delta


def test_bad_input_is_named():
    with pytest.raises(InputError, match="occupied"):
        plan_detour(np.zeros(5, bool), RES, ORIGIN, [0, 0], straight_path())
    with pytest.raises(InputError, match="path_xy"):
        plan_detour(np.zeros(SHAPE, bool), RES, ORIGIN, [0, 0], np.zeros((1, 2)))
    with pytest.raises(InputError, match="resolution"):
        plan_detour(np.zeros(SHAPE, bool), 0.0, ORIGIN, [0, 0], straight_path())
    with pytest.raises(ConfigError, match="robot_radius"):
        DetourSettings(robot_radius=0.0)
    with pytest.raises(InputError, match="points"):
        polyline_spline(np.zeros((3, 2)))
