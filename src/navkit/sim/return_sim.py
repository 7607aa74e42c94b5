"""Closed-loop simulation of paper 4's return to the operator (owned by the path area).

A simulated unicycle (:func:`navkit.sim.unicycle.unicycle_step`) is steered by
:class:`navkit.path.control.ReturnController`, which sees only the robot's *visual-odometry estimate* of
its pose; the VO error model of :class:`navkit.sensors.VisualOdometryNoise` corrupts every step's
body-frame increment (distance scaled by ``1 + scale_bias + N(0, scale_sigma)``, heading change
plus ``heading_bias_per_m * distance + N(0, heading_sigma)``), as in ``corrupt`` but online, so
the estimate is integrated while the robot moves. All runs go in lock-step (vectorised over
runs). The final position error is measured on the *true* robot against the path's start.

This module lives in ``navkit.sim`` because the path capability may not import the simulator.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import ConfigError
from navkit.path.control import PathFollowerSettings, ReturnController
from navkit.path.spline import PathSpline
from navkit.sensors import VisualOdometryNoise
from navkit.sim.unicycle import simulate_unicycle, unicycle_step

#: Bound on runs x time steps of one simulated batch of returns (memory of the histories and
#: run time stay bounded whatever the VO rate).
_MAX_ROBOT_STEPS = 20_000_000

__all__ = ["ReturnSimResult", "corrupt_step", "leg_drive", "simulate_returns"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ReturnSimResult:
    """The outcome of ``runs`` simulated returns.

    Attributes
    ----------
    path_length : float
        Length of the stored path, metres.
    start : (2,) array
        The path's start (the operator).
    final_true : (R, 2) array
        True final positions.
    final_error : (R,) array
        ``|final_true - start|``, metres.
    lateral_mean, lateral_max : (R,) arrays
        True distance of the robot from the path along the way (mean, max), metres.
    duration : (R,) array
        Time to stop, seconds (NaN if the run timed out).
    stopped : (R,) bool array
        The controller stopped before the time limit.
    true_xy : (K, R, 2) array
        True positions at every control cycle.
    est_xy : (K, R, 2) array
        VO-estimated positions.
    """

    path_length: float
    start: NDArray[np.float64]
    final_true: NDArray[np.float64]
    final_error: NDArray[np.float64]
    lateral_mean: NDArray[np.float64]
    lateral_max: NDArray[np.float64]
    duration: NDArray[np.float64]
    stopped: NDArray[np.bool_]
    true_xy: NDArray[np.float64] = field(repr=False)
    est_xy: NDArray[np.float64] = field(repr=False)

    @property
    def final_error_pct(self) -> NDArray[np.float64]:
        """Final error as % of the path length."""
        return 100.0 * self.final_error / self.path_length

    def summary(self) -> dict[str, Any]:
        """Key figures (the CLI's ``summary.json`` / ``returns.json``)."""
        e, pct = self.final_error, self.final_error_pct
        return {
            "runs": len(e),
            "path_length_m": self.path_length,
            "stopped": int(self.stopped.sum()),
            "final_error_mean_m": float(e.mean()),
            "final_error_p95_m": float(np.percentile(e, 95)),
            "final_error_max_m": float(e.max()),
            "final_error_mean_pct": float(pct.mean()),
            "final_error_p95_pct": float(np.percentile(pct, 95)),
            "lateral_error_mean_m": float(self.lateral_mean.mean()),
            "lateral_error_max_m": float(self.lateral_max.max()),
            "duration_mean_s": float(np.nanmean(self.duration)) if self.stopped.any() else None,
        }


def corrupt_step(
    est: NDArray[np.float64],
    true_before: NDArray[np.float64],
    true_after: NDArray[np.float64],
    vo: VisualOdometryNoise,
    rng: np.random.Generator | None = None,
    *,
    noise: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
) -> NDArray[np.float64]:
    """Advance VO estimates ``(R, 3)`` by the true steps ``before -> after``, corrupted by ``vo``.

    The two standard normals per run (scale, heading) come from ``noise`` when given, else from
    ``rng`` (``R`` scale draws, then ``R`` heading draws).
    """
    c, s = np.cos(true_before[:, 2]), np.sin(true_before[:, 2])
    d = true_after[:, :2] - true_before[:, :2]
    bx, by = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]  # body-frame increment
    dth = true_after[:, 2] - true_before[:, 2]
    dist = np.hypot(bx, by)
    n = len(est)
    if noise is None:
        if rng is None:
            raise ValueError("corrupt_step needs rng or noise")
        noise = (rng.standard_normal(n), rng.standard_normal(n))
    scale = 1.0 + vo.scale_bias + vo.scale_sigma * noise[0]
    moving = (dist > 0) | (dth != 0)
    dth_n = dth + np.where(moving, vo.heading_bias_per_m * dist + vo.heading_sigma * noise[1], 0.0)
    ce, se = np.cos(est[:, 2]), np.sin(est[:, 2])
    out = est.copy()
    out[:, 0] += scale * (ce * bx - se * by)
    out[:, 1] += scale * (se * bx + ce * by)
    out[:, 2] += dth_n
    return out


