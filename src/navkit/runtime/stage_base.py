"""What every capability of ``navkit run`` shares: a stage's result, the poses it buffers from
the recording (odometry, TF) and the planar part of a pose."""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from navkit.runtime.messages import Message, Output

__all__ = ["PoseBuffer", "StageResult", "planar"]

log = logging.getLogger(__name__)


@dataclass
class StageResult:
    """Outputs to publish and an optional per-frame record (plain JSON)."""

    outputs: list[Output] = field(default_factory=list)
    record: dict[str, Any] | None = None


def planar(T: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(x, y, yaw)`` of a ``(4, 4)`` pose (yaw of its x axis in the world plane)."""
    return np.array([T[0, 3], T[1, 3], np.arctan2(T[1, 0], T[0, 0])])


class PoseBuffer:
    """The recent poses of each pose topic, bounded, interpolated at a stamp, and the
    recording's TF tree (:class:`~navkit.runtime.tf.TransformTree`, ``/tf`` + ``/tf_static``).

    ``at(topic, stamp)`` interpolates linearly (translation) and by slerp (rotation) between the
    two poses around the stamp; before the first / after the last pose it holds the nearest one.
    ``sensor_pose(topic, stamp, frame)`` carries the pose topic's child frame to a sensor frame
    through the TF tree.
    """

    def __init__(self, maxlen: int = 256) -> None:
        from navkit.runtime.tf import TransformTree

        self.maxlen = maxlen
        self.poses: dict[str, deque[tuple[int, NDArray[np.float64]]]] = {}
        self.frames: dict[str, str] = {}
        self.children: dict[str, str] = {}
        self.tf = TransformTree(maxlen)
        self.warned: set[tuple[str, str]] = set()
        # the tree results.mcap carries (the run's TfPublisher's), when there is one
        self.published: TransformTree | None = None

    def add_tf(self, msg: Message) -> None:
        """One transform of a ``tf`` message (static when its topic is ``/tf_static``)."""
        static = msg.topic.rstrip("/").endswith("tf_static")
        self.tf.add(msg.frame_id, msg.child_frame_id, msg.stamp_ns, msg.data, static)

    def _child(self, topic: str, frame: str) -> str:
        """The pose topic's child frame when it differs from ``frame`` (else "")."""
        child = self.children.get(topic, "").lstrip("/")
        frame = frame.lstrip("/")
        return child if child and frame and child != frame else ""

    def sensor_pose(self, topic: str, stamp_ns: int, frame: str) -> NDArray[np.float64] | None:
        """``T_world_frame`` at ``stamp_ns``: the pose topic's ``T_world_child`` times the TF
        tree's ``T_child_frame`` (interpolated at the stamp). Without a child frame, with the
        same frame, or when the TF tree does not connect them (warned once), the pose topic is
        taken as the sensor's pose."""
        T = self.at(topic, stamp_ns)
        child = self._child(topic, frame)
        if T is None or not child:
            return T
        T_child_frame = self.tf.lookup(child, frame, stamp_ns)
        if T_child_frame is None:
            if (child, frame) not in self.warned:
                self.warned.add((child, frame))
                log.warning(
                    "no TF between %s (child frame of %s) and %s: %s taken as the pose of %s",
                    child,
                    topic,
                    frame,
                    topic,
                    frame,
                )
            return T
        return T @ T_child_frame

    def tf_ready(self, topic: str, stamp_ns: int, frame: str) -> bool:
        """Whether every dynamic TF edge between the pose topic's child frame and ``frame`` has a
        transform at or after ``stamp_ns`` (True when no TF connects them)."""
        child = self._child(topic, frame)
        if not child:
            return True
        latest = self.tf.latest_stamp(child, frame)
        return latest is None or latest >= stamp_ns

    def add(self, msg: Message) -> None:
        buf = self.poses.setdefault(msg.topic, deque(maxlen=self.maxlen))
        if buf and msg.stamp_ns < buf[-1][0]:
            log.warning(
                "%s: pose at %d ns older than the last one, ignored", msg.topic, msg.stamp_ns
            )
            return
        buf.append((msg.stamp_ns, np.asarray(msg.data, dtype=np.float64)))
        self.frames[msg.topic] = msg.frame_id
        self.children[msg.topic] = msg.child_frame_id

    def latest_stamp(self, topic: str) -> int | None:
        buf = self.poses.get(topic)
        return buf[-1][0] if buf else None

    def at(self, topic: str, stamp_ns: int) -> NDArray[np.float64] | None:
        buf = self.poses.get(topic)
        if not topic or not buf:
            return None
        from navkit.runtime.tf import pose_at

        return pose_at(buf, stamp_ns)


# --------------------------------------------------------------------------- obstacles
