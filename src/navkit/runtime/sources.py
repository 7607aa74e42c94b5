"""Recordings as streams of :class:`~navkit.runtime.messages.Message`, one at a time, in time order.

:func:`open_source` picks the reader from the path:

==========================================  ================================================
input                                        topics
==========================================  ================================================
ROS 1 ``.bag``, ROS 2 bag folder (sqlite3    the bag's own; by type: PointCloud2 -> cloud,
or mcap storage), plain ``.mcap``            LaserScan -> scan, Odometry / PoseStamped /
(``rosbags`` AnyReader)                      PoseWithCovarianceStamped -> pose, TFMessage ->
                                             tf (one per transform; the TF tree,
                                             :mod:`navkit.runtime.tf`), Image -> depth
                                             (16UC1, mono16, 32FC1) or color, CameraInfo
KITTI sequence folder (``*.bin``, optional   ``/velodyne_points`` (cloud), ``/ground_truth``
``poses*.txt``, ``calib*.txt``,              (pose of the Velodyne relative to its first
``times*.txt``)                              pose: z up, from the cam0 poses and ``Tr``)
CARMEN log (``.log``, ``.log.gz``)           ``/scan``, ``/odom`` (raw odometry),
                                             ``/ground_truth`` (the corrected pose)
TUM RGB-D / simple RGB-D folder, 7-Scenes    ``/camera/depth``, ``/camera/color``,
folder (``frame-*.color.*``)                 ``/camera/camera_info``, ``/ground_truth``
trajectory file (TUM, KITTI, EuRoC)          ``/trajectory`` (pose)
==========================================  ================================================

Folder formats are read one frame at a time (only the file list is held), so a source's memory
does not grow with the recording. ``messages(skip=n)`` starts after the first ``n`` *items* of the
source (a resumed run): bag messages are skipped without being deserialised.
"""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from navkit.errors import DataNotFoundError, FormatError, InputError
from navkit.runtime.messages import CameraData, Message, ScanData

__all__ = [
    "BagSource",
    "CarmenSource",
    "KittiSource",
    "RGBDSource",
    "Source",
    "TrajectorySource",
    "open_source",
]

log = logging.getLogger(__name__)

PathLike = str | os.PathLike[str]

_DEPTH_ENCODINGS = {"16UC1", "mono16", "32FC1", "16SC1", "64FC1"}


class Source(Protocol):
    """What the runtime needs from a recording."""

    name: str
    topics: dict[str, str]  # topic -> message kind
    start_ns: int
    end_ns: int
    n_items: int

    def messages(self, skip: int = 0) -> Iterator[tuple[int, list[Message]]]:
        """``(item index, messages)`` in time order; an item is one record of the source."""
        ...


def _ns(seconds: float) -> int:
    return round(float(seconds) * 1e9)


