"""``results.mcap``: navkit's results as standard ROS 2 messages (CDR), for Foxglove, RViz, rosbag2.

Message types (schemas ``ros2msg``, encoding ``cdr``; needs the extra ``ros``: ``rosbags`` for the
CDR serialisation, ``mcap`` for the container):

===================================  ===========================================================
``sensor_msgs/msg/PointCloud2``      classified clouds: ``x y z`` float32 + ``class`` int8 per
                                     point (0 ground, -1 unreliable, -2 obstacle, -3 side shadow,
                                     -4 shadow behind)
``visualization_msgs/msg/MarkerArray``  outlines (bounding shapes A1-A7, planes, walls): a
                                     DELETEALL marker (each array replaces the previous one),
                                     then ONE LINE_LIST marker holding every outline's segments
                                     with per-vertex colours (serialised with NumPy, see
                                     :func:`line_list_cdr`)
``nav_msgs/msg/OccupancyGrid``       obstacle map, wall map (-1 unknown, 0 free, 100 occupied)
``nav_msgs/msg/Path``                the stored path, sampled
``geometry_msgs/msg/PoseStamped``    the sensor's pose (localization fix, plane odometry)
``geometry_msgs/msg/PoseWithCovarianceStamped``  the robot's (``base_link``) pose with the
                                     match's covariance
``tf2_msgs/msg/TFMessage``           ``/tf`` and ``/tf_static``: the recording's transforms and
                                     navkit's own (``map -> odom``, pose topics)
===================================  ===========================================================

Header stamps and frame ids are the recording's; each message's log time is its stamp.

Crash safety: :class:`ResultsWriter` can write *unchunked* (each message record goes straight to
the file, flushed by :meth:`ResultsWriter.flush`), so a killed writer leaves every flushed message
readable with :func:`read_messages` (which stops at a truncated tail). :func:`merge_mcap` joins such
segments into one indexed, chunked file.
"""

from __future__ import annotations

import functools
import logging
import math
import os
import struct
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from navkit.errors import FormatError, InputError, require_module

__all__ = [
    "ROS_TYPES",
    "ResultRecord",
    "ResultsWriter",
    "classified_cloud_cdr",
    "line_list_cdr",
    "line_segments",
    "merge_mcap",
    "occupancy_grid_cdr",
    "read_messages",
]

log = logging.getLogger(__name__)

PathLike = str | os.PathLike[str]

ROS_TYPES = {
    "classified_cloud": "sensor_msgs/msg/PointCloud2",
    "markers": "visualization_msgs/msg/MarkerArray",
    "grid": "nav_msgs/msg/OccupancyGrid",
    "path": "nav_msgs/msg/Path",
    "pose": "geometry_msgs/msg/PoseStamped",
    "pose_cov": "geometry_msgs/msg/PoseWithCovarianceStamped",
    "tf": "tf2_msgs/msg/TFMessage",
}


@functools.cache
def _typestore() -> Any:
    """rosbags' ROS 2 type store (built once: each build makes new message classes)."""
    ts = require_module("rosbags.typesys", "ros", "writing results.mcap")
    return ts.get_typestore(ts.Stores.LATEST)


