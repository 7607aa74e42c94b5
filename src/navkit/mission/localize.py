"""Paper 3 in the mission, behind one object: :class:`MissionLocalizer`.

Two sources of fixes, both by correlative matching (:func:`navkit.localization.matcher.match_scan`):

- **the room**: views (2D wall points in the robot frame, with the pose estimate) are collected
  while the robot is in the room on its way out, up to ``room_map_views``; the map is built from
  them (wall segments, corners: :func:`navkit.localization.mapping.build_map`) when enough views
  are in, when the robot leaves the room, or when the link is lost. Every later view (with the
  previous ``fragment_views`` ones, brought into the current frame with the estimate's own
  relative motion) is located in that map around the estimate;
- **the obstacle map on the way back**: the scan's obstacle points located in the outbound
  obstacle map (the map the stored path was recorded with), as a likelihood field.

A fix that the matcher trusts (score, no ambiguity) and that lies within the gate of the estimate
pulls the estimate (:func:`take_fix`). Every attempt is logged as a :class:`Fix2D`.

This is the one place the mission localizes: the integrator swaps it for
``navkit.localization.Localizer`` here.
"""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from navkit.errors import NavkitError
from navkit.geometry import se2_from_xytheta
from navkit.mission.pose2d import blend, relative
from navkit.timing import Timings, timed

if TYPE_CHECKING:
    from navkit.localization.matcher import Fix

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
    fx: Fix,
    est: NDArray[np.float64],
    truth: NDArray[np.float64],
    t: float,
    gate_m: float,
    weight: float,
    log: list[Fix2D],
) -> NDArray[np.float64]:
    """Log a correlation fix and blend it into the estimate when it is confident (``fx.ok``)
    and within ``gate_m`` of the estimate; returns the (possibly corrected) estimate."""
    used = bool(fx.ok and float(np.hypot(*(fx.pose[:2] - est[:2]))) <= gate_m)
    reason = fx.ambiguity.reason if fx.ambiguity.ambiguous else ("" if fx.ok else "low score")
    log.append(
        Fix2D(
            t, fx.pose.copy(), float(fx.score), bool(fx.ok), used, est.copy(), truth.copy(), reason
        )
    )
    return blend(est, fx.pose, weight) if used else est


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
        from navkit.localization.matcher import MatcherSettings

        self.route, self.F, self.rec, self.timings = route, fusion, record, timings
        self.map_resolution = map_resolution
        self.matcher = MatcherSettings(linear_window=fusion.fix_gate_m, angular_window_deg=10.0)
        self.map_matcher = MatcherSettings(
            linear_window=fusion.map_fix_gate_m, angular_window_deg=8.0, point_spacing=0.2
        )
        self.field: Any = None
        self.return_field: Any = None  # the outbound obstacle map as a likelihood field
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
        from navkit.localization.matcher import match_scan

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
        # the fragment: this view and the previous ones, brought into the current frame with the
        # estimate's own relative motion (accurate over a few seconds) - a wider fragment than one
        # 80 deg view, so fewer fixes are ambiguous along a single wall
        self.recent.append((wall2d, est.copy()))
        if self.field is None or not inside or not may_fix:
            return est
        parts = []
        for v, p in self.recent:
            r = relative(est, p)
            parts.append(v @ se2_from_xytheta(*r)[:2, :2].T + r[:2])
        frag = np.vstack(parts)
        if len(frag) < 20:
            return est
        with timed(self.timings, "localize"):
            fx = match_scan(self.field, frag, prior=est, settings=self.matcher)
        return take_fix(fx, est, truth, t, F.fix_gate_m, F.fix_weight, rec.fixes)

    def finish_room(self) -> None:
        """Build the room map from the views collected (once)."""
        if self.done or not self.rec.room_views:
            return
        self.done = True
        with timed(self.timings, "room_map"):
            self.field = self._build_room_field()

    def link_lost(self, occupied_centres: NDArray[np.float64]) -> None:
        """The way back starts: the room map is finished and the outbound obstacle map (its
        occupied cell centres ``(N, 2)``) becomes a likelihood field for the return's fixes."""
        from navkit.localization.field import LikelihoodField

        if self.F.map_fix_weight > 0 and len(occupied_centres) >= 10:
            with timed(self.timings, "obstacle_map_field"):
                self.return_field = LikelihoodField.from_points(
                    occupied_centres, resolution=self.map_resolution, sigma=0.15
                )

    def map_fix(
        self,
        obstacle_xy: NDArray[np.float64],
        est: NDArray[np.float64],
        truth: NDArray[np.float64],
        t: float,
    ) -> NDArray[np.float64]:
        """Locate a scan's obstacle points ``(N, 2)`` (robot frame) in the outbound obstacle map;
        returns the (possibly corrected) estimate."""
        from navkit.localization.matcher import match_scan

        F = self.F
        if self.return_field is None or len(obstacle_xy) < F.map_fix_min_points:
            return est
        with timed(self.timings, "localize_obstacle_map"):
            fx = match_scan(self.return_field, obstacle_xy, prior=est, settings=self.map_matcher)
        return take_fix(fx, est, truth, t, F.map_fix_gate_m, F.map_fix_weight, self.rec.map_fixes)

    def _build_room_field(self) -> Any:
        """Room wall map from the first-visit views (paper 3) and its likelihood field."""
        from navkit.localization.field import LikelihoodField
        from navkit.localization.mapping import MapSettings, build_map, sample_segments

        views = [v for v, _ in self.rec.room_views]
        poses = np.array([p for _, p in self.rec.room_views]).reshape(-1, 3)
        try:
            # stereo wall points scatter by their depth error (the floor-plan front end keeps it
            # below 0.25 m): walls closer than that are one wall
            wm = build_map(
                views, poses, MapSettings(merge_distance=0.25, merge_angle_deg=8.0), ordered=False
            )
        except NavkitError as exc:
            log.warning("room map failed: %s", exc)
            wm = None
        self.rec.room_map = wm
        if wm is not None and len(wm.walls) >= 2:
            pts = sample_segments(wm.walls, 0.05)
        else:
            T = se2_from_xytheta(poses[:, 0], poses[:, 1], poses[:, 2])
            pts = np.vstack([v @ Tp[:2, :2].T + Tp[:2, 2] for v, Tp in zip(views, T, strict=True)])
        return LikelihoodField.from_points(pts, resolution=0.05, sigma=0.1)
