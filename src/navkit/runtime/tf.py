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

import logging
from collections import deque
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["TransformTree", "interpolate_pose", "pose_at"]

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
    i = int(np.searchsorted(stamps, stamp_ns))
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
