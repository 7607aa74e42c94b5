"""The TF tree of a recording (``/tf`` and ``/tf_static``, ``tf2_msgs/TFMessage``): where is one
frame in another at a stamp.

Each frame has at most one parent (a tree, as tf2 keeps it). Static edges (``/tf_static``) hold
one transform for all time; dynamic edges (``/tf``) keep their recent transforms (at most
``maxlen`` per edge, so memory is bounded) and are interpolated at a stamp: translation linearly,
rotation by slerp; before the first / after the last transform of an edge the nearest one is held
(as :class:`~navkit.runtime.capabilities.PoseBuffer` does for pose topics).

:meth:`TransformTree.lookup` walks both frames up to their common ancestor and composes
``T_target_source``. The runtime uses it to carry a pose topic's child frame (e.g. ``base_link``
of a ``nav_msgs/Odometry``) to the frame of a sensor message (e.g. a ``PointCloud2`` in
``velodyne``): ``T_world_sensor = T_world_base(pose topic) @ T_base_sensor(TF)``.
"""

from __future__ import annotations

import bisect
import logging
from collections import deque
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "TfPublisher",
    "TransformTree",
    "interpolate_pose",
    "planar_correction",
    "planar_covariance_6x6",
    "pose_at",
]

log = logging.getLogger(__name__)


def interpolate_pose(
    s0: int, T0: NDArray[np.float64], s1: int, T1: NDArray[np.float64], stamp: int
) -> NDArray[np.float64]:
    """``(4, 4)`` pose at ``stamp`` between ``T0`` at ``s0`` and ``T1`` at ``s1`` (ns): translation
    linear, rotation by slerp (clamped to the two ends)."""
    if s1 <= s0:
        return T1
    w = min(max((stamp - s0) / (s1 - s0), 0.0), 1.0)
    from scipy.spatial.transform import Rotation, Slerp

    rot = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([T0[:3, :3], T1[:3, :3]])))([w])
    T = np.eye(4)
    T[:3, :3] = rot.as_matrix()[0]
    T[:3, 3] = (1 - w) * T0[:3, 3] + w * T1[:3, 3]
    return T


def pose_at(buf: Any, stamp_ns: int) -> NDArray[np.float64]:
    """The pose of a time-ordered, non-empty buffer of ``(stamp_ns, T)`` at ``stamp_ns``: exact
    where a stamp matches, interpolated between neighbours (:func:`interpolate_pose`), held at the
    first / last pose outside the buffer's span."""
    stamps = [s for s, _ in buf]
    i = bisect.bisect_left(stamps, stamp_ns)
    if i < len(stamps) and stamps[i] == stamp_ns:
        return buf[i][1]  # type: ignore[no-any-return]
    if i == 0:
        return buf[0][1]  # type: ignore[no-any-return]
    if i >= len(stamps):
        return buf[-1][1]  # type: ignore[no-any-return]
    (s0, T0), (s1, T1) = buf[i - 1], buf[i]
    return interpolate_pose(s0, T0, s1, T1, stamp_ns)


