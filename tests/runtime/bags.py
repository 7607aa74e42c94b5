"""Write real recordings as ROS bags with ``rosbags``' writers (ROS 2 mcap storage, ROS 1)."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np


def _typestore(ros1: bool):
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)


class _BagWriter:
    """One writer API over rosbags' ROS 1 and ROS 2 (mcap storage) writers."""

    def __init__(self, path: Path, ros1: bool) -> None:
        self.ros1 = ros1
        self.ts = _typestore(ros1)
        if ros1:
            from rosbags.rosbag1 import Writer

            self.w = Writer(path)
        else:
            from rosbags.rosbag2 import StoragePlugin, Writer

            self.w = Writer(path, version=8, storage_plugin=StoragePlugin.MCAP)
        self.conns: dict[str, object] = {}

    def __enter__(self):
        self.w.open()
        return self

    def __exit__(self, *exc):
        self.w.close()

    def header(self, stamp_ns: int, frame: str):
        T = self.ts.types
        extra = {"seq": 0} if self.ros1 else {}
        return T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](
                sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000
            ),
            frame_id=frame,
            **extra,
        )

    def write(self, topic: str, stamp_ns: int, msg) -> None:
        typ = msg.__msgtype__
        if topic not in self.conns:
            self.conns[topic] = self.w.add_connection(topic, typ, typestore=self.ts)
        raw = self.ts.serialize_ros1(msg, typ) if self.ros1 else self.ts.serialize_cdr(msg, typ)
        self.w.write(self.conns[topic], stamp_ns, raw)

    def odometry(self, stamp_ns: int, frame: str, child: str, T: np.ndarray):
        from scipy.spatial.transform import Rotation

        M = self.ts.types
        q = Rotation.from_matrix(T[:3, :3]).as_quat()
        pose = M["geometry_msgs/msg/Pose"](
            position=M["geometry_msgs/msg/Point"](x=T[0, 3], y=T[1, 3], z=T[2, 3]),
            orientation=M["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
        )
        zero3 = M["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        return M["nav_msgs/msg/Odometry"](
            header=self.header(stamp_ns, frame),
            child_frame_id=child,
            pose=M["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            twist=M["geometry_msgs/msg/TwistWithCovariance"](
                twist=M["geometry_msgs/msg/Twist"](linear=zero3, angular=zero3),
                covariance=np.zeros(36),
            ),
        )


def kitti_velodyne_poses(folder: Path, n: int) -> np.ndarray:
    """Velodyne poses of the first ``n`` scans relative to the first (from the cam0 poses and Tr)."""
    P = np.loadtxt(next(folder.glob("poses*.txt"))).reshape(-1, 3, 4)[:n]
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3] = P
    line = next(
        ln
        for ln in next(folder.glob("calib*.txt")).read_text().splitlines()
        if ln.startswith("Tr:")
    )
    Tr = np.eye(4)
    Tr[:3] = np.array(line.split()[1:], dtype=float).reshape(3, 4)
    V = T @ Tr
    return np.linalg.inv(V[0]) @ V


def write_kitti_bag(folder: Path, dest: Path, ros1: bool) -> list[Path]:
    """SemanticKITTI scans as ``/velodyne_points`` (x y z intensity float32) and their ground
    truth poses as ``/ground_truth`` (``nav_msgs/Odometry``) at the scans' times."""
    bins = sorted(folder.glob("*.bin"))
    times = np.loadtxt(next(folder.glob("times*.txt")))[: len(bins)]
    poses = kitti_velodyne_poses(folder, len(bins))
    with _BagWriter(dest, ros1) as w:
        M = w.ts.types
        PF = M["sensor_msgs/msg/PointField"]
        fields = [PF(name=c, offset=4 * i, datatype=7, count=1) for i, c in enumerate("xyz")]
        fields.append(PF(name="intensity", offset=12, datatype=7, count=1))
        for k, b in enumerate(bins):
            st = round(times[k] * 1e9) + 1_000_000_000
            w.write("/ground_truth", st, w.odometry(st, "odom", "velodyne", poses[k]))
            data = np.fromfile(b, dtype="<f4")
            n = data.size // 4
            cloud = M["sensor_msgs/msg/PointCloud2"](
                header=w.header(st, "velodyne"),
                height=1,
                width=n,
                fields=fields,
                is_bigendian=False,
                point_step=16,
                row_step=16 * n,
                data=data.view(np.uint8),
                is_dense=True,
            )
            w.write("/velodyne_points", st, cloud)
    return bins