class _Builder:
    """Builds rosbags message objects from navkit outputs."""

    def __init__(self) -> None:
        self.ts = _typestore()
        T = self.ts.types
        self.Time = T["builtin_interfaces/msg/Time"]
        self.Duration = T["builtin_interfaces/msg/Duration"]
        self.Header = T["std_msgs/msg/Header"]
        self.Point = T["geometry_msgs/msg/Point"]
        self.Quaternion = T["geometry_msgs/msg/Quaternion"]
        self.Pose = T["geometry_msgs/msg/Pose"]
        self.PoseStamped = T["geometry_msgs/msg/PoseStamped"]
        self.Vector3 = T["geometry_msgs/msg/Vector3"]
        self.ColorRGBA = T["std_msgs/msg/ColorRGBA"]
        self.Marker = T["visualization_msgs/msg/Marker"]
        self.MarkerArray = T["visualization_msgs/msg/MarkerArray"]
        self.MeshFile = T["visualization_msgs/msg/MeshFile"]
        self.CompressedImage = T["sensor_msgs/msg/CompressedImage"]
        self.PointField = T["sensor_msgs/msg/PointField"]
        self.PointCloud2 = T["sensor_msgs/msg/PointCloud2"]
        self.OccupancyGrid = T["nav_msgs/msg/OccupancyGrid"]
        self.MapMetaData = T["nav_msgs/msg/MapMetaData"]
        self.Path = T["nav_msgs/msg/Path"]
        self.PoseWithCovariance = T["geometry_msgs/msg/PoseWithCovariance"]
        self.PoseWithCovarianceStamped = T["geometry_msgs/msg/PoseWithCovarianceStamped"]
        self.Transform = T["geometry_msgs/msg/Transform"]
        self.TransformStamped = T["geometry_msgs/msg/TransformStamped"]
        self.TFMessage = T["tf2_msgs/msg/TFMessage"]

    def header(self, stamp_ns: int, frame_id: str) -> Any:
        return self.Header(
            stamp=self.Time(
                sec=int(stamp_ns // 1_000_000_000), nanosec=int(stamp_ns % 1_000_000_000)
            ),
            frame_id=frame_id,
        )

    def pose(self, T: Any) -> Any:
        T = np.asarray(T, dtype=np.float64)
        q = quaternion_xyzw(T[:3, :3])
        return self.Pose(
            position=self.Point(x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])),
            orientation=self.Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
        )

    def identity(self) -> Any:
        return self.Pose(
            position=self.Point(x=0.0, y=0.0, z=0.0),
            orientation=self.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0),
        )

    def build(self, kind: str, stamp_ns: int, frame_id: str, data: Any) -> Any:
        h = self.header(stamp_ns, frame_id)
        if kind == "pose":
            return self.PoseStamped(header=h, pose=self.pose(data))
        if kind == "pose_cov":
            T, cov = data
            return self.PoseWithCovarianceStamped(
                header=h,
                pose=self.PoseWithCovariance(
                    pose=self.pose(T),
                    covariance=np.ascontiguousarray(cov, dtype=np.float64).reshape(36),
                ),
            )
        if kind == "tf":
            transforms = []
            for child, T in data:
                T = np.asarray(T, dtype=np.float64)
                q = quaternion_xyzw(T[:3, :3])
                transforms.append(
                    self.TransformStamped(
                        header=h,
                        child_frame_id=child,
                        transform=self.Transform(
                            translation=self.Vector3(
                                x=float(T[0, 3]), y=float(T[1, 3]), z=float(T[2, 3])
                            ),
                            rotation=self.Quaternion(x=q[0], y=q[1], z=q[2], w=q[3]),
                        ),
                    )
                )
            return self.TFMessage(transforms=transforms)
        if kind == "path":
            P = np.asarray(data, dtype=np.float64).reshape(-1, 3)
            q = self.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
            poses = [
                self.PoseStamped(
                    header=h,
                    pose=self.Pose(position=self.Point(x=x, y=y, z=z), orientation=q),
                )
                for x, y, z in P.tolist()
            ]
            return self.Path(header=h, poses=poses)
        if kind == "grid":
            occ, res, origin = data
            occ = np.asarray(occ, dtype=np.int8)
            T = np.eye(4)
            T[:2, 3] = np.asarray(origin, dtype=np.float64)[:2]
            info = self.MapMetaData(
                map_load_time=h.stamp,
                resolution=float(res),
                width=int(occ.shape[1]),
                height=int(occ.shape[0]),
                origin=self.pose(T),
            )
            return self.OccupancyGrid(
                header=h, info=info, data=np.ascontiguousarray(occ).reshape(-1)
            )
        if kind == "classified_cloud":
            pts, classes = data
            raw = classified_points(pts, classes)
            fields = [
                self.PointField(name="x", offset=0, datatype=7, count=1),
                self.PointField(name="y", offset=4, datatype=7, count=1),
                self.PointField(name="z", offset=8, datatype=7, count=1),
                self.PointField(name="class", offset=12, datatype=1, count=1),
            ]
            return self.PointCloud2(
                header=h,
                height=1,
                width=len(raw),
                fields=fields,
                is_bigendian=False,
                point_step=16,
                row_step=16 * len(raw),
                data=raw.reshape(-1),
                is_dense=False,
            )
        if kind == "markers":  # the reference of line_list_cdr (tests): rosbags' objects
            P, C = line_segments(data)
            zero = self.Duration(sec=0, nanosec=0)
            empty_mesh = self.MeshFile(filename="", data=np.zeros(0, np.uint8))
            empty_tex = self.CompressedImage(header=h, format="", data=np.zeros(0, np.uint8))

            def marker(ns: str, typ: int, action: int, pts: Any, colors: Any) -> Any:
                return self.Marker(
                    header=h,
                    ns=ns,
                    id=0,
                    type=typ,
                    action=action,
                    pose=self.identity(),
                    scale=self.Vector3(x=LINE_WIDTH_M, y=LINE_WIDTH_M, z=LINE_WIDTH_M),
                    color=self.ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0),
                    lifetime=zero,
                    frame_locked=False,
                    points=[self.Point(x=x, y=y, z=z) for x, y, z in np.asarray(pts).tolist()],
                    colors=[
                        self.ColorRGBA(r=r, g=g, b=b, a=a)
                        for r, g, b, a in np.asarray(colors, np.float32).tolist()
                    ],
                    texture_resource="",
                    texture=empty_tex,
                    uv_coordinates=[],
                    text="",
                    mesh_resource="",
                    mesh_file=empty_mesh,
                    mesh_use_embedded_materials=False,
                )

            markers = [marker("", 0, 3, [], [])]  # DELETEALL: replaces the last array
            if len(P):
                markers.append(marker(_lines_ns(data), 5, 0, P, C))
            return self.MarkerArray(markers=markers)
        raise InputError(
            f"unknown output kind {kind!r}", field="kind", expected=f"one of {sorted(ROS_TYPES)}"
        )