_NOISE_BLOCK = 256
"""Control cycles of noise drawn at a time from each run's own stream."""


def _step_noise(
    rng: np.random.Generator | Sequence[np.random.Generator], runs: int
) -> Iterator[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """The (scale, heading) standard normals of every run, one control cycle at a time.

    One shared generator: ``runs`` scale draws, then ``runs`` heading draws per cycle. One
    generator per run: run ``i`` draws (scale, heading) per cycle from ``rng[i]`` alone, in blocks
    of :data:`_NOISE_BLOCK` cycles (the same numbers as one cycle at a time), so a run's noise
    does not depend on which other runs share its lock-step batch.
    """
    if isinstance(rng, np.random.Generator):
        while True:
            yield rng.standard_normal(runs), rng.standard_normal(runs)
    gens = list(rng)
    while True:
        block = np.stack([g.standard_normal((_NOISE_BLOCK, 2)) for g in gens], axis=1)
        for k in range(_NOISE_BLOCK):
            yield block[k, :, 0], block[k, :, 1]


def simulate_returns(
    path: PathSpline,
    *,
    runs: int = 40,
    settings: PathFollowerSettings | None = None,
    vo: VisualOdometryNoise | None = None,
    rng: np.random.Generator | Sequence[np.random.Generator] | int | None = None,
    initial_true: ArrayLike | None = None,
    initial_estimate: ArrayLike | None = None,
    max_time: float | None = None,
) -> ReturnSimResult:
    """Drive ``runs`` simulated robots from the end of ``path`` back to its start.

    Parameters
    ----------
    path : PathSpline
        The stored path.
    runs : int
        Number of independent runs (paper: 40).
    settings : PathFollowerSettings, optional
        Controller settings.
    vo : VisualOdometryNoise, optional
        VO error model; its ``rate_hz`` is the control rate.
    rng : Generator, seed, or a sequence of ``runs`` Generators, optional
        One stream for all runs, or one stream per run (run ``i``'s noise then depends on
        ``rng[i]`` only, so the runs may be split into batches or across processes freely).
    initial_true : (3,) or (R, 3) array, optional
        True start poses; default: the path's end, facing along the path (the robot must turn).
    initial_estimate : (3,) or (R, 3) array, optional
        The VO estimate at the start of the return; default: equal to ``initial_true``.
    max_time : float, optional
        Time limit, seconds (default: ``3 L / v_max + 60``).
    """
    if runs < 1:
        raise ConfigError(f"is {runs}", field="runs", expected="at least 1")
    settings = settings or PathFollowerSettings()
    vo = vo or VisualOdometryNoise()
    if isinstance(rng, Sequence):
        if len(rng) != runs or not all(isinstance(g, np.random.Generator) for g in rng):
            raise ConfigError(
                f"has {len(rng)} entries", field="rng", expected=f"{runs} numpy Generators"
            )
        noise = _step_noise(rng, runs)
    else:
        noise = _step_noise(
            rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng), runs
        )
    L = path.total_length
    dt = 1.0 / vo.rate_hz
    if initial_true is None:
        end = path.position(L)
        initial_true = np.array([end[0], end[1], float(path.heading(L))])
    true = np.broadcast_to(np.asarray(initial_true, dtype=np.float64), (runs, 3)).copy()
    est = (
        true.copy()
        if initial_estimate is None
        else np.broadcast_to(np.asarray(initial_estimate, dtype=np.float64), (runs, 3)).copy()
    )
    max_time = 3.0 * L / settings.v_max + 60.0 if max_time is None else float(max_time)
    ctrl = ReturnController(path, settings, n_robots=runs)
    start = path.start
    true_hist, est_hist = [true[:, :2].copy()], [est[:, :2].copy()]
    lat_sum = np.zeros(runs)
    lat_max = np.zeros(runs)
    lat_n = np.zeros(runs)
    duration = np.full(runs, np.nan)
    if not (np.isfinite(max_time) and max_time > 0):
        raise ConfigError(f"is {max_time}", field="max_time", expected="seconds > 0")
    if max_time / dt * runs > _MAX_ROBOT_STEPS:
        raise ConfigError(
            f"{max_time:.3g} s at {vo.rate_hz:g} Hz for {runs} runs is "
            f"{max_time / dt * runs:.3g} robot steps",
            field="rate_hz / runs",
            expected=f"at most {_MAX_ROBOT_STEPS:.0e} (a lower VO rate or fewer runs)",
        )
    n_steps = int(np.ceil(max_time / dt))
    for k in range(n_steps):  # time steps (not points): each step is vectorised over the runs
        cmd = ctrl.command(est)
        newly = cmd.done & np.isnan(duration)
        duration[newly] = k * dt
        if cmd.done.all():
            break
        moving = ~cmd.done
        # true lateral error of the moving robots, near their progress along the path
        _, lat = path.nearest(
            true[:, :2],
            s_min=ctrl.progress - settings.window_back,
            s_max=ctrl.progress + settings.window_ahead,
        )
        lat_sum += np.where(moving, lat, 0.0)
        lat_n += moving
        lat_max = np.maximum(lat_max, np.where(moving, lat, 0.0))
        new_true = unicycle_step(true, cmd.v, cmd.omega, dt)
        est = corrupt_step(est, true, new_true, vo, noise=next(noise))
        true = new_true
        true_hist.append(true[:, :2].copy())
        est_hist.append(est[:, :2].copy())
    stopped = ~np.isnan(duration)
    if not stopped.all():
        log.warning(
            "%d of %d return runs did not reach the stop radius within %.0f s",
            int((~stopped).sum()),
            runs,
            max_time,
        )
    final = true[:, :2]
    return ReturnSimResult(
        path_length=L,
        start=start,
        final_true=final.copy(),
        final_error=np.hypot(*(final - start).T),
        lateral_mean=lat_sum / np.maximum(lat_n, 1),
        lateral_max=lat_max,
        duration=duration,
        stopped=stopped,
        true_xy=np.stack(true_hist),
        est_xy=np.stack(est_hist),
    )


