"""Point clouds and images from ROS bags (ROS1 ``.bag`` files and ROS2 bag folders).

Needs the optional extra ``rosbag`` (the pure-Python ``rosbags`` library, no ROS install):
``pip install 'navkit[rosbag]'``. The library is imported only when a function here is called.

- ``sensor_msgs/PointCloud2`` -> :class:`navkit.io.pointcloud.PointCloud` (fields decoded with a
  structured dtype built from the message's field offsets, row padding and big-endian data
  handled, ``height > 1`` kept as an organised cloud, NaN points kept, packed ``rgb`` unpacked).
- ``sensor_msgs/Image`` -> NumPy arrays: ``rgb8``/``bgr8`` -> ``(H, W, 3)`` RGB uint8,
  ``rgba8``/``bgra8`` -> RGBA, ``mono8``/``8UC1`` -> ``(H, W)`` uint8, ``mono16``/``16UC1`` ->
  uint16 (raw depth units), ``32FC1`` -> float32 (metres for depth).

Timestamps are the message header stamps in seconds (the bag's receive time when the header
stamp is zero).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from navkit.errors import DataNotFoundError, FormatError, require_module
from navkit.io.pointcloud import PointCloud

__all__ = [
    "BagInfo",
    "BagMessage",
    "bag_info",
    "camera_info_from_msg",
    "image_from_msg",
    "iter_images",
    "iter_pointclouds",
    "iter_raw_messages",
    "laserscan_from_msg",
    "list_topics",
    "pointcloud_from_msg",
    "pose_from_msg",
    "stamp_ns",
    "transforms_from_msg",
]

log = logging.getLogger(__name__)

PathLike = str | os.PathLike[str]

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
IMAGE = "sensor_msgs/msg/Image"
LASERSCAN = "sensor_msgs/msg/LaserScan"
CAMERAINFO = "sensor_msgs/msg/CameraInfo"
ODOMETRY = "nav_msgs/msg/Odometry"
POSESTAMPED = "geometry_msgs/msg/PoseStamped"
POSECOVSTAMPED = "geometry_msgs/msg/PoseWithCovarianceStamped"
TFMESSAGE = "tf2_msgs/msg/TFMessage"

# sensor_msgs/PointField datatypes
_POINTFIELD_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}

# sensor_msgs/Image encodings: (dtype, channels, to RGB channel order)
_IMAGE_ENCODINGS: dict[str, tuple[str, int, list[int] | None]] = {
    "rgb8": ("u1", 3, None),
    "bgr8": ("u1", 3, [2, 1, 0]),
    "rgba8": ("u1", 4, None),
    "bgra8": ("u1", 4, [2, 1, 0, 3]),
    "rgb16": ("u2", 3, None),
    "bgr16": ("u2", 3, [2, 1, 0]),
    "mono8": ("u1", 1, None),
    "mono16": ("u2", 1, None),
    "8UC1": ("u1", 1, None),
    "8UC3": ("u1", 3, None),
    "16UC1": ("u2", 1, None),
    "16SC1": ("i2", 1, None),
    "32FC1": ("f4", 1, None),
    "64FC1": ("f8", 1, None),
}


@dataclass(frozen=True)
class BagMessage:
    """One decoded message: its topic, stamp (s), frame id and data (a PointCloud or an array)."""

    topic: str
    timestamp: float
    frame_id: str
    data: Any
    encoding: str = ""


def _stamp(msg: Any, bag_ns: int) -> float:
    st = getattr(getattr(msg, "header", None), "stamp", None)
    if st is not None:
        sec = int(getattr(st, "sec", 0))
        nsec = int(getattr(st, "nanosec", getattr(st, "nsec", 0)))
        if sec or nsec:
            return sec + nsec * 1e-9
    return bag_ns * 1e-9


def pointcloud_from_msg(msg: Any, source: str = "PointCloud2") -> PointCloud:
    """Decode a ``sensor_msgs/PointCloud2`` message (as deserialised by rosbags).

    Raises
    ------
    FormatError
        Missing x/y/z, unknown field datatypes, fields past ``point_step``, short data.
    """
    h, w = int(msg.height), int(msg.width)
    n = h * w
    step, row_step = int(msg.point_step), int(msg.row_step)
    order = ">" if msg.is_bigendian else "<"
    names, formats, offsets = [], [], []
    for f in msg.fields:
        if int(f.datatype) not in _POINTFIELD_TYPES:
            raise FormatError(
                f"unknown datatype {f.datatype}",
                source=source,
                field=f.name,
                expected="PointField datatype 1..8",
            )
        base = order + _POINTFIELD_TYPES[int(f.datatype)]
        count = max(int(f.count), 1)
        names.append(f.name)
        formats.append(base if count == 1 else (base, (count,)))
        offsets.append(int(f.offset))
    try:
        dt = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": step})
    except ValueError as exc:
        raise FormatError(
            f"fields do not fit point_step {step}: {exc}",
            source=source,
            field="fields",
            expected="fields within point_step",
        ) from None
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if row_step < w * step or len(data) < h * row_step:
        raise FormatError(
            f"data has {len(data)} bytes, row_step {row_step}, point_step {step}",
            source=source,
            field="data",
            expected=f"{h} rows of >= {w * step} bytes",
        )
    rows = data[: h * row_step].reshape(h, row_step)[:, : w * step]
    rec = np.ascontiguousarray(rows).view(dt).reshape(n)
    for axis in "xyz":
        if axis not in names:
            raise FormatError(
                f"no field {axis!r} among {names}",
                source=source,
                field="fields",
                expected="x, y, z",
            )
    points = np.column_stack([rec["x"], rec["y"], rec["z"]]).astype(np.float64)
    fields: dict[str, NDArray[Any]] = {}
    colors = None
    for name in names:
        if name in "xyz":
            continue
        vals = np.ascontiguousarray(rec[name]).astype(rec[name].dtype.newbyteorder("="))
        if (
            name in ("rgb", "rgba")
            and vals.ndim == 1
            and vals.dtype.itemsize == 4
            and colors is None
        ):
            u = vals.view(np.uint32)
            colors = np.column_stack([(u >> 16) & 0xFF, (u >> 8) & 0xFF, u & 0xFF]).astype(np.uint8)
            if name == "rgba":
                fields["alpha"] = ((u >> 24) & 0xFF).astype(np.uint8)
            continue
        fields[name] = vals
    return PointCloud(points, fields, w, h, colors=colors)


def image_from_msg(msg: Any, source: str = "Image") -> NDArray[Any]:
    """Decode a ``sensor_msgs/Image`` message into an array (RGB channel order for colour)."""
    enc = str(msg.encoding)
    if enc not in _IMAGE_ENCODINGS:
        raise FormatError(
            f"unsupported encoding {enc!r}",
            source=source,
            field="encoding",
            expected=", ".join(_IMAGE_ENCODINGS),
        )
    base, ch, perm = _IMAGE_ENCODINGS[enc]
    dtype = np.dtype((">" if msg.is_bigendian else "<") + base)
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    row_bytes = w * ch * dtype.itemsize
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if step < row_bytes or len(data) < h * step:
        raise FormatError(
            f"data has {len(data)} bytes, step {step}",
            source=source,
            field="data",
            expected=f"{h} rows of >= {row_bytes} bytes",
        )
    rows = np.ascontiguousarray(data[: h * step].reshape(h, step)[:, :row_bytes])
    img = (
        rows.view(dtype).reshape((h, w) if ch == 1 else (h, w, ch)).astype(dtype.newbyteorder("="))
    )
    if perm is not None:
        img = img[..., perm]
    return np.ascontiguousarray(img)


@contextmanager
def _open_reader(path: PathLike) -> Iterator[Any]:
    p = Path(path)
    if not p.exists():
        raise DataNotFoundError(f"{p}: no such bag file or folder")
    highlevel = require_module("rosbags.highlevel", "rosbag", "reading ROS bags")
    stores = require_module("rosbags.typesys", "rosbag", "reading ROS bags")
    typestore = stores.get_typestore(stores.Stores.LATEST)
    reader = highlevel.AnyReader([p], default_typestore=typestore)
    try:
        reader.open()
    except Exception as exc:  # rosbags raises its own error types for unreadable bags
        reader = _scan_instead(p, exc)
    try:
        yield reader
    finally:
        reader.close()


def _scan_instead(p: Path, exc: Exception) -> Any:
    """A bag rosbags cannot open (index missing, damaged or in a layout it rejects): its records
    scanned up to the last whole message (:mod:`navkit.io.bag_recovery`), with one warning."""
    from navkit.io.bag_recovery import scan_bag

    reason = " ".join(str(exc).split()) or type(exc).__name__
    try:
        bag = scan_bag(p)
    except (FormatError, OSError) as scan_exc:
        raise FormatError(
            f"cannot open as a ROS bag ({reason}), and scanning its records found none: {scan_exc}",
            source=p,
            field="bag",
            expected="a ROS 1 .bag file, a ROS 2 bag folder or an .mcap file",
        ) from None
    key = (str(p.resolve()), bag.n_messages)
    if key not in _WARNED:  # one warning per bag, however often it is opened
        _WARNED.add(key)
        log.warning(
            "%s: the index is missing or unreadable (%s); read by scanning its records: "
            "%d messages recovered, up to the last whole one",
            p,
            reason,
            bag.n_messages,
        )
    return bag


_WARNED: set[tuple[str, int]] = set()


def list_topics(path: PathLike) -> dict[str, tuple[str, int]]:
    """``{topic: (message type, message count)}`` of a bag."""
    with _open_reader(path) as reader:
        out: dict[str, tuple[str, int]] = {}
        for c in reader.connections:
            typ, cnt = out.get(c.topic, (c.msgtype, 0))
            out[c.topic] = (typ, cnt + int(c.msgcount))
        return out


def _iter(
    path: PathLike, msgtype: str, topics: Sequence[str] | str | None
) -> Iterator[tuple[str, int, Any]]:
    wanted = [topics] if isinstance(topics, str) else topics
    with _open_reader(path) as reader:
        conns = [
            c
            for c in reader.connections
            if c.msgtype == msgtype and (wanted is None or c.topic in wanted)
        ]
        if wanted is not None:
            missing = set(wanted) - {c.topic for c in conns}
            if missing:
                have = sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections})
                raise FormatError(
                    f"no {msgtype} topic {sorted(missing)}",
                    source=path,
                    field="topic",
                    expected=f"one of {have}",
                )
        for conn, bag_ns, raw in reader.messages(connections=conns):
            yield conn.topic, bag_ns, reader.deserialize(raw, conn.msgtype)


def iter_pointclouds(
    path: PathLike, topics: Sequence[str] | str | None = None
) -> Iterator[BagMessage]:
    """Iterate the ``sensor_msgs/PointCloud2`` messages of a bag (all topics, or ``topics``).

    Yields
    ------
    BagMessage
        ``data`` is a :class:`~navkit.io.pointcloud.PointCloud`.
    """
    for topic, bag_ns, msg in _iter(path, POINTCLOUD2, topics):
        cloud = pointcloud_from_msg(msg, source=f"{path}:{topic}")
        yield BagMessage(topic, _stamp(msg, bag_ns), str(msg.header.frame_id), cloud)


def iter_images(path: PathLike, topics: Sequence[str] | str | None = None) -> Iterator[BagMessage]:
    """Iterate the ``sensor_msgs/Image`` messages of a bag as arrays (``encoding`` kept)."""
    for topic, bag_ns, msg in _iter(path, IMAGE, topics):
        img = image_from_msg(msg, source=f"{path}:{topic}")
        yield BagMessage(
            topic, _stamp(msg, bag_ns), str(msg.header.frame_id), img, str(msg.encoding)
        )


# --------------------------------------------------------------------------- streaming access
@dataclass(frozen=True)
class BagInfo:
    """What a bag holds: ``{topic: (type, count)}``, first / last message time (ns), total count."""

    topics: dict[str, tuple[str, int]]
    start_ns: int
    end_ns: int
    n_messages: int


def bag_info(path: PathLike) -> BagInfo:
    """Topics, types, counts and time span of a ROS1 bag, ROS2 bag folder or ``.mcap`` file."""
    with _open_reader(path) as reader:
        topics: dict[str, tuple[str, int]] = {}
        for c in reader.connections:
            typ, cnt = topics.get(c.topic, (c.msgtype, 0))
            topics[c.topic] = (typ, cnt + int(c.msgcount))
        n = sum(cnt for _, cnt in topics.values())
        return BagInfo(topics, int(reader.start_time), int(reader.end_time), n)


def iter_raw_messages(
    path: PathLike, topics: Sequence[str] | None = None, skip: int = 0
) -> Iterator[tuple[str, str, int, Any]]:
    """Deserialised messages of a bag in time order: ``(topic, type, bag time ns, message)``.

    ``skip`` messages (of the selected topics) are passed over without being deserialised, so a
    resumed run starts where it stopped at the cost of reading the raw bytes only.
    """
    with _open_reader(path) as reader:
        conns = [c for c in reader.connections if topics is None or c.topic in topics]
        for k, (conn, bag_ns, raw) in enumerate(reader.messages(connections=conns)):
            if k < skip:
                continue
            yield conn.topic, conn.msgtype, int(bag_ns), reader.deserialize(raw, conn.msgtype)


def stamp_ns(msg: Any, bag_ns: int) -> int:
    """Header stamp of a message in ns (the bag's receive time when the stamp is zero)."""
    st = getattr(getattr(msg, "header", None), "stamp", None)
    if st is not None:
        sec = int(getattr(st, "sec", 0))
        nsec = int(getattr(st, "nanosec", getattr(st, "nsec", 0)))
        if sec or nsec:
            return sec * 1_000_000_000 + nsec
    return int(bag_ns)


def laserscan_from_msg(
    msg: Any, source: str = "LaserScan"
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """``(ranges (B,), bearings (B,), range_max)`` of a ``sensor_msgs/LaserScan``.

    Ranges outside ``[range_min, range_max]`` and non-finite ones become NaN (no return);
    bearings are ``angle_min + k * angle_increment`` (radians, 0 forward, positive left).
    """
    r = np.asarray(msg.ranges, dtype=np.float64).copy()
    if r.ndim != 1 or len(r) == 0:
        raise FormatError(
            f"has {r.size} ranges", source=source, field="ranges", expected="at least one range"
        )
    inc = float(msg.angle_increment)
    if not np.isfinite(inc) or inc == 0.0:
        raise FormatError(
            f"angle_increment = {inc}",
            source=source,
            field="angle_increment",
            expected="a finite non-zero angle step (rad)",
        )
    rmin, rmax = float(msg.range_min), float(msg.range_max)
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(r) | (r < rmin) | (r > rmax) | (r <= 0)
    r[bad] = np.nan
    bearings = float(msg.angle_min) + inc * np.arange(len(r), dtype=np.float64)
    return r, bearings, rmax


def _pose_matrix(position: Any, orientation: Any) -> NDArray[np.float64]:
    from scipy.spatial.transform import Rotation

    q = np.array([orientation.x, orientation.y, orientation.z, orientation.w], dtype=np.float64)
    n = float(np.linalg.norm(q))
    T = np.eye(4)
    T[:3, :3] = np.eye(3) if n < 1e-12 else Rotation.from_quat(q / n).as_matrix()
    T[:3, 3] = [position.x, position.y, position.z]
    return T


def pose_from_msg(msg: Any, msgtype: str, source: str = "pose") -> tuple[NDArray[np.float64], str]:
    """``(T_parent_child (4, 4), child frame id)`` of an Odometry / PoseStamped /
    PoseWithCovarianceStamped message (the parent frame is the header's ``frame_id``)."""
    if msgtype == ODOMETRY:
        p = msg.pose.pose
        child = str(msg.child_frame_id)
    elif msgtype == POSESTAMPED:
        p = msg.pose
        child = ""
    elif msgtype == POSECOVSTAMPED:
        p = msg.pose.pose
        child = ""
    else:
        raise FormatError(
            f"message type {msgtype}",
            source=source,
            field="type",
            expected="nav_msgs/Odometry, geometry_msgs/PoseStamped or PoseWithCovarianceStamped",
        )
    return _pose_matrix(p.position, p.orientation), child


def transforms_from_msg(msg: Any) -> list[tuple[int, str, str, NDArray[np.float64]]]:
    """``[(stamp ns, parent frame, child frame, T_parent_child)]`` of a ``tf2_msgs/TFMessage``."""
    out = []
    for t in msg.transforms:
        tr = t.transform
        out.append(
            (
                stamp_ns(t, 0),
                str(t.header.frame_id),
                str(t.child_frame_id),
                _pose_matrix(tr.translation, tr.rotation),
            )
        )
    return out


def camera_info_from_msg(
    msg: Any, source: str = "CameraInfo"
) -> tuple[float, float, float, float, int, int]:
    """``(fx, fy, cx, cy, width, height)`` of a ``sensor_msgs/CameraInfo`` (``k`` or ROS1 ``K``)."""
    K = getattr(msg, "k", None)
    if K is None:
        K = getattr(msg, "K", None)
    K = np.asarray(K, dtype=np.float64).reshape(-1)
    if K.size != 9 or K[0] <= 0 or K[4] <= 0:
        raise FormatError(
            f"K = {K.tolist()}", source=source, field="k", expected="3x3 intrinsics, fx, fy > 0"
        )
    return float(K[0]), float(K[4]), float(K[2]), float(K[5]), int(msg.width), int(msg.height)
