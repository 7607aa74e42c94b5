"""The mission as a composer: out under remote control, map, localize, come back when the link is lost.

:class:`Mission` holds the simulated robot (:class:`~navkit.mission.robot.SimRobot`, the truth)
and one online object per capability; :meth:`Mission.step` is one control step every
``robot.dt`` (the VO's 10 Hz), each sensor read at its own rate:

1. drive: outbound, the scripted operator (:class:`~navkit.mission.driver.PurePursuit`) steers on
   the true pose; after "link lost", paper 4's :class:`navkit.path.Return` steers on the
   corrected estimate (round a blocked stretch when the obstacle map shows one, or stops);
2. move the simulated robot and read the visual odometry;
3. dead-reckon the estimate with the VO increment;
4. lidar (2 Hz): paper 1's :class:`navkit.obstacles.ObstacleMapper` fuses the scan's obstacles
   with the current estimate; paper 3 (:class:`~navkit.mission.localize.MissionLocalizer`)
   localizes in the room map or, on the way back, in the outbound obstacle map; the
   :class:`~navkit.path.Return` checks the way ahead on the map;
5. RGB-D camera (1 Hz): paper 2's plane motion corrects the estimate
   (:class:`~navkit.mission.plane_fusion.PlaneMotionFusion`); in the room, the stereo rig's wall
   points go to the localizer;
6. path memory (outbound): paper 4's :class:`navkit.path.OnlineApproximator` records the estimate.

Ground truth is kept throughout; :mod:`navkit.mission.metrics` scores the run.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from navkit.errors import ConfigError, InputError
from navkit.geometry import se2_from_xytheta
from navkit.mission.driver import PurePursuit, polyline_arclength, polyline_point
from navkit.mission.localize import Fix2D, MissionLocalizer, RoomRecord
from navkit.mission.plane_fusion import PlaneMotionFusion, PlaneRecord, PlaneStep
from navkit.mission.pose2d import compose
from navkit.mission.robot import SimRobot
from navkit.mission.settings import MissionSettings, Route
from navkit.obstacles import ObstacleSettings, detect_obstacles
from navkit.obstacles.mapper import ObstacleMapper, ObstacleMapperSettings, scan_points_2d
from navkit.path import (
    ApproximatorSettings,
    OnlineApproximator,
    PathUpdate,
    Return,
    ReturnFailure,
    ReturnStep,
    WayAhead,
    WayBlocked,
)
from navkit.path.control import PathFollowerSettings
from navkit.path.returning import ReturnTripSettings
from navkit.timing import Timings, new_timings, timed

__all__ = [
    "Fix2D",
    "Mission",
    "MissionLog",
    "PlaneStep",
    "StepRecord",
    "StepSink",
    "run_mission",
]

log = logging.getLogger(__name__)

OUTBOUND, RETURN = 0, 1


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
    timings: Timings = field(default_factory=new_timings)


@dataclass(frozen=True, eq=False)
class StepRecord:
    """What one control step produced, capability by capability (:attr:`Mission.last_step`).

    The mission's output stream: :func:`navkit.runtime.mission_sink` turns these records into
    the same ``results.mcap`` / Rerun outputs as ``navkit run`` (the mission never imports the
    runtime, io or viz layers for this; the CLI joins them). Arrays are copies; ``mapper`` and
    ``path`` are the live online objects (read them during the callback, not later).

    Attributes
    ----------
    k : int
        Control step (0 = the start pose).
    time : float
        Simulated seconds.
    phase : int
        0 outbound, 1 return.
    truth, vo, estimate : (3,) arrays
        True pose, dead-reckoned VO and corrected estimate ``(x, y, theta)`` after the step.
    detection : ObstacleDetection or None
        Paper 1 on this step's lidar scan (level body frame), None without a scan.
    scan_pose : (3,) array or None
        The estimate the detection was fused into the obstacle map with.
    mapper : ObstacleMapper or None
        The obstacle map after the scan was fused (lidar steps only).
    fixes : tuple of Fix2D
        Paper 3's localization attempts of this step (room and map fixes).
    plane_step : PlaneStep or None
        Paper 2's plane motion of this step's RGB-D frame.
    path : CubicSpline-like or None
        Paper 4's stored spline when a point was accepted this step (outbound), or the final
        stored path on the step the link was lost.
    link_lost : bool
        The link was lost on this step (the stored path is final, the return starts).
    """

    k: int
    time: float
    phase: int
    truth: NDArray[np.float64]
    vo: NDArray[np.float64]
    estimate: NDArray[np.float64]
    detection: Any = None
    scan_pose: NDArray[np.float64] | None = None
    mapper: ObstacleMapper | None = None
    fixes: tuple[Fix2D, ...] = ()
    plane_step: PlaneStep | None = None
    path: Any = None
    link_lost: bool = False


StepFn = Callable[[StepRecord], None]


class StepSink(Protocol):
    """Where a mission's :class:`StepRecord` stream goes (e.g.
    :class:`navkit.runtime.mission_sink.MissionSink`: ``results.mcap`` and Rerun)."""

    def step(self, record: StepRecord) -> None:
        """Take one step's record."""

    def finish(self, log: MissionLog) -> list[str]:
        """Publish the final results of the run; returns the names of the files written."""


