"""The mission loop: out under remote control, map, localize, come back when the link is lost.

One control step every ``robot.dt`` (the VO's 10 Hz); each sensor reads at its own rate. The
stages of a step, in order (each uses the capabilities' public API):

1. drive: outbound, the scripted operator (:class:`~navkit.mission.driver.PurePursuit`) steers on
   the true pose; after "link lost", paper 4's :class:`~navkit.path.ReturnController` steers on
   the robot's corrected estimate; when the obstacle map shows the stored path blocked, the
   same controller follows a detour planned round the block (:mod:`navkit.path.detour`) and
   then resumes the stored path; with no detour the robot stops;
2. move the simulated robot (exact unicycle arcs) and read the visual odometry (the true body
   increment corrupted by :class:`~navkit.sensors.VisualOdometryNoise`'s error model);
3. dead-reckon the estimate with the VO increment;
4. lidar (2 Hz): paper 1's obstacle detection on the scan, fused into the global 2D obstacle map
   with the current estimate (:mod:`navkit.mission.obstacle_map`); in the room, wall points build
   the room map on the first visit and are localized against it afterwards (paper 3's
   correlation, :func:`navkit.localization.matcher.match_scan`) - a fix pulls the estimate;
5. RGB-D camera (1 Hz): paper 2's planes and the motion since the previous frame (geometry with
   >= 3 plane directions, texture with fewer); the plane increment and the VO increment over the
   same interval are blended (complementary filter) and the estimate corrected by the difference;
6. path memory (outbound, 10 Hz): paper 4's online spline approximator records the estimate.

Ground truth is kept throughout; :mod:`navkit.mission.metrics` scores the run.
"""

from __future__ import annotations

import logging
import time
from collections import defaultdict, deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from navkit.errors import ConfigError, InputError, NavkitError
from navkit.geometry import R_BODY_FROM_OPTICAL, se3_from_rt, se3_inverse, wrap_angle
from navkit.mission.driver import PurePursuit, polyline_arclength, polyline_point
from navkit.mission.settings import MissionSettings, Route
from navkit.obstacles.mapper import MapperSettings, ObstacleMapper, scan_points_2d

if TYPE_CHECKING:
    from navkit.localization.matcher import Fix
    from navkit.path.detour import DetourFailure

__all__ = ["Fix2D", "MissionLog", "PlaneStep", "run_mission"]

log = logging.getLogger(__name__)

OUTBOUND, RETURN = 0, 1
OBSTACLE_LABEL = -2
"""Paper 1's class m_t of obstacle triangles / vertices."""


@dataclass(frozen=True)
class PlaneStep:
    """One camera frame's plane-based motion (paper 2) and what the fusion did with it.

    Attributes
    ----------
    time : float
        Seconds.
    n_planes : int
        Planes extracted in the frame.
    case : int
        Independent plane directions used (3 = ">= 3"; 1-2 = texture fixed the rest; 0 = none).
    status : str
        ``"ok"``, ``"failed: ..."`` or ``"gated"`` (too far from the VO increment).
    plane_inc, vo_inc, true_inc : (3,) arrays
        Body-frame increments ``(dx, dy, dtheta)`` since the previous frame: from the planes
        (NaN when failed), from the VO, and the truth.
    """

    time: float
    n_planes: int
    case: int
    status: str
    plane_inc: NDArray[np.float64]
    vo_inc: NDArray[np.float64]
    true_inc: NDArray[np.float64]


@dataclass(frozen=True)
class Fix2D:
    """A room-map localization attempt (paper 3).

    Attributes
    ----------
    time : float
    pose : (3,) array
        Fix ``(x, y, theta)`` in the map frame (NaN if the matcher failed).
    score : float
    ok : bool
        The matcher's verdict (score and ambiguity).
    used : bool
        Accepted by the fusion (ok and within the gate).
    estimate_before, truth : (3,) arrays
    reason : str
        Why the matcher did not trust it (``""`` when ok; ``"elongated peak"``, ``"second
        peak"``, ``"low score"``).
    """

    time: float
    pose: NDArray[np.float64]
    score: float
    ok: bool
    used: bool
    estimate_before: NDArray[np.float64]
    truth: NDArray[np.float64]
    reason: str = ""


