"""One small adapter per capability: it holds the capability's online object(s) and turns
messages into calls and results into :class:`~navkit.runtime.messages.Output` records.

Each stage has the same three methods, so the run loop never knows which capability it feeds:

- ``handle(msg, poses) -> StageResult``: one message (``poses`` answers "where was the sensor
  at this stamp"); returns outputs to publish and a per-frame record (``frames.jsonl``).
- ``finish(out) -> StageResult``: end of the recording: final maps / paths, files of today's
  commands, summary figures.
- the stage's state is plain Python / NumPy, so a checkpoint pickles it as is.

The online objects of the capabilities are used, the same ones the CLI commands and the
mission use: ``obstacles.detect_obstacles_in_grid`` + ``obstacles.ObstacleMapper``,
``localization.build_map_from_scans`` (wall map) and ``localization.Localizer``,
``planes.PlaneOdometry``, ``path.OnlineApproximator``.
"""

from __future__ import annotations

import logging
import math
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from navkit.runtime.messages import (
    Message,
    Output,
    Polyline,
    ScanData,
)
from navkit.runtime.pipeline import Pipeline
from navkit.runtime.stage_base import PoseBuffer, StageResult, planar

__all__ = [
    "LaserLocalizationStage",
    "LaserMappingStage",
    "ObstaclesStage",
    "PathStage",
    "PoseBuffer",
    "StageResult",
    "build_stages",
]

log = logging.getLogger(__name__)

SHAPE_COLORS: dict[str, tuple[float, float, float, float]] = {
    "A1": (0.9, 0.1, 0.1, 1.0),
    "A2": (0.1, 0.6, 0.9, 1.0),
    "A3": (0.2, 0.8, 0.2, 1.0),
    "A4": (0.9, 0.6, 0.1, 1.0),
    "A5": (0.7, 0.2, 0.8, 1.0),
    "A6": (0.9, 0.9, 0.1, 1.0),
    "MEC": (0.5, 0.5, 0.5, 1.0),
    "MVEE": (0.3, 0.3, 0.3, 1.0),
}
A7_COLOR = (1.0, 0.4, 0.7, 1.0)
WALL_COLOR = (0.1, 0.1, 0.9, 1.0)
CORNER_COLOR = (0.0, 0.7, 0.7, 1.0)


def _outlines(shapes: list[Any], n: int = 36) -> tuple[NDArray[np.float64], list[int]]:
    """``shape.outline(n)`` of each shape, one after the other in one ``(M, 2)`` array, and
    each outline's end row; rectangles (A1) and ellipses (A6, MVEE) all at once (the same
    numbers as ``Rectangle.outline`` / ``Ellipse.outline``, without a NumPy call chain per
    shape), written to their rows in one assignment per kind."""
    from navkit.geometry.shapes import Ellipse, Rectangle

    ell, rect, other = [], [], {}
    lens = []
    for i, shp in enumerate(shapes):
        kind = type(shp)
        if kind is Ellipse:
            ell.append(i)
            lens.append(n)
        elif kind is Rectangle:
            rect.append(i)
            lens.append(4)
        else:
            other[i] = shp.outline(n)
            lens.append(len(other[i]))
    ends = np.cumsum(lens)
    starts = ends - lens
    XY = np.empty((int(ends[-1]) if len(ends) else 0, 2))
    if ell:
        t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
        ct, st = np.cos(t), np.sin(t)
        # one row per ellipse: x, y, a, b, cos(angle), sin(angle) (math's, as Ellipse.outline)
        A = np.array(
            [
                (e.x, e.y, e.a, e.b, math.cos(e.angle), math.sin(e.angle))
                for e in (shapes[i] for i in ell)
            ]
        )
        x, y, a, b, c, s = (A[:, k : k + 1] for k in range(6))
        u, v = a * ct, b * st
        rows = (starts[ell][:, None] + np.arange(n)).reshape(-1)
        XY[rows, 0] = (x + c * u - s * v).reshape(-1)
        XY[rows, 1] = (y + s * u + c * v).reshape(-1)
    if rect:
        # the four corners counter-clockwise: (xmin, ymin) (xmax, ymin) (xmax, ymax) (xmin, ymax)
        B = np.array([(r.xmin, r.xmax, r.ymin, r.ymax) for r in (shapes[i] for i in rect)])
        rows = (starts[rect][:, None] + np.arange(4)).reshape(-1)
        XY[rows] = B[:, [[0, 2], [1, 2], [1, 3], [0, 3]]].reshape(-1, 2)
    for i, xy in other.items():
        XY[starts[i] : ends[i]] = xy
    return XY, ends.tolist()


