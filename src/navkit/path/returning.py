"""The return to the operator as one online object: paper 4's controller on the stored path, going
round a blocked stretch (:mod:`navkit.path.detour`), stopping when there is no way round.

:class:`Return` is built from the stored :class:`~navkit.path.PathSpline` and frozen
:class:`ReturnTripSettings`; it keeps its own state (the controller's progress, the detour being
followed, since when the way is blocked) and takes one observation at a time through
:meth:`Return.update`:

- ``update(pose, t)`` every control cycle: the pose estimate -> a :class:`ReturnStep` (speeds,
  whether home) or a :class:`ReturnFailure` (blocked for ``wait`` seconds with no way round);
- ``update(pose, t, obstacles)`` whenever a new obstacle map is available (a lidar scan): is the
  way ahead (the detour being followed, or the stored path) blocked? -> a :class:`WayAhead`
  (clear, or a detour round the block was started) or a :class:`WayBlocked` (no way round: the
  robot stops).

Two observations rather than one because the map is checked at the sensor's rate with the pose
after the motion, the controller at the control rate with the pose before it. The obstacle map is any
object with the :class:`ObstacleView` methods (:class:`navkit.obstacles.ObstacleMapper` has
them); the path package does not import the obstacles package.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Protocol, overload

import numpy as np
from numpy.typing import NDArray

from navkit.domains import Domain, domain_field
from navkit.errors import ConfigError
from navkit.geometry._validate import check_settings
from navkit.path.control import PathFollowerSettings, ReturnController
from navkit.path.detour import (
    _METRES,
    _METRES_OR_0,
    Detour,
    DetourFailure,
    DetourSettings,
    plan_detour,
    polyline_spline,
)
from navkit.path.spline import PathSpline
from navkit.results import Failure, Result, deprecated_alias
from navkit.timing import Timings, timed

__all__ = [
    "ObstacleView",
    "Return",
    "ReturnFailure",
    "ReturnStep",
    "ReturnTripSettings",
    "WayAhead",
    "WayBlocked",
]

log = logging.getLogger(__name__)


class ObstacleView(Protocol):
    """What the return needs of an obstacle map (row = y, column = x cells)."""

    resolution: float
    origin: NDArray[np.float64]

    def blocked(self, path_xy: NDArray[np.float64], half_width: float) -> NDArray[np.bool_]: ...

    def planning_grid(self) -> NDArray[np.bool_]: ...


@dataclass(frozen=True)
class ReturnTripSettings:
    """Settings of :class:`Return` (SI units).

    Attributes
    ----------
    controller : PathFollowerSettings
        Paper 4's controller on the stored path.
    half_width : float
        Half the corridor the robot needs (half its width plus a clearance), metres.
    lookahead : float
        Length of the way ahead checked for a block, metres.
    wait : float
        Give up when the way stays blocked this long, seconds (``inf``: never give up).
    detour : bool
        Go round a blocked stretch (else stop in front of it).
    detour_margin : float
        Extra clearance of a detour beyond ``half_width``, metres.
    detour_search : float
        Stored path searched beyond the block for the rejoin point, metres.
    detour_delta : float
        The controller's look-ahead on a detour, metres.
    rejoin_offset : float
        See :class:`~navkit.path.detour.DetourSettings`.
    """

    controller: PathFollowerSettings = field(default_factory=PathFollowerSettings)
    half_width: float = domain_field(0.3, _METRES)
    lookahead: float = domain_field(2.0, _METRES)
    wait: float = domain_field(
        3.0, Domain(lo=0.0, allow_inf=True, note="seconds, inf = wait for ever")
    )
    detour: bool = True
    detour_margin: float = domain_field(0.2, _METRES_OR_0)
    detour_search: float = domain_field(8.0, _METRES)
    detour_delta: float = domain_field(0.4, _METRES)
    rejoin_offset: float = domain_field(0.5, _METRES_OR_0)

    def __post_init__(self) -> None:
        check_settings(self)
        if not isinstance(self.controller, PathFollowerSettings):
            raise ConfigError(
                f"is {self.controller!r} ({type(self.controller).__name__})",
                source=type(self).__name__,
                field="controller",
                expected="a PathFollowerSettings",
            )


@dataclass(frozen=True)
class ReturnStep(Result):
    """One control cycle: speeds (m/s, rad/s) and whether the robot is home."""

    v: float
    omega: float
    home: bool


@dataclass(frozen=True)
class ReturnFailure(Failure):
    """The return gave up.

    Attributes
    ----------
    reason : str
        ``"blocked"``: the way ahead stayed blocked for ``wait`` seconds.
    detail : str
        Why there is no way round (the last :class:`~navkit.path.detour.DetourFailure`, or
        ``"detours disabled"``).
    free_dof : tuple of str
        Empty: the pose is known, the way is not.
    """

    reason: str
    detail: str = ""
    free_dof: tuple[str, ...] = ()


@dataclass(frozen=True)
class WayAhead(Result):
    """The way ahead on the obstacle map is free to drive.

    Attributes
    ----------
    detour_started : bool
        The stored path was blocked and a detour round the block was started on this map
        (:attr:`Return.detours` holds it); False: the way ahead (stored path or the detour
        being followed) is clear.
    """

    detour_started: bool = False


@dataclass(frozen=True)
class WayBlocked(Failure):
    """The way ahead is blocked on the obstacle map and there is no way round: the robot stops
    (a :class:`ReturnFailure` follows when it stays blocked for ``wait`` seconds).

    Attributes
    ----------
    reason : str
        Why there is no way round (the last :class:`~navkit.path.detour.DetourFailure`, or
        ``"detours disabled"``).
    distance_ahead_m : float
        The blocked point, metres ahead along the way.
    point : (2,) array
        The blocked point, world x, y metres.
    free_dof : tuple of str
        Empty: the pose is known, the way is not.
    """

    reason: str
    distance_ahead_m: float
    point: NDArray[np.float64]
    free_dof: tuple[str, ...] = ()


@dataclass
class _Detouring:
    """A detour being followed: paper 4's return controller on the detour polyline (its start
    is the rejoin point), then the stored path resumed at arc length ``s_rejoin``."""

    detour: Detour
    controller: ReturnController  # on the reversed detour
    s_from: float  # stored-path arc length where the searched stretch starts
    block_dist: float  # the blocked point, metres along the stored path from s_from
    s_rejoin: float
    stop_radius: float
    ok = True

    def done(self, est: NDArray[np.float64]) -> bool:
        """The estimate is within the stop radius of the rejoin point."""
        return bool(np.hypot(*(est[:2] - self.detour.rejoin)) <= self.stop_radius)

    def ahead(self, length: float) -> NDArray[np.float64]:
        """``(21, 2)`` points of the detour still ahead, up to ``length`` metres."""
        p = float(self.controller.progress[0])
        return np.asarray(self.controller.path.position(np.linspace(p, max(p - length, 0.0), 21)))


class Return:
    """Brings the robot home along the stored path, round blocks (see the module docstring).

    Attributes
    ----------
    blocked : dict or None
        The last block met (time, distance ahead, the point, the reason there is no way round,
        ``active``); a record for the mission's report.
    detours : list of dict
        Every detour started (time, start, length, clearance, rejoin, replans, completed time).
    detour_paths : list of (K, 2) arrays
        Each detour as first planned.
    """

    def __init__(
        self,
        path: PathSpline,
        settings: ReturnTripSettings | None = None,
        timings: Timings | None = None,
    ) -> None:
        self.path = path
        self.settings = settings or ReturnTripSettings()
        self.controller = ReturnController(path, self.settings.controller)
        self.timings = timings
        self.round: _Detouring | None = None
        self.blocked_since: float | None = None
        self.no_detour = ""
        self.n_stops = 0
        self.blocked: dict[str, Any] | None = None
        self.detours: list[dict[str, Any]] = []
        self.detour_paths: list[NDArray[np.float64]] = []

    # --- one observation ---------------------------------------------------------------------
    @overload
    def update(self, pose: NDArray[np.float64], t: float) -> ReturnStep | ReturnFailure: ...

    @overload
    def update(
        self, pose: NDArray[np.float64], t: float, obstacles: ObstacleView
    ) -> WayAhead | WayBlocked: ...

    def update(
        self, pose: NDArray[np.float64], t: float, obstacles: ObstacleView | None = None
    ) -> ReturnStep | ReturnFailure | WayAhead | WayBlocked:
        """One observation: the estimated ``pose`` ``(x, y, theta)`` at time ``t`` (a control
        cycle: the speeds, :meth:`_control`), or with the latest ``obstacles`` map (the way
        ahead checked on it, a detour planned round a block, :meth:`_check_way`)."""
        if obstacles is None:
            return self._control(pose, t)
        return self._check_way(pose, t, obstacles)

    def step(self, pose: NDArray[np.float64], t: float) -> ReturnStep | ReturnFailure:
        """Deprecated alias of ``update(pose, t)`` (removed in the next release)."""
        deprecated_alias("Return.step", "Return.update(pose, t)")
        return self._control(pose, t)

    def observe(self, pose: NDArray[np.float64], t: float, obstacles: ObstacleView) -> str:
        """Deprecated alias of ``update(pose, t, obstacles)`` (removed in the next release):
        ``"detour"``, ``"blocked"`` or ``""``."""
        deprecated_alias("Return.observe", "Return.update(pose, t, obstacles)")
        r = self._check_way(pose, t, obstacles)
        if isinstance(r, WayBlocked):
            return "blocked"
        return "detour" if r.detour_started else ""

    # --- every control cycle -----------------------------------------------------------------
    def _control(self, pose: NDArray[np.float64], t: float) -> ReturnStep | ReturnFailure:
        """Speeds for the robot at the estimated ``pose`` ``(x, y, theta)`` at time ``t``."""
        with timed(self.timings, "return_control"):
            if self.round is not None and self.round.done(pose):
                # round the block: resume the stored path at the rejoin point
                self.controller.progress[:] = self.round.s_rejoin
                self.detours[-1]["completed_time"] = t
                log.info("detour done at t = %.1f s; back on the stored path", t)
                self.round = None
            if self.round is not None:
                cmd = self.round.controller.command(pose[None, :])
                home = False
            else:
                cmd = self.controller.command(pose[None, :])
                home = bool(cmd.done[0])
        v, om = float(cmd.v[0]), float(cmd.omega[0])
        if self.blocked is not None and self.blocked.get("active"):
            v, om = 0.0, 0.0
        waited = self.blocked_since is not None and t - self.blocked_since >= self.settings.wait
        if waited and not home:
            detail = self.no_detour or "detours disabled"
            if self.blocked is not None:
                self.blocked["detour"] = detail
            return ReturnFailure("blocked", detail)
        return ReturnStep(v, om, home)

    # --- whenever the obstacle map changes ---------------------------------------------------
    def _check_way(
        self, pose: NDArray[np.float64], t: float, obstacles: ObstacleView
    ) -> WayAhead | WayBlocked:
        """Check the way ahead on the map: clear, a detour started, or blocked with no way
        round."""
        st = self.settings
        with timed(self.timings, "block_check"):
            if self.round is not None:
                ahead, s_now = self.round.ahead(st.lookahead), self.round.s_from
            else:
                s_now = float(self.controller.progress[0])
                ss = np.linspace(s_now, max(s_now - st.lookahead, 0.0), 21)
                ahead = self.path.position(ss)
            hit = obstacles.blocked(ahead, st.half_width)
        if self.round is not None and st.detour:
            # replan on every scan while going round: the far side of the obstacle comes into
            # view as the robot turns
            new = self._plan(obstacles, pose, self.round.s_from, self.round.block_dist)
            if isinstance(new, _Detouring):
                self.round = new
                # the first plan stays in the log (the figure draws it); the rejoin point may
                # move as more of the obstacle is seen
                self.detours[-1]["replans"] += 1
                self.detours[-1]["rejoin_xy"] = new.detour.rejoin.tolist()
                self.detours[-1]["rejoin_s_m"] = new.s_rejoin
                hit = np.zeros(1, dtype=bool)
            elif hit.any():
                self.no_detour = str(new)
        if hit.any() and self.round is None and st.detour:
            j = int(np.argmax(hit))
            new = self._plan(obstacles, pose, s_now, s_now - float(ss[j]))
            if isinstance(new, _Detouring):
                self._start_detour(new, pose, t, ahead[j], float(s_now - ss[j]))
                return WayAhead(detour_started=True)
            self.no_detour = str(new)
        if hit.any():
            j = int(np.argmax(hit))
            d_ahead = (
                float(np.hypot(*np.diff(ahead[: j + 1], axis=0).T).sum())
                if self.round is not None
                else abs(float(ss[j]) - s_now)
            )
            self._block(t, s_now, d_ahead, ahead[j])
            return WayBlocked(
                self.no_detour or "detours disabled", d_ahead, np.asarray(ahead[j], float).copy()
            )
        if self.blocked_since is not None:
            self.blocked_since = None
            if self.blocked is not None:
                self.blocked["active"] = False
        return WayAhead()

    def _start_detour(
        self, new: _Detouring, pose: NDArray[np.float64], t: float, point: Any, dist: float
    ) -> None:
        self.round = new
        self.detours.append(
            {
                "time": t,
                "start_xy": pose[:2].tolist(),
                "blocked_path_point_xy": point.tolist(),
                "distance_ahead_m": dist,
                "length_m": new.detour.length,
                "min_clearance_m": new.detour.min_clearance,
                "rejoin_xy": new.detour.rejoin.tolist(),
                "rejoin_s_m": new.s_rejoin,
                "replans": 0,
                "completed_time": None,
            }
        )
        self.detour_paths.append(new.detour.points)
        log.info(
            "return blocked %.2f m ahead at t = %.1f s: going round (%.1f m)",
            dist,
            t,
            new.detour.length,
        )
        self.blocked_since = None
        if self.blocked is not None:
            self.blocked["active"] = False

    def _block(self, t: float, s_now: float, d_ahead: float, point: Any) -> None:
        if self.blocked_since is None:
            self.blocked_since = t
            self.n_stops += 1
            log.warning(
                "return blocked %.2f m ahead at t = %.1f s: stopping (%s)",
                d_ahead,
                t,
                self.no_detour or "detours disabled",
            )
        self.blocked = {
            "active": True,
            "stops": self.n_stops,
            "time": self.blocked_since,
            "s": s_now,
            "distance_ahead_m": d_ahead,
            "blocked_path_point_xy": point.tolist(),
            "detour": self.no_detour or "detours disabled",
        }

    def _plan(
        self,
        obstacles: ObstacleView,
        est: NDArray[np.float64],
        s_from: float,
        block_dist: float | None,
    ) -> _Detouring | DetourFailure:
        """Plan a way round the block on the obstacle map (:func:`plan_detour`): the cells of
        ``obstacles.planning_grid()``, inflated by the corridor half-width plus
        ``detour_margin``; the stored path from arc length ``s_from`` towards home is searched
        for the rejoin point."""
        st = self.settings
        with timed(self.timings, "detour_plan"):
            step = 0.5 * obstacles.resolution
            s_to = max(s_from - st.detour_search, 0.0)
            if s_from - s_to < step:
                return DetourFailure("no free path point beyond the block", "the block is at home")
            ss = np.linspace(s_from, s_to, int(np.ceil((s_from - s_to) / step)) + 1)
            bi = (
                None
                if block_dist is None
                else int(np.clip(round(block_dist / step), 0, len(ss) - 1))
            )
            settings = DetourSettings(
                robot_radius=st.half_width,
                margin=st.detour_margin,
                search_length=st.detour_search,
                rejoin_offset=st.rejoin_offset,
            )
            d = plan_detour(
                obstacles.planning_grid(),
                obstacles.resolution,
                obstacles.origin,
                est[:2],
                self.path.position(ss),
                settings,
                block_index=bi,
            )
            if isinstance(d, DetourFailure):
                log.info("%s", d)
                return d
            c = st.controller
            stop = c.stop_radius
            ctrl = ReturnController(
                polyline_spline(d.points[::-1]),
                PathFollowerSettings(
                    delta=st.detour_delta,
                    v_max=c.v_max,
                    stop_radius=stop,
                    approach_radius=stop,
                    omega_max=c.omega_max,
                ),
            )
            return _Detouring(
                detour=d,
                controller=ctrl,
                s_from=s_from,
                block_dist=float(ss[0] - ss[bi]) if bi is not None else float("nan"),
                s_rejoin=float(s_from - d.rejoin_arclength),
                stop_radius=stop,
            )