def quaternion_xyzw(R: Any) -> tuple[float, float, float, float]:
    """Unit quaternion ``(x, y, z, w)`` (``w >= 0``) of a rotation matrix ``(3, 3)`` (Shepperd's
    method: the largest of the four squared components first; agrees with
    ``scipy.spatial.transform.Rotation.from_matrix(R).as_quat()`` up to the sign, at a fraction
    of its per-call cost for single poses)."""
    m = np.asarray(R, dtype=np.float64).tolist()
    (a, b, c), (d, e, f), (g, h, i) = m
    tr = a + e + i
    if tr >= max(a, e, i):
        w = 0.5 * math.sqrt(max(1.0 + tr, 0.0))
        x, y, z = (h - f) / (4 * w), (c - g) / (4 * w), (d - b) / (4 * w)
    elif a >= e and a >= i:
        x = 0.5 * math.sqrt(max(1.0 + a - e - i, 0.0))
        w, y, z = (h - f) / (4 * x), (b + d) / (4 * x), (c + g) / (4 * x)
    elif e >= i:
        y = 0.5 * math.sqrt(max(1.0 - a + e - i, 0.0))
        w, x, z = (c - g) / (4 * y), (b + d) / (4 * y), (f + h) / (4 * y)
    else:
        z = 0.5 * math.sqrt(max(1.0 - a - e + i, 0.0))
        w, x, y = (d - b) / (4 * z), (c + g) / (4 * z), (f + h) / (4 * z)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    sgn = -1.0 if w < 0 else 1.0
    return (sgn * x / n, sgn * y / n, sgn * z / n, sgn * w / n)


LINE_WIDTH_M = 0.05  # the outlines' line width (Marker.scale.x)