@dataclass
class MissionLog:
    """Everything a run recorded (arrays are per control step ``K``).

    Attributes
    ----------
    time, phase : (K,) arrays
        Seconds; 0 outbound, 1 return.
    truth, vo, estimate : (K, 3) arrays
        True pose, raw dead-reckoned VO, corrected estimate ``(x, y, theta)``.
    """

    settings: MissionSettings
    route: Route
    scene: Any
    time: NDArray[np.float64]
    phase: NDArray[np.int8]
    truth: NDArray[np.float64]
    vo: NDArray[np.float64]
    estimate: NDArray[np.float64]
    path: Any = None
    path_summary: dict[str, Any] = field(default_factory=dict)
    obstacle_grid: ObstacleMapper | None = None
    seen_primitives: set[int] = field(default_factory=set)
    plane_steps: list[PlaneStep] = field(default_factory=list)
    plane_points: list[NDArray[np.float64]] = field(default_factory=list)
    plane_normals: list[NDArray[np.float64]] = field(default_factory=list)
    room_map: Any = None
    room_views: list[tuple[NDArray[np.float64], NDArray[np.float64]]] = field(default_factory=list)
    fixes: list[Fix2D] = field(default_factory=list)
    map_fixes: list[Fix2D] = field(default_factory=list)
    link_lost_index: int = -1
    outcome: str = ""
    blocked: dict[str, Any] | None = None
    detours: list[dict[str, Any]] = field(default_factory=list)
    detour_paths: list[NDArray[np.float64]] = field(default_factory=list)
    dropped_obstacle: Any = None
    timings: dict[str, list[float]] = field(default_factory=lambda: defaultdict(list))


def _se2(p: NDArray[np.float64]) -> NDArray[np.float64]:
    c, s = np.cos(p[2]), np.sin(p[2])
    return np.array([[c, -s, p[0]], [s, c, p[1]], [0.0, 0.0, 1.0]])


