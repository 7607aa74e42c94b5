"""2D scans to localize, from a CARMEN log or a stereo frame folder, one at a time.

:func:`read_scan_sequence` opens either input and returns a :class:`ScanSequence`: per scan its
index in the input, timestamp, reference pose (the log's corrected pose or the frames' poses),
odometry pose, and its body-frame points on demand (:meth:`ScanSequence.points`):

- a CARMEN log (``.log`` / ``.log.gz``): the laser end points (no return and readings at or
  beyond ``max_range`` dropped); odometry = the log's raw odometry;
- a stereo frame folder (``calib.yaml``, ``poses.tum``, ``left/``, ``right/``; see ``navkit
  stereo simulate``): the front end's wall points of ``group`` consecutive frames taken at one
  place, each moved into the first frame's body frame by its relative planar pose (relative
  headings from the camera drive, paper 3); odometry = the frames' poses. Decision: the stereo
  front end (:func:`navkit.stereo.stereo_wall_points`) runs here, at the edge, so that the
  localizer and the command line both see plain 2D points.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from navkit.errors import DataNotFoundError, InputError
from navkit.geometry import (
    se2_apply,
    se2_compose,
    se2_from_xytheta,
    se2_inverse,
    se2_to_xytheta,
)
from navkit.localization.visibility import ViewModel

if TYPE_CHECKING:
    from navkit.io.carmen import CarmenLog

__all__ = ["ScanSequence", "heading_of_camera", "read_scan_sequence"]


def heading_of_camera(T: NDArray[np.float64]) -> NDArray[np.float64]:
    """Heading (rad) of the optical axis of ``T_world_camera`` ``(..., 4, 4)`` in the world plane."""
    z = T[..., :3, 2]
    return np.asarray(np.arctan2(z[..., 1], z[..., 0]), dtype=np.float64)


@dataclass(frozen=True)
class ScanSequence:
    """Scans to localize (see the module docstring).

    Attributes
    ----------
    kind : str
        ``"carmen"`` or ``"stereo"``.
    source : str
    indices : (K,) int array
        Each scan's index in the input (stereo: the group's first frame).
    timestamps : (K,) array
        Seconds.
    reference : (K, 3) array
        Reference ``(x, y, theta)`` (the log's corrected poses; the frames' poses).
    odometry : (K, 3) array
        Odometry ``(x, y, theta)`` (the log's raw odometry; the frames' poses).
    range_sigma_coefficient : float
        1/m; ``k`` of the points' error along their rays ``k r^2`` (0 for a laser).
    view : ViewModel or None
        The view of one scan (stereo, one frame per scan), for the negative-information check.
    carmen : CarmenLog or None
        The whole log (CARMEN input), e.g. for map building from its ordered scans.
    """

    kind: str
    source: str
    indices: NDArray[np.intp]
    timestamps: NDArray[np.float64]
    reference: NDArray[np.float64]
    odometry: NDArray[np.float64]
    range_sigma_coefficient: float
    view: ViewModel | None
    _points: Callable[[int], NDArray[np.float64]]
    _world_points: Callable[[int], NDArray[np.float64]]
    carmen: CarmenLog | None = None

    def __len__(self) -> int:
        return len(self.indices)

    def points(self, k: int) -> NDArray[np.float64]:
        """Body-frame points ``(N, 2)`` of scan ``k`` (x forward, y left, metres)."""
        return self._points(k)

    def world_points(self, k: int) -> NDArray[np.float64]:
        """World-frame points ``(N, 2)`` of scan ``k`` placed with its reference pose (stereo:
        each frame of the group with its full ``T_world_camera``), for map building."""
        return self._world_points(k)

    def odometry_delta(self, k: int) -> NDArray[np.float64] | None:
        """Body-frame odometry increment ``(dx, dy, dtheta)`` from scan ``k - 1`` to ``k``
        (None for the first scan)."""
        if k == 0:
            return None
        a, b = (se2_from_xytheta(*self.odometry[j]) for j in (k - 1, k))
        return se2_to_xytheta(se2_compose(se2_inverse(a), b))


def read_scan_sequence(
    path: str | os.PathLike[str], *, every: int = 1, group: int = 1, max_range: float = 30.0
) -> ScanSequence:
    """Open a CARMEN log or a stereo frame folder as scans to localize.

    Parameters
    ----------
    path : path
        CARMEN log file or stereo frame folder.
    every : int
        Use every N-th scan (stereo: every N-th group).
    group : int
        Stereo: N consecutive frames taken at one place form one scan (a fragment).
    max_range : float
        Metres; laser readings at or beyond this are no return.
    """
    p = Path(path)
    if not p.exists():
        raise DataNotFoundError(f"{p}: no such CARMEN log or stereo frame folder")
    if every < 1 or group < 1:
        raise InputError(f"every {every}, group {group}", field="every/group", expected=">= 1")
    if p.is_file():
        return _carmen(p, every, max_range)
    return _stereo(p, every, group)


def _carmen(path: Path, every: int, max_range: float) -> ScanSequence:
    from navkit.io.carmen import read_carmen

    lg = read_carmen(path)
    sel = np.arange(0, len(lg), every)

    def points(k: int) -> NDArray[np.float64]:
        return lg.points(int(sel[k]), max_range)

    def world_points(k: int) -> NDArray[np.float64]:
        return se2_apply(se2_from_xytheta(*lg.poses[sel[k]]), points(k))

    return ScanSequence(
        "carmen",
        str(path),
        sel,
        lg.timestamps[sel],
        lg.poses[sel],
        lg.odom_poses[sel],
        0.0,
        None,
        points,
        world_points,
        lg,
    )


def _stereo(path: Path, every: int, group: int) -> ScanSequence:
    from navkit.io.images import read_image
    from navkit.io.stereo import read_stereo_frames
    from navkit.localization.localizer import stack_views
    from navkit.stereo import stereo_wall_points
    from navkit.stereo.floorplan import FloorplanSettings, default_num_disparities, usable_depth

    fr = read_stereo_frames(path)
    if len(fr) % group:
        raise InputError(
            f"{len(fr)} frames are not a multiple of --group {group}",
            source=path,
            field="--group",
            expected="groups of frames taken at one place",
        )
    sel = np.arange(0, len(fr), group)[::every]
    planar = np.column_stack([fr.poses[:, 0, 3], fr.poses[:, 1, 3], heading_of_camera(fr.poses)])

    def points(k: int) -> NDArray[np.float64]:
        j0 = int(sel[k])
        views = [
            stereo_wall_points(
                read_image(fr.left[j]),
                read_image(fr.right[j]),
                fr.rig,
                camera_height=float(fr.poses[j][2, 3]),
            )
            for j in range(j0, j0 + group)
        ]
        return stack_views(views, planar[j0 : j0 + group])

    def world_points(k: int) -> NDArray[np.float64]:
        j0 = int(sel[k])
        return np.concatenate(
            [
                stereo_wall_points(
                    read_image(fr.left[j]),
                    read_image(fr.right[j]),
                    fr.rig,
                    T_world_camera=fr.poses[j],
                )
                for j in range(j0, j0 + group)
            ]
        )

    fp = FloorplanSettings()
    view = None
    if group == 1:  # the view of one frame, for the negative-information check
        view = ViewModel.from_stereo(
            fr.rig,
            max_depth=usable_depth(fr.rig, fp),
            num_disparities=default_num_disparities(fr.rig, fp),
            disparity_sigma=fp.disparity_sigma,
        )
    reference = planar[sel]
    return ScanSequence(
        "stereo",
        str(path),
        sel,
        fr.timestamps[sel],
        reference,
        reference,  # the frames' poses serve as odometry for the tracking prior
        # stereo_range_sigma: r^2 sigma_d / (b f)
        fp.disparity_sigma / (fr.rig.baseline * fr.rig.camera.fx),
        view,
        points,
        world_points,
    )