def _lines_ns(lines: Sequence[Any]) -> str:
    """The LINE_LIST's namespace: the lines' common namespace (``shape`` for ``shape/A1`` ...)."""
    names = {str(ln.ns).split("/")[0] for ln in lines}
    return names.pop() if len(names) == 1 else "navkit"


def line_segments(lines: Sequence[Any]) -> tuple[np.ndarray, np.ndarray]:
    """Polylines (:class:`~navkit.runtime.messages.Polyline`: ``points (M, 3)``, ``color``,
    ``closed``) as LINE_LIST vertices: ``(2 S, 3)`` float64 segment ends, two per segment (a
    closed line also gets its last-to-first segment), and ``(2 S, 4)`` float32 RGBA per vertex."""
    pts = [np.asarray(ln.points, dtype=np.float64).reshape(-1, 3) for ln in lines]
    if not pts:
        return np.zeros((0, 3)), np.zeros((0, 4), np.float32)
    n = np.array([len(p) for p in pts], dtype=np.int64)
    closed = np.array([bool(ln.closed) for ln in lines]) & (n > 2)
    nseg = np.where(closed, n, np.maximum(n - 1, 0))
    allp = np.concatenate(pts)
    starts = np.cumsum(n) - n
    line = np.repeat(np.arange(len(pts)), nseg)
    k = np.arange(int(nseg.sum())) - np.repeat(np.cumsum(nseg) - nseg, nseg)
    a = starts[line] + k
    b = starts[line] + (k + 1) % np.maximum(n[line], 1)
    P = np.empty((2 * len(a), 3))
    P[0::2], P[1::2] = allp[a], allp[b]
    colors = np.array([ln.color for ln in lines], dtype=np.float32).reshape(-1, 4)
    return P, np.repeat(colors[line], 2, axis=0)


class _Cdr:
    """A little-endian CDR buffer (alignment counted after the 4-byte encapsulation header)."""

    def __init__(self) -> None:
        self.parts: list[bytes] = [b"\x00\x01\x00\x00"]
        self.n = 0

    def align(self, a: int) -> None:
        pad = (-self.n) % a
        if pad:
            self.raw(b"\x00" * pad)

    def raw(self, b: bytes) -> None:
        self.parts.append(b)
        self.n += len(b)

    def pack(self, fmt: str, *v: Any, align: int) -> None:
        self.align(align)
        self.raw(struct.pack("<" + fmt, *v))

    def string(self, s: str) -> None:
        b = s.encode() + b"\x00"
        self.pack("I", len(b), align=4)
        self.raw(b)

    def array(self, a: np.ndarray, dtype: str, align: int) -> None:
        """A sequence of fixed-size elements: count, then the elements' bytes."""
        self.pack("I", len(a), align=4)
        if len(a):
            self.align(align)
            self.raw(np.ascontiguousarray(a, dtype=dtype).tobytes())


def _marker_cdr(
    c: _Cdr, sec: int, nsec: int, frame: str, ns: str, typ: int, action: int, P: Any, C: Any
) -> None:
    c.pack("iI", sec, nsec, align=4)  # header
    c.string(frame)
    c.string(ns)
    c.pack("iii", 0, typ, action, align=4)  # id, type, action
    c.pack("7d", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, align=8)  # pose: identity
    c.pack("3d", LINE_WIDTH_M, LINE_WIDTH_M, LINE_WIDTH_M, align=8)  # scale
    c.pack("4f", 1.0, 1.0, 1.0, 1.0, align=4)  # color (the vertices carry theirs)
    c.pack("iI?", 0, 0, False, align=4)  # lifetime, frame_locked
    c.array(P, "<f8", 8)  # points
    c.array(C, "<f4", 4)  # colors
    c.string("")  # texture_resource
    c.pack("iI", sec, nsec, align=4)  # texture: header, format, data
    c.string(frame)
    c.string("")
    c.pack("I", 0, align=4)
    c.pack("I", 0, align=4)  # uv_coordinates
    c.string("")  # text
    c.string("")  # mesh_resource
    c.string("")  # mesh_file: filename, data
    c.pack("I", 0, align=4)
    c.pack("?", False, align=1)  # mesh_use_embedded_materials