def obstacle_lines(
    obstacles: Any,
    z: float = 0.0,
    T: NDArray[np.float64] | None = None,
    names: tuple[str, ...] | None = None,
) -> list[Polyline]:
    """Outlines of the bounding shapes A1-A6 (+ MEC, MVEE; ns ``shape/<name>``) and A7
    (``shape/A7:<name>``) of detected obstacles at height ``z`` of their (level body) frame;
    ``T`` (4, 4), optional, maps them into another frame; ``names``, optional, keeps only these
    shapes (``"A7"`` keeps every A7 outline). Without ``T`` the lines' points are views of one
    array (filled at once)."""
    items = []
    style: dict[str, tuple[str, tuple[float, float, float, float]]] = {}  # ns, colour
    a7 = names is None or "A7" in names
    for ob in obstacles:
        for n, shp in ob.shapes.items():
            if names is None or n in names:
                st = style.get(n)
                if st is None:
                    st = style[n] = (f"shape/{n}", SHAPE_COLORS.get(n, (1, 1, 1, 1)))
                items.append((ob.id, st[0], shp, st[1]))
        if a7:
            items += [(ob.id, f"shape/A7:{n}", shp, A7_COLOR) for n, shp in ob.guaranteed.items()]
    if not items:
        return []
    XY, ends = _outlines([it[2] for it in items])
    bounds = zip([0, *ends[:-1]], ends, strict=True)
    if T is None:
        P = np.empty((len(XY), 3))
        P[:, :2], P[:, 2] = XY, z
        pts = [P[a:b] for a, b in bounds]
    else:
        pts = []
        for a, b in bounds:
            Q = np.empty((b - a, 3))
            Q[:, :2], Q[:, 2] = XY[a:b], z
            pts.append(Q @ T[:3, :3].T + T[:3, 3])
    # the records built without the frozen dataclass's __init__ (its per-field
    # object.__setattr__ is most of the cost of a KITTI frame's ~130 outlines); Polyline has
    # no __post_init__
    new = object.__new__
    out = []
    for (oid, ns, _, color), Q in zip(items, pts, strict=True):
        ln = new(Polyline)
        d = ln.__dict__
        d["ns"] = ns
        d["id"] = oid
        d["points"] = Q
        d["color"] = color
        d["closed"] = True
        out.append(ln)
    return out


def class_counts(labels: NDArray[np.int8]) -> dict[str, int]:
    """Points per class ``{"-2": n, "0": m, ...}`` (ascending, classes present only) of per-point
    int8 classes: one comparison pass per value between the smallest and the largest (the
    classes are a handful of values; a wider span is counted by ``np.bincount``)."""
    if not labels.size:
        return {}
    lo, hi = int(labels.min()), int(labels.max())
    if hi - lo < 16:
        counts = [int(np.count_nonzero(labels == k)) for k in range(lo, hi + 1)]
    else:
        counts = np.bincount(labels.astype(np.int64) - lo).tolist()
    return {str(k + lo): int(v) for k, v in enumerate(counts) if v}


def obstacle_map_output(mapper: Any, stamp_ns: int, frame_id: str) -> Output:
    """An :class:`~navkit.obstacles.ObstacleMapper`'s grid as ``/navkit/obstacle_map``
    (-1 never seen, 0 seen free, 100 occupied)."""
    occ = mapper.occupancy()
    origin = np.array(mapper.origin, dtype=np.float64)
    return Output(
        "/navkit/obstacle_map", "grid", stamp_ns, frame_id, (occ, mapper.resolution, origin)
    )