class Mission:
    """The integrated mission in a simulated ``scene`` along ``route`` (see the module docstring).

    Parameters
    ----------
    scene : navkit.sim.Scene
        The world (e.g. ``navkit.sim.load_scene("yard")``).
    route : Route
        The operator's waypoints, the room, and optionally an obstacle dropped on the way back.
    settings : MissionSettings, optional
    """

    def __init__(self, scene: Any, route: Route, settings: MissionSettings | None = None) -> None:
        s = self.s = settings or MissionSettings()
        self.route, self.k, self.t, self.t_phase, self.phase = route, 0, 0.0, 0.0, OUTBOUND
        start = np.array(scene.start, dtype=np.float64)
        W = np.asarray(route.waypoints)
        if np.hypot(*(W[0] - start[:2])) > 0.5:
            W = np.vstack([start[:2], W])
        R = s.robot
        self.driver = PurePursuit(W, R.v_max, R.omega_max, R.lookahead, R.goal_tolerance)
        self.lg = lg = MissionLog(s, route, scene, *_empty_rows())
        self.robot = SimRobot(scene, start, s, lg.timings)
        self.est = start.copy()
        self.every_lidar, self.every_cam = s.every(s.lidar.rate_hz), s.every(s.camera.rate_hz)
        lo, hi = scene.bounds()
        pts = np.vstack([lo[:2], hi[:2], W, start[None, :2]])
        M = s.obstacle_map
        settings_map = ObstacleMapperSettings(
            M.resolution, M.min_hits, M.min_ratio, M.recent_scans, M.max_range
        )
        self.mapper = ObstacleMapper(pts.min(0) - M.margin, pts.max(0) + M.margin, settings_map)
        self.recorder = OnlineApproximator(ApproximatorSettings(tolerance=s.path_tolerance))
        self.obstacle_settings = ObstacleSettings(
            shapes=s.obstacle_shapes, guaranteed_shapes=s.obstacle_guaranteed_shapes
        )
        self.rooms = RoomRecord()
        self.localizer = MissionLocalizer(route, s.fusion, M.resolution, self.rooms, lg.timings)
        self.planes = PlaneRecord()
        self.plane_fusion = PlaneMotionFusion(
            s.fusion, self.robot.T_bc, self.planes, lg.timings, self.robot.vo_model
        )
        self.ret: Return | None = None
        self.n_stereo = 0
        self.rows: list[tuple[float, int, Any, Any, Any]] = []
        self._record()
        with timed(lg.timings, "path_record"):
            added = isinstance(self.recorder.update(self.est[:2]), PathUpdate)
        self._det: Any = None
        self._scan_pose: NDArray[np.float64] | None = None
        self.last_step = self._step_record(added, False, 0, 0, 0)

    # --- one control step ----------------------------------------------------------------------
    def step(self) -> bool:
        """One control step; False when the mission is over (``self.lg.outcome`` says why).

        What the step produced is in :attr:`last_step` (a :class:`StepRecord`)."""
        self.k += 1
        self.t = self.k * self.s.robot.dt
        n_fix, n_map_fix, n_plane = (
            len(self.rooms.fixes),
            len(self.rooms.map_fixes),
            len(self.planes.steps),
        )
        phase_before = self.phase
        self._det = self._scan_pose = None
        cmd = self._drive()  # 1. the operator / paper 4's return
        if cmd is None:
            return False
        inc_vo = self.robot.move(*cmd)  # 2. the simulated robot and its VO
        self.est = compose(self.est, inc_vo)  # 3. dead reckoning
        if self.k % self.every_lidar == 0:
            self._lidar()  # 4. paper 1 map, paper 3 fixes, the way back checked on the map
        if self.k % self.every_cam == 0:
            self._camera()  # 5. paper 2 plane motion, paper 3 room views (stereo)
        added = False
        if self.phase == OUTBOUND:
            with timed(self.lg.timings, "path_record"):
                added = isinstance(self.recorder.update(self.est[:2]), PathUpdate)  # 6. paper 4
        self._record()
        link_lost = phase_before == OUTBOUND and self.phase == RETURN
        self.last_step = self._step_record(added, link_lost, n_fix, n_map_fix, n_plane)
        return True

    def _step_record(
        self, path_added: bool, link_lost: bool, n_fix: int, n_map_fix: int, n_plane: int
    ) -> StepRecord:
        r = self.robot
        fixes = (*self.rooms.fixes[n_fix:], *self.rooms.map_fixes[n_map_fix:])
        path = self.lg.path if link_lost else (self.recorder.spline if path_added else None)
        return StepRecord(
            k=self.k,
            time=self.t,
            phase=self.phase,
            truth=r.truth.copy(),
            vo=r.vo.copy(),
            estimate=self.est.copy(),
            detection=self._det,
            scan_pose=self._scan_pose,
            mapper=self.mapper if self._det is not None else None,
            fixes=tuple(fixes),
            plane_step=self.planes.steps[-1] if len(self.planes.steps) > n_plane else None,
            path=path,
            link_lost=link_lost,
        )

    def run(self, progress: ProgressFn | None = None, on_step: StepFn | None = None) -> MissionLog:
        """Step until home, blocked or out of time; returns the log.

        ``on_step(record)`` is called with the start's and every step's :class:`StepRecord`
        (e.g. :class:`navkit.runtime.mission_sink.MissionSink`, which writes ``results.mcap``)."""
        s = self.s
        n_max = int(np.ceil(2 * s.max_time / s.robot.dt))
        steps: Iterator[int] = iter(range(1, n_max + 1))
        if progress is not None:
            # expected length: the route out and back at 80 % of the cruise speed (the bar is a
            # guide; the loop ends when the robot is home, blocked or out of time)
            expected = 2.0 * self.driver.length / (0.8 * s.robot.v_max) / s.robot.dt
            steps = progress(steps, "mission", int(min(n_max, max(expected, 1.0))))
        if on_step is not None:
            on_step(self.last_step)
        for _ in steps:
            if not self.step():
                break
            if on_step is not None:
                on_step(self.last_step)
        else:
            self.lg.outcome = self.lg.outcome or "timeout"
        return self.finish()

    # --- the stages ----------------------------------------------------------------------------
    def _drive(self) -> tuple[float, float] | None:
        """``(v, omega)`` for this step, or None when the mission ends here."""
        truth, s, t = self.robot.truth, self.s, self.t
        if self.phase == OUTBOUND:
            cmd = self.driver.command(truth)
            if self.driver.done(truth) or t - self.t_phase > s.max_time:
                self._link_lost()
            else:
                return cmd
        assert self.ret is not None
        got = self.ret.update(self.est, t)
        if isinstance(got, ReturnStep) and got.home:
            self.lg.outcome = "returned"
        elif t - self.t_phase > s.max_time:
            self.lg.outcome = "timeout"
        elif isinstance(got, ReturnFailure):
            self.lg.outcome = got.reason
        else:
            return got.v, got.omega
        return None

    def _lidar(self) -> None:
        sim = self.robot.scan(self.t)
        lg, M, F = self.lg, self.s.obstacle_map, self.s.fusion
        # truth: which primitives the lidar hit within the fusion range (recall counts these)
        in_range = sim.scan.valid & (sim.true_ranges <= M.max_range)
        lg.seen_primitives.update(np.unique(sim.hit_index[in_range]).tolist())
        with timed(lg.timings, "obstacles_detect"):
            det = detect_obstacles(sim.scan, self.obstacle_settings)
        truth, fix_now = self.robot.truth, self.k % self.every_cam == 0
        if self.phase == RETURN and fix_now:
            body, _ = scan_points_2d(det, np.eye(3), M.max_range)
            self.est = self.localizer.map_fix(body, self.est, truth, self.t)
        with timed(lg.timings, "obstacles_fuse"):
            self.mapper.update(det, se2_from_xytheta(*self.est))
        self._det, self._scan_pose = det, self.est.copy()
        if F.room_sensor == "lidar":  # the room (laser variant)
            B = sim.scan.points("body")[sim.scan.valid]
            z_ok = (B[:, 2] >= F.wall_z_min) & (B[:, 2] <= F.wall_z_max)
            r_ok = np.hypot(B[:, 0], B[:, 1]) <= F.room_view_range
            view = B[z_ok & r_ok][:, :2]
            outbound = self.phase == OUTBOUND
            self.est = self.localizer.room_view(view, self.est, truth, self.t, outbound, fix_now)
        if self.ret is not None:
            way = self.ret.update(self.est, self.t, self.mapper)
            if isinstance(way, WayAhead) and way.detour_started:
                self.ret.detours[-1]["start_true_xy"] = truth[:2].tolist()
            elif isinstance(way, WayBlocked) and self.ret.blocked is not None:
                self.ret.blocked["robot_true"] = truth.tolist()

    def _camera(self) -> None:
        r, t, outbound = self.robot, self.t, self.phase == OUTBOUND
        gz = r.ground()
        frame = r.rgbd(t).frame
        self.est = self.plane_fusion.add_frame(frame, self.est, r.vo, r.truth, t, gz, outbound)
        # the room (stereo variant, paper 3): a level stereo pair on a pan drive; the drive's
        # angle sensor gives the pan, so the wall points are turned into the body frame
        S, F = self.s.stereo, self.s.fusion
        in_room = self.route.in_room(self.est[:2]) or self.localizer.views_pending
        if F.room_sensor == "stereo" and in_room:
            from navkit.stereo import FloorplanSettings, stereo_wall_points

            pan = np.radians(S.pan_deg[self.n_stereo % len(S.pan_deg)])
            self.n_stereo += 1
            pair = r.stereo(t, pan)
            floorplan = FloorplanSettings(
                min_height=F.wall_z_min, max_height=F.wall_z_max, max_depth=F.room_view_range
            )
            with timed(self.lg.timings, "stereo_points"):
                wall2d = stereo_wall_points(
                    pair.left, pair.right, r.rig, camera_height=S.height, settings=floorplan
                )
            c, s = np.cos(pan), np.sin(pan)
            wall2d = wall2d @ np.array([[c, s], [-s, c]])
            self.est = self.localizer.room_view(wall2d, self.est, r.truth, t, outbound, True)

    def _link_lost(self) -> None:
        """Freeze the path memory, start the return; the map's obstacles become known."""
        s, lg, t = self.s, self.lg, self.t
        self.phase, self.t_phase = RETURN, t
        lg.link_lost_index = len(self.rows) - 1
        with timed(lg.timings, "path_finish"):
            result = self.recorder.finish()
        lg.path, lg.path_summary = result.spline, result.summary()
        if lg.path.n_segments == 0:
            raise InputError(
                "the outbound route produced no stored path",
                field="route.waypoints",
                expected="a route of at least a few metres",
            )
        self.ret = Return(lg.path, _return_settings(s), lg.timings)
        self.mapper.freeze_known(s.block.known_margin)
        rows, cols = np.nonzero(self.mapper.occupied)
        self.localizer.link_lost(self.mapper.centres(rows, cols))
        if self.route.block_at is not None:
            truth_xy = np.array([row[2] for row in self.rows])[:, :2]
            scene, lg.dropped_obstacle = _drop_obstacle(lg.scene, self.route, truth_xy)
            lg.scene = self.robot.scene = scene
        log.info(
            "link lost at t = %.1f s; stored path %.1f m in %d segments",
            t,
            lg.path.total_length,
            lg.path.n_segments,
        )

    def _record(self) -> None:
        r = self.robot
        self.rows.append((self.t, self.phase, r.truth.copy(), r.vo.copy(), self.est.copy()))

    def finish(self) -> MissionLog:
        """Close the run: the room map if still pending, the log's arrays and records."""
        lg = self.lg
        if self.phase == OUTBOUND:
            lg.outcome = "link never lost (route not finished)"
        self.localizer.finish_room()
        t, p, tr, vo, est = zip(*self.rows, strict=True)
        lg.time, lg.phase = np.array(t), np.array(p, dtype=np.int8)
        lg.truth, lg.vo, lg.estimate = np.array(tr), np.array(vo), np.array(est)
        lg.obstacle_grid = self.mapper
        lg.plane_steps, lg.plane_points, lg.plane_normals = (
            self.planes.steps,
            self.planes.points,
            self.planes.normals,
        )
        lg.room_views, lg.room_map = self.rooms.room_views, self.rooms.room_map
        lg.fixes, lg.map_fixes = self.rooms.fixes, self.rooms.map_fixes
        if self.ret is not None:
            lg.blocked, lg.detours = self.ret.blocked, self.ret.detours
            lg.detour_paths = self.ret.detour_paths
        if lg.blocked is not None:
            lg.blocked["active"] = lg.outcome == "blocked"
        log.info("mission %s after %.1f s simulated", lg.outcome, self.t)
        return lg


