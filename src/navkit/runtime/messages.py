"""The messages the runtime streams: one small record per sensor reading, whatever the source.

A source (a ROS bag, an MCAP file, a KITTI folder, a CARMEN log, ...) turns its records into
:class:`Message` objects in time order; the capabilities' stages only see these.

Kinds and their ``data``:

- ``"cloud"``: ``(N, 3)`` float64 points in the sensor frame (``frame_id``), metres, in the order
  of the recording (a spinning lidar's ring order is kept).
- ``"scan"``: :class:`ScanData`, a planar laser scan.
- ``"pose"``: ``(4, 4)`` float64 ``T_parent_child``; the parent frame is ``frame_id``, the child
  frame ``child_frame_id`` (empty when the message does not say).
- ``"depth"``: ``(H, W)`` float64 depth, metres, NaN = no return.
- ``"color"``: ``(H, W, 3)`` uint8 RGB.
- ``"camera_info"``: :class:`CameraData`.
- ``"tf"``: one transform of a ``tf2_msgs/TFMessage``: ``(4, 4)`` ``T_parent_child``, parent
  ``frame_id``, child ``child_frame_id``; static when the topic is ``/tf_static``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "KINDS",
    "OUTPUT_KINDS",
    "CameraData",
    "Message",
    "Output",
    "Polyline",
    "ScanData",
    "TexturedPlane",
]

KINDS = ("cloud", "scan", "pose", "depth", "color", "camera_info", "tf")


@dataclass(frozen=True, eq=False)
class ScanData:
    """A planar laser scan: ranges (m, NaN = no return), bearings (rad, 0 forward, + left)."""

    ranges: NDArray[np.float64]
    bearings: NDArray[np.float64]
    range_max: float

    def points(self, max_range: float = np.inf) -> NDArray[np.float64]:
        """End points ``(n, 2)`` in the sensor frame (no-return and ``>= max_range`` dropped)."""
        r = self.ranges
        ok = np.isfinite(r) & (r < max_range)
        return np.stack([r[ok] * np.cos(self.bearings[ok]), r[ok] * np.sin(self.bearings[ok])], 1)


@dataclass(frozen=True)
class CameraData:
    """Pinhole intrinsics (pixels) and image size of a camera."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int


@dataclass(frozen=True, eq=False)
class Message:
    """One reading: topic, kind (see module docstring), stamp (ns), frame id and data."""

    topic: str
    kind: str
    stamp_ns: int
    frame_id: str
    data: Any
    child_frame_id: str = ""

    @property
    def stamp(self) -> float:
        """Stamp in seconds."""
        return self.stamp_ns * 1e-9


OUTPUT_KINDS = ("classified_cloud", "markers", "grid", "path", "pose", "textured_planes")


@dataclass(frozen=True, eq=False)
class TexturedPlane:
    """A plane of one RGB-D frame as a mesh with its texture: the colour pixels of its region.

    ``vertices (V, 3)`` metres (on the fitted plane, in the output's frame), ``triangles (F, 3)``
    vertex indices, ``texcoords (V, 2)`` in ``texture`` (U right, V down, origin at the top-left
    corner, 0..1), ``texture (h, w, 3)`` uint8 RGB: the image crop around the region.
    """

    id: int
    vertices: NDArray[np.float64]
    triangles: NDArray[np.int64]
    texcoords: NDArray[np.float64]
    texture: NDArray[np.uint8]


@dataclass(frozen=True, eq=False)
class Polyline:
    """A drawn outline: ``points (M, 3)`` metres, RGBA colour in [0, 1], closed or open."""

    ns: str
    id: int
    points: NDArray[np.float64]
    color: tuple[float, float, float, float]
    closed: bool = True


@dataclass(frozen=True, eq=False)
class Output:
    """A result of a stage, stamped and framed like the message that produced it.

    ``data`` by kind: ``classified_cloud`` ``(points (N, 3), classes (N,) int8)``; ``markers`` a
    list of :class:`Polyline`; ``grid`` ``(occupancy (H, W) int8 -1/0/100, resolution m,
    origin (2,) m)``; ``path`` ``(N, 3)`` points; ``pose`` ``(4, 4)`` ``T_frame_child``;
    ``textured_planes`` a list of :class:`TexturedPlane` (viewer only: ``results.mcap`` has the
    planes' outlines, see ``docs/runtime.md``).
    """

    topic: str
    kind: str
    stamp_ns: int
    frame_id: str
    data: Any
