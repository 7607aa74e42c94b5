"""Mode 2 of paper 4: the return to the operator along the stored path.

Each control cycle (steps 2.1-2.4): find the path point nearest to the robot (``s_n``), take the
point ``delta`` metres closer to the start along the arc length (``s_t = max(s_n - delta, 0)``),
and steer to it with angular speed proportional to the heading error ``psi`` to that point
and a linear speed that drops with ``|psi|``; stop inside ``stop_radius`` of the start.

The paper's printed formulas for ``v`` and ``omega`` are damaged; the decisions taken here:

- ``omega = clip(k_omega * psi, -omega_max, omega_max)``;
- ``v = v_max * max(0, cos psi) * min(1, d_start / approach_radius)`` - full speed when heading at
  the target, zero when it is more than 90 deg off (the robot turns in place first, which also
  covers turning round at the end of the recorded path), and slowing down in the last
  ``approach_radius`` so the stop radius is not overshot;
- the nearest point is searched only in a window ``[s_p - window_back, s_p + window_ahead]``
  around the previous answer ``s_p`` (starting at the path's end), so where the path passes
  close to itself the robot does not jump to the wrong branch. All of it is vectorised over a
  batch of robots (the return simulation runs its 40 runs in lock-step).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.domains import Domain, domain_field
from navkit.errors import InputError
from navkit.geometry._validate import check_settings
from navkit.path.spline import PathSpline

__all__ = ["PathFollowerSettings", "ReturnCommand", "ReturnController"]


#: A distance along or around the path, metres (0 would stall the controller).
_METRES = Domain(lo=0.0, lo_open=True, note="metres")


@dataclass(frozen=True)
class PathFollowerSettings:
    """Settings of the return controller (SI units).

    Attributes
    ----------
    delta : float
        Look-ahead along the path towards the start (step 2.2), metres.
    v_max : float
        Linear speed on a straight path, m/s.
    k_omega : float
        Gain of the angular speed on the heading error, 1/s.
    omega_max : float
        Angular speed limit, rad/s.
    stop_radius : float
        Stop when the robot is this close to the start (step 2.4), metres.
    approach_radius : float
        Slow down linearly within this distance of the start, metres.
    min_speed_fraction : float
        Floor of the approach slow-down, as a fraction of ``v_max``.
    window_back, window_ahead : float
        Search window of the nearest point around the previous one, metres.
    """

    delta: float = domain_field(0.3, _METRES)
    v_max: float = domain_field(0.3, Domain(lo=0.0, lo_open=True, note="m/s"))
    k_omega: float = domain_field(2.0, Domain(lo=0.0, lo_open=True, note="1/s"))
    omega_max: float = domain_field(1.0, Domain(lo=0.0, lo_open=True, note="rad/s"))
    stop_radius: float = domain_field(0.05, _METRES)
    approach_radius: float = domain_field(0.3, _METRES)
    min_speed_fraction: float = domain_field(
        0.1, Domain(lo=0.0, hi=1.0, lo_open=True, note="a fraction of v_max")
    )
    window_back: float = domain_field(1.0, _METRES)
    window_ahead: float = domain_field(0.5, _METRES)

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class ReturnCommand:
    """One control cycle's output for a batch of robots (all arrays ``(N,)``).

    Attributes
    ----------
    v, omega : arrays
        Linear (m/s) and angular (rad/s) speed; zero once stopped.
    s_nearest, s_target : arrays
        Arc lengths of the nearest and of the target point, metres.
    lateral : arrays
        Distance from the (estimated) robot position to the path, metres.
    heading_error : arrays
        ``psi``, radians.
    done : bool array
        Inside the stop radius.
    """

    v: NDArray[np.float64]
    omega: NDArray[np.float64]
    s_nearest: NDArray[np.float64]
    s_target: NDArray[np.float64]
    lateral: NDArray[np.float64]
    heading_error: NDArray[np.float64]
    done: NDArray[np.bool_]


class ReturnController:
    """Steers robots back along ``path`` to its start.

    Parameters
    ----------
    path : PathSpline
        The stored path (from its start at the operator to where the robot is).
    settings : PathFollowerSettings, optional
    n_robots : int
        Batch size (each robot keeps its own progress ``s``).
    """

    def __init__(
        self, path: PathSpline, settings: PathFollowerSettings | None = None, n_robots: int = 1
    ) -> None:
        if path.n_segments == 0 or path.total_length <= 0:
            raise InputError(
                "the path has zero length",
                field="path",
                expected="a path with at least one segment",
            )
        self.path = path
        self.settings = settings or PathFollowerSettings()
        self.start = path.start
        self.progress = np.full(int(n_robots), path.total_length)
        self.stopped = np.zeros(int(n_robots), dtype=bool)

    def command(self, poses_xytheta: ArrayLike) -> ReturnCommand:
        """Commands for robots at (estimated) poses ``(N, 3)`` (x, y metres, theta radians)."""
        P = np.asarray(poses_xytheta, dtype=np.float64).reshape(-1, 3)
        if len(P) != len(self.progress):
            raise InputError(
                f"{len(P)} poses for {len(self.progress)} robots",
                field="poses_xytheta",
                expected=f"({len(self.progress)}, 3)",
            )
        st = self.settings
        xy = P[:, :2]
        # 2.1 nearest path point, searched around the previous progress
        s_n, lateral = self.path.nearest(
            xy, s_min=self.progress - st.window_back, s_max=self.progress + st.window_ahead
        )
        self.progress = s_n
        # 2.2 the point delta closer to the start along the arc length
        s_t = np.maximum(s_n - st.delta, 0.0)
        target = self.path.position(s_t)
        d_start = np.hypot(*(xy - self.start).T)
        # 2.4 stop inside the radius (latched: a stopped robot stays stopped)
        self.stopped |= d_start <= st.stop_radius
        # 2.3 heading error to the target, speeds
        to_t = target - xy
        psi = np.angle(np.exp(1j * (np.arctan2(to_t[:, 1], to_t[:, 0]) - P[:, 2])))
        omega = np.clip(st.k_omega * psi, -st.omega_max, st.omega_max)
        approach = np.clip(d_start / st.approach_radius, st.min_speed_fraction, 1.0)
        v = st.v_max * np.maximum(np.cos(psi), 0.0) * approach
        v = np.where(self.stopped, 0.0, v)
        omega = np.where(self.stopped, 0.0, omega)
        return ReturnCommand(
            v=v,
            omega=omega,
            s_nearest=s_n,
            s_target=s_t,
            lateral=lateral,
            heading_error=psi,
            done=self.stopped.copy(),
        )
