"""Paper 3 in the mission, behind one object: :class:`MissionLocalizer`, over two
:class:`navkit.localization.Localizer` s - the same object ``navkit map locate`` and the
benchmarks use.

Two sources of fixes, both by correlative matching around the mission's estimate (the fused
estimate is the Localizer's ``prior``):

- **the room**: views (2D wall points in the robot frame, with the pose estimate) are collected
  while the robot is in the room on its way out, up to ``room_map_views``; the room's Localizer
  is built from them (:meth:`Localizer.from_views`: wall segments and corners, or the views'
  points when fewer than two walls are found) when enough views are in, when the robot leaves
  the room, or when the link is lost. Every later view (with the previous ``fragment_views``
  ones, brought into the current frame with the estimate's own relative motion) is located in
  that map (settings: :meth:`FusionSettings.room_localizer`);
- **the obstacle map on the way back**: the scan's obstacle points located in the outbound
  obstacle map (the map the stored path was recorded with), a Localizer on its occupied cells
  (:meth:`Localizer.from_points`, settings: :meth:`FusionSettings.map_localizer`).

A fix the matcher trusts (score, no ambiguity) within the gate of the estimate pulls the
estimate by the fix weight (the Localizer's blend); every attempt is logged as a
:class:`Fix2D` (:func:`take_fix`).

Decisions: a rejected fix leaves the estimate (``recentre_on_rejected=False``: the mission's
estimate is fused, not the matcher's). The fragment is stacked with the mission's own pose
algebra (:func:`navkit.mission.pose2d.relative`), not
:func:`navkit.localization.localizer.stack_views`: the two differ by ~1e-15 m, which the closed loop of
gates and thresholds amplifies into different runs; this keeps the mission's figures those of
the published runs. A fix weight of 0 turns that source of fixes off (no Localizer is built,
no attempt is logged).
"""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from navkit.geometry import se2_from_xytheta
from navkit.localization import Fix, LocalizationFailure, Localizer
from navkit.mission.pose2d import relative
from navkit.timing import Timings, timed