def split_carmen(log_gz: Path, dest_dir: Path) -> tuple[Path, Path]:
    """The log's first and second half (by FLASER count) as two plain CARMEN logs."""
    with gzip.open(log_gz, "rt", encoding="utf-8", errors="replace") as fh:
        lines = fh.read().splitlines()
    scans = [i for i, ln in enumerate(lines) if ln.startswith("FLASER")]
    cut = scans[len(scans) // 2]
    head = [ln for ln in lines[:cut] if not ln.startswith(("FLASER", "ODOM"))]
    first, second = dest_dir / "first.log", dest_dir / "second.log"
    first.write_text("\n".join(lines[:cut]) + "\n")
    second.write_text("\n".join(head + lines[cut:]) + "\n")
    return first, second


def write_carmen_bag(log_path: Path, dest: Path, ros1: bool, every: int = 1) -> int:
    """Every ``every``-th scan of a CARMEN log as ``/scan`` (``sensor_msgs/LaserScan``), its
    odometry as ``/odom`` and its corrected pose as ``/ground_truth`` (``nav_msgs/Odometry``)."""
    from navkit.io.carmen import read_carmen

    lg = read_carmen(log_path)
    sel = np.arange(0, len(lg), every)
    n = lg.ranges.shape[1]

    def planar(x, y, th):
        T = np.eye(4)
        T[:2, :2] = [[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]]
        T[:2, 3] = x, y
        return T

    with _BagWriter(dest, ros1) as w:
        M = w.ts.types
        for k in sel:
            st = round(lg.timestamps[k] * 1e9)
            w.write("/odom", st, w.odometry(st, "odom", "laser", planar(*lg.odom_poses[k])))
            w.write("/ground_truth", st, w.odometry(st, "map", "laser", planar(*lg.poses[k])))
            r = np.where(np.isfinite(lg.ranges[k]), lg.ranges[k], np.inf).astype(np.float32)
            scan = M["sensor_msgs/msg/LaserScan"](
                header=w.header(st, "laser"),
                angle_min=float(lg.bearings[0]),
                angle_max=float(lg.bearings[-1]),
                angle_increment=float((lg.bearings[-1] - lg.bearings[0]) / (n - 1)),
                time_increment=0.0,
                scan_time=0.0,
                range_min=0.0,
                range_max=81.0,
                ranges=r,
                intensities=np.zeros(0, np.float32),
            )
            w.write("/scan", st, scan)
    return len(sel)


def transform_msg(w: _BagWriter, stamp_ns: int, parent: str, child: str, T: np.ndarray):
    """A ``geometry_msgs/TransformStamped`` ``T_parent_child``."""
    from scipy.spatial.transform import Rotation

    M = w.ts.types
    q = Rotation.from_matrix(T[:3, :3]).as_quat()
    return M["geometry_msgs/msg/TransformStamped"](
        header=w.header(stamp_ns, parent),
        child_frame_id=child,
        transform=M["geometry_msgs/msg/Transform"](
            translation=M["geometry_msgs/msg/Vector3"](x=T[0, 3], y=T[1, 3], z=T[2, 3]),
            rotation=M["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
        ),
    )


def planar_pose(x: float, y: float, th: float, z: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    T[:2, :2] = [[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]]
    T[:3, 3] = x, y, z
    return T


def write_robot_bag(log_path: Path, dest: Path, T_base_laser: np.ndarray, ros1: bool = False):
    """A CARMEN log as a robot records it: ``/scan`` in frame ``laser`` mounted at
    ``T_base_laser`` on ``base_link`` (``/tf_static``), wheel odometry of ``base_link`` on
    ``/odom`` (``nav_msgs/Odometry``) and ``/tf`` (odom -> base_link), the corrected pose of
    ``base_link`` on ``/ground_truth`` (map -> base_link). The log's poses are the laser's: the
    base is ``T_laser inv(T_base_laser)`` (the laser at the mounting's height). Returns the
    scans' stamps (ns) and the true ``T_map_base`` of each."""
    from navkit.io.carmen import read_carmen

    lg = read_carmen(log_path)
    n = lg.ranges.shape[1]
    h = float(T_base_laser[2, 3])
    inv = np.linalg.inv(T_base_laser)
    stamps, truth = [], []
    with _BagWriter(dest, ros1) as w:
        M = w.ts.types
        TF = M["tf2_msgs/msg/TFMessage"]
        t0 = round(lg.timestamps[0] * 1e9)
        w.write(
            "/tf_static",
            t0,
            TF(transforms=[transform_msg(w, t0, "base_link", "laser", T_base_laser)]),
        )
        for k in range(len(lg)):
            st = round(lg.timestamps[k] * 1e9)
            T_odom_base = planar_pose(*lg.odom_poses[k], z=h) @ inv
            T_map_base = planar_pose(*lg.poses[k], z=h) @ inv
            w.write("/odom", st, w.odometry(st, "odom", "base_link", T_odom_base))
            w.write(
                "/tf", st, TF(transforms=[transform_msg(w, st, "odom", "base_link", T_odom_base)])
            )
            w.write("/ground_truth", st, w.odometry(st, "map", "base_link", T_map_base))
            r = np.where(np.isfinite(lg.ranges[k]), lg.ranges[k], np.inf).astype(np.float32)
            scan = M["sensor_msgs/msg/LaserScan"](
                header=w.header(st, "laser"),
                angle_min=float(lg.bearings[0]),
                angle_max=float(lg.bearings[-1]),
                angle_increment=float((lg.bearings[-1] - lg.bearings[0]) / (n - 1)),
                time_increment=0.0,
                scan_time=0.0,
                range_min=0.0,
                range_max=81.0,
                ranges=r,
                intensities=np.zeros(0, np.float32),
            )
            w.write("/scan", st, scan)
            stamps.append(st)
            truth.append(T_map_base)
    return np.array(stamps), np.array(truth)
