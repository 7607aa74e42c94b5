"""Live and recorded 3D viewing of a ``navkit run`` with Rerun (``rerun-sdk``, extra ``rerun``).

:class:`RerunLogger` has the interface of :class:`navkit.runtime.run.NullLogger`, so the run loop
never branches on whether anything is viewed (kiss-icp style). One timeline, ``recording``
(the messages' stamps, seconds); entities:

- ``world/obstacles/points``: the classified cloud, coloured by class (green ground, grey
  unreliable, red obstacle, orange / purple shadows), ``class_ids`` kept;
- ``world/obstacles/shapes/<name>``, ``world/walls``, ``world/planes``: outlines (line strips;
  of the bounding shapes only ``shapes``, default A1 and A6 as ``navkit obstacles detect``'s
  PNG: twelve overlapping outlines per obstacle hide the scene; ``results.mcap`` has them all);
- ``world/<topic>/grid``: occupancy grids as the occupied cells' centres;
- ``world/path``: the stored path; ``world/<topic>``: poses (fixes, plane odometry, input poses)
  as transforms with a short axis triad;
- ``world/planes/textured/<k>``: each RGB-D frame's planes as meshes textured with the colour
  pixels of their regions (``rr.Mesh3D`` with ``albedo_texture``), replaced every frame;
- ``world/<topic>`` of an input scan: its end points in the laser's frame;
- ``world/tf/<child>``: the TF tree ``results.mcap`` carries (outputs of kind ``tf``), each edge a
  Rerun named-frame transform (``Transform3D`` with ``parent_frame`` / ``child_frame``) drawn as
  an axis triad labelled with the frame's name; ``world/tf/map`` marks ``map``.

Everything is drawn in the frame of its message (``rr.CoordinateFrame`` = its header frame, a
pose's transform has the message's frame as ``parent_frame``), and the view's target frame is
``map``: the TF edges chain the frames as tf2 does, so a scan in ``laser`` lands on the walls in
``map`` through ``map -> odom -> base_link -> laser``, as Foxglove and RViz draw ``results.mcap``.
Named frames need ``rerun-sdk >= 0.28``.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from navkit.errors import ConfigError, require_module

__all__ = ["CLASS_COLORS", "TF_AXIS_M", "RerunLogger", "blueprint", "check_rrd_path"]

log = logging.getLogger(__name__)

CLASS_COLORS = {
    0: (60, 180, 75),  # ground
    -1: (150, 150, 150),  # unreliable
    -2: (230, 25, 75),  # obstacle
    -3: (245, 130, 48),  # side shadow
    -4: (145, 30, 180),  # shadow behind
}

# length of a TF frame's axes (m): a robot's size, visible beside a building's walls
TF_AXIS_M = 0.5
SCAN_COLOR = (0, 150, 200)


def _entity(topic: str) -> str:
    return "world/" + topic.strip("/").replace("navkit/", "")


def _frame(frame_id: str) -> str:
    """A header frame as a Rerun frame name (no leading slash; an empty one is ``map``)."""
    return frame_id.strip("/") or "map"


def check_rrd_path(save: str | os.PathLike[str]) -> Path:
    """``save`` as the path of a Rerun recording: a file name ending in ``.rrd`` that is not a
    folder (checked before a run starts, so a typo costs nothing)."""
    p = Path(save)
    if p.suffix.lower() != ".rrd":
        raise ConfigError(
            f"is {str(save)!r}", field="--rerun-save", expected="a file name ending in .rrd"
        )
    if p.is_dir():
        raise ConfigError(f"{p} is a folder", field="--rerun-save", expected="an .rrd file path")
    return p


def blueprint(eye: Any = None, look_at: Any = None) -> Any:
    """One 3D view of ``world`` in frame ``map`` (every entity, the TF chains resolved to
    ``map``) with the side panels collapsed; ``eye`` / ``look_at`` (x, y, z in ``map``, m) place
    the camera, else the viewer fits it to the scene."""
    import rerun.blueprint as rrb

    eye_controls = None
    if eye is not None or look_at is not None:
        eye_controls = rrb.EyeControls3D(position=eye, look_target=look_at)
    view = rrb.Spatial3DView(
        origin="/world",
        spatial_information=rrb.SpatialInformation(target_frame="map"),
        eye_controls=eye_controls,
    )
    return rrb.Blueprint(view, collapse_panels=True)


class RerunLogger:
    """Send a run to the Rerun viewer (``spawn``) and/or record it to an ``.rrd`` file (``save``)."""

    def __init__(
        self,
        spawn: bool = False,
        save: str | os.PathLike[str] | None = None,
        application_id: str = "navkit",
        shapes: tuple[str, ...] = ("A1", "A6"),
    ) -> None:
        if save is not None:
            check_rrd_path(save)
        rr = require_module("rerun", "rerun", "viewing a run in Rerun (--rerun / --rerun-save)")
        self.rr = rr
        self.rec = rr.RecordingStream(application_id)
        if save is not None:
            Path(save).parent.mkdir(parents=True, exist_ok=True)
            self.rec.save(str(save))
        if spawn:
            self.rec.spawn(connect=save is None)
        self.save = save
        self.shapes = set(shapes)
        self._axes: set[str] = set()  # pose entities whose axes are logged
        self._frames: set[str] = {"map"}  # TF frames whose axes are logged
        self._lut = np.zeros((256, 3), dtype=np.uint8)
        for k, c in CLASS_COLORS.items():
            self._lut[k & 0xFF] = c
        self.rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self.rec.log(
            "world/tf/map",
            rr.CoordinateFrame("map"),
            rr.TransformAxes3D(TF_AXIS_M, show_frame=True),
            static=True,
        )
        # the default layout: a blueprint the user loads (an .rbl) or keeps in the viewer wins
        self.rec.send_blueprint(self.blueprint(), make_active=False, make_default=True)

    def blueprint(self) -> Any:
        """The recording's layout (:func:`blueprint`)."""
        return blueprint()

    def set_time(self, stamp_ns: int) -> None:
        """Move the ``recording`` timeline to ``stamp_ns``."""
        self.rec.set_time("recording", timestamp=stamp_ns * 1e-9)

    def log_message(self, msg: Any) -> None:
        """Input poses as transforms, scans as their end points (clouds are shown classified,
        by their output; transforms by the TF outputs the run passes them through as)."""
        if msg.kind == "pose":
            self._pose(_entity(msg.topic), msg.frame_id, msg.data)
        elif msg.kind == "scan":
            xy = msg.data.points()
            self.rec.log(
                _entity(msg.topic),
                self.rr.Points3D(
                    np.c_[xy, np.zeros(len(xy))].astype(np.float32),
                    colors=SCAN_COLOR,
                    radii=self.rr.Radius.ui_points(1.5),
                ),
                self.rr.CoordinateFrame(_frame(msg.frame_id)),
            )

    def _pose(self, entity: str, frame_id: str, T: Any) -> None:
        rr = self.rr
        T = np.asarray(T, dtype=np.float64)
        self.rec.log(
            entity,
            rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3], parent_frame=_frame(frame_id)),
        )
        if entity not in self._axes:  # the axes move with the transform: logged once, static
            self._axes.add(entity)
            self.rec.log(
                entity + "/axes",
                rr.Arrows3D(
                    vectors=np.eye(3) * 0.5, colors=[(255, 0, 0), (0, 255, 0), (0, 0, 255)]
                ),
                static=True,
            )

    def log_output(self, o: Any) -> None:
        """Show one :class:`~navkit.runtime.messages.Output`."""
        rr = self.rr
        ent = _entity(o.topic)
        frame = rr.CoordinateFrame(_frame(o.frame_id))
        if o.kind == "tf":
            static = o.topic.rstrip("/").endswith("tf_static")
            for child, T in o.data:
                T = np.asarray(T, dtype=np.float64)
                name = _frame(child)
                self.rec.log(
                    "world/tf/" + name,
                    rr.Transform3D(
                        translation=T[:3, 3],
                        mat3x3=T[:3, :3],
                        parent_frame=_frame(o.frame_id),
                        child_frame=name,
                    ),
                    static=static,
                )
                if name not in self._frames:  # the triad sits in the frame: logged once, static
                    self._frames.add(name)
                    self.rec.log(
                        "world/tf/" + name,
                        rr.CoordinateFrame(name),
                        rr.TransformAxes3D(TF_AXIS_M, show_frame=True),
                        static=True,
                    )
        elif o.kind == "classified_cloud":
            pts, cls = o.data
            cls = np.asarray(cls, dtype=np.int8)
            self.rec.log(
                ent,
                rr.Points3D(
                    np.asarray(pts, np.float32),
                    colors=self._lut[cls.astype(np.uint8)],
                    class_ids=cls.astype(np.int16),
                    radii=rr.Radius.ui_points(1.5),
                ),
                frame,
            )
        elif o.kind == "markers":
            self.rec.log(ent, rr.Clear(recursive=True))  # this array replaces the last one
            groups: dict[str, tuple[list[Any], list[Any]]] = {}
            for line in o.data:  # one entity per outline kind (shape name, walls, corners, planes)
                if line.ns.startswith("shape/") and line.ns[len("shape/") :] not in self.shapes:
                    continue
                P = np.asarray(line.points, np.float32)
                name = line.ns.split("/")[-1].replace(":", "/")
                strips, colors = groups.setdefault(name, ([], []))
                strips.append(np.vstack([P, P[:1]]) if line.closed and len(P) > 1 else P)
                colors.append([int(255 * c) for c in line.color])
            for name, (strips, colors) in groups.items():
                sub = ent if name == ent.rsplit("/", 1)[-1] else f"{ent}/{name}"
                self.rec.log(
                    sub,
                    rr.LineStrips3D(strips, colors=colors, radii=rr.Radius.ui_points(1.5)),
                    frame,
                )
        elif o.kind == "grid":
            occ, res, origin = o.data
            rows, cols = np.nonzero(np.asarray(occ) == 100)
            xy = np.asarray(origin)[:2] + (np.c_[cols, rows] + 0.5) * res
            self.rec.log(
                ent,
                rr.Points3D(np.c_[xy, np.zeros(len(xy))], colors=(40, 40, 40), radii=0.5 * res),
                frame,
            )
        elif o.kind == "path":
            self.rec.log(
                ent, rr.LineStrips3D([np.asarray(o.data, np.float32)], colors=(0, 120, 255)), frame
            )
        elif o.kind == "pose":
            self._pose(ent, o.frame_id, o.data)
        elif o.kind == "textured_planes":
            self.rec.log(ent, rr.Clear(recursive=True))  # this frame's planes replace the last
            for p in o.data:
                self.rec.log(
                    f"{ent}/{p.id}",
                    rr.Mesh3D(
                        vertex_positions=np.asarray(p.vertices, np.float32),
                        triangle_indices=np.asarray(p.triangles, np.uint32),
                        vertex_texcoords=np.asarray(p.texcoords, np.float32),
                        albedo_texture=np.asarray(p.texture, np.uint8),
                    ),
                    frame,
                )

    def close(self) -> None:
        """Flush and close the recording (the ``.rrd`` is complete after this)."""
        self.rec.flush()
        if self.save is not None:
            self.rec.disconnect()