class ObstaclesStage:
    """Paper 1 on every ``PointCloud2``: per-point classes, bounding shapes A1-A7, and (with a
    pose topic) the fused 2D obstacle map (:class:`navkit.obstacles.ObstacleMapper`, the object
    the mission uses, on a fixed window around the first pose).

    The pose topic and the TF tree give ``T_world_sensor``
    (:meth:`PoseBuffer.sensor_pose`); the detection's points are in the level body frame
    (:class:`~navkit.obstacles.Mounting`), so the mapper gets
    ``T_world_sensor @ inv(T_body_sensor)``."""

    name = "obstacles"

    def __init__(self, pipe: Pipeline, out: Path, with_map: bool) -> None:
        from navkit.obstacles import Mounting, ObstacleSettings

        c = pipe.obstacles
        self.cfg = c
        self.settings = ObstacleSettings.from_dict(dict(c.detector), source="[obstacles.detector]")
        # the height is set on the first cloud (given, or measured on its ground)
        self.mounting = Mounting(height_m=0.0, roll_deg=c.roll_deg, pitch_deg=c.pitch_deg)
        self.height: Any = None
        self.with_map = with_map
        self.pose_topic = pipe.topics.pose
        self.write_frames = pipe.run.write_frames
        self.out = out / "obstacles"
        self.mapper: Any = None
        self.map_frame = "map"
        self.n = 0
        self.files: Any = None  # the writer process of the per-frame files (not pickled)

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["files"] = None
        return state

    def flush(self) -> None:
        """Wait until every per-frame file is written (before a checkpoint, at the end)."""
        if self.files is not None:
            self.files.drain()

    def close(self) -> None:
        """Hand the writer back, everything written (:func:`~navkit.runtime.files.release_writer`)."""
        if self.files is not None:
            from navkit.runtime.files import release_writer

            files, self.files = self.files, None
            release_writer(files)

    def _write_frame(self, seq: int, msg: Message, labels: Any, det: Any) -> None:
        """Queue the frame's ``labels.npy`` + ``obstacles.json`` (as ``navkit obstacles
        detect`` writes them) for the writer process (:mod:`navkit.runtime.files`)."""
        if self.files is None:
            from navkit.runtime.files import acquire_writer

            self.files = acquire_writer()
        d = self.out / f"{seq:06d}"
        doc = {
            "topic": msg.topic,
            "stamp_ns": msg.stamp_ns,
            "frame": "body (x forward, y left, z up, origin on the ground under the sensor)",
            "sensor": det.sensor_origin,
            # formatted by the writer process (Obstacle.to_dict's dicts, built there)
            "obstacle_fields": [ob.json_fields() for ob in det.obstacles],
        }
        self.files.submit_files(
            [("npy", d / "labels.npy", labels), ("obstacles", d / "obstacles.json", doc)]
        )

    def _set_height(self, points: NDArray[np.float64], src: str) -> None:
        """The run's sensor height, once: given, or measured on this cloud's ground (as
        ``navkit obstacles detect``: :func:`~navkit.obstacles.mounting.choose_sensor_height`)."""
        import dataclasses

        from navkit.obstacles.mounting import choose_sensor_height

        self.height = choose_sensor_height(
            points,
            self.mounting.R_body_sensor,
            given_m=self.cfg.sensor_height_m,
            source=src,
        )
        if self.height.source != "given":
            log.info("sensor height %.3f m (%s)", self.height.height_m, self.height.source)
        self.mounting = dataclasses.replace(self.mounting, height_m=self.height.height_m)
        self.T_sensor_body = np.linalg.inv(self.mounting.T_body_sensor)

    def _mapper(self, T: NDArray[np.float64]) -> Any:
        if self.mapper is None:
            from navkit.obstacles import ObstacleMapper, ObstacleMapperSettings

            c = self.cfg
            centre = T[:2, 3]
            self.mapper = ObstacleMapper(
                centre - c.map_half_extent_m,
                centre + c.map_half_extent_m,
                ObstacleMapperSettings(
                    resolution=c.map_resolution_m,
                    min_hits=c.map_min_hits,
                    min_ratio=c.map_min_ratio,
                    max_range=c.map_max_range_m,
                ),
            )
        return self.mapper

    def grid_output(self, stamp_ns: int) -> Output:
        return obstacle_map_output(self.mapper, stamp_ns, self.map_frame)

    def handle(self, msg: Message, poses: PoseBuffer) -> StageResult:
        from navkit.obstacles import detect_obstacles_in_grid
        from navkit.obstacles.grids import cloud_to_grid

        c = self.cfg
        src = f"{msg.topic}@{msg.stamp_ns}"
        grid = cloud_to_grid(
            msg.data, n_rings=c.rings, n_columns=c.columns, ring_method=c.ring_method, source=src
        )
        if self.height is None:
            self._set_height(grid.points, src)
        det = detect_obstacles_in_grid(grid, self.mounting, self.settings, source=src)
        labels = grid.per_point(det.vertex_labels).astype(np.int8, copy=False)
        seq = self.n
        self.n += 1
        outs = [
            Output(
                "/navkit/obstacles/points",
                "classified_cloud",
                msg.stamp_ns,
                msg.frame_id,
                (msg.data, labels),
            )
        ]
        z = -self.mounting.height_m  # shapes lie on the ground, in the level body frame
        lines = obstacle_lines(det.obstacles, z, names=c.shapes)
        outs.append(
            Output("/navkit/obstacles/shapes", "markers", msg.stamp_ns, msg.frame_id, lines)
        )
        record: dict[str, Any] = {
            "seq": seq,
            "n_points": int(labels.size),
            "n_obstacles": len(det.obstacles),
            "counts": class_counts(labels),
            "triangles": det.counts,
        }
        if self.write_frames:
            self._write_frame(seq, msg, labels, det)
        T = (
            poses.sensor_pose(self.pose_topic, msg.stamp_ns, msg.frame_id)
            if self.with_map
            else None
        )
        if T is not None:
            self.map_frame = poses.frames.get(self.pose_topic, "map") or "map"
            self._mapper(T).update(det, T @ self.T_sensor_body)
            if self.n % max(c.map_every, 1) == 0:
                outs.append(self.grid_output(msg.stamp_ns))
        return StageResult(outs, record)

    def finish(self, out: Path, stamp_ns: int) -> StageResult:
        self.close()
        height = {} if self.height is None else {"sensor_height": self.height.to_dict()}
        if self.mapper is None:
            return StageResult(record={"frames": self.n, **height})
        from navkit.io.maps import write_occupancy_grid

        o = self.grid_output(stamp_ns)
        occ, res, origin = o.data
        self.out.mkdir(parents=True, exist_ok=True)
        write_occupancy_grid(self.out / "obstacle_map", occ, res, origin)
        return StageResult(
            [o],
            {
                "frames": self.n,
                **height,
                "map_cells_occupied": int((occ == 100).sum()),
                "map_scans": int(self.mapper.n_scans),
                "map_obstacles": len(self.mapper.obstacles()),
            },
        )