def leg_drive(
    n_legs: int,
    leg_length: float = 0.5,
    turn_deg: float = 90.0,
    speed: float = 0.2,
    turn_rate: float = 0.5,
    rate_hz: float = 10.0,
    rng: np.random.Generator | None = None,
    random_turns: bool = False,
) -> NDArray[np.float64]:
    """True poses ``(N, 3)`` at ``rate_hz`` of a robot driving straight legs joined by turns in place.

    The paper's experiment: legs of 0.5 m and 90 deg turns. The turns alternate left and right (a
    staircase that gets away from the start); with ``random_turns`` each has a random sign (a
    random rectilinear walk, which may close loops).
    """
    dt = 1.0 / rate_hz
    v: list[NDArray[np.float64]] = []
    w: list[NDArray[np.float64]] = []
    n_leg = max(1, round(leg_length / (speed * dt)))
    n_turn = max(1, round(np.radians(turn_deg) / (turn_rate * dt)))
    for i in range(n_legs):
        v.append(np.full(n_leg, leg_length / (n_leg * dt)))
        w.append(np.zeros(n_leg))
        if i < n_legs - 1:
            if random_turns:
                sign = float((rng or np.random.default_rng()).choice([-1.0, 1.0]))
            else:
                sign = 1.0 if i % 2 == 0 else -1.0
            v.append(np.zeros(n_turn))
            w.append(np.full(n_turn, sign * np.radians(turn_deg) / (n_turn * dt)))
    return simulate_unicycle(np.concatenate(v), np.concatenate(w), dt)
