"""The stored path: a chain of parametric cubics over arc length (paper 4, eq. 1 and section 4).

Each segment ``k`` is ``x(s) = a0 + a1 u + a2 u^2 + a3 u^3``, ``y(s) = b0 + b1 u + b2 u^2 + b3 u^3``
with ``u = s - s0[k]`` in ``[0, length[k]]`` metres, ``s`` the arc length from the path's start
(the natural parameterisation of section 4: the refit makes ``|C'(s)|`` close to 1, see
:func:`natural_refit` in :mod:`navkit.path.fitting`). All evaluation methods take arrays.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import DegenerateGeometryError, FormatError, InputError

__all__ = ["PathSpline", "cubic_eval", "cubic_shift", "gauss_legendre_length"]

log = logging.getLogger(__name__)

# 5-point Gauss-Legendre nodes / weights on [0, 1] (exact for polynomials of degree <= 9).
_GL_X, _GL_W = np.polynomial.legendre.leggauss(5)
_GL_X = 0.5 * (_GL_X + 1.0)
_GL_W = 0.5 * _GL_W


def cubic_eval(
    coef: NDArray[np.float64], u: NDArray[np.float64] | float, der: int = 0
) -> NDArray[np.float64]:
    """Evaluate cubics (or their derivatives) row-wise.

    Parameters
    ----------
    coef : (..., 4) array
        Coefficients ``c0..c3`` of ``c0 + c1 u + c2 u^2 + c3 u^3``, broadcast against ``u``.
    u : (...) array
        Parameter values.
    der : {0, 1, 2}
        Derivative order.
    """
    c0, c1, c2, c3 = coef[..., 0], coef[..., 1], coef[..., 2], coef[..., 3]
    if der == 0:
        return c0 + u * (c1 + u * (c2 + u * c3))
    if der == 1:
        return c1 + u * (2.0 * c2 + 3.0 * c3 * u)
    if der == 2:
        return 2.0 * c2 + 6.0 * c3 * u
    raise ValueError("der must be 0, 1 or 2")


def cubic_shift(coef: NDArray[np.float64], u0: float) -> NDArray[np.float64]:
    """Coefficients of ``w -> p(u0 + w)`` (an exact Taylor shift, used to trim a segment's start)."""
    c0, c1, c2, c3 = coef
    return np.array(
        [
            c0 + u0 * (c1 + u0 * (c2 + u0 * c3)),
            c1 + u0 * (2.0 * c2 + 3.0 * c3 * u0),
            c2 + 3.0 * c3 * u0,
            c3,
        ]
    )


def gauss_legendre_length(
    ax: NDArray[np.float64], ay: NDArray[np.float64], u: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Arc length of one cubic curve from ``u[0]`` to each ``u[i]`` (section 4, step 2).

    The integral of the speed ``sqrt(x'^2 + y'^2)`` has no closed form; each interval
    ``[u[i-1], u[i]]`` is integrated with 5-point Gauss-Legendre, vectorised over the intervals.
    The arithmetic is ``_kernels.gauss_legendre_length``'s, so both give the same bits on every
    CPU: the speed as ``sqrt`` of the sum of squares (not the libm ``hypot``), each interval's
    weighted sum from 0 node by node (not a BLAS product), the running sum in point order.

    Parameters
    ----------
    ax, ay : (4,) arrays
        Cubic coefficients of x and y.
    u : (n,) array, non-decreasing
        Parameter values.

    Returns
    -------
    (n,) array
        Arc length ``s[i]`` (metres), ``s[0] = 0``.
    """
    u = np.asarray(u, dtype=np.float64)
    h = np.diff(u)
    weighted = np.zeros(len(h))
    for g, w in zip(_GL_X.tolist(), _GL_W.tolist(), strict=True):
        t = u[:-1] + h * g
        dx, dy = cubic_eval(ax, t, 1), cubic_eval(ay, t, 1)
        weighted += np.sqrt(dx * dx + dy * dy) * w
    out = np.zeros(len(u))
    out[1:] = np.cumsum(h * weighted)
    return out


@dataclass(frozen=True)
class PathSpline:
    """A planar path stored as cubic segments over arc length.

    Attributes
    ----------
    s0 : (M,) array
        Arc length at the start of each segment, metres (``s0[0] = 0``, cumulative).
    length : (M,) array
        Length of each segment, metres (``u`` runs over ``[0, length]``).
    ax, ay : (M, 4) arrays
        Coefficients of ``x(u)``, ``y(u)``, metres / metre^k.
    tolerance : float
        The approximation tolerance ``eps`` the path was recorded with, metres.
    frame : dict
        The frame the x, y are in (free-form, written to ``path.json``).
    """

    s0: NDArray[np.float64]
    length: NDArray[np.float64]
    ax: NDArray[np.float64]
    ay: NDArray[np.float64]
    tolerance: float = float("nan")
    frame: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        s0 = np.asarray(self.s0, dtype=np.float64).reshape(-1)
        length = np.asarray(self.length, dtype=np.float64).reshape(-1)
        ax = np.asarray(self.ax, dtype=np.float64).reshape(-1, 4)
        ay = np.asarray(self.ay, dtype=np.float64).reshape(-1, 4)
        if not (len(s0) == len(length) == len(ax) == len(ay)):
            raise InputError(
                "segment arrays differ in length",
                field="segments",
                expected="s0, length, ax, ay with one row per segment",
            )
        object.__setattr__(self, "s0", s0)
        object.__setattr__(self, "length", length)
        object.__setattr__(self, "ax", ax)
        object.__setattr__(self, "ay", ay)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_segments(
        cls,
        lengths: ArrayLike,
        ax: ArrayLike,
        ay: ArrayLike,
        *,
        tolerance: float = float("nan"),
        frame: dict[str, Any] | None = None,
    ) -> PathSpline:
        """Build from per-segment lengths and coefficients; ``s0`` is their running sum."""
        length = np.asarray(lengths, dtype=np.float64).reshape(-1)
        s0 = np.concatenate([[0.0], np.cumsum(length)[:-1]]) if len(length) else np.zeros(0)
        return cls(
            s0=s0,
            length=length,
            ax=np.asarray(ax, dtype=np.float64).reshape(-1, 4),
            ay=np.asarray(ay, dtype=np.float64).reshape(-1, 4),
            tolerance=tolerance,
            frame=dict(frame or {}),
        )

    # ------------------------------------------------------------------ basic properties
    @property
    def n_segments(self) -> int:
        """Number of cubic segments."""
        return len(self.length)

    @property
    def total_length(self) -> float:
        """Path length ``L`` (metres)."""
        return float(self.length.sum()) if len(self.length) else 0.0

    @property
    def knots(self) -> NDArray[np.float64]:
        """``(M + 1, 2)`` positions of the segment ends (the spline's knots)."""
        starts = np.stack([self.ax[:, 0], self.ay[:, 0]], axis=1)
        end = self.position(np.array([self.total_length]))
        return np.concatenate([starts, end], axis=0)

    @property
    def start(self) -> NDArray[np.float64]:
        """``(2,)`` start point (the operator's position)."""
        self._require_nonempty()
        return np.array([self.ax[0, 0], self.ay[0, 0]])

    @property
    def n_numbers(self) -> int:
        """Independent numbers that describe the path: ``7 M + 2``.

        Per segment 6 coefficients and the length; ``a0, b0`` repeat the previous segment's end
        (the chain is continuous) and ``s0`` is a running sum, so only the start point is extra.
        ``path.json`` writes 10 numbers per segment for readability.
        """
        return 7 * self.n_segments + 2 if self.n_segments else 0

    def _require_nonempty(self) -> None:
        if self.n_segments == 0 or self.total_length <= 0.0:
            raise DegenerateGeometryError("the path has zero length: nothing to evaluate")

    # ------------------------------------------------------------------ evaluation
    def locate(self, s: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
        """Segment index and local parameter ``u`` of arc lengths ``s`` (clipped to ``[0, L]``)."""
        self._require_nonempty()
        s = np.clip(np.asarray(s, dtype=np.float64), 0.0, self.total_length)
        k = np.clip(np.searchsorted(self.s0, s, side="right") - 1, 0, self.n_segments - 1)
        u = np.clip(s - self.s0[k], 0.0, self.length[k])
        return k, u

    def _eval(self, s: ArrayLike, der: int) -> NDArray[np.float64]:
        k, u = self.locate(s)
        return np.stack([cubic_eval(self.ax[k], u, der), cubic_eval(self.ay[k], u, der)], axis=-1)

    def position(self, s: ArrayLike) -> NDArray[np.float64]:
        """``(..., 2)`` points at arc lengths ``s`` (any shape, metres; clipped to ``[0, L]``)."""
        return self._eval(s, 0)

    def derivative(self, s: ArrayLike, der: int = 1) -> NDArray[np.float64]:
        """``(..., 2)`` first or second derivative ``dC/ds`` at ``s`` (``|C'| ~ 1``)."""
        return self._eval(s, der)

    def heading(self, s: ArrayLike) -> NDArray[np.float64]:
        """Tangent direction ``atan2(y', x')`` at ``s``, radians in ``(-pi, pi]``."""
        d = self.derivative(s, 1)
        return np.arctan2(d[..., 1], d[..., 0])

    def curvature(self, s: ArrayLike) -> NDArray[np.float64]:
        """Signed curvature ``(x' y'' - y' x'') / |C'|^3`` at ``s`` (1/m, positive = left turn).

        The exact formula is used rather than ``|C''|``, so the small departure of the refit from
        unit speed does not bias it.
        """
        d1 = self.derivative(s, 1)
        d2 = self.derivative(s, 2)
        speed = np.hypot(d1[..., 0], d1[..., 1])
        with np.errstate(invalid="ignore", divide="ignore"):
            return (d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]) / speed**3

    # ------------------------------------------------------------------ sampling and search
    def sample(self, step: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Arc lengths ``(K,)`` every ``step`` metres (plus every knot and the end) and their points."""
        self._require_nonempty()
        if not step > 0:
            raise InputError(f"is {step}", field="step", expected="a positive distance in metres")
        n = int(np.ceil(self.total_length / step))
        s = np.unique(np.concatenate([np.linspace(0.0, self.total_length, n + 1), self.s0]))
        return s, self.position(s)

    @cached_property
    def _search_grid(self) -> tuple[NDArray[np.float64], NDArray[np.float64], Any]:
        from scipy.spatial import cKDTree

        step = float(np.clip(self.total_length / 20000.0, 1e-3, 0.05))
        s, xy = self.sample(step)
        return s, xy, cKDTree(xy)

    def nearest(
        self, points: ArrayLike, s_min: ArrayLike | None = None, s_max: ArrayLike | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Arc length of the path point nearest to each point (mode 2, step 2.1).

        A dense sample of the path (spacing ``h <= 5 cm``) gives the starting guess (a KD-tree, or a
        window search when ``s_min`` / ``s_max`` restrict the answer); three Newton steps on
        ``|C(s) - p|^2`` refine it within ``+-h``.

        Parameters
        ----------
        points : (2,) or (N, 2) array
            Query points.
        s_min, s_max : float or (N,) array, optional
            Restrict the answer to ``[s_min, s_max]`` (the return controller uses a window around
            its progress so it never jumps to another part of the path that passes close by).

        Returns
        -------
        s : (N,) or scalar array
            Arc length of the nearest point, metres.
        distance : (N,) or scalar array
            Distance to it, metres.
        """
        self._require_nonempty()
        p = np.asarray(points, dtype=np.float64)
        single = p.ndim == 1
        P = np.atleast_2d(p)
        if P.shape[-1] != 2:
            raise InputError(f"has shape {p.shape}", field="points", expected="(2,) or (N, 2)")
        grid_s, grid_xy, tree = self._search_grid
        h = float(np.max(np.diff(grid_s))) if len(grid_s) > 1 else 0.0
        if s_min is None and s_max is None:
            # several grid candidates, so a second branch of the path passing nearby cannot win
            # just because its samples happen to fall closer than the right branch's (<= h / 2)
            k = int(min(12, len(grid_s)))
            _, idx = tree.query(P, k=k)
            idx = np.asarray(idx).reshape(len(P), k)
            rep = np.repeat(np.arange(len(P)), k)
            s_all, d_all = self._refine(P[rep], grid_s[idx.reshape(-1)], h)
            best = np.argmin(d_all.reshape(len(P), k), axis=1)
            s = s_all.reshape(len(P), k)[np.arange(len(P)), best]
            dist = d_all.reshape(len(P), k)[np.arange(len(P)), best]
            return (s[0], dist[0]) if single else (s, dist)
        lo = np.broadcast_to(
            np.clip(0.0 if s_min is None else s_min, 0.0, self.total_length), len(P)
        )
        hi = np.broadcast_to(
            np.clip(self.total_length if s_max is None else s_max, 0.0, self.total_length), len(P)
        )
        lo = np.minimum(lo, hi)
        i0 = np.searchsorted(grid_s, lo, side="left")
        i1 = np.searchsorted(grid_s, hi, side="right")
        width = int(max(1, np.max(i1 - i0)))
        cand = np.minimum(i0[:, None] + np.arange(width)[None, :], len(grid_s) - 1)
        valid = cand < i1[:, None]
        d2 = ((grid_xy[cand] - P[:, None, :]) ** 2).sum(-1)
        d2[~valid] = np.inf
        best_i = cand[np.arange(len(P)), np.argmin(d2, axis=1)]
        s_guess = np.clip(grid_s[best_i], lo, hi)
        s, dist = self._refine(P, s_guess, h, lo, hi)
        return (s[0], dist[0]) if single else (s, dist)

    def _refine(
        self,
        P: NDArray[np.float64],
        s_guess: NDArray[np.float64],
        h: float,
        lo: NDArray[np.float64] | None = None,
        hi: NDArray[np.float64] | None = None,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Newton on ``|C(s) - p|^2 / 2`` within ``[s_guess - h, s_guess + h]`` (and ``[lo, hi]``)."""
        lo_ = np.maximum(s_guess - h, 0.0 if lo is None else lo)
        hi_ = np.minimum(s_guess + h, self.total_length if hi is None else hi)
        s = s_guess
        for _ in range(3):
            r = self.position(s) - P
            d1 = self.derivative(s, 1)
            d2_ = self.derivative(s, 2)
            g = (r * d1).sum(-1)
            H = (d1 * d1).sum(-1) + (r * d2_).sum(-1)
            step = np.where(H > 1e-12, g / np.where(H > 1e-12, H, 1.0), 0.0)
            s = np.clip(s - step, lo_, hi_)
        # keep the better of the Newton result and the grid guess (Newton can climb on concave f)
        d_new = np.linalg.norm(self.position(s) - P, axis=-1)
        d_old = np.linalg.norm(self.position(s_guess) - P, axis=-1)
        better = d_new <= d_old
        return np.where(better, s, s_guess), np.where(better, d_new, d_old)

    # ------------------------------------------------------------------ path.json (dict form)
    def to_dict(self) -> dict[str, Any]:
        """The ``path.json`` structure (see ``docs/path.md``)."""
        return {
            "format": "navkit-path",
            "version": 1,
            "tolerance": self.tolerance,
            "length": self.total_length,
            "frame": self.frame,
            "segments": [
                {
                    "s0": float(s0),
                    "length": float(ln),
                    "x": [float(v) for v in ax],
                    "y": [float(v) for v in ay],
                }
                for s0, ln, ax, ay in zip(self.s0, self.length, self.ax, self.ay, strict=True)
            ],
        }

    @classmethod
    def from_dict(cls, data: Any, source: str | None = None) -> PathSpline:
        """Parse the ``path.json`` structure, checking every field.

        Raises
        ------
        FormatError
            Naming ``source`` and the offending field.
        """
        if not isinstance(data, dict):
            raise FormatError("top level is not an object", source=source, expected="a JSON object")
        segs = data.get("segments")
        if not isinstance(segs, list):
            raise FormatError(
                "missing or not a list",
                source=source,
                field="segments",
                expected="a list of {s0, length, x, y}",
            )
        lengths, ax, ay, s0 = [], [], [], []
        for i, seg in enumerate(segs):
            where = f"segments[{i}]"
            if not isinstance(seg, dict):
                raise FormatError(
                    "not an object", source=source, field=where, expected="{s0, length, x, y}"
                )
            try:
                ln = float(seg["length"])
                s0.append(float(seg.get("s0", np.nan)))
                cx = [float(v) for v in seg["x"]]
                cy = [float(v) for v in seg["y"]]
            except KeyError as exc:
                raise FormatError(
                    f"missing key {exc}",
                    source=source,
                    field=where,
                    expected="keys s0, length, x, y",
                ) from None
            except (TypeError, ValueError):
                raise FormatError(
                    "non-numeric value",
                    source=source,
                    field=where,
                    expected="numbers: length, x[4], y[4]",
                ) from None
            if len(cx) != 4 or len(cy) != 4:
                raise FormatError(
                    "coefficient lists must have 4 numbers",
                    source=source,
                    field=where,
                    expected="x = [a0, a1, a2, a3], y = [b0, b1, b2, b3]",
                )
            if not (
                np.isfinite(ln) and ln >= 0 and np.all(np.isfinite(cx)) and np.all(np.isfinite(cy))
            ):
                raise FormatError(
                    "non-finite or negative value",
                    source=source,
                    field=where,
                    expected="finite coefficients and length >= 0",
                )
            lengths.append(ln)
            ax.append(cx)
            ay.append(cy)
        tol = data.get("tolerance")
        out = cls.from_segments(
            lengths,
            np.reshape(ax, (-1, 4)),
            np.reshape(ay, (-1, 4)),
            tolerance=float("nan") if tol is None else float(tol),
            frame=data.get("frame") or {},
        )
        stored = np.asarray(s0)
        if (
            len(stored)
            and np.all(np.isfinite(stored))
            and not np.allclose(stored, out.s0, atol=1e-6)
        ):
            raise FormatError(
                "segment start lengths are not the running sum of the lengths",
                source=source,
                field="segments[].s0",
                expected="s0[k] = sum of length[:k]",
            )
        return out