# --------------------------------------------------------------------------- laser: wall map
def wall_lines(walls: Any, corners: Any = ()) -> list[Polyline]:
    """Wall segments as open two-point polylines and corners as 0.3 m squares (z = 0)."""
    out = [
        Polyline("walls", k, np.array([[*w.start, 0.0], [*w.end, 0.0]]), WALL_COLOR, closed=False)
        for k, w in enumerate(walls)
    ]
    sq = 0.15 * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    for k, c in enumerate(corners):
        P = np.asarray(c.point, dtype=np.float64)[:2] + sq
        out.append(Polyline("corners", k, np.c_[P, np.zeros(4)], CORNER_COLOR))
    return out


class LaserMappingStage:
    """Paper 3's wall map from ``LaserScan`` + poses: keyframes (bounded, see
    :class:`~navkit.runtime.pipeline.LaserConfig`), the map built at the end as ``navkit map build``."""

    name = "wall_map"

    def __init__(self, pipe: Pipeline, out: Path) -> None:
        self.cfg = pipe.laser
        self.pose_topic = pipe.topics.pose
        self.out = out / "wall_map"
        self.ranges: list[NDArray[np.float64]] = []
        self.poses: list[NDArray[np.float64]] = []
        self.bearings: NDArray[np.float64] | None = None
        self.dist = self.cfg.keyframe_distance_m
        self.angle = np.radians(self.cfg.keyframe_angle_deg)
        self.n = 0
        self.frame = "map"

    def handle(self, msg: Message, poses: PoseBuffer) -> StageResult:
        scan: ScanData = msg.data
        T = poses.sensor_pose(self.pose_topic, msg.stamp_ns, msg.frame_id)
        self.n += 1
        if T is None:
            return StageResult(record={"used": False, "reason": "no pose yet"})
        if self.bearings is None:
            self.bearings = scan.bearings
        elif len(scan.bearings) != len(self.bearings) or not np.allclose(
            scan.bearings, self.bearings
        ):
            return StageResult(
                record={"used": False, "reason": "beam layout differs from the first scan"}
            )
        self.frame = poses.frames.get(self.pose_topic, "map") or "map"
        x = planar(T)
        if self.poses:
            last = self.poses[-1]
            moved = np.hypot(*(x[:2] - last[:2])) >= self.dist
            turned = abs(np.angle(np.exp(1j * (x[2] - last[2])))) >= self.angle
            if not (moved or turned):
                return StageResult(record={"used": False, "reason": "not a keyframe"})
        self.ranges.append(np.asarray(scan.ranges, dtype=np.float64))
        self.poses.append(x)
        if len(self.ranges) > self.cfg.max_keyframes:
            self.ranges, self.poses = self.ranges[::2], self.poses[::2]
            self.dist, self.angle = max(2 * self.dist, 0.05), max(2 * self.angle, np.radians(2.0))
            log.info("wall map: keyframes thinned to %d", len(self.ranges))
        return StageResult(record={"used": True, "keyframes": len(self.ranges)})

    def finish(self, out: Path, stamp_ns: int) -> StageResult:
        if not self.ranges or self.bearings is None:
            return StageResult(record={"scans": self.n, "keyframes": 0, "walls": 0})
        from navkit.io.atomic import write_json
        from navkit.io.maps import write_occupancy_grid
        from navkit.localization import WallMapSettings, build_map_from_scans

        wm = build_map_from_scans(
            np.stack(self.ranges),
            self.bearings,
            np.stack(self.poses),
            WallMapSettings(resolution=self.cfg.map_resolution_m),
            max_range=self.cfg.max_range_m,
        )
        self.out.mkdir(parents=True, exist_ok=True)
        assert wm.occupancy is not None
        write_occupancy_grid(self.out / "map", wm.occupancy, wm.resolution, wm.origin)
        write_json(
            self.out / "map.json", {**wm.to_dict(), "grid": "map.yaml", "source": "navkit run"}
        )
        outs = [
            Output(
                "/navkit/wall_map",
                "grid",
                stamp_ns,
                self.frame,
                (np.asarray(wm.occupancy, np.int8), wm.resolution, np.asarray(wm.origin)),
            ),
            Output(
                "/navkit/walls", "markers", stamp_ns, self.frame, wall_lines(wm.walls, wm.corners)
            ),
        ]
        return StageResult(
            outs,
            {
                "scans": self.n,
                "keyframes": len(self.ranges),
                "walls": len(wm.walls),
                "corners": len(wm.corners),
            },
        )