def _planar_pose(x: float, y: float, theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = [x, y]
    return T


# --------------------------------------------------------------------------- ROS bags / MCAP
@dataclass
class BagSource:
    """A ROS 1 bag, ROS 2 bag folder or MCAP file read with ``rosbags`` (extra ``ros``)."""

    path: Path
    depth_scale: float = 1000.0
    name: str = ""
    topics: dict[str, str] = field(default_factory=dict)
    types: dict[str, str] = field(default_factory=dict)
    start_ns: int = 0
    end_ns: int = 0
    n_items: int = 0

    def __post_init__(self) -> None:
        from navkit.io import rosbag as rb

        info = rb.bag_info(self.path)
        self.name = str(self.path)
        kinds = {
            rb.POINTCLOUD2: "cloud",
            rb.LASERSCAN: "scan",
            rb.ODOMETRY: "pose",
            rb.POSESTAMPED: "pose",
            rb.POSECOVSTAMPED: "pose",
            rb.TFMESSAGE: "tf",
            rb.IMAGE: "image",
            rb.CAMERAINFO: "camera_info",
        }
        self.types = {t: typ for t, (typ, _) in info.topics.items()}
        self.topics = {t: kinds[typ] for t, typ in self.types.items() if typ in kinds}
        skipped = sorted(set(self.types) - set(self.topics))
        if skipped:
            log.info("%s: topics of no capability ignored: %s", self.path, skipped)
        self.start_ns, self.end_ns = info.start_ns, info.end_ns
        self.n_items = sum(info.topics[t][1] for t in self.topics)

    def messages(self, skip: int = 0) -> Iterator[tuple[int, list[Message]]]:
        from navkit.io import rosbag as rb

        k = skip
        for topic, typ, bag_ns, msg in rb.iter_raw_messages(self.path, list(self.topics), skip):
            src = f"{self.path}:{topic}"
            stamp = rb.stamp_ns(msg, bag_ns)
            frame = str(getattr(getattr(msg, "header", None), "frame_id", ""))
            out: list[Message]
            if typ == rb.POINTCLOUD2:
                cloud = rb.pointcloud_from_msg(msg, source=src)
                out = [Message(topic, "cloud", stamp, frame, cloud.points)]
            elif typ == rb.LASERSCAN:
                r, b, rmax = rb.laserscan_from_msg(msg, source=src)
                out = [Message(topic, "scan", stamp, frame, ScanData(r, b, rmax))]
            elif typ == rb.TFMESSAGE:
                out = [
                    Message(topic, "tf", st or bag_ns, parent, T, child)
                    for st, parent, child, T in rb.transforms_from_msg(msg)
                ]
            elif typ == rb.CAMERAINFO:
                cam = CameraData(*rb.camera_info_from_msg(msg, source=src))
                out = [Message(topic, "camera_info", stamp, frame, cam)]
            elif typ == rb.IMAGE:
                img = rb.image_from_msg(msg, source=src)
                if str(msg.encoding) in _DEPTH_ENCODINGS:
                    depth = img.astype(np.float64)
                    if img.dtype.kind in "iu":
                        depth /= self.depth_scale
                    depth[~(depth > 0)] = np.nan
                    out = [Message(topic, "depth", stamp, frame, depth)]
                else:
                    if img.ndim == 2:
                        img = np.repeat(img[..., None], 3, axis=2)
                    out = [Message(topic, "color", stamp, frame, img[..., :3])]
            else:
                T, child = rb.pose_from_msg(msg, typ, source=src)
                out = [Message(topic, "pose", stamp, frame, T, child)]
            yield k, out
            k += 1


# --------------------------------------------------------------------------- KITTI folders
def _read_kitti_tr(path: Path) -> np.ndarray:
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("Tr:"):
            vals = np.array(line.split()[1:], dtype=np.float64)
            if vals.size == 12:
                T = np.eye(4)
                T[:3] = vals.reshape(3, 4)
                return T
    raise FormatError(
        "no 'Tr:' line with 12 numbers",
        source=path,
        field="Tr",
        expected="Tr: the 3x4 Velodyne -> cam0 transform",
    )


@dataclass
class KittiSource:
    """A KITTI / SemanticKITTI sequence folder: ``*.bin`` scans, optional poses, calib, times.

    Poses (``poses*.txt``, cam0 poses ``T_w_cam0``) become Velodyne poses with the calibration's
    ``Tr`` (``T_w_velo = T_w_cam0 Tr``), re-expressed relative to the first Velodyne pose so the
    world frame is the first scan's (x forward, y left, z up), frame id ``odom``. Without a
    ``times*.txt`` the scans are 0.1 s apart (10 Hz).
    """

    path: Path
    name: str = ""
    topics: dict[str, str] = field(default_factory=dict)
    start_ns: int = 0
    end_ns: int = 0
    n_items: int = 0
    files: list[Path] = field(default_factory=list)
    times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    poses: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.name = str(self.path)
        self.files = sorted(self.path.glob("*.bin"))
        if not self.files:
            raise InputError("has no .bin scans", source=self.path, expected="KITTI *.bin files")
        n = len(self.files)
        times = sorted(self.path.glob("times*.txt"))
        if times:
            t = np.loadtxt(times[0], dtype=np.float64, ndmin=1)
            if len(t) < n:
                raise FormatError(
                    f"has {len(t)} times for {n} scans",
                    source=times[0],
                    field="times",
                    expected="one time per scan",
                )
            self.times = t[:n]
        else:
            self.times = 0.1 * np.arange(n)
        poses = sorted(self.path.glob("poses*.txt"))
        self.topics = {"/velodyne_points": "cloud"}
        if poses:
            from navkit.io.trajectory import read_kitti_poses

            P = read_kitti_poses(poses[0]).poses
            if len(P) < n:
                raise FormatError(
                    f"has {len(P)} poses for {n} scans",
                    source=poses[0],
                    field="poses",
                    expected="one pose per scan",
                )
            calib = sorted(self.path.glob("calib*.txt"))
            Tr = _read_kitti_tr(calib[0]) if calib else np.eye(4)
            T_w_velo = P[:n] @ Tr
            self.poses = np.linalg.inv(T_w_velo[0]) @ T_w_velo
            self.topics["/ground_truth"] = "pose"
        self.start_ns, self.end_ns = _ns(self.times[0]), _ns(self.times[-1])
        self.n_items = n

    def messages(self, skip: int = 0) -> Iterator[tuple[int, list[Message]]]:
        from navkit.io.pointcloud import read_kitti_bin

        for k in range(skip, len(self.files)):
            st = _ns(self.times[k])
            out = []
            if self.poses is not None:
                out.append(Message("/ground_truth", "pose", st, "odom", self.poses[k], "velodyne"))
            pts = read_kitti_bin(self.files[k])[:, :3].astype(np.float64)
            out.append(Message("/velodyne_points", "cloud", st, "velodyne", pts))
            yield k, out


# --------------------------------------------------------------------------- CARMEN logs
@dataclass
class CarmenSource:
    """A CARMEN log: per scan ``/odom`` (raw odometry), ``/ground_truth`` (corrected pose) and
    ``/scan``, all at the scan's logger timestamp, frame ids ``odom`` / ``map`` / ``laser``."""

    path: Path
    name: str = ""
    topics: dict[str, str] = field(default_factory=dict)
    start_ns: int = 0
    end_ns: int = 0
    n_items: int = 0
    log: Any = None

    def __post_init__(self) -> None:
        from navkit.io.carmen import read_carmen

        self.name = str(self.path)
        self.log = read_carmen(self.path)
        self.topics = {"/odom": "pose", "/ground_truth": "pose", "/scan": "scan"}
        t = self.log.timestamps
        self.start_ns, self.end_ns, self.n_items = _ns(t[0]), _ns(t[-1]), len(self.log)

    def messages(self, skip: int = 0) -> Iterator[tuple[int, list[Message]]]:
        lg = self.log
        rmax = float(np.nanmax(lg.ranges)) if np.isfinite(lg.ranges).any() else np.inf
        for k in range(skip, len(lg)):
            st = _ns(lg.timestamps[k])
            yield (
                k,
                [
                    Message("/odom", "pose", st, "odom", _planar_pose(*lg.odom_poses[k]), "laser"),
                    Message(
                        "/ground_truth", "pose", st, "map", _planar_pose(*lg.poses[k]), "laser"
                    ),
                    Message(
                        "/scan", "scan", st, "laser", ScanData(lg.ranges[k], lg.bearings, rmax)
                    ),
                ],
            )


# --------------------------------------------------------------------------- RGB-D folders
def _seven_scenes_intrinsics(folder: Path) -> tuple[float, float, float, float]:
    f = folder / "camera-intrinsics.txt"
    if not f.is_file():
        return 585.0, 585.0, 320.0, 240.0  # the published 7-Scenes intrinsics
    K = np.loadtxt(f, dtype=np.float64)
    if K.shape != (3, 3):
        raise FormatError(f"has shape {K.shape}", source=f, expected="a 3x3 intrinsics matrix")
    return float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])


