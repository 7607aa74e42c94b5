"""Mode 1 of paper 4: the online spline memory of the odometry trajectory.

Points arrive one at a time (step 1.2). The current segment is a parametric cubic fitted by
least squares over the polyline length ``t`` (1.3, :mod:`navkit.path.fitting`); when the largest
deviation exceeds ``eps`` (1.4-1.5) the segment is frozen on all points but the last, refitted
over arc length (1.6, section 4), searched for loops that are then cut out (1.7, section 3,
:mod:`navkit.path.loops`), and a new segment starts where it ended.

Guarantee: every accepted point ``P_i`` satisfies ``|P_i - C(s_i)| <= eps`` for the stored
(arc-length) segment that covers it, hence lies within ``eps`` of the stored spline. The
deviation is measured at the point's own parameter - an upper bound of the point-to-curve
distance, so the guarantee is conservative. It is checked on the *stored* curve (distance by
Newton projection): if the refit of step 1.6 would push a point beyond ``eps``, the fit over t
(which passed the test) is stored with its parameter scaled to arc length instead.

Cost per point: the normal equations come from running power sums (O(1) per point); the cheap
test ``SSR <= eps^2`` (which bounds every residual) accepts most points of smooth data without
touching them; otherwise the residuals of the segment's points are computed in one vectorised
pass. Freezing costs O(points in the segment) once.

Decisions where the paper is silent: the tangent variants use the plain start / endpoints fit for
the first segment (there is no previous tangent); points within ``min_step`` of the previous
accepted point (repeats) and non-finite points are skipped and counted, with one warning.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.domains import NON_NEGATIVE, POSITIVE, Domain, domain_field
from navkit.errors import InputError
from navkit.geometry._validate import MAX_COORDINATE_M, check_coordinates, check_settings
from navkit.jit import kernels_enabled
from navkit.path.fitting import (
    CubicFit,
    check_variant,
    fit_from_sums,
    fit_points,
    needs_tangent,
    project,
    residuals,
)
from navkit.path.loops import LoopCut, LoopFreeChain, kept_intervals
from navkit.path.spline import _GL_W, _GL_X, PathSpline, gauss_legendre_length
from navkit.results import Failure, Result, deprecated_alias

__all__ = [
    "ApproximationResult",
    "ApproximatorSettings",
    "OnlineApproximator",
    "PathUpdate",
    "Skipped",
    "approximate",
]

log = logging.getLogger(__name__)

_KERNELS: Any = None

# The loop search resolves the stored path down to these fractions of the tolerance (or the
# settings' absolute values, whichever is finer): a loop longer than eps / 100 is cut, so the
# path sampled every eps / 100 is simple; the boxes are refined ten times finer than that, the
# paper's ratio of 0.1 mm precision to 1 mm shortest loop.
MIN_LOOP_PER_EPS = 1e-2
LOOP_PRECISION_PER_EPS = 1e-3


def _kernels() -> Any:
    """:mod:`navkit.path._kernels`, imported on first use (it loads Numba)."""
    global _KERNELS
    if _KERNELS is None:
        from navkit.path import _kernels as kernels

        _KERNELS = kernels
    return _KERNELS


@dataclass(frozen=True)
class ApproximatorSettings:
    """Settings of the online approximator.

    Attributes
    ----------
    tolerance : float
        ``eps``: largest allowed distance of an input point from the stored spline, metres.
    variant : str
        Constraints of each segment (paper fig. 1): ``"start"``, ``"start_tangent"``,
        ``"endpoints"`` (the paper's recommendation for low-noise data, the default) or
        ``"endpoints_tangent"``.
    remove_loops : bool
        Cut loops out as segments are frozen (step 1.7).
    loop_precision : float
        Box size the crossing search refines to, metres (paper: 0.1 mm); the search uses
        ``min(loop_precision, tolerance / 1000)``.
    min_loop_length : float
        Crossings closer than this along the path are not loops, metres; the search uses
        ``min(min_loop_length, tolerance / 100)``, so the stored path is simple down to that
        scale (a loop any shorter is within ``tolerance / 200`` of its crossing).
    min_step : float
        A point closer than this to the previous accepted point is a repeat and is skipped, metres.
    geometric_test : bool
        When a point's residual at its own parameter exceeds the limit, measure its distance to
        the curve (Newton projection) before freezing: segments get longer, the guarantee is the
        same (it is on the distance). False: the paper's residual test only.
    max_segment_points : int
        A segment is frozen when it holds this many points even if it still fits: bounds the
        per-point cost on dense, slow data (e.g. 100 Hz wheel odometry of a robot standing still
        half the time).
    fit_margin : float
        The running fit over the polyline length must stay within ``fit_margin * tolerance``, so
        the arc-length refit of step 1.6 (which moves the curve slightly) rarely breaks
        ``tolerance``; when it does, the segment is frozen earlier. In ``(0, 1]``.
    """

    tolerance: float = domain_field(0.05, POSITIVE)
    variant: str = "endpoints"
    remove_loops: bool = True
    loop_precision: float = domain_field(1e-4, POSITIVE)
    min_loop_length: float = domain_field(1e-3, NON_NEGATIVE)
    min_step: float = domain_field(1e-9, NON_NEGATIVE)
    fit_margin: float = domain_field(0.9, Domain(lo=0.0, hi=1.0, lo_open=True, note="a fraction"))
    geometric_test: bool = True
    max_segment_points: int = domain_field(
        2000, Domain(integer=True, lo=3, note="a cubic segment's fit needs 3")
    )

    def __post_init__(self) -> None:
        check_settings(self)
        check_variant(self.variant)


@dataclass(frozen=True)
class ApproximationResult:
    """What the recorder produced.

    Attributes
    ----------
    spline : PathSpline
        The stored path (loop-free unless ``remove_loops`` was off).
    raw_spline : PathSpline
        All frozen segments before loop removal (the one the eps guarantee is stated on).
    loops : tuple of LoopCut
        The loops cut out (arc lengths refer to the path as it was at the cut).
    points : (N, 2) array
        The accepted input points.
    point_s : (N,) array
        Arc length of each accepted point's parameter on ``raw_spline``.
    deviation : (N,) array
        ``|P_i - C(s_i)|`` on ``raw_spline``, metres (all ``<= tolerance``).
    n_input, n_repeated, n_nonfinite : int
        Points offered, skipped as repeats, skipped as NaN / inf.
    n_cheap : int
        Points accepted by the O(1) test without computing residuals.
    n_refit_fallbacks : int
        Segments stored as the fit over t scaled to arc length, because the refit over arc
        length would have broken eps.
    seconds_per_point : (n_input,) array
        Wall time of each ``add`` call (including freezing and loop search), seconds.
    cpu_seconds_per_point : (n_input,) array
        The same as thread CPU time (immune to other processes taking the CPU), seconds.
    """

    spline: PathSpline
    raw_spline: PathSpline
    loops: tuple[LoopCut, ...]
    points: NDArray[np.float64]
    point_s: NDArray[np.float64]
    deviation: NDArray[np.float64]
    n_input: int
    n_repeated: int
    n_nonfinite: int
    n_cheap: int
    n_refit_fallbacks: int = 0
    seconds_per_point: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    cpu_seconds_per_point: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))

    def stored_arclength(self, raw_s: ArrayLike) -> NDArray[np.float64]:
        """Arc length on ``spline`` of arc lengths ``raw_s`` on ``raw_spline`` (e.g.
        ``point_s``); NaN where that part of the path was cut out with a loop. Where it is
        finite, ``spline.position(result) == raw_spline.position(raw_s)``: an input point kept
        this way is within ``tolerance`` of the stored path."""
        s = np.asarray(raw_s, dtype=np.float64)
        kept = kept_intervals(self.loops, self.raw_spline.total_length)
        if len(kept) == 0:
            return np.full(s.shape, np.nan)
        before = np.concatenate([[0.0], np.cumsum(kept[:, 1] - kept[:, 0])[:-1]])
        k = np.clip(np.searchsorted(kept[:, 0], s, side="right") - 1, 0, len(kept) - 1)
        inside = (s >= kept[k, 0]) & (s <= kept[k, 1])
        return np.where(inside, before[k] + (s - kept[k, 0]), np.nan)

    @property
    def max_deviation(self) -> float:
        """Largest deviation of an accepted point, metres (NaN without points)."""
        return float(self.deviation.max()) if len(self.deviation) else float("nan")

    def summary(self) -> dict[str, Any]:
        """Key figures (the CLI's ``summary.json``)."""
        us = self.seconds_per_point * 1e6
        cpu = self.cpu_seconds_per_point * 1e6
        return {
            "points": self.n_input,
            "points_used": len(self.points),
            "points_repeated": self.n_repeated,
            "points_nonfinite": self.n_nonfinite,
            "segments": self.spline.n_segments,
            "segments_before_loop_removal": self.raw_spline.n_segments,
            "loops_removed": len(self.loops),
            "loop_length_removed_m": float(sum(c.length for c in self.loops)),
            "length_m": self.spline.total_length,
            "raw_length_m": self.raw_spline.total_length,
            "tolerance_m": self.raw_spline.tolerance,
            "max_deviation_m": self.max_deviation,
            "stored_numbers": self.spline.n_numbers,
            "cheap_test_fraction": self.n_cheap / max(len(self.points), 1),
            "refit_fallbacks": self.n_refit_fallbacks,
            "mean_us_per_point": float(us.mean()) if len(us) else None,
            "p99_us_per_point": float(np.percentile(us, 99)) if len(us) else None,
            "max_us_per_point": float(us.max()) if len(us) else None,
            "mean_cpu_us_per_point": float(cpu.mean()) if len(cpu) else None,
            "max_cpu_us_per_point": float(cpu.max()) if len(cpu) else None,
        }


@dataclass(frozen=True, slots=True)
class PathUpdate(Result):
    """A point :meth:`OnlineApproximator.update` took into the path.

    Attributes
    ----------
    index : int
        The point's number among all points offered (0-based, skipped ones counted).
    frozen : int
        Segments this point froze (0: it extends the current segment; 1: the segment before it
        was frozen and the next one starts).
    segments : int
        Segments frozen so far (:attr:`OnlineApproximator.spline`).
    """

    index: int
    frozen: int
    segments: int


@dataclass(frozen=True, slots=True)
class Skipped(Failure):
    """A point :meth:`OnlineApproximator.update` did not take (normal for sensor data).

    Attributes
    ----------
    index : int
        The point's number among all points offered (0-based).
    reason : str
        ``"not finite"`` (a NaN or infinite coordinate) or ``"repeat"`` (within
        ``ApproximatorSettings.min_step`` of the last point taken).
    free_dof : tuple of str
        Empty: a skipped point is not about a pose.
    """

    index: int
    reason: str
    free_dof: tuple[str, ...] = ()


class OnlineApproximator:
    """The path recorder: feed points with :meth:`update`, get the path with :meth:`finish`.

    Examples
    --------
    >>> rec = OnlineApproximator(ApproximatorSettings(tolerance=0.05))
    >>> for p in np.c_[np.linspace(0, 3, 31), np.zeros(31)]:
    ...     _ = rec.update(p)
    >>> result = rec.finish()
    >>> result.spline.n_segments, round(result.spline.total_length, 6)
    (1, 3.0)
    """

    def __init__(
        self, settings: ApproximatorSettings | None = None, frame: dict[str, Any] | None = None
    ) -> None:
        self.settings = settings or ApproximatorSettings()
        self.frame = dict(frame or {})
        s = self.settings
        self._eps = float(s.tolerance)
        self._eps_fit = self._eps * float(s.fit_margin)
        self._max_points = int(s.max_segment_points)
        self._min_step = float(s.min_step)
        self._eps2 = self._eps_fit**2
        self._geometric = bool(s.geometric_test)
        self._chain = LoopFreeChain(
            precision=min(s.loop_precision, self._eps * LOOP_PRECISION_PER_EPS),
            min_loop_length=min(s.min_loop_length, self._eps * MIN_LOOP_PER_EPS),
        )
        # the freeze's O(n) passes and the loop search as compiled loops (navkit.path._kernels)
        # when the process runs the kernels (navkit.jit); False: the NumPy versions (the oracle
        # the tests compare with)
        self.compiled = kernels_enabled()
        self._raw: list[tuple[NDArray[np.float64], NDArray[np.float64], float]] = []
        self._raw_length = 0.0
        self._loops: list[LoopCut] = []
        # accepted points and their bookkeeping
        self._pts: list[NDArray[np.float64]] = []
        self._pt_s: list[NDArray[np.float64]] = []
        self._pt_dev: list[NDArray[np.float64]] = []
        self.n_input = self.n_repeated = self.n_nonfinite = self.n_cheap = 0
        self.n_refit_fallbacks = 0
        # current segment: buffer row 0 is the anchor
        self._buf = np.zeros((64, 2))
        self._tau = np.zeros(64)
        self._n = 0
        self._anchor_is_point = True  # the very first anchor is a data point
        self._tangent: NDArray[np.float64] | None = None
        self._last: NDArray[np.float64] | None = None
        self._fit_t: tuple[Any, ...] | None = None  # the last freeze's fit over t (compiled)
        self._work: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None

    # ------------------------------------------------------------------ state
    @property
    def spline(self) -> PathSpline:
        """The frozen (and loop-free) part of the path recorded so far."""
        return self._chain.spline(tolerance=self._eps, frame=self.frame)

    @property
    def _variant(self) -> str:
        v = self.settings.variant
        if needs_tangent(v) and self._tangent is None:
            return "start" if v == "start_tangent" else "endpoints"
        return v

    def _start_segment(self, anchor: NDArray[np.float64]) -> None:
        self._buf[0] = anchor
        self._tau[0] = 0.0
        self._n = 1
        self._S = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]  # the anchor: u = 0 adds only to S_0
        self._D = ([0.0] * 4, [0.0] * 4)
        self._Q = 0.0
        self._anchor = (float(anchor[0]), float(anchor[1]))
        self._lastxy = self._anchor
        self._tangent_t = (
            None if self._tangent is None else (float(self._tangent[0]), float(self._tangent[1]))
        )
        self._fit: CubicFit | None = None

    # ------------------------------------------------------------------ adding points (steps 1.2 - 1.5)
    def update(self, point: ArrayLike) -> PathUpdate | Skipped:
        """Offer the next point ``(2,)`` (x, y metres): a :class:`PathUpdate` when it was taken,
        a :class:`Skipped` naming why when not (not finite, or a repeat).

        Raises
        ------
        InputError
            For a finite coordinate beyond ``MAX_COORDINATE_M`` (1e9 m): the loop search's
            ``loop_precision`` (1e-4 m) is below float64's spacing there, and its box tree
            would not end. Nothing is recorded for such a point.
        """
        p = np.asarray(point, dtype=np.float64).reshape(-1)
        if p.shape != (2,):
            raise InputError(
                f"has shape {np.shape(point)}", field="point", expected="(2,) x, y in metres"
            )
        x, y = float(p[0]), float(p[1])
        if abs(x) > MAX_COORDINATE_M or abs(y) > MAX_COORDINATE_M:  # NaN compares False
            check_coordinates(p, field="point")  # refuses a finite one; inf is a no-return
        index = self.n_input
        self.n_input += 1
        if not (math.isfinite(x) and math.isfinite(y)):
            self.n_nonfinite += 1
            return Skipped(index, "not finite")
        last = self._last
        if last is not None and math.hypot(x - last[0], y - last[1]) <= self._min_step:
            self.n_repeated += 1
            return Skipped(index, "repeat")
        self._last = p
        before = len(self._raw)
        if self._n == 0:
            self._start_segment(p)
        else:
            self._push(p)
        return PathUpdate(index, len(self._raw) - before, len(self._raw))

    def add(self, point: ArrayLike) -> bool:
        """Deprecated alias of :meth:`update` (removed in the next release): True when the
        point was taken."""
        deprecated_alias("OnlineApproximator.add", "OnlineApproximator.update")
        return isinstance(self.update(point), PathUpdate)

    def _grow(self) -> None:
        if self._n + 1 >= len(self._tau):
            self._buf = np.resize(self._buf, (2 * len(self._tau), 2))
            self._tau = np.resize(self._tau, 2 * len(self._tau))

    def _push(self, p: NDArray[np.float64]) -> None:
        n = self._n
        px, py = float(p[0]), float(p[1])
        ax_, ay_ = self._anchor
        lx, ly = self._lastxy
        dx, dy = px - ax_, py - ay_
        step = math.hypot(px - lx, py - ly)
        if step <= 0.0:  # coincides with the anchor of a fresh segment: it is on the spline
            self._record(p[None, :], np.array([self._raw_length]), np.zeros(1))
            return
        tau = self._tau[n - 1] + step
        # running power sums (plain floats: 7 + 8 multiply-adds per point)
        t2 = tau * tau
        t3 = t2 * tau
        tp = (1.0, tau, t2, t3, t2 * t2, t3 * t2, t3 * t3)
        S = [a + b for a, b in zip(self._S, tp, strict=True)]
        Dx = [a + dx * b for a, b in zip(self._D[0], tp[:4], strict=True)]
        Dy = [a + dy * b for a, b in zip(self._D[1], tp[:4], strict=True)]
        Q = self._Q + dx * dx + dy * dy
        inv = 1.0 / tau
        sc = [1.0, inv]
        for _ in range(5):
            sc.append(sc[-1] * inv)
        Su = [a * b for a, b in zip(S, sc, strict=True)]
        D = (
            [a * b for a, b in zip(Dx, sc[:4], strict=True)],
            [a * b for a, b in zip(Dy, sc[:4], strict=True)],
        )
        fit = fit_from_sums(self._variant, Su, D, Q, n, tau, end=(dx, dy), tangent=self._tangent_t)
        ok = fit.ssr <= self._eps2 * (1.0 - 1e-9) - 1e-15 * Q  # rounding margin of the sums
        if n >= self._max_points:
            ok = False  # bound the O(n) work of the exact test and of freezing
        if ok:
            self.n_cheap += 1
        elif n < self._max_points:
            self._grow()
            self._buf[n] = p
            self._tau[n] = tau
            if self.compiled:  # the same test in one compiled pass, stopping at the first miss
                ok = _kernels().within(
                    fit.coef, self._tau, self._buf, n + 1, self._eps_fit, self._geometric
                )
            else:
                ok = self._within(fit, n, tau)
        if ok:
            self._grow()
            self._buf[n], self._tau[n] = p, tau
            self._n, self._S, self._D, self._Q, self._fit = n + 1, S, (Dx, Dy), Q, fit
            self._lastxy = (px, py)
            return
        # step 1.5: freeze on all points but the last, start the next segment where it ends
        self._freeze(self._n)
        self._push(p)

    def _within(self, fit: CubicFit, n: int, tau: float) -> bool:
        """The exact deviation test on buffer rows ``[0, n]`` (NumPy; the compiled twin is
        ``_kernels.within``)."""
        u = self._tau[: n + 1] / tau
        d = self._buf[: n + 1] - self._buf[0]
        r = residuals(fit, u, d)
        inside = r <= self._eps_fit
        ok = bool(inside.all())
        if not ok and self.settings.geometric_test and not np.isnan(r).any():
            # the residual at a point's own parameter includes along-track misfit; the
            # distance to the curve (Newton projection) is what the guarantee is about
            far = ~inside
            _, dist = project(fit, u[far], d[far])
            ok = bool((dist <= self._eps_fit).all())
        return ok

    # ------------------------------------------------------------------ freezing (steps 1.5 - 1.7)
    def _freeze(self, n_use: int) -> None:
        """Freeze the segment on buffer rows ``[0, n_use)`` (steps 1.5 - 1.7)."""
        variant = self._variant
        anchor = self._buf[0].copy()
        fit_s, s, dev = self._natural_fit(variant, anchor, n_use)
        if dev.max() > self._eps:
            # The refit over arc length moved a point beyond eps (it can, on long wiggly
            # segments). Store the fit over t instead - its shape passed the test - with the
            # parameter scaled so it runs over the curve's arc length [0, S]: the same curve, the
            # total length exact, the speed |C'| = S'(t) T / S only approximately 1.
            self.n_refit_fallbacks += 1
            fit_s, s, dev = self._scaled_t_fit(variant, anchor, n_use)
            if dev.max() > self._eps * (1.0 + 1e-9):
                log.warning(
                    "segment %d: a point is %.6g m from the curve (eps %.6g m)",
                    len(self._raw),
                    dev.max(),
                    self._eps,
                )
        self._fit_t = None
        pts = self._buf[:n_use]
        ax, ay = fit_s.metric_coefficients(anchor)
        length = float(fit_s.T)
        first = 0 if self._anchor_is_point else 1
        self._record(pts[first:], self._raw_length + s[first:], dev[first:])
        self._raw.append((ax, ay, length))
        self._raw_length += length
        self._loops.extend(
            self._chain.append(ax, ay, length, remove_loops=self.settings.remove_loops)
        )
        # the next segment starts where this one ends, with its tangent (cubic_eval's formulas
        # on plain floats: the same numbers without ~10 NumPy scalar calls)
        x0, x1, x2, x3 = ax.tolist()
        y0, y1, y2, y3 = ay.tolist()
        u = length
        end = np.array([x0 + u * (x1 + u * (x2 + u * x3)), y0 + u * (y1 + u * (y2 + u * y3))])
        tan = np.array([x1 + u * (2.0 * x2 + 3.0 * x3 * u), y1 + u * (2.0 * y2 + 3.0 * y3 * u)])
        norm = float(np.hypot(tan[0], tan[1]))
        self._tangent = tan / norm if norm > 0 else None
        self._anchor_is_point = False
        self._start_segment(end)

    def _natural_fit(
        self, variant: str, anchor: NDArray[np.float64], n_use: int
    ) -> tuple[CubicFit, NDArray[np.float64], NDArray[np.float64]]:
        """Section 4's three steps on buffer rows ``[0, n_use)``: (fit, arc lengths, deviations).

        With ``compiled`` (the default) the O(n) passes - power sums, Gauss-Legendre arc
        lengths, Newton projection - run as compiled loops (:mod:`navkit.path._kernels`; the
        same operations in the same order: the NumPy passes' bits)."""
        if self.compiled and variant == "endpoints" and n_use >= 4:
            # the whole step in one call (a degenerate grid takes the route below)
            K = _kernels()
            W, speed = self._workspace(n_use)
            ok, far, T_t, ssr_t, c_t, T_s, ssr_s, c_s = K.natural_fit_endpoints(
                self._buf, self._tau, n_use, _GL_X, _GL_W, self._eps, W, speed
            )
            if ok:
                fit_t = CubicFit(coef=c_t, T=T_t, ssr=ssr_t)
                # for the fallback (_scaled_t_fit), with its projection when it will be needed;
                # rows of the workspace, valid until the next freeze
                n = n_use
                far_uv = (W[K.W_UP2, :n], W[K.W_DIST2, :n]) if far else None
                self._fit_t = (n, fit_t, W[K.W_U, :n], W[K.W_S, :n], None, far_uv)
                s = np.multiply(W[K.W_UP, :n], T_s, out=W[K.W_OUT, :n])
                return CubicFit(coef=c_s, T=T_s, ssr=ssr_s), s, W[K.W_DIST, :n]
        d = self._buf[:n_use] - anchor
        tau = self._tau[:n_use]
        if not self.compiled:
            # 1) fit over the polyline length t
            fit_t = fit_points(variant, tau, d, tangent=self._tangent)
            # 2) arc length of that curve at each point (Gauss-Legendre)
            s = gauss_legendre_length(fit_t.coef[0], fit_t.coef[1], tau / fit_t.T)
            # 3) refit over (s_i, P_i): the stored curve is x(s), y(s)
            fit_s = fit_points(variant, s, d, tangent=self._tangent)
            # the guarantee is on the distance to the stored curve (its parameter moved)
            u, dist = project(fit_s, s / fit_s.T, d)
            return fit_s, u * fit_s.T, dist
        K = _kernels()
        fit_t = self._fit_compiled(variant, tau, d)
        u_t = tau / fit_t.T
        s = K.gauss_legendre_length(fit_t.coef[0], fit_t.coef[1], u_t, _GL_X, _GL_W)
        # the fallback (_scaled_t_fit) starts from the same fit over t and arc lengths
        self._fit_t = (n_use, fit_t, u_t, s, d, None)
        fit_s = self._fit_compiled(variant, s, d)
        u, dist = K.project(fit_s.coef, s / fit_s.T, d, 3)
        return fit_s, u * fit_s.T, dist

    def _workspace(self, n: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The freeze's scratch arrays (``_kernels.natural_fit_endpoints``), kept between
        freezes: fresh arrays of up to 10,000 numbers per freeze cost page faults on every
        freeze."""
        if self._work is None or self._work[0].shape[1] < n:
            size = max(n, len(self._tau))
            self._work = (np.zeros((_kernels().W_ROWS, size)), np.zeros(5 * size))
        return self._work

    def _fit_compiled(
        self, variant: str, tau: NDArray[np.float64], d: NDArray[np.float64]
    ) -> CubicFit:
        """:func:`navkit.path.fitting.fit_points` with the compiled power sums."""
        T = float(tau[-1])
        u = tau / T if T > 0 else np.zeros_like(tau)
        S, D, Q = _kernels().power_sums(u, d)
        tangent = self._tangent
        return fit_from_sums(
            variant,
            S.tolist(),
            D.tolist(),
            float(Q),
            len(tau) - 1,
            T,
            end=d[-1].tolist(),
            tangent=None if tangent is None else np.asarray(tangent).tolist(),
        )

    def _scaled_t_fit(
        self, variant: str, anchor: NDArray[np.float64], n_use: int
    ) -> tuple[CubicFit, NDArray[np.float64], NDArray[np.float64]]:
        """The fit over t with its parameter rescaled to the arc length (fallback of step 1.6)."""
        tau = self._tau[:n_use]
        if self.compiled:
            K = _kernels()
            cached, self._fit_t = self._fit_t, None
            d: NDArray[np.float64] | None
            if cached is not None and cached[0] == n_use:  # _natural_fit's first two steps
                _, fit_t, u, s, d, projected = cached
            else:
                d = self._buf[:n_use] - anchor
                fit_t = self._fit_compiled(variant, tau, d)
                u = tau / fit_t.T
                s = K.gauss_legendre_length(fit_t.coef[0], fit_t.coef[1], u, _GL_X, _GL_W)
                projected = None
            fit = CubicFit(coef=fit_t.coef, T=float(s[-1]), ssr=fit_t.ssr)
            if projected is None:  # (natural_fit_endpoints did it when a point was beyond eps)
                projected = K.project(
                    fit.coef, u, self._buf[:n_use] - anchor if d is None else d, 3
                )
            u2, dist = projected
            return fit, u2 * fit.T, dist
        d = self._buf[:n_use] - anchor
        fit_t = fit_points(variant, tau, d, tangent=self._tangent)
        u = tau / fit_t.T
        s = gauss_legendre_length(fit_t.coef[0], fit_t.coef[1], u)
        fit = CubicFit(coef=fit_t.coef, T=float(s[-1]), ssr=fit_t.ssr)  # same u in [0, 1], T = S
        u2, dist = project(fit, u, d)
        return fit, u2 * fit.T, dist

    def _record(
        self, pts: NDArray[np.float64], s: NDArray[np.float64], dev: NDArray[np.float64]
    ) -> None:
        self._pts.append(np.array(pts, dtype=np.float64).reshape(-1, 2))
        self._pt_s.append(np.asarray(s, dtype=np.float64))
        self._pt_dev.append(np.array(dev, dtype=np.float64))  # (may be a workspace row)

    # ------------------------------------------------------------------ the end
    def finish(self, seconds_per_point: ArrayLike | None = None) -> ApproximationResult:
        """Freeze the open segment and return the result (the recorder can keep going after)."""
        if self._n >= 2:
            self._freeze(self._n)
        elif self._n == 1 and self._anchor_is_point:
            self._record(self._buf[:1], np.zeros(1), np.zeros(1))
            self._n = 0
            self._anchor_is_point = True
        skipped = self.n_repeated + self.n_nonfinite
        if skipped:
            log.warning(
                "skipped %d of %d points (%d repeats, %d NaN/inf)",
                skipped,
                self.n_input,
                self.n_repeated,
                self.n_nonfinite,
            )
        raw = PathSpline.from_segments(
            [r[2] for r in self._raw],
            np.reshape([r[0] for r in self._raw], (-1, 4)),
            np.reshape([r[1] for r in self._raw], (-1, 4)),
            tolerance=self._eps,
            frame=self.frame,
        )

        def cat(xs: list[NDArray[np.float64]], shape: tuple[int, ...]) -> NDArray[np.float64]:
            return np.concatenate(xs) if xs else np.zeros(shape)

        return ApproximationResult(
            spline=self.spline,
            raw_spline=raw,
            loops=tuple(self._loops),
            points=cat(self._pts, (0, 2)),
            point_s=cat(self._pt_s, (0,)),
            deviation=cat(self._pt_dev, (0,)),
            n_input=self.n_input,
            n_repeated=self.n_repeated,
            n_nonfinite=self.n_nonfinite,
            n_cheap=self.n_cheap,
            n_refit_fallbacks=self.n_refit_fallbacks,
            seconds_per_point=np.asarray(
                seconds_per_point if seconds_per_point is not None else np.zeros(0),
                dtype=np.float64,
            ),
        )


def approximate(
    points: ArrayLike,
    settings: ApproximatorSettings | None = None,
    *,
    frame: dict[str, Any] | None = None,
    timed: bool = True,
    iterate: Callable[[Iterable[Any]], Iterable[Any]] | None = None,
) -> ApproximationResult:
    """Record a whole trajectory point by point (mode 1) and return the stored path.

    Parameters
    ----------
    points : (N, 2) array
        Positions in arrival order, metres (NaN rows are skipped).
    settings : ApproximatorSettings, optional
    frame : dict, optional
        Description of the frame (stored in ``path.json``).
    timed : bool
        Measure the wall time of every ``add`` call (``seconds_per_point``).
    iterate : callable, optional
        Wraps the iteration over the points (the CLI passes a progress bar).
    """
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 2:
        raise InputError(f"has shape {P.shape}", field="points", expected="(N, 2) x, y in metres")
    rec = OnlineApproximator(settings, frame=frame)
    times = np.zeros(len(P))
    cpu = np.zeros(len(P))
    clock, cpu_clock = time.perf_counter, time.thread_time
    wrap = iterate or (lambda items: items)
    if timed:
        for i, p in wrap(enumerate(P)):
            t0, c0 = clock(), cpu_clock()
            rec.update(p)
            times[i], cpu[i] = clock() - t0, cpu_clock() - c0
    else:
        for p in wrap(P):
            rec.update(p)
    result = rec.finish(seconds_per_point=times if timed else None)
    return dataclasses.replace(result, cpu_seconds_per_point=cpu) if timed else result