# --------------------------------------------------------------------------- laser: localization
class LaserLocalizationStage:
    """Paper 3's localization of each ``LaserScan`` in a wall map (``--map``) with
    :class:`navkit.localization.Localizer`, the object ``navkit map locate`` and the mission use,
    like ``navkit map locate --prior odometry``: the body-frame odometry increment between
    consecutive scans (from the odometry topic) moves the last estimate into the next tracking
    window; the first scan, and every scan without an odometry pose, is searched globally.

    Only accepted fixes are published (``/navkit/localization/pose``); a
    :class:`~navkit.localization.LocalizationFailure` is a per-frame record with its reason (and
    the rejected candidate), never a pose. Errors against the reference topic, when there is
    one, are summarised as ``map locate`` does (:func:`~navkit.localization.evaluate_fixes`):
    medians over the accepted fixes, a success is an accepted fix within ``success_m`` and
    ``success_deg``.
    """

    name = "localization"

    def __init__(self, pipe: Pipeline, out: Path) -> None:
        from navkit.io.wallmap import read_wall_map
        from navkit.localization import Localizer, LocalizerSettings

        self.cfg = pipe.laser
        self.odom_topic = pipe.topics.odometry if pipe.laser.prior == "odometry" else ""
        self.ref_topic = pipe.topics.reference
        self.wall_map = read_wall_map(Path(pipe.map))
        self.localizer = Localizer(self.wall_map, LocalizerSettings(sigma=self.cfg.sigma_m))
        self.last_odom: NDArray[np.float64] | None = None
        self.errors: deque[tuple[float, float]] = deque(maxlen=100000)
        self.n = self.n_ok = self.n_success = self.n_ref = 0
        self.out = out / "localization"
        self.published_map = False
        self.root = ""  # the frame map is linked to (the odometry's), and the last correction
        self.T_map_root: NDArray[np.float64] | None = None

    def _covariance(self, fix: Any, pts: NDArray[np.float64]) -> NDArray[np.float64]:
        """``(3, 3)`` covariance of the fix's ``(x, y, theta)`` (m^2, rad^2): the point-to-line
        refinement's when it ran and is finite; else the match's own, from its peak analysis:
        x, y the score-weighted covariance of the near-optimal translations
        (``Ambiguity.covariance``), floored by the search cell's quantisation (``res^2 / 12``);
        theta the quantisation of the heading step (Olson's rule: the 95th-percentile range
        point moves one cell, ``step = res / r95``; ``step^2 / 12``)."""
        cov = fix.covariance
        if cov is not None and np.all(np.isfinite(cov)):
            return np.asarray(cov, dtype=np.float64)
        res = float(getattr(self.wall_map, "resolution", 0.05) or 0.05)
        out = np.zeros((3, 3))
        peak = getattr(getattr(fix.match, "ambiguity", None), "covariance", None)
        if peak is not None and np.all(np.isfinite(peak)):
            out[:2, :2] = peak
        out[:2, :2] += np.eye(2) * res**2 / 12
        r95 = float(np.percentile(np.hypot(pts[:, 0], pts[:, 1]), 95)) if len(pts) else 0.0
        step = res / r95 if r95 > res else np.radians(1.0)
        out[2, 2] = step**2 / 12
        return out

    def _base_frame(self, poses: PoseBuffer, sensor: str, stamp_ns: int) -> str:
        """The robot's frame: the odometry's child frame, else ``base_link`` /
        ``base_footprint``, when the TF tree connects it to the sensor; else the sensor."""
        cands = (poses.children.get(self.odom_topic, "") if self.odom_topic else "",)
        for base in (*cands, "base_link", "base_footprint"):
            base = base.lstrip("/")
            if base and base != sensor and poses.tf.can_transform(sensor, base):
                return base
        return sensor

    def _robot(
        self,
        msg: Message,
        poses: PoseBuffer,
        pose: NDArray[np.float64],
        cov3: NDArray[np.float64],
        rec: dict[str, Any],
    ) -> list[Output]:
        """A fix's outputs: ``map -> root`` of the sensor's odometry tree (the AMCL form,
        :func:`~navkit.runtime.tf.planar_correction`), the robot's frame in ``map``
        (``PoseWithCovarianceStamped``) and the sensor's (``PoseStamped``)."""
        from navkit.runtime.tf import planar_correction, planar_covariance_6x6

        stamp, sensor = msg.stamp_ns, msg.frame_id.lstrip("/")
        c, s = np.cos(pose[2]), np.sin(pose[2])
        T_fix = np.eye(4)
        T_fix[:2, :2] = [[c, -s], [s, c]]
        T_fix[:2, 3] = pose[:2]
        T_root_sensor = (
            poses.sensor_pose(self.odom_topic, stamp, sensor) if self.odom_topic else None
        )
        if T_root_sensor is not None:
            root = poses.frames.get(self.odom_topic, "").lstrip("/") or "odom"
        else:  # no odometry: the top of the sensor's own TF tree (the sensor itself without)
            root = poses.tf._chain(sensor)[-1] if sensor else ""
            T_root_sensor = poses.tf.lookup(root, sensor, stamp) if root else None
            if T_root_sensor is None:
                root, T_root_sensor = sensor, np.eye(4)
        T_map_root = planar_correction(T_fix, T_root_sensor)
        T_map_sensor = T_map_root @ T_root_sensor
        base = self._base_frame(poses, sensor, stamp)
        T_sensor_base = poses.tf.lookup(sensor, base, stamp) if base != sensor else None
        T_map_base = T_map_sensor if T_sensor_base is None else T_map_sensor @ T_sensor_base
        lever = T_map_base[:2, 3] - T_map_sensor[:2, 3]
        cov6 = planar_covariance_6x6(cov3, lever)
        b = planar(T_map_base)
        rec.update(
            base_frame=base,
            base=[float(v) for v in b],
            sigma_xy_m=float(np.sqrt(max(cov6[0, 0] + cov6[1, 1], 0.0))),
            sigma_theta_deg=float(np.degrees(np.sqrt(max(cov6[5, 5], 0.0)))),
        )
        outs = [
            Output("/navkit/localization/pose", "pose_cov", stamp, "map", (T_map_base, cov6)),
            Output("/navkit/localization/sensor_pose", "pose", stamp, "map", T_map_sensor),
        ]
        if root:
            self.root, self.T_map_root = root, T_map_root
            outs.append(Output("/tf", "tf", stamp, "map", [(root, T_map_root)]))
        return outs

    def _odometry_delta(self, odom: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
        """Body-frame increment since the previous scan's odometry (None: unknown)."""
        from navkit.geometry import se2_compose, se2_from_xytheta, se2_inverse, se2_to_xytheta

        last, self.last_odom = self.last_odom, odom
        if last is None or odom is None:
            return None
        a, b = se2_from_xytheta(*last), se2_from_xytheta(*odom)
        return se2_to_xytheta(se2_compose(se2_inverse(a), b))

    def handle(self, msg: Message, poses: PoseBuffer) -> StageResult:
        from navkit.localization import Fix

        scan: ScanData = msg.data
        self.n += 1
        outs: list[Output] = []
        if not self.published_map:
            self.published_map = True
            outs.append(
                Output(
                    "/navkit/walls",
                    "markers",
                    msg.stamp_ns,
                    "map",
                    wall_lines(self.wall_map.walls, self.wall_map.corners),
                )
            )
        # the odometry of the scan's frame (carried from the topic's child through the TF tree:
        # a laser ahead of base_link moves sideways when the base turns)
        To = (
            poses.sensor_pose(self.odom_topic, msg.stamp_ns, msg.frame_id)
            if self.odom_topic
            else None
        )
        delta = self._odometry_delta(planar(To) if To is not None else None)
        pts = scan.points(self.cfg.max_range_m)
        r = self.localizer.update(pts, odometry_delta=delta)
        ok = isinstance(r, Fix)
        pose = r.pose if isinstance(r, Fix) else r.candidate
        rec: dict[str, Any] = {
            "ok": ok,
            "method": r.method,
            "score": float(r.score),
            "ambiguous": bool(r.ambiguous),
            "reason": r.reason,
            "ms": 1e3 * r.seconds,
        }
        if ok:
            rec.update(x=float(pose[0]), y=float(pose[1]), theta=float(pose[2]))
            cov3 = self._covariance(r, pts)
            outs += self._robot(msg, poses, pose, cov3, rec)
        else:
            if np.all(np.isfinite(pose)):
                rec["candidate"] = [float(v) for v in pose]
            if self.T_map_root is not None:  # as AMCL: the last correction, re-stamped
                outs.append(
                    Output("/tf", "tf", msg.stamp_ns, "map", [(self.root, self.T_map_root)])
                )
        self.n_ok += ok
        Tr = (
            poses.sensor_pose(self.ref_topic, msg.stamp_ns, msg.frame_id)
            if self.ref_topic
            else None
        )
        self.n_ref += Tr is not None
        if Tr is not None and np.all(np.isfinite(pose)):
            ref = planar(Tr)
            pe = float(np.hypot(*(pose[:2] - ref[:2])))
            he = float(np.degrees(abs(np.angle(np.exp(1j * (pose[2] - ref[2]))))))
            rec.update(position_error_m=pe, heading_error_deg=he)
            if ok:
                self.errors.append((pe, he))
                self.n_success += pe <= self.cfg.success_m and he <= self.cfg.success_deg
        return StageResult(outs, rec)

    def finish(self, out: Path, stamp_ns: int) -> StageResult:
        rec: dict[str, Any] = {"fixes": self.n, "ok_rate": self.n_ok / max(self.n, 1)}
        if self.n_ref:
            rec.update(success_rate=self.n_success / max(self.n, 1), reference=self.ref_topic)
        if self.errors:
            e = np.array(self.errors)
            rec.update(
                position_error_m_median=float(np.median(e[:, 0])),
                position_error_m_p95=float(np.percentile(e[:, 0], 95)),
                heading_error_deg_median=float(np.median(e[:, 1])),
            )
        return StageResult(record=rec)


# --------------------------------------------------------------------------- planes
class PathStage:
    """Paper 4's path memory of the pose topic (``path.OnlineApproximator``): the stored spline,
    sampled every 0.1 m, is published every ``publish_every`` accepted poses and at the end
    (``path.json`` as ``navkit path record`` writes it)."""

    name = "path"

    def __init__(self, pipe: Pipeline, out: Path) -> None:
        from navkit.path import ApproximatorSettings, OnlineApproximator

        self.cfg = pipe.path
        self.rec = OnlineApproximator(ApproximatorSettings(tolerance=self.cfg.tolerance_m))
        self.n_accepted = 0
        self.frame = "map"
        self.out = out / "path"

    def _path_output(self, spline: Any, stamp_ns: int) -> Output:
        if spline.n_segments == 0:
            xy = np.zeros((0, 2))
        else:
            _, xy = spline.sample(0.1)
        return Output("/navkit/path", "path", stamp_ns, self.frame, np.c_[xy, np.zeros(len(xy))])

    def handle(self, msg: Message, poses: PoseBuffer) -> StageResult:
        from navkit.path import Skipped

        self.frame = msg.frame_id or "map"
        T = msg.data
        if isinstance(self.rec.update(T[:2, 3]), Skipped):  # NaN or a repeat
            return StageResult()
        self.n_accepted += 1
        if self.n_accepted % max(self.cfg.publish_every, 1) == 0:
            return StageResult([self._path_output(self.rec.spline, msg.stamp_ns)])
        return StageResult()

    def finish(self, out: Path, stamp_ns: int) -> StageResult:
        from navkit.io.pathjson import write_path_json

        res = self.rec.finish()
        self.out.mkdir(parents=True, exist_ok=True)
        write_path_json(self.out / "path.json", res.spline)
        return StageResult(
            [self._path_output(res.spline, stamp_ns)],
            {
                "poses": self.rec.n_input,
                "accepted": self.n_accepted,
                "segments": res.spline.n_segments,
                "length_m": float(res.spline.total_length),
            },
        )


def build_stages(pipe: Pipeline, out: Path) -> dict[str, Any]:
    """The stages of a pipeline, by capability name (obstacle map = the obstacles stage)."""
    caps = set(pipe.capabilities)
    stages: dict[str, Any] = {}
    if "obstacles" in caps or "obstacle_map" in caps:
        stages["obstacles"] = ObstaclesStage(pipe, out, with_map="obstacle_map" in caps)
    if "wall_map" in caps:
        stages["wall_map"] = LaserMappingStage(pipe, out)
    if "localization" in caps:
        stages["localization"] = LaserLocalizationStage(pipe, out)
    if "planes" in caps:
        from navkit.runtime.planes_stage import PlanesStage

        stages["planes"] = PlanesStage(pipe, out)
    if "path" in caps:
        stages["path"] = PathStage(pipe, out)
    return stages


def route(pipe: Pipeline, stages: dict[str, Any], msg: Message) -> list[Any]:
    """The stages a message goes to."""
    t = pipe.topics
    out = []
    if msg.kind == "cloud" and msg.topic in t.clouds and "obstacles" in stages:
        out.append(stages["obstacles"])
    elif msg.kind == "scan" and msg.topic in t.scans:
        for name in ("wall_map", "localization"):
            if name in stages:
                out.append(stages[name])
    elif msg.kind in ("depth", "color", "camera_info") and "planes" in stages:
        if msg.topic in (t.depth, t.color, t.camera_info):
            out.append(stages["planes"])
    elif msg.kind == "pose" and msg.topic == t.pose and "path" in stages:
        out.append(stages["path"])
    return out


def needs_pose(pipe: Pipeline, stages: dict[str, Any], msg: Message) -> list[str]:
    """Pose topics whose value at the message's stamp the message's stages need."""
    t = pipe.topics
    need = []
    if msg.kind == "cloud" and "obstacle_map" in pipe.capabilities and t.pose:
        need.append(t.pose)
    if msg.kind == "scan":
        if "wall_map" in stages and t.pose:
            need.append(t.pose)
        if "localization" in stages:
            need += [x for x in (stages["localization"].odom_topic, t.reference) if x]
    return need