_CLASSIFIED_RECORD = np.dtype([("xyz", "V12"), ("class", "i1"), ("pad", "V3")])


def classified_points(points: Any, classes: Any, out: Any = None) -> np.ndarray:
    """The ``(N, 16)`` uint8 records of a classified cloud: ``x y z`` float32, ``class`` int8,
    three zero bytes; written into ``out`` (``16 N`` zeroed bytes, e.g. a slice of the
    message's buffer) when given."""
    pts = np.asarray(points).reshape(-1, 3)
    n = len(pts)
    if out is None:
        out = np.zeros(16 * n, dtype=np.uint8)
    rec = np.frombuffer(out, dtype=_CLASSIFIED_RECORD, count=n)
    # x y z cast at once (contiguous), then moved as 12-byte items: one long strided copy
    rec["xyz"] = np.ascontiguousarray(pts, dtype="<f4").view("V12").reshape(-1)
    rec["class"] = np.asarray(classes, dtype=np.int8).reshape(-1)
    return rec.view(np.uint8).reshape(n, 16)


def classified_cloud_cdr(stamp_ns: int, frame_id: str, points: Any, classes: Any) -> bytearray:
    """The CDR bytes of the ``sensor_msgs/PointCloud2`` of a classified cloud (fields ``x y z``
    float32 + ``class`` int8, 16 bytes a point): the points written once, straight into the
    message's buffer, without rosbags' message object. Byte for byte ``serialize_cdr`` of
    :meth:`_Builder.build` (tested)."""
    n = int(np.asarray(points).size // 3)
    c = _Cdr()
    c.pack("iI", int(stamp_ns // 1_000_000_000), int(stamp_ns % 1_000_000_000), align=4)
    c.string(frame_id)
    c.pack("II", 1, n, align=4)  # height, width
    c.pack("I", 4, align=4)
    for name, offset, datatype in (("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("class", 12, 1)):
        c.string(name)
        c.pack("I", offset, align=4)
        c.pack("B", datatype, align=1)
        c.pack("I", 1, align=4)
    c.pack("?", False, align=1)  # is_bigendian
    c.pack("II", 16, 16 * n, align=4)  # point_step, row_step
    c.pack("I", 16 * n, align=4)
    head = b"".join(c.parts)
    buf = bytearray(len(head) + 16 * n + 1)  # zeroed: padding, and is_dense False at the end
    buf[: len(head)] = head
    classified_points(points, classes, memoryview(buf)[len(head) : len(head) + 16 * n])
    return buf


def occupancy_grid_cdr(
    stamp_ns: int, frame_id: str, occ: Any, resolution: float, origin: Any
) -> bytearray:
    """The CDR bytes of a ``nav_msgs/OccupancyGrid``: ``occ`` ``(H, W)`` int8 cells (rows =
    y), ``resolution`` metres, ``origin`` the lower-left corner's ``(x, y)``; the cells copied
    once, straight into the message's buffer (a 2001 x 2001 map: about 4 MB per message).
    Byte for byte ``serialize_cdr`` of :meth:`_Builder.build` (tested)."""
    occ = np.asarray(occ, dtype=np.int8)
    T = np.eye(4)
    T[:2, 3] = np.asarray(origin, dtype=np.float64)[:2]
    q = quaternion_xyzw(T[:3, :3])
    sec, nsec = int(stamp_ns // 1_000_000_000), int(stamp_ns % 1_000_000_000)
    c = _Cdr()
    c.pack("iI", sec, nsec, align=4)  # header
    c.string(frame_id)
    c.pack("iI", sec, nsec, align=4)  # info: map_load_time, resolution, width, height
    c.pack("fII", float(resolution), int(occ.shape[1]), int(occ.shape[0]), align=4)
    c.pack("3d", float(T[0, 3]), float(T[1, 3]), float(T[2, 3]), align=8)  # origin
    c.pack("4d", *(float(v) for v in q), align=8)
    c.pack("I", occ.size, align=4)  # data
    head = b"".join(c.parts)
    buf = bytearray(len(head) + occ.size)
    buf[: len(head)] = head
    np.frombuffer(buf, dtype=np.int8, offset=len(head)).reshape(occ.shape)[...] = occ
    return buf


def line_list_cdr(stamp_ns: int, frame_id: str, lines: Sequence[Any]) -> bytes:
    """The CDR bytes of a ``visualization_msgs/MarkerArray``: DELETEALL, then one LINE_LIST of
    every polyline's segments with per-vertex colours (none when there are no segments).

    Serialised with NumPy (the vertices' bytes in one piece): rosbags' serialiser builds one
    Python object per point, about 20 us each, 0.5 s for the ~650 outlines of a KITTI frame.
    Byte for byte equal to ``serialize_cdr`` of :meth:`_Builder.build` (tested)."""
    P, C = line_segments(lines)
    sec, nsec = int(stamp_ns // 1_000_000_000), int(stamp_ns % 1_000_000_000)
    c = _Cdr()
    c.pack("I", 2 if len(P) else 1, align=4)
    _marker_cdr(c, sec, nsec, frame_id, "", 0, 3, np.zeros((0, 3)), np.zeros((0, 4)))
    if len(P):
        _marker_cdr(c, sec, nsec, frame_id, _lines_ns(lines), 5, 0, P, C)
    return b"".join(c.parts)


@functools.cache
def _builder() -> _Builder:
    return _Builder()


@dataclass(frozen=True)
class ResultRecord:
    """One message read back: topic, ROS type, log time (ns) and the decoded message."""

    topic: str
    msgtype: str
    log_time_ns: int
    message: Any


def _compression() -> Any:
    from mcap.writer import CompressionType

    try:
        import zstandard  # noqa: F401
    except ImportError:
        return CompressionType.NONE
    return CompressionType.ZSTD


class _UnchunkedWriter:
    """An unchunked MCAP writer (the run's crash-safe segments): the records and summary of
    ``mcap.writer.Writer(use_chunking=False)``, with each message's header and data written to
    the file as they are (``Writer`` first copies every record into a buffer: for a 2 MB cloud
    that is one more pass over it per frame). Schemas and channels are written when
    registered; :meth:`finish` writes the data end, the summary (schemas, channels, statistics,
    empty index groups, offsets) and the footer, as ``Writer.finish`` does."""

    def __init__(self, fh: Any) -> None:
        from mcap.records import Statistics

        self._fh = fh
        self._schemas: list[Any] = []
        self._channels: list[Any] = []
        self._stats = Statistics(
            attachment_count=0,
            channel_count=0,
            channel_message_counts={},
            chunk_count=0,
            message_count=0,
            metadata_count=0,
            message_start_time=0,
            message_end_time=0,
            schema_count=0,
        )

    def _record(self, record: Any) -> None:
        from mcap.data_stream import RecordBuilder

        b = RecordBuilder()
        record.write(b)
        self._fh.write(b.end())

    def start(self, profile: str, library: str) -> None:
        from mcap.records import Header
        from mcap.writer import MCAP0_MAGIC

        self._fh.write(MCAP0_MAGIC)
        self._record(Header(profile, library))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        from mcap.records import Schema

        schema = Schema(id=len(self._schemas) + 1, data=data, encoding=encoding, name=name)
        self._schemas.append(schema)
        self._stats.schema_count += 1
        self._record(schema)
        return int(schema.id)

    def register_channel(self, topic: str, message_encoding: str, schema_id: int) -> int:
        from mcap.records import Channel

        channel = Channel(
            id=len(self._channels) + 1,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata={},
        )
        self._channels.append(channel)
        self._stats.channel_count += 1
        self._record(channel)
        return int(channel.id)

    def add_message(self, channel_id: int, log_time: int, data: Any, publish_time: int) -> None:
        from mcap.opcode import Opcode

        st = self._stats
        if st.message_count == 0:
            st.message_start_time = log_time
        else:
            st.message_start_time = min(log_time, st.message_start_time)
        st.message_end_time = max(log_time, st.message_end_time)
        counts = st.channel_message_counts
        counts[channel_id] = counts.get(channel_id, 0) + 1
        st.message_count += 1
        size = memoryview(data).nbytes
        # opcode, record length, channel id, sequence, log time, publish time; then the data
        self._fh.write(
            struct.pack("<BQHIQQ", Opcode.MESSAGE, 22 + size, channel_id, 0, log_time, publish_time)
        )
        self._fh.write(data)

    def finish(self) -> None:
        import zlib

        from mcap.data_stream import RecordBuilder
        from mcap.opcode import Opcode
        from mcap.records import DataEnd, Footer, SummaryOffset
        from mcap.writer import MCAP0_MAGIC

        self._record(DataEnd(0))
        start = self._fh.tell()
        b = RecordBuilder()
        offsets = []
        groups: tuple[tuple[int, list[Any]], ...] = (
            (Opcode.SCHEMA, self._schemas),
            (Opcode.CHANNEL, self._channels),
            (Opcode.STATISTICS, [self._stats]),
            (Opcode.CHUNK_INDEX, []),
            (Opcode.ATTACHMENT_INDEX, []),
            (Opcode.METADATA_INDEX, []),
        )
        for opcode, records in groups:
            g0 = b.count
            for rec in records:
                rec.write(b)
            offsets.append(SummaryOffset(opcode, start + g0, b.count - g0))
        offset_start = start + b.count
        for off in offsets:
            off.write(b)
        summary = b.end()
        crc = zlib.crc32(summary)
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, start, offset_start), crc)
        self._fh.write(summary)
        self._record(
            Footer(summary_start=start, summary_offset_start=offset_start, summary_crc=crc)
        )
        self._fh.write(MCAP0_MAGIC)


class ResultsWriter:
    """Writes navkit outputs to an MCAP file as ROS 2 messages.

    Parameters
    ----------
    path : path
        The ``.mcap`` file (created or truncated).
    chunked : bool
        True: indexed, compressed chunks (a finished file). False: each message record written
        directly and made durable by :meth:`flush` (a crash-safe segment; merge later).
    """

    def __init__(self, path: PathLike, chunked: bool = True) -> None:
        require_module("mcap", "ros", "writing results.mcap")
        from mcap.writer import Writer

        self.path = Path(path)
        self._fh = open(self.path, "wb")
        self._w: Any = (
            Writer(self._fh, compression=_compression(), use_chunking=True, chunk_size=1 << 20)
            if chunked
            else _UnchunkedWriter(self._fh)
        )
        self._w.start(profile="ros2", library="navkit")
        self._b = _builder()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self.n_messages = 0

    def _channel(self, topic: str, msgtype: str, msgdef: bytes | None = None) -> int:
        if topic not in self._channels:
            if msgtype not in self._schemas:
                if msgdef is None:
                    msgdef = self._b.ts.generate_msgdef(msgtype, ros_version=2)[0].encode()
                self._schemas[msgtype] = self._w.register_schema(msgtype, "ros2msg", msgdef)
            self._channels[topic] = self._w.register_channel(topic, "cdr", self._schemas[msgtype])
        return self._channels[topic]

    def write(self, topic: str, kind: str, stamp_ns: int, frame_id: str, data: Any) -> None:
        """Write one output (see :class:`navkit.runtime.messages.Output` for ``data``)."""
        msgtype, raw = self.serialize(kind, stamp_ns, frame_id, data)
        self.write_raw(topic, msgtype, stamp_ns, raw)

    def serialize(
        self, kind: str, stamp_ns: int, frame_id: str, data: Any
    ) -> tuple[str, bytes | bytearray]:
        """One output's ROS type and CDR bytes (what :meth:`write` writes)."""
        msgtype = ROS_TYPES.get(kind)
        if msgtype is None:
            raise InputError(
                f"unknown output kind {kind!r}",
                field="kind",
                expected=f"one of {sorted(ROS_TYPES)}",
            )
        if kind == "markers":
            return msgtype, line_list_cdr(stamp_ns, frame_id, data)
        if kind == "classified_cloud":
            return msgtype, classified_cloud_cdr(stamp_ns, frame_id, *data)
        if kind == "grid":
            return msgtype, occupancy_grid_cdr(stamp_ns, frame_id, *data)
        msg = self._b.build(kind, stamp_ns, frame_id, data)
        return msgtype, bytes(self._b.ts.serialize_cdr(msg, msgtype))

    def write_raw(
        self,
        topic: str,
        msgtype: str,
        log_time_ns: int,
        raw: bytes | bytearray,
        msgdef: bytes | None = None,
    ) -> None:
        """Write an already serialised CDR message."""
        ch = self._channel(topic, msgtype, msgdef)
        self._w.add_message(ch, log_time=int(log_time_ns), data=raw, publish_time=int(log_time_ns))
        self.n_messages += 1

    def flush(self, sync: bool = False) -> None:
        """Hand everything written so far to the OS (survives a killed process); ``sync``: also
        to the disk (survives a power cut)."""
        self._fh.flush()
        if sync:
            os.fsync(self._fh.fileno())

    def close(self) -> None:
        """Write the summary and footer and close the file."""
        if not self._fh.closed:
            self._w.finish()
            self._fh.close()

    def __enter__(self) -> ResultsWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _iter_raw(path: Path) -> Iterator[tuple[str, str, bytes, int, bytes]]:
    """``(topic, msgtype, msgdef, log time, data)`` of every complete message record, in file
    order; stops quietly at a truncated tail (a killed writer)."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader

    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    with open(path, "rb") as fh:
        reader = StreamReader(fh, skip_magic=False, emit_chunks=False)
        try:
            for rec in reader.records:
                if isinstance(rec, Schema):
                    schemas[rec.id] = rec
                elif isinstance(rec, Channel):
                    channels[rec.id] = rec
                elif isinstance(rec, Message):
                    ch = channels[rec.channel_id]
                    sc = schemas[ch.schema_id]
                    yield ch.topic, sc.name, sc.data, rec.log_time, rec.data
        except (McapError, EOFError, ValueError, KeyError) as exc:
            log.info("%s: stopped at a truncated or damaged record (%s)", path, exc)


def read_messages(path: PathLike, topics: Sequence[str] | None = None) -> Iterator[ResultRecord]:
    """Decode the messages of a results MCAP (finished or a killed run's segment), in file order.

    Raises
    ------
    FormatError
        If the file is not MCAP.
    """
    p = Path(path)
    with open(p, "rb") as fh:
        if fh.read(8) != b"\x89MCAP0\r\n":
            raise FormatError(
                "is not an MCAP file", source=p, field="magic", expected="MCAP magic bytes"
            )
    ts = _typestore()
    for topic, msgtype, _, t, raw in _iter_raw(p):
        if topics is not None and topic not in topics:
            continue
        yield ResultRecord(topic, msgtype, t, ts.deserialize_cdr(raw, msgtype))


def merge_mcap(segments: Iterable[PathLike], dest: PathLike) -> int:
    """Copy the messages of ``segments`` (in order) into one chunked, indexed MCAP; returns the
    message count. Messages are copied as raw CDR, one at a time (bounded memory)."""
    n = 0
    w = ResultsWriter(dest, chunked=True)
    try:
        for seg in segments:
            for topic, msgtype, msgdef, t, raw in _iter_raw(Path(seg)):
                w.write_raw(topic, msgtype, t, raw, msgdef)
                n += 1
    finally:
        w.close()
    return n
