"""The scripted operator: a pure-pursuit driver along a waypoint polyline.

The operator sees the robot (line of sight or its video) while the link is up, so the driver
steers on the *true* pose; the robot's own estimate plays no part in the outbound drive.
Pure pursuit (Coulter, 1992): the goal is the point ``lookahead`` metres further along the route
than the robot's projection on it; the turn rate is ``omega = 2 v sin(alpha) / L`` with ``alpha``
the bearing of the goal in the robot frame; the speed drops with ``|alpha|`` so the robot turns
on the spot at sharp corners.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError

__all__ = ["PurePursuit", "polyline_arclength", "polyline_point"]


def polyline_arclength(points: ArrayLike) -> NDArray[np.float64]:
    """Cumulative arc length ``(N,)`` of a polyline ``(N, 2)``, metres."""
    P = np.asarray(points, dtype=np.float64)
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(P, axis=0).T))])


def polyline_point(points: ArrayLike, s: ArrayLike) -> NDArray[np.float64]:
    """Points ``(..., 2)`` at arc lengths ``s`` along the polyline (clipped to its ends)."""
    P = np.asarray(points, dtype=np.float64)
    cum = polyline_arclength(P)
    s = np.clip(np.asarray(s, dtype=np.float64), 0.0, cum[-1])
    return np.stack([np.interp(s, cum, P[:, 0]), np.interp(s, cum, P[:, 1])], axis=-1)


class PurePursuit:
    """Follows a waypoint polyline from its start.

    Parameters
    ----------
    waypoints : (N, 2) array
        Metres; ``N >= 2``.
    v_max, omega_max : float
        Speed (m/s) and turn-rate limit (rad/s).
    lookahead : float
        Metres.
    goal_tolerance : float
        Done within this distance of the last waypoint, metres.
    """

    def __init__(
        self,
        waypoints: ArrayLike,
        v_max: float,
        omega_max: float,
        lookahead: float,
        goal_tolerance: float,
    ) -> None:
        W = np.asarray(waypoints, dtype=np.float64)
        if W.ndim != 2 or W.shape[1] != 2 or len(W) < 2:
            raise InputError(
                f"has shape {W.shape}", field="waypoints", expected="(N >= 2, 2) metres"
            )
        keep = np.concatenate([[True], np.hypot(*np.diff(W, axis=0).T) > 1e-9])
        self.waypoints = W[keep]
        self.cum = polyline_arclength(self.waypoints)
        self.length = float(self.cum[-1])
        self.v_max, self.omega_max = float(v_max), float(omega_max)
        self.lookahead, self.goal_tolerance = float(lookahead), float(goal_tolerance)
        self.progress = 0.0

    def _project(self, xy: NDArray[np.float64]) -> float:
        """Arc length of the nearest route point, searched ahead of the last progress."""
        A, B = self.waypoints[:-1], self.waypoints[1:]
        AB = B - A
        L2 = np.maximum((AB**2).sum(1), 1e-12)
        t = np.clip(((xy - A) * AB).sum(1) / L2, 0.0, 1.0)
        d = np.hypot(*(A + t[:, None] * AB - xy).T)
        s = self.cum[:-1] + t * np.sqrt(L2)
        d = np.where((s >= self.progress - 0.5) & (s <= self.progress + 3.0), d, np.inf)
        k = int(np.argmin(d))
        return float(s[k]) if np.isfinite(d[k]) else self.progress

    def done(self, pose: ArrayLike) -> bool:
        """Whether the robot at ``pose`` ``(3,)`` has reached the last waypoint."""
        p = np.asarray(pose, dtype=np.float64)
        return bool(np.hypot(*(p[:2] - self.waypoints[-1])) <= self.goal_tolerance)

    def command(self, pose: ArrayLike) -> tuple[float, float]:
        """``(v, omega)`` for the robot at ``pose`` ``(x, y, theta)``."""
        p = np.asarray(pose, dtype=np.float64)
        if self.done(p):
            return 0.0, 0.0
        self.progress = max(self.progress, self._project(p[:2]))
        goal = polyline_point(self.waypoints, self.progress + self.lookahead)
        d = goal - p[:2]
        alpha = float(np.angle(np.exp(1j * (np.arctan2(d[1], d[0]) - p[2]))))
        dist_goal = float(np.hypot(*(p[:2] - self.waypoints[-1])))
        v = self.v_max * max(np.cos(alpha), 0.0) * min(1.0, max(dist_goal / self.lookahead, 0.2))
        L = max(float(np.hypot(*d)), 1e-6)
        omega = 2.0 * max(v, 0.1 * self.v_max) * np.sin(alpha) / L
        return float(v), float(np.clip(omega, -self.omega_max, self.omega_max))