@dataclass
class RGBDSource:
    """A TUM RGB-D folder, the simple ``color/`` + ``depth/`` layout or a 7-Scenes folder.

    Per frame: ``/camera/camera_info`` (first frame only), ``/ground_truth`` (when the folder
    has poses: TUM ``groundtruth.txt`` / simple ``pose.txt`` / 7-Scenes ``frame-*.pose.txt``),
    ``/camera/depth`` and ``/camera/color``. 7-Scenes frames are 30 Hz apart.
    """

    path: Path
    intrinsics: tuple[float, float, float, float] | None = None
    depth_scale: float = 1000.0
    name: str = ""
    topics: dict[str, str] = field(default_factory=dict)
    start_ns: int = 0
    end_ns: int = 0
    n_items: int = 0
    color: list[Path] = field(default_factory=list)
    depth: list[Path] = field(default_factory=list)
    pose_files: list[Path] = field(default_factory=list)
    times: np.ndarray = field(default_factory=lambda: np.zeros(0))
    poses: np.ndarray | None = None
    camera: CameraData | None = None

    def __post_init__(self) -> None:
        from navkit.io.images import read_image

        self.name = str(self.path)
        seven = sorted(self.path.glob("frame-*.color.*"))
        if seven:
            self.color = seven
            self.depth = [self.path / (p.name.split(".")[0] + ".depth.png") for p in seven]
            self.pose_files = [self.path / (p.name.split(".")[0] + ".pose.txt") for p in seven]
            self.times = np.arange(len(seven)) / 30.0
            fx, fy, cx, cy = self.intrinsics or _seven_scenes_intrinsics(self.path)
            h, w = read_image(self.depth[0]).shape[:2]
        else:
            from navkit.io.rgbd import open_rgbd_sequence

            cam = None
            if self.intrinsics is not None:
                fx, fy, cx, cy = self.intrinsics
                cam = {"fx": fx, "fy": fy, "cx": cx, "cy": cy, "depth_scale": self.depth_scale}
            seq = open_rgbd_sequence(self.path, cam)
            self.color, self.depth = list(seq.color_paths), list(seq.depth_paths)
            self.times = np.asarray(seq.timestamps, dtype=np.float64)
            c = seq.camera
            fx, fy, cx, cy, w, h = c.fx, c.fy, c.cx, c.cy, c.width, c.height
            self.depth_scale = seq.depth_scale
            self.poses = self._folder_poses()
        self.camera = CameraData(fx, fy, cx, cy, int(w), int(h))
        self.topics = {
            "/camera/camera_info": "camera_info",
            "/camera/depth": "depth",
            "/camera/color": "color",
        }
        if self.pose_files or self.poses is not None:
            self.topics["/ground_truth"] = "pose"
        self.start_ns, self.end_ns = _ns(self.times[0]), _ns(self.times[-1])
        self.n_items = len(self.color)

    def _folder_poses(self) -> np.ndarray | None:
        from navkit.io.trajectory import read_tum

        pose_txt = self.path / "pose.txt"
        if pose_txt.is_file():  # one "tx ty tz qx qy qz qw" per frame (slambook layout)
            from scipy.spatial.transform import Rotation

            v = np.loadtxt(pose_txt, dtype=np.float64, ndmin=2)
            if v.shape[1] != 7 or len(v) < len(self.color):
                return None
            T = np.tile(np.eye(4), (len(v), 1, 1))
            T[:, :3, :3] = Rotation.from_quat(v[:, 3:7]).as_matrix()
            T[:, :3, 3] = v[:, :3]
            return T[: len(self.color)]
        gt = self.path / "groundtruth.txt"
        if gt.is_file():
            tr = read_tum(gt)
            idx = np.clip(np.searchsorted(tr.timestamps, self.times), 0, len(tr.timestamps) - 1)
            return np.asarray(tr.poses[idx])
        return None

    def messages(self, skip: int = 0) -> Iterator[tuple[int, list[Message]]]:
        from navkit.io.images import read_depth, read_image

        for k in range(skip, len(self.color)):
            st = _ns(self.times[k])
            out = []
            if k == skip:
                out.append(Message("/camera/camera_info", "camera_info", st, "camera", self.camera))
            T = None
            if self.pose_files:
                T = np.loadtxt(self.pose_files[k], dtype=np.float64)
            elif self.poses is not None:
                T = self.poses[k]
            if T is not None:
                out.append(Message("/ground_truth", "pose", st, "world", T, "camera"))
            depth = read_depth(self.depth[k], self.depth_scale)
            color = read_image(self.color[k])
            if color.ndim == 2:
                color = np.repeat(color[..., None], 3, axis=2)
            if color.dtype != np.uint8:
                color = (color.astype(np.float64) / 257.0).round().astype(np.uint8)
            out.append(Message("/camera/depth", "depth", st, "camera", depth))
            out.append(Message("/camera/color", "color", st, "camera", color[..., :3]))
            yield k, out