class TransformTree:
    """Static and time-stamped transforms between named frames.

    Parameters
    ----------
    maxlen : int
        Transforms kept per dynamic edge (the most recent ones).
    """

    def __init__(self, maxlen: int = 256) -> None:
        self.maxlen = maxlen
        self.parent: dict[str, str] = {}
        self.static: dict[str, NDArray[np.float64]] = {}  # child -> T_parent_child
        self.dynamic: dict[str, deque[tuple[int, NDArray[np.float64]]]] = {}

    def __len__(self) -> int:
        return len(self.parent)

    def add(
        self, parent: str, child: str, stamp_ns: int, T: NDArray[np.float64], static: bool
    ) -> None:
        """Add ``T_parent_child`` (a frame that changes parent starts a new edge)."""
        parent, child = parent.lstrip("/"), child.lstrip("/")
        if not parent or not child or parent == child:
            log.warning("TF %r -> %r ignored (empty or self frame)", parent, child)
            return
        if self.parent.get(child) not in (None, parent):
            log.warning("TF: %s's parent changes from %s to %s", child, self.parent[child], parent)
            self.static.pop(child, None)
            self.dynamic.pop(child, None)
        self.parent[child] = parent
        T = np.asarray(T, dtype=np.float64)
        if static:
            self.static[child] = T
            return
        buf = self.dynamic.setdefault(child, deque(maxlen=self.maxlen))
        if buf and stamp_ns < buf[-1][0]:
            log.debug(
                "TF %s -> %s at %d ns older than the last one, ignored", parent, child, stamp_ns
            )
            return
        buf.append((stamp_ns, T))

    def _edge(self, child: str, stamp_ns: int) -> NDArray[np.float64]:
        if child in self.static:
            return self.static[child]
        return pose_at(self.dynamic[child], stamp_ns)

    def _chain(self, frame: str) -> list[str]:
        """``frame`` and its ancestors, up to the root."""
        out = [frame]
        while out[-1] in self.parent and len(out) <= len(self.parent):
            out.append(self.parent[out[-1]])
        return out

    def path(self, target: str, source: str) -> tuple[list[str], list[str]] | None:
        """The frames below the common ancestor: ``(source side, target side)``, each from the
        frame up to (not including) the ancestor; None when the frames are not connected."""
        target, source = target.lstrip("/"), source.lstrip("/")
        up_s, up_t = self._chain(source), self._chain(target)
        common = next((f for f in up_s if f in set(up_t)), None)
        if common is None:
            return None
        return up_s[: up_s.index(common)], up_t[: up_t.index(common)]

    def can_transform(self, target: str, source: str) -> bool:
        """Whether the two frames are connected."""
        return self.path(target, source) is not None

    def latest_stamp(self, target: str, source: str) -> int | None:
        """The stamp up to which every dynamic edge between the frames has data (the oldest of
        their latest transforms); ``2**63 - 1`` for an all-static chain, None if not connected."""
        p = self.path(target, source)
        if p is None:
            return None
        latest = [self.dynamic[f][-1][0] for f in (*p[0], *p[1]) if f not in self.static]
        return min(latest) if latest else 2**63 - 1

    def lookup(self, target: str, source: str, stamp_ns: int) -> NDArray[np.float64] | None:
        """``(4, 4)`` ``T_target_source`` at ``stamp_ns`` (maps points from ``source`` to
        ``target``), or None when the frames are not connected."""
        p = self.path(target, source)
        if p is None:
            return None
        T_anc_source = np.eye(4)
        for f in p[0]:  # source up to the ancestor: T_anc_source = ... T_pp_p T_p_source
            T_anc_source = self._edge(f, stamp_ns) @ T_anc_source
        T_anc_target = np.eye(4)
        for f in p[1]:
            T_anc_target = self._edge(f, stamp_ns) @ T_anc_target
        R, t = T_anc_target[:3, :3], T_anc_target[:3, 3]
        inv = np.eye(4)
        inv[:3, :3], inv[:3, 3] = R.T, -R.T @ t
        return inv @ T_anc_source