ProgressFn = Callable[[Iterator[int], str, int], Iterator[int]]


def run_mission(
    scene: Any,
    route: Route,
    settings: MissionSettings | None = None,
    progress: ProgressFn | None = None,
    on_step: StepFn | None = None,
) -> MissionLog:
    """Run the integrated mission (:class:`Mission`) to its end.

    Parameters
    ----------
    scene : navkit.sim.Scene
    route : Route
    settings : MissionSettings, optional
    progress : callable, optional
        ``progress(iterable, description, total)`` wrapping the step loop (a progress bar).
    on_step : callable, optional
        Called with every step's :class:`StepRecord` (see :meth:`Mission.run`).

    Returns
    -------
    MissionLog
        Trajectories, maps, fixes, timings; score it with :func:`navkit.mission.metrics.mission_metrics`.
    """
    return Mission(scene, route, settings).run(progress, on_step)


def _empty_rows() -> tuple[Any, ...]:
    return (np.zeros(0), np.zeros(0, np.int8), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)))


def _return_settings(s: MissionSettings) -> ReturnTripSettings:
    """Paper 4's return as the mission configures it."""
    stop = s.return_stop_radius
    B = s.block
    return ReturnTripSettings(
        controller=PathFollowerSettings(
            delta=s.return_delta,
            v_max=s.return_v_max,
            stop_radius=stop,
            approach_radius=max(2 * stop, 0.3),
            omega_max=s.robot.omega_max,
        ),
        half_width=0.5 * s.robot.width + B.clearance,
        lookahead=B.lookahead,
        wait=B.wait,
        detour=B.detour,
        detour_margin=B.detour_margin,
        detour_search=B.detour_search,
    )


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