def _xyt(T: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.array([T[0, 2], T[1, 2], np.arctan2(T[1, 0], T[0, 0])])


def relative(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Body-frame increment ``a^-1 b`` of two poses ``(3,)``."""
    return _xyt(np.linalg.inv(_se2(a)) @ _se2(b))


def compose(a: NDArray[np.float64], inc: NDArray[np.float64]) -> NDArray[np.float64]:
    """The pose ``a`` moved by the body-frame increment ``inc``."""
    out = _xyt(_se2(a) @ _se2(inc))
    out[2] = a[2] + inc[2]  # keep the heading continuous (no wrap)
    return out


def blend(a: NDArray[np.float64], b: NDArray[np.float64], w: float) -> NDArray[np.float64]:
    """``(1 - w) a + w b`` for poses, the heading difference wrapped."""
    out = a + w * (b - a)
    out[2] = a[2] + w * float(wrap_angle(b[2] - a[2]))
    return out


def take_fix(
    fx: Fix,
    est: NDArray[np.float64],
    truth: NDArray[np.float64],
    t: float,
    gate_m: float,
    weight: float,
    log: list[Fix2D],
) -> NDArray[np.float64]:
    """Log a correlation fix and blend it into the estimate when it is confident (``fx.ok``)
    and within ``gate_m`` of the estimate; returns the (possibly corrected) estimate."""
    used = bool(fx.ok and float(np.hypot(*(fx.pose[:2] - est[:2]))) <= gate_m)
    reason = fx.ambiguity.reason if fx.ambiguity.ambiguous else ("" if fx.ok else "low score")
    log.append(
        Fix2D(
            t, fx.pose.copy(), float(fx.score), bool(fx.ok), used, est.copy(), truth.copy(), reason
        )
    )
    return blend(est, fx.pose, weight) if used else est


def _pose3(p: NDArray[np.float64], z: float) -> NDArray[np.float64]:
    c, s = np.cos(p[2]), np.sin(p[2])
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return se3_from_rt(R, np.array([p[0], p[1], z]))


def _T_body_camera(height: float, pitch_down_deg: float) -> NDArray[np.float64]:
    p = np.radians(pitch_down_deg)
    cp, sp = np.cos(p), np.sin(p)
    Ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])  # +pitch about y tips x down
    return se3_from_rt(Ry @ R_BODY_FROM_OPTICAL, np.array([0.0, 0.0, height]))


def _inc_se3(inc: NDArray[np.float64]) -> NDArray[np.float64]:
    return _pose3(inc, 0.0)


def _inc_from_se3(T: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.array([T[0, 3], T[1, 3], np.arctan2(T[1, 0], T[0, 0])])


class _Timer:
    def __init__(self, store: dict[str, list[float]], key: str) -> None:
        self.store, self.key = store, key

    def __enter__(self) -> _Timer:
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        self.store[self.key].append(time.perf_counter() - self.t0)


def _drop_obstacle(scene: Any, route: Route, truth_xy: NDArray[np.float64]) -> tuple[Any, Any]:
    """The scene with a box dropped on the outbound trajectory at ``route.block_at`` metres."""
    from navkit.sim import Box, Texture

    cum = polyline_arclength(truth_xy)
    s = min(float(route.block_at or 0.0), float(cum[-1]) - 0.5)
    if s <= 0.5:
        raise ConfigError(
            f"is {route.block_at} on a {cum[-1]:.1f} m route",
            field="route.block_at",
            expected="an arc length inside the outbound route",
        )
    p = polyline_point(truth_xy, s)
    q = polyline_point(truth_xy, s + 0.3)
    yaw = float(np.arctan2(*(q - p)[::-1]))
    size = route.block_size
    g = float(scene.ground_height(p[0], p[1]))
    box = Box(
        center=(float(p[0]), float(p[1]), g + 0.5 * size[2]),
        size=size,
        yaw=yaw,
        name="dropped_obstacle",
        texture=Texture("checker", scale=0.2, seed=3),
    )
    return scene.with_primitives([box]), box


def run_mission(
    scene: Any,
    route: Route,
    settings: MissionSettings | None = None,
    progress: Callable[[Iterator[int], str, int], Iterator[int]] | None = None,
) -> MissionLog:
    """Run the integrated mission in a simulated ``scene`` along ``route``.

    Parameters
    ----------
    scene : navkit.sim.Scene
        The world (e.g. ``navkit.sim.load_scene("yard")``).
    route : Route
        The operator's waypoints, the room, and optionally an obstacle dropped on the way back.
    settings : MissionSettings, optional
    progress : callable, optional
        ``progress(iterable, description, total)`` wrapping the step loop (a progress bar).

    Returns
    -------
    MissionLog
        Trajectories, maps, fixes, timings; score it with :func:`navkit.mission.metrics.mission_metrics`.
    """
    from navkit.localization.field import LikelihoodField
    from navkit.localization.matcher import MatcherSettings, match_scan
    from navkit.obstacles.detector import detect_obstacles
    from navkit.path import ApproximatorSettings, OnlineApproximator
    from navkit.path.control import ReturnController, ReturnSettings
    from navkit.planes import MotionPrior, estimate_motion, observe_rgbd
    from navkit.planes.solve import MotionEstimate
    from navkit.sensors import PinholeCamera, StereoRig, VisualOdometryNoise
    from navkit.sim import (
        RangeNoise,
        SpinningLidar,
        render_rgbd,
        render_scan,
        render_stereo,
        unicycle_step,
    )
    from navkit.stereo import FloorplanSettings, stereo_wall_points

    s = settings or MissionSettings()
    rng = np.random.default_rng(s.seed)
    R = s.robot
    dt = R.dt
    start = np.array(scene.start, dtype=np.float64)
    W = np.asarray(route.waypoints)
    if np.hypot(*(W[0] - start[:2])) > 0.5:
        W = np.vstack([start[:2], W])
    driver = PurePursuit(W, R.v_max, R.omega_max, R.lookahead, R.goal_tolerance)
    vo_model = VisualOdometryNoise(
        rate_hz=1.0 / dt,
        scale_bias=s.vo.scale_bias,
        scale_sigma=s.vo.scale_sigma,
        heading_bias_per_m=np.radians(s.vo.heading_bias_deg_per_m),
        heading_sigma=np.radians(s.vo.heading_sigma_deg),
    )
    L, C, F = s.lidar, s.camera, s.fusion
    lidar = SpinningLidar(
        n_beams=L.n_beams,
        n_columns=L.n_columns,
        elevation_min_deg=L.elevation_min_deg,
        elevation_max_deg=L.elevation_max_deg,
    )
    lidar_noise = RangeNoise(L.relative_sigma, L.absolute_sigma, L.dropout)
    camera = PinholeCamera.from_fov(C.width_px, C.height_px, C.hfov_deg)
    T_bc = _T_body_camera(C.height, C.pitch_down_deg)
    T_cb = se3_inverse(T_bc)
    every_lidar, every_cam = s.every(L.rate_hz), s.every(C.rate_hz)

    lo, hi = scene.bounds()
    pts = np.vstack([lo[:2], hi[:2], W, start[None, :2]])
    M = s.obstacle_map
    grid = ObstacleMapper(
        pts.min(0) - M.margin,
        pts.max(0) + M.margin,
        MapperSettings(M.resolution, M.min_hits, M.min_ratio, M.recent_scans, M.max_range),
    )
    recorder = OnlineApproximator(ApproximatorSettings(tolerance=s.path_tolerance))

    lg = MissionLog(
        settings=s,
        route=route,
        scene=scene,
        time=np.zeros(0),
        phase=np.zeros(0, np.int8),
        truth=np.zeros((0, 3)),
        vo=np.zeros((0, 3)),
        estimate=np.zeros((0, 3)),
    )
    lg.obstacle_grid = grid
    T_: dict[str, list[float]] = lg.timings

    truth, vo, est = start.copy(), start.copy(), start.copy()
    rows_t: list[float] = [0.0]
    rows_p: list[int] = [OUTBOUND]
    rows_truth, rows_vo, rows_est = [truth.copy()], [vo.copy()], [est.copy()]
    with _Timer(T_, "path_record"):
        recorder.add(est[:2])
    phase = OUTBOUND
    controller: Any = None
    room = _Room(lg, route, F, MatcherSettings(linear_window=F.fix_gate_m, angular_window_deg=10.0))
    S = s.stereo
    rig = StereoRig(PinholeCamera.from_fov(S.width_px, S.height_px, S.hfov_deg), S.baseline)
    T_b_stereo = _T_body_camera(S.height, 0.0)
    n_stereo = 0
    floorplan = FloorplanSettings(
        min_height=F.wall_z_min, max_height=F.wall_z_max, max_depth=F.room_view_range
    )
    cam_prev: Any = None  # (observation, vo pose, truth pose)
    blocked_since: float | None = None
    return_field: Any = None  # the outbound obstacle map as a likelihood field
    map_matcher = MatcherSettings(
        linear_window=F.map_fix_gate_m, angular_window_deg=8.0, point_spacing=0.2
    )
    n_stops = 0  # times the return stopped for an obstacle ahead (a stop may clear again)
    round_: _Detouring | None = None  # the detour being followed (round a blocked stretch)
    no_detour = ""  # why the last detour planning failed
    n_max = int(np.ceil(2 * s.max_time / dt))

    steps: Iterator[int] = iter(range(1, n_max + 1))
    if progress is not None:
        # expected length: the route out and back at 80 % of the cruise speed (the bar is a
        # guide; the loop ends when the robot is home, blocked or out of time)
        expected = 2.0 * driver.length / (0.8 * R.v_max) / dt
        steps = progress(steps, "mission", int(min(n_max, max(expected, 1.0))))
    t = 0.0
    t_phase = 0.0
    for k in steps:
        t = k * dt
        # --- 1. drive -------------------------------------------------------------------------
        if phase == OUTBOUND:
            v, om = driver.command(truth)
            if driver.done(truth) or t - t_phase > s.max_time:
                # link lost: freeze the path memory, start the return
                phase, t_phase = RETURN, t
                lg.link_lost_index = len(rows_t) - 1
                with _Timer(T_, "path_finish"):
                    result = recorder.finish()
                lg.path = result.spline
                lg.path_summary = result.summary()
                if lg.path.n_segments == 0:
                    raise InputError(
                        "the outbound route produced no stored path",
                        field="route.waypoints",
                        expected="a route of at least a few metres",
                    )
                controller = ReturnController(
                    lg.path,
                    ReturnSettings(
                        delta=s.return_delta,
                        v_max=s.return_v_max,
                        stop_radius=s.return_stop_radius,
                        approach_radius=max(2 * s.return_stop_radius, 0.3),
                        omega_max=R.omega_max,
                    ),
                )
                grid.freeze_known(s.block.known_margin)
                if F.map_fix_weight > 0:
                    rows_o, cols_o = np.nonzero(grid.occupied)
                    if len(rows_o) >= 10:
                        with _Timer(T_, "obstacle_map_field"):
                            return_field = LikelihoodField.from_points(
                                grid.centres(rows_o, cols_o), resolution=M.resolution, sigma=0.15
                            )
                if route.block_at is not None:
                    scene, lg.dropped_obstacle = _drop_obstacle(
                        scene, route, np.array(rows_truth)[:, :2]
                    )
                    lg.scene = scene
                log.info(
                    "link lost at t = %.1f s; stored path %.1f m in %d segments",
                    t,
                    lg.path.total_length,
                    lg.path.n_segments,
                )
        if phase == RETURN:
            with _Timer(T_, "return_control"):
                if round_ is not None and round_.done(est):
                    # round the block: resume the stored path at the rejoin point
                    controller.progress[:] = round_.s_rejoin
                    lg.detours[-1]["completed_time"] = t
                    log.info("detour done at t = %.1f s; back on the stored path", t)
                    round_ = None
                if round_ is not None:
                    cmd = round_.controller.command(est[None, :])
                    home = False
                else:
                    cmd = controller.command(est[None, :])
                    home = bool(cmd.done[0])
            v, om = float(cmd.v[0]), float(cmd.omega[0])
            if lg.blocked is not None and lg.blocked.get("active"):
                v, om = 0.0, 0.0
            if home:
                lg.outcome = "returned"
                break
            if t - t_phase > s.max_time:
                lg.outcome = "timeout"
                break
            if blocked_since is not None and t - blocked_since >= s.block.wait:
                lg.outcome = "blocked"
                if lg.blocked is not None:
                    lg.blocked["detour"] = no_detour or "detours disabled"
                break
        # --- 2. move, read the VO -------------------------------------------------------------
        new_truth = unicycle_step(truth, v, om, dt)
        inc_true = relative(truth, new_truth)
        dist = float(np.hypot(inc_true[0], inc_true[1]))
        moving = dist > 0 or inc_true[2] != 0
        scale = 1.0 + vo_model.scale_bias + vo_model.scale_sigma * rng.standard_normal()
        dth = inc_true[2] + (
            vo_model.heading_bias_per_m * dist + vo_model.heading_sigma * rng.standard_normal()
            if moving
            else 0.0
        )
        inc_vo = np.array([inc_true[0] * scale, inc_true[1] * scale, dth])
        truth = new_truth
        vo = compose(vo, inc_vo)
        # --- 3. dead-reckon the estimate ------------------------------------------------------
        est = compose(est, inc_vo)
        # --- 4. lidar -------------------------------------------------------------------------
        if k % every_lidar == 0:
            gz = float(scene.ground_height(truth[0], truth[1]))
            with _Timer(T_, "sim_lidar"):
                sim = render_scan(
                    scene, lidar, _pose3(truth, gz + L.height), lidar_noise, rng, L.max_range, t
                )
            # truth: which primitives the lidar hit within the fusion range (recall counts these)
            in_range = sim.scan.valid & (sim.true_ranges <= M.max_range)
            lg.seen_primitives.update(np.unique(sim.hit_index[in_range]).tolist())
            with _Timer(T_, "obstacles_detect"):
                det = detect_obstacles(sim.scan)
            # on the way back: correlation fix of this scan's obstacles in the outbound obstacle
            # map (paper 3's matching, on the map the stored path was recorded with)
            if phase == RETURN and return_field is not None and k % every_cam == 0:
                body, _ = scan_points_2d(det, np.eye(3), M.max_range)
                if len(body) >= F.map_fix_min_points:
                    with _Timer(T_, "localize_obstacle_map"):
                        fx = match_scan(return_field, body, prior=est, settings=map_matcher)
                    est = take_fix(
                        fx, est, truth, t, F.map_fix_gate_m, F.map_fix_weight, lg.map_fixes
                    )
            with _Timer(T_, "obstacles_fuse"):
                grid.add_scan(det, _se2(est))
            # the room (laser variant): map on the first visit, localization later
            if F.room_sensor == "lidar":
                B = sim.scan.points("body")[sim.scan.valid]
                z_ok = (B[:, 2] >= F.wall_z_min) & (B[:, 2] <= F.wall_z_max)
                r_ok = np.hypot(B[:, 0], B[:, 1]) <= F.room_view_range
                est = room.step(B[z_ok & r_ok][:, :2], est, truth, t, phase, k % every_cam == 0)
            # the way back: is the way ahead blocked? (the detour being followed, or the
            # stored path) -> plan a way round it on the obstacle map, or stop
            if phase == RETURN and lg.path is not None:
                half_width = 0.5 * R.width + s.block.clearance
                with _Timer(T_, "block_check"):
                    if round_ is not None:
                        ahead, s_now = round_.ahead(est, s.block.lookahead), round_.s_from
                    else:
                        s_now = float(controller.progress[0])
                        ss = np.linspace(s_now, max(s_now - s.block.lookahead, 0.0), 21)
                        ahead = lg.path.position(ss)
                    hit = grid.blocked(ahead, half_width)
                if round_ is not None and s.block.detour:
                    # replan on every scan while going round: the far side of the obstacle
                    # comes into view as the robot turns
                    with _Timer(T_, "detour_plan"):
                        new_det = _plan_round(
                            grid, est, lg.path, round_.s_from, round_.block_dist, s, half_width
                        )
                    if isinstance(new_det, _Detouring):
                        round_ = new_det
                        # the first plan stays in the log (the figure draws it); the rejoin
                        # point may move as more of the obstacle is seen
                        lg.detours[-1]["replans"] += 1
                        lg.detours[-1]["rejoin_xy"] = round_.detour.rejoin.tolist()
                        lg.detours[-1]["rejoin_s_m"] = round_.s_rejoin
                        hit = np.zeros(1, dtype=bool)
                    elif hit.any():
                        no_detour = str(new_det)
                if hit.any() and round_ is None and s.block.detour:
                    j = int(np.argmax(hit))
                    with _Timer(T_, "detour_plan"):
                        new_det = _plan_round(
                            grid, est, lg.path, s_now, s_now - float(ss[j]), s, half_width
                        )
                    if isinstance(new_det, _Detouring):
                        round_ = new_det
                        lg.detours.append(
                            {
                                "time": t,
                                "start_xy": est[:2].tolist(),
                                "start_true_xy": truth[:2].tolist(),
                                "blocked_path_point_xy": ahead[j].tolist(),
                                "distance_ahead_m": float(s_now - ss[j]),
                                "length_m": round_.detour.length,
                                "min_clearance_m": round_.detour.min_clearance,
                                "rejoin_xy": round_.detour.rejoin.tolist(),
                                "rejoin_s_m": round_.s_rejoin,
                                "replans": 0,
                                "completed_time": None,
                            }
                        )
                        lg.detour_paths.append(round_.detour.points)
                        log.info(
                            "return blocked %.2f m ahead at t = %.1f s: going round (%.1f m)",
                            s_now - ss[j],
                            t,
                            round_.detour.length,
                        )
                        hit = np.zeros(1, dtype=bool)
                        blocked_since = None
                        if lg.blocked is not None:
                            lg.blocked["active"] = False
                    else:
                        no_detour = str(new_det)
                if hit.any():
                    j = int(np.argmax(hit))
                    d_ahead = (
                        float(np.hypot(*np.diff(ahead[: j + 1], axis=0).T).sum())
                        if round_ is not None
                        else abs(float(ss[j]) - s_now)
                    )
                    if blocked_since is None:
                        blocked_since = t
                        n_stops += 1
                        log.warning(
                            "return blocked %.2f m ahead at t = %.1f s: stopping (%s)",
                            d_ahead,
                            t,
                            no_detour or "detours disabled",
                        )
                    lg.blocked = {
                        "active": True,
                        "stops": n_stops,
                        "time": blocked_since,
                        "s": s_now,
                        "distance_ahead_m": d_ahead,
                        "blocked_path_point_xy": ahead[j].tolist(),
                        "robot_true": truth.tolist(),
                        "detour": no_detour or "detours disabled",
                    }
                elif blocked_since is not None:
                    blocked_since = None
                    if lg.blocked is not None:
                        lg.blocked["active"] = False
        # --- 5. camera: plane-based motion ----------------------------------------------------
        if k % every_cam == 0:
            gz = float(scene.ground_height(truth[0], truth[1]))
            T_wc = _pose3(truth, gz) @ T_bc
            with _Timer(T_, "sim_camera"):
                frame = render_rgbd(
                    scene,
                    camera,
                    T_wc,
                    RangeNoise(C.depth_relative_sigma),
                    rng,
                    timestamp=t,
                    max_depth=C.max_depth,
                )
            with _Timer(T_, "planes_extract"):
                obs = observe_rgbd(frame.frame)
            if cam_prev is not None:
                obs0, vo0, truth0 = cam_prev
                vo_int = relative(vo0, vo)
                true_int = relative(truth0, truth)
                # T_c1_c2 predicted by the VO, with the fusion gate as its 3-sigma bound: it gates
                # the association, starts the texture search and fills what the planes cannot fix
                prior = MotionPrior(
                    T_cb @ _inc_se3(vo_int) @ T_bc, F.gate_deg / 3.0, F.gate_m / 3.0
                )
                with _Timer(T_, "planes_motion"):
                    try:
                        mot = estimate_motion(obs0, obs, prior)
                    except NavkitError as exc:
                        log.debug("plane motion failed: %s", exc)
                        mot = None
                if isinstance(mot, MotionEstimate):
                    pinc = _inc_from_se3(T_bc @ mot.T @ T_cb)
                    diff = pinc - vo_int
                    ok_gate = np.hypot(diff[0], diff[1]) <= F.gate_m and abs(
                        float(wrap_angle(diff[2]))
                    ) <= np.radians(F.gate_deg)
                    if ok_gate:
                        geo = mot.case >= 3
                        w_xy = F.weight_xy_geometry if geo else F.weight_xy_texture
                        w_th = F.weight_heading_geometry if geo else F.weight_heading_texture
                        fused = vo_int + np.array([w_xy, w_xy, w_th]) * diff
                        est = compose(est, relative(vo_int, fused))
                        status = "ok"
                    else:
                        status = "gated"
                    case = int(mot.case)
                else:
                    pinc = np.full(3, np.nan)
                    status = f"failed: {getattr(mot, 'reason', 'exception')}"
                    case = int(getattr(mot, "case", 0))
                lg.plane_steps.append(
                    PlaneStep(t, len(obs.segments), case, status, pinc, vo_int, true_int)
                )
            # plane map: the frame's large planes, moved to the map with the corrected estimate
            if phase == OUTBOUND:
                _add_plane_map(lg, obs, _pose3(est, gz) @ T_bc)
            cam_prev = (obs, vo.copy(), truth.copy())
            # the room (stereo variant, paper 3): a level stereo pair on a pan drive; the drive's
            # angle sensor gives the pan, so the wall points are turned into the body frame
            if F.room_sensor == "stereo" and (route.in_room(est[:2]) or room.views_pending):
                pan = np.radians(S.pan_deg[n_stereo % len(S.pan_deg)])
                n_stereo += 1
                T_ws = _pose3(truth, gz) @ _pose3(np.array([0.0, 0.0, pan]), 0.0) @ T_b_stereo
                with _Timer(T_, "sim_stereo"):
                    pair = render_stereo(
                        scene,
                        rig,
                        T_ws,
                        rng,
                        pixel_noise=S.pixel_noise,
                        supersample=S.supersample,
                        timestamp=t,
                    ).pair
                with _Timer(T_, "stereo_points"):
                    wall2d = stereo_wall_points(
                        pair.left, pair.right, rig, camera_height=S.height, settings=floorplan
                    )
                cp_, sp_ = np.cos(pan), np.sin(pan)
                wall2d = wall2d @ np.array([[cp_, sp_], [-sp_, cp_]])
                est = room.step(wall2d, est, truth, t, phase, True)
        # --- 6. path memory -------------------------------------------------------------------
        if phase == OUTBOUND:
            with _Timer(T_, "path_record"):
                recorder.add(est[:2])
        rows_t.append(t)
        rows_p.append(phase)
        rows_truth.append(truth.copy())
        rows_vo.append(vo.copy())
        rows_est.append(est.copy())
    else:
        lg.outcome = lg.outcome or "timeout"
    if phase == OUTBOUND:
        lg.outcome = "link never lost (route not finished)"
    room.finish()
    lg.time = np.array(rows_t)
    lg.phase = np.array(rows_p, dtype=np.int8)
    lg.truth, lg.vo, lg.estimate = np.array(rows_truth), np.array(rows_vo), np.array(rows_est)
    if lg.blocked is not None:
        lg.blocked["active"] = lg.outcome == "blocked"
    log.info("mission %s after %.1f s simulated", lg.outcome, t)
    return lg


@dataclass
class _Detouring:
    """A detour being followed: paper 4's return controller on the detour polyline (its start
    is the rejoin point), then the stored path resumed at arc length ``s_rejoin``."""

    detour: Any  # navkit.path.detour.Detour
    controller: Any  # ReturnController on the reversed detour
    s_from: float  # stored-path arc length where the searched stretch starts
    block_dist: float  # the blocked point, metres along the stored path from s_from
    s_rejoin: float
    stop_radius: float
    ok = True

    def done(self, est: NDArray[np.float64]) -> bool:
        """The estimate is within the stop radius of the rejoin point."""
        return bool(np.hypot(*(est[:2] - self.detour.rejoin)) <= self.stop_radius)

    def ahead(self, est: NDArray[np.float64], length: float) -> NDArray[np.float64]:
        """``(21, 2)`` points of the detour still ahead, up to ``length`` metres."""
        p = float(self.controller.progress[0])
        return np.asarray(self.controller.path.position(np.linspace(p, max(p - length, 0.0), 21)))


def _plan_round(
    grid: ObstacleMapper,
    est: NDArray[np.float64],
    path: Any,
    s_from: float,
    block_dist: float | None,
    s: MissionSettings,
    half_width: float,
) -> _Detouring | DetourFailure:
    """Plan a way round the block on the obstacle map (:func:`navkit.path.detour.plan_detour`):
    the confirmed cells and those of the recent scans, inflated by the corridor half-width plus
    ``block.detour_margin``; the stored path from arc length ``s_from`` towards home is searched
    for the rejoin point. Returns the detour to follow, or the planner's
    :class:`~navkit.path.detour.DetourFailure`."""
    from navkit.path.control import ReturnController, ReturnSettings
    from navkit.path.detour import DetourFailure, DetourSettings, plan_detour, polyline_spline

    B = s.block
    step = 0.5 * grid.resolution
    s_to = max(s_from - B.detour_search, 0.0)
    if s_from - s_to < step:
        return DetourFailure("no free path point beyond the block", "the block is at home")
    ss = np.linspace(s_from, s_to, int(np.ceil((s_from - s_to) / step)) + 1)
    bi = None if block_dist is None else int(np.clip(round(block_dist / step), 0, len(ss) - 1))
    settings = DetourSettings(
        robot_radius=half_width,
        margin=B.detour_margin,
        search_length=B.detour_search,
        rejoin_offset=0.5,
    )
    d = plan_detour(
        grid.occupied | grid.recent_occupied,
        grid.resolution,
        grid.origin,
        est[:2],
        path.position(ss),
        settings,
        block_index=bi,
    )
    if isinstance(d, DetourFailure):
        log.info("%s", d)
        return d
    stop = s.return_stop_radius
    ctrl = ReturnController(
        polyline_spline(d.points[::-1]),
        ReturnSettings(
            delta=0.4,
            v_max=s.return_v_max,
            stop_radius=stop,
            approach_radius=stop,
            omega_max=s.robot.omega_max,
        ),
    )
    return _Detouring(
        detour=d,
        controller=ctrl,
        s_from=s_from,
        block_dist=float(ss[0] - ss[bi]) if bi is not None else float("nan"),
        s_rejoin=float(s_from - d.rejoin_arclength),
        stop_radius=stop,
    )


def _add_plane_map(
    lg: MissionLog,
    obs: Any,
    T_world_cam: NDArray[np.float64],
    min_points: int = 2000,
    keep: int = 300,
    max_depth: float = 10.0,
) -> None:
    """Store a sample of each large plane's points (map frame, within ``max_depth`` metres of the
    camera, where the depth noise stays centimetric) and its normal."""
    P = obs.points.reshape(-1, 3)
    R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]
    for seg in obs.segments:
        if seg.plane.count < min_points:
            continue
        inl = seg.inliers[P[seg.inliers, 2] <= max_depth]
        if len(inl) == 0:
            continue
        idx = inl[:: max(1, len(inl) // keep)]
        lg.plane_points.append(P[idx] @ R.T + t)
        lg.plane_normals.append(R @ seg.normal)


class _Room:
    """Paper 3 in the mission: the room map on the first visit, correlation fixes afterwards.

    Views (2D wall points in the robot frame, with the pose estimate) are collected while the
    robot is in the room on its way out, up to ``room_map_views``; the map is built from them
    (wall segments, corners: :func:`navkit.localization.mapping.build_map`) when enough views
    are in, when the robot leaves the room, or when the link is lost. Every later view is
    located in that map by correlative matching around the estimate
    (:func:`navkit.localization.matcher.match_scan`); a fix that the matcher trusts (score,
    no ambiguity) and that lies within ``fix_gate_m`` of the estimate pulls the estimate.
    """

    def __init__(self, lg: MissionLog, route: Route, fusion: Any, matcher: Any) -> None:
        self.lg, self.route, self.F, self.matcher = lg, route, fusion, matcher
        self.field: Any = None
        self.done = False
        self.recent: deque[tuple[NDArray[np.float64], NDArray[np.float64]]] = deque(
            maxlen=fusion.fragment_views
        )

    @property
    def views_pending(self) -> bool:
        """Views are collected but the map is not built yet."""
        return bool(self.lg.room_views) and not self.done

    def step(
        self,
        wall2d: NDArray[np.float64],
        est: NDArray[np.float64],
        truth: NDArray[np.float64],
        t: float,
        phase: int,
        may_fix: bool,
    ) -> NDArray[np.float64]:
        """Use one view; returns the (possibly corrected) estimate."""
        from navkit.localization.matcher import match_scan

        lg, F = self.lg, self.F
        inside = self.route.in_room(est[:2])
        if not self.done:
            if inside and phase == OUTBOUND and len(lg.room_views) < F.room_map_views:
                if len(wall2d) >= 10:
                    lg.room_views.append((wall2d, est.copy()))
                return est
            if lg.room_views:
                self.finish()
            return est
        # the fragment: this view and the previous ones, brought into the current frame with the
        # estimate's own relative motion (accurate over a few seconds) - a wider fragment than one
        # 80 deg view, so fewer fixes are ambiguous along a single wall
        self.recent.append((wall2d, est.copy()))
        if self.field is None or not inside or not may_fix:
            return est
        frag = np.vstack(
            [v @ _se2(relative(est, p))[:2, :2].T + relative(est, p)[:2] for v, p in self.recent]
        )
        if len(frag) < 20:
            return est
        with _Timer(lg.timings, "localize"):
            fx = match_scan(self.field, frag, prior=est, settings=self.matcher)
        return take_fix(fx, est, truth, t, F.fix_gate_m, F.fix_weight, lg.fixes)

    def finish(self) -> None:
        """Build the map from the views collected (once)."""
        if self.done or not self.lg.room_views:
            return
        self.done = True
        with _Timer(self.lg.timings, "room_map"):
            self.field = _build_room_field(self.lg)


def _build_room_field(lg: MissionLog) -> Any:
    """Room wall map from the first-visit views (paper 3) and its likelihood field."""
    from navkit.localization.field import LikelihoodField
    from navkit.localization.mapping import MapSettings, build_map, sample_segments

    views = [v for v, _ in lg.room_views]
    poses = np.array([p for _, p in lg.room_views]).reshape(-1, 3)
    try:
        # stereo wall points scatter by their depth error (the floor-plan front end keeps it
        # below 0.25 m): walls closer than that are one wall
        wm = build_map(
            views, poses, MapSettings(merge_distance=0.25, merge_angle_deg=8.0), ordered=False
        )
    except NavkitError as exc:
        log.warning("room map failed: %s", exc)
        wm = None
    lg.room_map = wm
    if wm is not None and len(wm.walls) >= 2:
        pts = sample_segments(wm.walls, 0.05)
    else:
        pts = np.vstack([v @ _se2(p)[:2, :2].T + p[:2] for v, p in zip(views, poses, strict=True)])
    return LikelihoodField.from_points(pts, resolution=0.05, sigma=0.1)
