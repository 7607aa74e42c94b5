"""The simulated mission into the runtime's result sinks: ``results.mcap`` and the Rerun logger.

:class:`MissionSink` takes the :class:`~navkit.mission.run.StepRecord` of every control step
(``Mission.run(on_step=sink.step)``; ``navkit demo`` and ``navkit mission run`` pass it through
:func:`navkit.mission.demo.run_to_dir`) and publishes what each capability produced as the same
:class:`~navkit.runtime.messages.Output` records ``navkit run`` publishes, through the same
writer (:class:`navkit.io.results_mcap.ResultsWriter`) and viewer
(:class:`navkit.viz.rerun_logger.RerunLogger` or :class:`~navkit.runtime.run.NullLogger`). The
mission itself imports neither: it composes the capabilities, this module joins it to the sinks.

Topics (stamps = simulated time, log time = stamp, frame ``map`` = the mission's world frame):

================================  ===================================  =========================
topic                             type                                 when
================================  ===================================  =========================
``/navkit/obstacles/points``      ``PointCloud2`` (x y z + ``class``)  every lidar scan
``/navkit/obstacles/shapes``      ``MarkerArray`` (A1-A7 outlines)     every lidar scan
``/navkit/obstacle_map``          ``OccupancyGrid``                    every ``map_every`` scans
                                                                       and at the end
``/navkit/localization/pose``     ``PoseStamped``                      every fix the matcher
                                                                       accepted (paper 3)
``/navkit/planes/pose``           ``PoseStamped``                      every RGB-D frame
``/navkit/path``                  ``Path`` (stored spline, 0.1 m)      every ``path_every``
                                                                       accepted points, when the
                                                                       link is lost, at the end
``/navkit/return_path``           ``Path`` (estimate on the way back)  every ``return_every``
                                                                       steps and at the end
``/navkit/estimate``              ``PoseStamped``                      every ``pose_every`` steps
``/navkit/truth``                 ``PoseStamped`` (simulator truth)    every ``pose_every`` steps
``/navkit/walls``                 ``MarkerArray``                      the room map, at the end
================================  ===================================  =========================

Decisions: the simulator has no TF tree, so the scan's points and shapes (level body frame) are
published in ``map``, placed by the estimate the scan was fused into the obstacle map with (what
the mapper did). The mission's paper 2 is a frame-to-frame plane motion fused with the VO
(:mod:`navkit.mission.plane_fusion`), so ``/navkit/planes/pose`` is the planes' own odometry:
the start pose composed with each frame's plane increment (the VO increment where the planes
failed or were gated), not the fused estimate.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from navkit.mission.pose2d import compose
from navkit.runtime.capabilities import obstacle_lines, obstacle_map_output, wall_lines
from navkit.runtime.messages import Output

__all__ = ["MissionSink", "MissionSinkSettings", "open_mission_sink", "pose_matrix", "step_outputs"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MissionSinkSettings:
    """How often the mission's slower-changing results are published.

    Attributes
    ----------
    map_every : int
        Lidar scans between obstacle-map grids.
    path_every : int
        Accepted path points between stored-path messages (outbound).
    return_every : int
        Control steps between return-path messages.
    pose_every : int
        Control steps between ``/navkit/estimate`` and ``/navkit/truth`` poses.
    shapes : tuple of str
        Bounding shapes published per obstacle (``"A7"``: the guaranteed ones). Decision: A1 and
        A6 by default, the two the Rerun logger draws; all of them (``navkit run``'s choice) cost
        about five times as many markers per scan, 20 % of the demo's time. Only the shapes the
        mission computed can be published (``MissionSettings.obstacle_shapes``: A1 and A6 by
        default, and A7 over A1 and MEC).
    frame : str
        Frame id of the mission's world.
    """

    map_every: int = 10
    path_every: int = 20
    return_every: int = 20
    pose_every: int = 1
    shapes: tuple[str, ...] = ("A1", "A6")
    frame: str = "map"


def pose_matrix(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(4, 4)`` ``T_world_body`` of a planar pose ``(x, y, theta)`` (z = 0)."""
    c, s = np.cos(x[2]), np.sin(x[2])
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = x[:2]
    return T


def _stamp(t: float) -> int:
    return round(float(t) * 1e9)


def _path_points(spline: Any) -> NDArray[np.float64]:
    if spline is None or spline.n_segments == 0:
        return np.zeros((0, 3))
    _, xy = spline.sample(0.1)
    return np.c_[xy, np.zeros(len(xy))]


class _State:
    """What the sink keeps between steps (counters, the planes' odometry, the return path)."""

    def __init__(self) -> None:
        self.n_scans = 0
        self.n_path = 0
        self.plane_pose: NDArray[np.float64] | None = None
        self.return_xy: list[NDArray[np.float64]] = []
        self.last_t = 0.0
        self.published_path = False


def step_outputs(rec: Any, state: _State, s: MissionSinkSettings) -> list[Output]:
    """The outputs of one :class:`~navkit.mission.run.StepRecord` (``state`` is updated)."""
    stamp, F = _stamp(rec.time), s.frame
    outs: list[Output] = []
    state.last_t = rec.time
    if state.plane_pose is None:
        state.plane_pose = np.asarray(rec.estimate, dtype=np.float64).copy()
    if rec.k % max(s.pose_every, 1) == 0:
        outs.append(Output("/navkit/estimate", "pose", stamp, F, pose_matrix(rec.estimate)))
        outs.append(Output("/navkit/truth", "pose", stamp, F, pose_matrix(rec.truth)))
    det = rec.detection
    if det is not None:
        T = pose_matrix(rec.scan_pose if rec.scan_pose is not None else rec.estimate)
        valid = det.valid & np.all(np.isfinite(det.points), axis=-1)
        P = det.points[valid] @ T[:3, :3].T + T[:3, 3]
        labels = np.asarray(det.vertex_labels)[valid].astype(np.int8)
        outs.append(Output("/navkit/obstacles/points", "classified_cloud", stamp, F, (P, labels)))
        lines = obstacle_lines(det.obstacles, 0.0, T, s.shapes)
        outs.append(Output("/navkit/obstacles/shapes", "markers", stamp, F, lines))
        state.n_scans += 1
        if rec.mapper is not None and state.n_scans % max(s.map_every, 1) == 0:
            outs.append(obstacle_map_output(rec.mapper, stamp, F))
    for fix in rec.fixes:
        if fix.ok and np.all(np.isfinite(fix.pose)):
            outs.append(
                Output("/navkit/localization/pose", "pose", stamp, F, pose_matrix(fix.pose))
            )
    ps = rec.plane_step
    if ps is not None:
        inc = (
            ps.plane_inc
            if str(ps.status) == "ok" and np.all(np.isfinite(ps.plane_inc))
            else ps.vo_inc
        )
        if np.all(np.isfinite(inc)):
            state.plane_pose = compose(state.plane_pose, np.asarray(inc, dtype=np.float64))
        outs.append(Output("/navkit/planes/pose", "pose", stamp, F, pose_matrix(state.plane_pose)))
    if rec.path is not None:
        state.n_path += 1
        if rec.link_lost or state.n_path % max(s.path_every, 1) == 0:
            outs.append(Output("/navkit/path", "path", stamp, F, _path_points(rec.path)))
            state.published_path = True
    if rec.phase == 1:
        state.return_xy.append(np.asarray(rec.estimate[:2], dtype=np.float64))
        if len(state.return_xy) % max(s.return_every, 1) == 0:
            outs.append(_return_output(state, stamp, F))
    return outs


def _return_output(state: _State, stamp: int, frame: str) -> Output:
    xy = np.array(state.return_xy).reshape(-1, 2)
    return Output("/navkit/return_path", "path", stamp, frame, np.c_[xy, np.zeros(len(xy))])


class MissionSink:
    """Writes a mission's step records to ``out/results.mcap`` and shows them in a viewer.

    Parameters
    ----------
    out : path
        The run's output folder (``results.mcap`` is written into it).
    logger : optional
        A viewer with the :class:`~navkit.runtime.run.NullLogger` interface (e.g.
        :class:`navkit.viz.rerun_logger.RerunLogger`); None: none.
    settings : MissionSinkSettings, optional

    Attributes
    ----------
    seconds : float
        Time spent building, writing and viewing outputs (the logging overhead of the run).
    n_messages : int
        Messages written to ``results.mcap``.
    """

    def __init__(
        self,
        out: str | Path,
        logger: Any = None,
        settings: MissionSinkSettings | None = None,
    ) -> None:
        from navkit.runtime.run import NullLogger

        self.out = Path(out)
        self.logger = logger if logger is not None else NullLogger()
        self.s = settings or MissionSinkSettings()
        self.state = _State()
        self.writer: Any = None
        self.seconds = 0.0
        self.n_messages = 0

    def _publish(self, outs: list[Output]) -> None:
        if self.writer is None:
            from navkit.io.results_mcap import ResultsWriter

            self.out.mkdir(parents=True, exist_ok=True)
            self.writer = ResultsWriter(self.out / "results.mcap", chunked=True)
        for o in outs:
            self.writer.write(o.topic, o.kind, o.stamp_ns, o.frame_id, o.data)
            self.logger.log_output(o)
        self.n_messages += len(outs)

    def step(self, record: Any) -> None:
        """Publish one :class:`~navkit.mission.run.StepRecord`."""
        t0 = time.perf_counter()
        self.logger.set_time(_stamp(record.time))
        self._publish(step_outputs(record, self.state, self.s))
        self.seconds += time.perf_counter() - t0

    def finish(self, lg: Any) -> list[str]:
        """Publish the final obstacle map, stored path, return path and room walls of the
        :class:`~navkit.mission.run.MissionLog`; close the file and the viewer. Returns
        ``["results.mcap"]``."""
        t0 = time.perf_counter()
        st, F = self.state, self.s.frame
        stamp = _stamp(max(st.last_t, float(lg.time[-1]) if len(lg.time) else 0.0))
        self.logger.set_time(stamp)
        outs: list[Output] = []
        if lg.obstacle_grid is not None:
            outs.append(obstacle_map_output(lg.obstacle_grid, stamp, F))
        if lg.path is not None:
            outs.append(Output("/navkit/path", "path", stamp, F, _path_points(lg.path)))
        if st.return_xy:
            outs.append(_return_output(st, stamp, F))
        if lg.room_map is not None:
            walls = wall_lines(lg.room_map.walls, getattr(lg.room_map, "corners", ()))
            outs.append(Output("/navkit/walls", "markers", stamp, F, walls))
        try:
            self._publish(outs)
        finally:
            if self.writer is not None:
                self.writer.close()
            self.logger.close()
        self.seconds += time.perf_counter() - t0
        log.info(
            "results.mcap: %d messages, %.2f s building, writing and viewing them",
            self.n_messages,
            self.seconds,
        )
        return ["results.mcap"]


def open_mission_sink(
    out: str | Path,
    rerun: bool = False,
    rerun_save: str | Path | None = None,
    settings: MissionSinkSettings | None = None,
) -> MissionSink:
    """The sink of ``navkit demo`` / ``navkit mission run``: ``out/results.mcap``, and with
    ``rerun`` (live viewer) or ``rerun_save`` (an ``.rrd`` file) the Rerun logger of ``navkit run``
    (extra ``rerun``; without it a :class:`~navkit.errors.NavkitError` with the install hint)."""
    logger = None
    if rerun or rerun_save is not None:
        from navkit.viz.rerun_logger import RerunLogger

        logger = RerunLogger(spawn=rerun, save=rerun_save, application_id="navkit-mission")
    return MissionSink(out, logger, settings)