def planar_correction(
    T_map_sensor: NDArray[np.float64], T_root_sensor: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``T_map_root`` of a planar fix, the way AMCL and Cartographer publish ``map -> odom``:
    ``T_map_root = T_map_sensor inv(T_root_sensor)`` taken in the plane (x, y, yaw of both
    poses), so the correction has no height, roll or pitch and the sensor keeps the height and
    tilt its odometry chain gives it."""
    a, b = _xyyaw(T_map_sensor), _xyyaw(T_root_sensor)
    yaw = a[2] - b[2]
    c, s = np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = a[:2] - T[:2, :2] @ b[:2]
    return T


def _xyyaw(T: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.array([T[0, 3], T[1, 3], np.arctan2(T[1, 0], T[0, 0])])


def planar_covariance_6x6(
    cov3: NDArray[np.float64] | None, lever_xy: NDArray[np.float64]
) -> NDArray[np.float64]:
    """ROS's ``(6, 6)`` pose covariance (x, y, z, roll, pitch, yaw; row-major) of a frame that
    sits ``lever_xy`` (map-frame vector from the matched sensor to it) away from a sensor whose
    planar pose ``(x, y, yaw)`` has covariance ``cov3``: ``J cov3 J^T`` with ``J = [[1, 0, -ly],
    [0, 1, lx], [0, 0, 1]]`` (a heading error swings the lever). z, roll and pitch are not
    estimated (0, as AMCL publishes them)."""
    out = np.zeros((6, 6))
    if cov3 is None:
        return out
    J = np.array([[1.0, 0.0, -lever_xy[1]], [0.0, 1.0, lever_xy[0]], [0.0, 0.0, 1.0]])
    C = J @ np.asarray(cov3, dtype=np.float64) @ J.T
    idx = [0, 1, 5]
    out[np.ix_(idx, idx)] = C
    return out


class TfPublisher:
    """The TF tree ``results.mcap`` carries (``/tf``, ``/tf_static``), so every frame of its
    outputs links to ``map``.

    - The recording's own transforms are passed through (same topic, stamp and frames).
    - A pose topic (the run's ``pose`` and ``odometry`` topics; the reference too unless
      localization runs, which owns ``map``) that gives ``T_frame_child`` publishes
      ``frame -> child`` when ``child`` has no parent yet (e.g. KITTI's poses, CARMEN's
      odometry), or ``frame -> root`` of the child's tree (``T_frame_child T_child_root``, the
      AMCL form) when ``frame`` is not connected to it yet (e.g. a ground truth in ``map`` beside
      odometry in ``odom``); afterwards every pose of that topic republishes its edge.
    - Stages publish their own transforms (localization's ``map -> odom``, plane odometry's
      ``planes_odom``) as outputs of kind ``tf``.
    - Without localization, a frame still not linked to ``map`` when an output uses it gets a
      static identity ``map -> root of its tree`` (the world is the odometry's frame; logged
      once). With localization, ``map`` is linked by its first fix.
    """

    def __init__(self, pose_topics: tuple[str, ...], link_map: bool, maxlen: int = 256) -> None:
        self.tree = TransformTree(maxlen)
        self.pose_topics = tuple(t for t in dict.fromkeys(pose_topics) if t)
        self.link_map = link_map
        self.owner: dict[str, str] = {}  # child frame -> the pose topic publishing its edge

    def root(self, frame: str, below: str = "") -> str:
        """The top of ``frame``'s chain (stopping under ``below`` when the chain reaches it)."""
        chain = self.tree._chain(frame.lstrip("/"))
        if below and below in chain:
            chain = chain[: chain.index(below)]
        return chain[-1] if chain else frame

    def add(self, topic: str, parent: str, child: str, stamp_ns: int, T: Any) -> None:
        """Record a published transform (``topic`` ``/tf_static``: static)."""
        self.tree.add(parent, child, stamp_ns, T, topic.rstrip("/").endswith("tf_static"))

    def pose(self, topic: str, stamp_ns: int, frame: str, child: str, T: Any) -> list[Any]:
        """The ``/tf`` output of one pose message (empty when its topic does not publish)."""
        from navkit.runtime.messages import Output

        frame, child = frame.lstrip("/"), child.lstrip("/")
        if topic not in self.pose_topics or not frame or not child or frame == child:
            return []
        T = np.asarray(T, dtype=np.float64)
        target = child
        if self.owner.get(child) != topic:
            owned = [c for c, t in self.owner.items() if t == topic and self.tree.parent.get(c)]
            if owned:  # this topic already links frame to child's tree through another edge
                target = owned[0]
            elif child not in self.tree.parent:
                self.owner[child] = topic
            elif not self.tree.can_transform(frame, child):
                target = self.root(child)
                self.owner[target] = topic
            else:
                return []
        if target != child:
            T_child_target = self.tree.lookup(child, target, stamp_ns)
            if T_child_target is None:
                return []
            T = T @ T_child_target
        self.tree.add(frame, target, stamp_ns, T, static=False)
        return [Output("/tf", "tf", stamp_ns, frame, [(target, T)])]

    def link(self, frame: str, stamp_ns: int) -> list[Any]:
        """A static identity ``map -> root`` when ``frame`` is not linked to ``map`` (only
        without localization; empty otherwise)."""
        from navkit.runtime.messages import Output

        frame = frame.lstrip("/")
        if not self.link_map or not frame or frame == "map":
            return []
        if self.tree.can_transform("map", frame):
            return []
        root = self.root(frame)
        if root == "map":
            return []
        log.info("TF: no transform links %s to map; publishing map -> %s as identity", frame, root)
        self.tree.add("map", root, stamp_ns, np.eye(4), static=True)
        return [Output("/tf_static", "tf", stamp_ns, "map", [(root, np.eye(4))])]