# --------------------------------------------------------------------------- trajectories
@dataclass
class TrajectorySource:
    """A trajectory file (TUM, KITTI or EuRoC, sniffed by :func:`navkit.io.trajectory.read_trajectory`)."""

    path: Path
    name: str = ""
    topics: dict[str, str] = field(default_factory=dict)
    start_ns: int = 0
    end_ns: int = 0
    n_items: int = 0
    traj: Any = None

    def __post_init__(self) -> None:
        from navkit.io.trajectory import read_trajectory

        self.name = str(self.path)
        self.traj = read_trajectory(self.path)
        self.topics = {"/trajectory": "pose"}
        t = self.traj.timestamps
        self.start_ns, self.end_ns, self.n_items = _ns(t[0]), _ns(t[-1]), len(t)

    def messages(self, skip: int = 0) -> Iterator[tuple[int, list[Message]]]:
        t, P = self.traj.timestamps, self.traj.poses
        for k in range(skip, len(t)):
            yield k, [Message("/trajectory", "pose", _ns(t[k]), "world", P[k], "body")]


def open_source(
    path: PathLike,
    *,
    intrinsics: tuple[float, float, float, float] | None = None,
    depth_scale: float = 1000.0,
) -> Source:
    """The reader for a recording (see the module docstring for what is recognised).

    Raises
    ------
    DataNotFoundError
        If ``path`` does not exist.
    InputError
        If it is none of the recognised kinds.
    """
    p = Path(path)
    if not p.exists():
        raise DataNotFoundError(f"{p}: no such recording (file or folder)")
    name = p.name.lower()
    if p.is_dir():
        if (p / "metadata.yaml").is_file() or any(p.glob("*.db3")) or any(p.glob("*.mcap")):
            return BagSource(p, depth_scale=depth_scale)
        if any(p.glob("*.bin")):
            return KittiSource(p)
        if any(p.glob("frame-*.color.*")) or (p / "rgb.txt").is_file() or (p / "color").is_dir():
            return RGBDSource(p, intrinsics=intrinsics, depth_scale=depth_scale)
    else:
        if name.endswith((".bag", ".mcap", ".db3")):
            return BagSource(p, depth_scale=depth_scale)
        if re.search(r"\.log(\.gz)?$", name) or name.endswith(".gz"):
            return CarmenSource(p)
        if name.endswith((".txt", ".tum", ".csv", ".kitti")):
            return TrajectorySource(p)
    raise InputError(
        "is not a recording navkit can stream",
        source=p,
        expected="a ROS 1 .bag, a ROS 2 bag folder, an .mcap file, a KITTI sequence folder, "
        "a CARMEN .log(.gz), a TUM RGB-D / 7-Scenes folder or a trajectory file",
    )