__all__ = ["Fix2D", "MissionLocalizer", "RoomRecord", "take_fix"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Fix2D:
    """A localization attempt (paper 3).

    Attributes
    ----------
    time : float
    pose : (3,) array
        Fix ``(x, y, theta)`` in the map frame (NaN if the matcher failed).
    score : float
    ok : bool
        The matcher's verdict (score and ambiguity).
    used : bool
        Accepted by the fusion (ok and within the gate).
    estimate_before, truth : (3,) arrays
    reason : str
        Why the matcher did not trust it (``""`` when ok; ``"elongated peak"``, ``"second
        peak"``, ``"low score"``).
    """

    time: float
    pose: NDArray[np.float64]
    score: float
    ok: bool
    used: bool
    estimate_before: NDArray[np.float64]
    truth: NDArray[np.float64]
    reason: str = ""


@dataclass
class RoomRecord:
    """What localization recorded: the room views and map, and every fix."""

    room_views: list[tuple[NDArray[np.float64], NDArray[np.float64]]] = field(default_factory=list)
    room_map: Any = None
    fixes: list[Fix2D] = field(default_factory=list)
    map_fixes: list[Fix2D] = field(default_factory=list)


def take_fix(
    res: Fix | LocalizationFailure,
    est: NDArray[np.float64],
    truth: NDArray[np.float64],
    t: float,
    log: list[Fix2D],
) -> NDArray[np.float64]:
    """Log a Localizer's answer for the estimate ``est`` and return the estimate after it (the
    fix blended in when confident and within the gate; ``est`` otherwise)."""
    pose = res.pose if isinstance(res, Fix) else res.candidate
    log.append(
        Fix2D(
            t,
            np.array(pose, dtype=np.float64),
            float(res.score),
            bool(res.ok),
            bool(res.used),
            est.copy(),
            truth.copy(),
            res.reason,
        )
    )
    return res.estimate


class MissionLocalizer:
    """The mission's localization (see the module docstring).

    Parameters
    ----------
    route : Route
        For the room's extent (``route.in_room``).
    fusion : FusionSettings
    map_resolution : float
        Cell size of the obstacle map, metres.
    record : RoomRecord
        Where views, the room map and fixes go.
    timings : Timings, optional
    """

    def __init__(
        self,
        route: Any,
        fusion: Any,
        map_resolution: float,
        record: RoomRecord,
        timings: Timings | None = None,
    ) -> None:
        self.route, self.F, self.rec, self.timings = route, fusion, record, timings
        self.map_resolution = map_resolution
        self.room: Localizer | None = None  # the room map, once built
        self.return_map: Localizer | None = None  # the outbound obstacle map, on the way back
        self.done = False
        self.recent: deque[tuple[NDArray[np.float64], NDArray[np.float64]]] = deque(
            maxlen=fusion.fragment_views
        )

    @property
    def views_pending(self) -> bool:
        """Views are collected but the map is not built yet."""
        return bool(self.rec.room_views) and not self.done

    def room_view(
        self,
        wall2d: NDArray[np.float64],
        est: NDArray[np.float64],
        truth: NDArray[np.float64],
        t: float,
        outbound: bool,
        may_fix: bool,
    ) -> NDArray[np.float64]:
        """Use one room view (``(N, 2)`` wall points, robot frame); returns the estimate."""
        rec, F = self.rec, self.F
        inside = self.route.in_room(est[:2])
        if not self.done:
            if inside and outbound and len(rec.room_views) < F.room_map_views:
                if len(wall2d) >= 10:
                    rec.room_views.append((wall2d, est.copy()))
                return est
            if rec.room_views:
                self.finish_room()
            return est
        # the fragment: this view and the previous ones - a wider fragment than one 80 deg
        # view, so fewer fixes are ambiguous along a single wall
        self.recent.append((wall2d, est.copy()))
        if self.room is None or not inside or not may_fix:
            return est
        frag = fragment(self.recent, est)
        if len(frag) < 20:
            return est
        with timed(self.timings, "localize"):
            res = self.room.update(frag, prior=est)
        return take_fix(res, est, truth, t, rec.fixes)

    def finish_room(self) -> None:
        """Build the room map and its Localizer from the views collected (once)."""
        if self.done or not self.rec.room_views:
            return
        self.done = True
        settings = self.F.room_localizer()
        if settings is None:
            return
        from navkit.localization import WallMapSettings

        views, poses = zip(*self.rec.room_views, strict=True)
        # stereo wall points scatter by their depth error (the floor-plan front end keeps it
        # below 0.25 m): walls closer than that are one wall
        mapping = WallMapSettings(merge_distance=0.25, merge_angle_deg=8.0)
        with timed(self.timings, "room_map"):
            self.room = Localizer.from_views(list(views), np.array(poses), settings, mapping)
        self.rec.room_map = self.room.map

    def link_lost(self, occupied_centres: NDArray[np.float64]) -> None:
        """The way back starts: the outbound obstacle map (its occupied cell centres ``(N, 2)``)
        becomes the Localizer of the return's fixes."""
        settings = self.F.map_localizer(self.map_resolution)
        if settings is not None and len(occupied_centres) >= 10:
            with timed(self.timings, "obstacle_map_field"):
                self.return_map = Localizer.from_points(occupied_centres, settings)

    def map_fix(
        self,
        obstacle_xy: NDArray[np.float64],
        est: NDArray[np.float64],
        truth: NDArray[np.float64],
        t: float,
    ) -> NDArray[np.float64]:
        """Locate a scan's obstacle points ``(N, 2)`` (robot frame) in the outbound obstacle map;
        returns the (possibly corrected) estimate."""
        if self.return_map is None or len(obstacle_xy) < self.F.map_fix_min_points:
            return est
        with timed(self.timings, "localize_obstacle_map"):
            res = self.return_map.update(obstacle_xy, prior=est)
        return take_fix(res, est, truth, t, self.rec.map_fixes)


def fragment(
    views: Any,
    est: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The views ``(wall points (N_i, 2), pose (3,))`` brought into the body frame at ``est``
    with the estimate's own relative motion (accurate over a few seconds), stacked."""
    parts = []
    for v, p in views:
        r = relative(est, p)
        parts.append(v @ se2_from_xytheta(*r)[:2, :2].T + r[:2])
    return np.vstack(parts)
