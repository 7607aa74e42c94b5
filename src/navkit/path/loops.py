"""Loop removal: self-intersections of the spline through a bounding-box tree (paper 4, section 3).

Each cubic segment is split at the extrema of ``x(u)`` and ``y(u)`` (roots of the derivative
quadratics) into *monotone pieces*; a monotone piece lies inside the box spanned by its two end
points, and so does every sub-piece, so boxes cost two evaluations. The pieces, in path order,
are the leaves of a complete binary tree (an implicit heap: node ``i`` has children ``2i`` and
``2i + 1``) whose nodes hold the union box of their subtree - the root the whole spline, its
children the halves of the piece list, and so on (the paper's tree). New segments append leaves
and update only their ancestors, so the tree is built once and extended as data arrive.

A new segment's pieces descend the tree, level by level and vectorised over (piece, node) pairs,
keeping the nodes whose boxes overlap. Each overlapping pair of pieces is then refined by binary
search: both pieces are split in parameter and the overlapping sub-pairs kept, until both boxes
are smaller than ``precision`` (0.1 mm, as in the paper). Sub-pairs whose boxes overlap must also
pass a chord test (a sub-piece stays within ``du^2 / 8 max|C''|`` of its chord), which keeps
near-parallel curves from multiplying the pairs. A crossing at parameters ``s1 < s2``
makes the loop ``[s1, s2]``; loops shorter than ``min_loop_length`` are the shared end points of
neighbouring pieces, not loops, and are pruned as soon as the arc-length bound proves it. The
crossing that is cut is then solved on the two cubics (:meth:`LoopFreeChain.exact_crossing`), so
the kept head ends and the kept tail starts on the same point: a box of ``precision`` is
``precision / sin(theta)`` long along branches meeting at a shallow angle ``theta``, and a cut
there left a small crossing at the junction.

Decision (the paper does not say): when a new segment crosses the old path at several places,
the crossing with the smallest ``s1`` is cut first (it removes the largest loop, and every other
crossing whose ``s1`` falls inside it disappears with it); the search then repeats on what is
left of the new segment, so a path is loop-free after every segment.
"""

from __future__ import annotations

import bisect
import functools
import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from navkit.errors import ConfigError
from navkit.jit import kernels_enabled
from navkit.path.spline import PathSpline, cubic_eval, cubic_shift

__all__ = [
    "Crossing",
    "LoopCut",
    "LoopFreeChain",
    "find_crossings",
    "kept_intervals",
    "monotone_breaks",
    "remove_loops",
]

log = logging.getLogger(__name__)

_EMPTY_LO = np.inf
_EMPTY_HI = -np.inf


@dataclass(frozen=True)
class Crossing:
    """A self-intersection ``C(s_a) = C(s_b)``, ``s_a < s_b`` (arc lengths, metres)."""

    s_a: float
    s_b: float
    point: NDArray[np.float64]


@dataclass(frozen=True)
class LoopCut:
    """A loop that was cut out: ``[s_start, s_end]`` of the path as it was before the cut.

    Attributes
    ----------
    s_start, s_end : float
        Arc lengths of the crossing on the path before the cut (metres).
    point : (2,) array
        The crossing.
    polyline : (K, 2) array
        Samples of the removed loop (for figures), every ~1 cm (16 to 2000 samples); computed
        on first access from the chain's segments as they were before the cut (kept as
        ``segments``: lengths, x and y coefficients), not at the cut: sampling it costs ~0.3 ms,
        which would otherwise fall on the point that closes the loop.
    """

    s_start: float
    s_end: float
    point: NDArray[np.float64]
    segments: tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]] = field(
        repr=False, compare=False
    )

    @functools.cached_property
    def polyline(self) -> NDArray[np.float64]:
        """``(K, 2)`` samples of the removed loop."""
        n = int(np.clip((self.s_end - self.s_start) / 0.01, 16, 2000))
        s = np.linspace(self.s_start, self.s_end, n)
        return PathSpline.from_segments(*self.segments).position(s)

    @property
    def length(self) -> float:
        """Length of the removed loop, metres."""
        return self.s_end - self.s_start


def _quadratic_roots(a: float, b: float, c: float) -> list[float]:
    """Real roots of ``a u^2 + b u + c`` (linear / constant cases included)."""
    if abs(a) < 1e-300:
        return [-c / b] if abs(b) > 1e-300 else []
    disc = b * b - 4.0 * a * c
    if disc < 0:
        return []
    q = -0.5 * (b + math.copysign(math.sqrt(disc), b))  # numerically stable form
    roots = [q / a]
    if abs(q) > 1e-300:
        roots.append(c / q)
    return roots


def _dot2(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``a_x b_x + a_y b_y`` over the last axis (written out: the kernels' order on any NumPy)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def _segment_distance(
    p1: NDArray[np.float64],
    q1: NDArray[np.float64],
    p2: NDArray[np.float64],
    q2: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Distances between segments ``p1 q1`` and ``p2 q2`` (rows ``(N, 2)``), vectorised
    (closest points of two segments, Ericson, Real-Time Collision Detection, 5.1.9)."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a = _dot2(d1, d1)
    e = _dot2(d2, d2)
    f = _dot2(d2, r)
    c = _dot2(d1, r)
    b = _dot2(d1, d2)
    tiny = 1e-300
    a_ok, e_ok = a > tiny, e > tiny
    safe_a = np.where(a_ok, a, 1.0)
    safe_e = np.where(e_ok, e, 1.0)
    denom = a * e - b * b
    s = np.where(
        denom > tiny, np.clip((b * f - c * e) / np.where(denom > tiny, denom, 1.0), 0.0, 1.0), 0.0
    )
    s = np.where(a_ok, s, 0.0)
    t = np.where(e_ok, (b * s + f) / safe_e, 0.0)
    s = np.where(
        t < 0.0,
        np.clip(-c / safe_a, 0.0, 1.0),
        np.where(t > 1.0, np.clip((b - c) / safe_a, 0.0, 1.0), s),
    )
    s = np.where(e_ok, s, np.clip(-c / safe_a, 0.0, 1.0))  # B is a point: project it on A
    s = np.where(a_ok, s, 0.0)
    t = np.where(e_ok, np.clip(t, 0.0, 1.0), 0.0)
    v = p1 + d1 * s[:, None] - p2 - d2 * t[:, None]
    return np.sqrt(_dot2(v, v))


def monotone_breaks(
    ax: NDArray[np.float64], ay: NDArray[np.float64], length: float
) -> NDArray[np.float64]:
    """Parameters ``0 = u_0 < ... < u_m = length`` between which ``x(u)`` and ``y(u)`` are monotone.

    The extrema are the roots of ``x'(u) = a1 + 2 a2 u + 3 a3 u^2`` (and the same for y) inside
    ``(0, length)``.
    """
    inner = sorted(
        r
        for c in (ax.tolist(), ay.tolist())
        for r in _quadratic_roots(3.0 * c[3], 2.0 * c[2], c[1])
        if 0.0 < r < length
    )
    tol = 1e-12 * max(length, 1.0)
    cuts = [0.0]
    for r in inner:
        if r - cuts[-1] > tol and length - r > tol:
            cuts.append(r)
    cuts.append(float(length))
    return np.array(cuts)


class LoopFreeChain:
    """A chain of cubic segments kept free of loops as segments are appended.

    Parameters
    ----------
    precision : float
        Size (metres) the overlapping boxes are refined to; the crossing is known to this
        precision (paper: 0.1 mm).
    min_loop_length : float
        Crossings closer than this along the path (metres) are not loops (neighbouring pieces
        share their end point).
    max_pairs : int
        Bound on the candidate sub-pairs of one refinement pass (curves lying on top of each
        other give a pair per precision step; the pairs with the smallest ``s1`` are kept).
    split : int
        Sub-intervals per piece and pass (2 = the paper's binary search).
    """

    def __init__(
        self,
        precision: float = 1e-4,
        min_loop_length: float = 1e-3,
        max_pairs: int = 50000,
        split: int = 8,
    ) -> None:
        if not precision > 0:
            raise ConfigError(
                f"is {precision}", field="loop_precision", expected="a positive distance (m)"
            )
        if not min_loop_length > 0:
            raise ConfigError(
                f"is {min_loop_length}", field="min_loop_length", expected="a positive distance (m)"
            )
        self.precision = float(precision)
        self.min_loop_length = float(min_loop_length)
        self.max_pairs = int(max_pairs)
        if split < 2:
            raise ConfigError(
                f"is {split}", field="split", expected="an integer >= 2 (2 = binary search)"
            )
        self.split = int(split)
        self._f = np.linspace(0.0, 1.0, self.split + 1)  # the split fractions of a pass
        # the refinement passes in one compiled loop (navkit.path._kernels) when the process runs
        # the kernels (navkit.jit); False: NumPy (the oracle the tests compare with)
        self.compiled = kernels_enabled()
        # segments (growing arrays, first n_seg rows valid)
        self.n_seg = 0
        self._ax = np.zeros((16, 4))
        self._ay = np.zeros((16, 4))
        self._len = np.zeros(16)
        self._s0 = np.zeros(16)
        # monotone pieces in path order
        self.n_piece = 0
        self._pseg = np.zeros(64, dtype=np.intp)
        self._pu0 = np.zeros(64)
        self._pu1 = np.zeros(64)
        self._seg_first_piece = np.zeros(17, dtype=np.intp)
        # the tree: leaves at [cap, 2 cap)
        self._cap = 64
        self._lo = np.full((2 * self._cap, 2), _EMPTY_LO)
        self._hi = np.full((2 * self._cap, 2), _EMPTY_HI)
        self.cuts: list[LoopCut] = []

    # ------------------------------------------------------------------ segments
    @property
    def total_length(self) -> float:
        """Length of the chain, metres."""
        return float(self._s0[self.n_seg - 1] + self._len[self.n_seg - 1]) if self.n_seg else 0.0

    def spline(self, tolerance: float = float("nan"), frame: dict | None = None) -> PathSpline:
        """The chain as a :class:`PathSpline` (copies)."""
        n = self.n_seg
        return PathSpline.from_segments(
            self._len[:n].copy(),
            self._ax[:n].copy(),
            self._ay[:n].copy(),
            tolerance=tolerance,
            frame=frame,
        )

    def _grow_segments(self) -> None:
        if self.n_seg + 2 >= len(self._len):
            m = 2 * len(self._len)
            self._ax = np.resize(self._ax, (m, 4))
            self._ay = np.resize(self._ay, (m, 4))
            self._len = np.resize(self._len, m)
            self._s0 = np.resize(self._s0, m)
            self._seg_first_piece = np.resize(self._seg_first_piece, m + 1)

    def _push_segment(self, ax: NDArray[np.float64], ay: NDArray[np.float64], length: float) -> int:
        self._grow_segments()
        k = self.n_seg
        self._ax[k], self._ay[k], self._len[k] = ax, ay, length
        self._s0[k] = self.total_length
        self.n_seg += 1
        breaks = monotone_breaks(ax, ay, length)
        m = len(breaks) - 1
        if self.n_piece + m > len(self._pseg):
            size = max(2 * len(self._pseg), self.n_piece + m)
            self._pseg = np.resize(self._pseg, size)
            self._pu0 = np.resize(self._pu0, size)
            self._pu1 = np.resize(self._pu1, size)
        a, b = self.n_piece, self.n_piece + m
        self._seg_first_piece[k] = a
        self._pseg[a:b] = k
        self._pu0[a:b] = breaks[:-1]
        self._pu1[a:b] = breaks[1:]
        self.n_piece = b
        self._seg_first_piece[k + 1] = b
        self._update_leaves(a, b)
        return k

    def _truncate(self, n_seg: int) -> None:
        """Drop segments ``n_seg..`` and their pieces (their leaves become empty boxes)."""
        first = int(self._seg_first_piece[n_seg]) if n_seg < self.n_seg else self.n_piece
        old = self.n_piece
        self.n_seg = n_seg
        self.n_piece = first
        if old > first:
            self._update_leaves(first, old)

    # ------------------------------------------------------------------ the box tree
    def _piece_ends(self, idx: NDArray[np.intp]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        seg = self._pseg[idx]
        u0, u1 = self._pu0[idx], self._pu1[idx]
        ax, ay = self._ax[seg], self._ay[seg]
        p0 = np.stack([cubic_eval(ax, u0), cubic_eval(ay, u0)], axis=-1)
        p1 = np.stack([cubic_eval(ax, u1), cubic_eval(ay, u1)], axis=-1)
        return p0, p1

    def _update_leaves(self, a: int, b: int) -> None:
        """Recompute leaves ``[a, b)`` and their ancestors (one vectorised step per level)."""
        if b > self._cap:
            cap = self._cap
            while cap < b:
                cap *= 2
            self._cap = cap
            self._lo = np.full((2 * cap, 2), _EMPTY_LO)
            self._hi = np.full((2 * cap, 2), _EMPTY_HI)
            a = 0
            b = max(b, self.n_piece)
        if self.compiled:  # the same boxes, in one compiled loop
            from navkit.path import _kernels

            _kernels.update_leaves(
                self._lo, self._hi, self._cap, int(a), int(b), int(self.n_piece),
                self._pseg.astype(np.int64, copy=False), self._pu0, self._pu1, self._ax, self._ay,
            )  # fmt: skip
            return
        idx = np.arange(a, b)
        live = idx < self.n_piece
        leaf = idx + self._cap
        self._lo[leaf] = _EMPTY_LO
        self._hi[leaf] = _EMPTY_HI
        if live.any():
            p0, p1 = self._piece_ends(idx[live])
            self._lo[leaf[live]] = np.minimum(p0, p1)
            self._hi[leaf[live]] = np.maximum(p0, p1)
        lo_n, hi_n = leaf[0], leaf[-1]
        while lo_n > 1:
            lo_n, hi_n = lo_n // 2, hi_n // 2
            lo, hi = self._lo, self._hi  # contiguous node ranges: slices, not fancy indexing
            np.minimum(
                lo[2 * lo_n : 2 * hi_n + 2 : 2],
                lo[2 * lo_n + 1 : 2 * hi_n + 2 : 2],
                out=lo[lo_n : hi_n + 1],
            )
            np.maximum(
                hi[2 * lo_n : 2 * hi_n + 2 : 2],
                hi[2 * lo_n + 1 : 2 * hi_n + 2 : 2],
                out=hi[lo_n : hi_n + 1],
            )

    def _candidate_pairs(self, first_piece: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """(older piece, newer piece) pairs with overlapping boxes, newer pieces ``>= first_piece``
        (NumPy; the compiled search does this inside ``_kernels.find_crossings`` with
        ``_kernels.candidate_pairs``: the same pairs in the same order)."""
        q = np.arange(first_piece, self.n_piece)
        if len(q) == 0:
            return np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp)
        qlo = self._lo[q + self._cap]
        qhi = self._hi[q + self._cap]
        # start the descent a few levels below the root (at most 64 nodes there): one vectorised
        # test replaces the top levels' short steps
        level = min(6, self._cap.bit_length() - 1)
        first, count = 1 << level, 1 << level
        qi = np.repeat(np.arange(len(q)), count)
        node = np.tile(np.arange(first, first + count), len(q))
        keep = np.all((self._lo[node] <= qhi[qi]) & (qlo[qi] <= self._hi[node]), axis=1)
        qi, node = qi[keep], node[keep]
        while len(node) and node[0] < self._cap:  # all frontier nodes sit on the same level
            qi = np.repeat(qi, 2)
            node = np.stack([2 * node, 2 * node + 1], axis=1).reshape(-1)
            keep = np.all((self._lo[node] <= qhi[qi]) & (qlo[qi] <= self._hi[node]), axis=1)
            qi, node = qi[keep], node[keep]
        older = node - self._cap
        newer = q[qi]
        keep = older < newer
        return older[keep], newer[keep]

    # ------------------------------------------------------------------ binary refinement
    def find_crossings(self, first_segment: int, *, first_only: bool = False) -> list[Crossing]:
        """Crossings between the pieces of segments ``>= first_segment`` and all earlier pieces.

        Binary refinement generalised to ``split``-ary: each pass cuts both pieces of every pair
        into ``split`` equal parameter intervals (``split = 2`` is the paper's halving; 8 reaches
        0.1 mm on a 30 m piece in 6 passes instead of 18, with the same boxes) and keeps the
        overlapping sub-pairs. With ``first_only`` only the crossing with the smallest ``s_a`` is
        wanted (what loop removal cuts): once one is found, pairs that start later are dropped.
        """
        if first_segment >= self.n_seg:
            return []
        K = self.split
        f = self._f
        if self.compiled:  # the whole search in one compiled call: the same crossings, same order
            from navkit.path import _kernels

            A, B, Pt, truncated = _kernels.find_crossings(
                self._lo, self._hi, self._cap, int(self._seg_first_piece[first_segment]),
                self.n_piece, self._pseg, self._pu0, self._pu1, self._ax[: self.n_seg],
                self._ay[: self.n_seg], self._s0[: self.n_seg], f, self.precision,
                self.min_loop_length, self.max_pairs, first_only,
            )  # fmt: skip
            if truncated:
                log.warning(
                    "loop search: more than %d overlapping sub-pairs (curves on top of each "
                    "other?) in %d passes; kept those with the smallest s",
                    self.max_pairs,
                    truncated,
                )
            return self._crossings(A, B, Pt, first_only)
        ia, ib = self._candidate_pairs(int(self._seg_first_piece[first_segment]))
        if len(ia) == 0:
            return []
        sa, sb = self._pseg[ia], self._pseg[ib]
        ua0, ua1 = self._pu0[ia].copy(), self._pu1[ia].copy()
        ub0, ub1 = self._pu0[ib].copy(), self._pu1[ib].copy()
        # neighbouring pieces share an end point: trim min_loop / 2 off each side of it (u ~ s)
        adj = ib == ia + 1
        m = 0.5 * self.min_loop_length
        ua1 = np.where(adj, ua1 - m, ua1)
        ub0 = np.where(adj, ub0 + m, ub0)
        ok = (ua1 > ua0) & (ub1 > ub0)
        sa, sb = sa[ok], sb[ok]
        ua0, ua1, ub0, ub1 = ua0[ok], ua1[ok], ub0[ok], ub1[ok]
        found_a: list[NDArray[np.float64]] = []
        found_b: list[NDArray[np.float64]] = []
        found_p: list[NDArray[np.float64]] = []
        for _ in range(100):  # each pass divides the intervals by K; 100 is a safety bound
            if len(sa) == 0:
                break
            if len(sa) * K * K > self.max_pairs:
                order = np.argsort(self._s0[sa] + ua0, kind="stable")[
                    : max(1, self.max_pairs // (K * K))
                ]
                log.warning(
                    "loop search: %d overlapping pairs (curves on top of each other?); keeping the "
                    "%d with the smallest s",
                    len(sa),
                    len(order),
                )
                sa, sb = sa[order], sb[order]
                ua0, ua1, ub0, ub1 = ua0[order], ua1[order], ub0[order], ub1[order]
            # both pieces of every pair in one array: index 0 = A (older), 1 = B (newer)
            U = (
                np.stack([ua0, ub0])[:, :, None] + np.stack([ua1 - ua0, ub1 - ub0])[:, :, None] * f
            )  # (2, P, K+1)
            seg = np.stack([sa, sb])
            coef = np.stack([self._ax[seg], self._ay[seg]], axis=-2)  # (2, P, 2, 4)
            pts = cubic_eval(coef[:, :, None], U[..., None])  # (2, P, K + 1, 2)
            lo = np.minimum(pts[:, :, :-1], pts[:, :, 1:])  # sub-piece boxes (2, P, K, 2)
            hi = np.maximum(pts[:, :, :-1], pts[:, :, 1:])
            ext = (hi - lo).max(-1)  # (2, P, K)
            overlap = np.all(
                (lo[0][:, :, None] <= hi[1][:, None, :]) & (lo[1][:, None, :] <= hi[0][:, :, None]),
                axis=-1,
            )
            ua, ub = U[0], U[1]
            pa, pb = pts[0], pts[1]
            ga, gb = self._s0[sa], self._s0[sb]
            long_enough = (
                (gb[:, None, None] + ub[:, None, 1:]) - (ga[:, None, None] + ua[:, :-1, None])
            ) >= self.min_loop_length
            p, i, j = np.nonzero(overlap & long_enough)
            # Tighter than the boxes: a sub-piece lies within delta = du^2 / 8 max|C''| of its
            # chord (interpolation error bound; C'' is linear in u, so its max norm is at an end),
            # so two sub-pieces can only meet if their chords are within delta_a + delta_b.
            # Near-parallel curves (a road driven twice) then stop spawning box pairs early.
            c2 = cubic_eval(coef[:, :, None], U[..., None], 2)
            acc = np.sqrt(_dot2(c2, c2))  # (2, P, K+1)
            du = U[:, :, 1] - U[:, :, 0]  # (2, P), equal steps
            delta = (du * du / 8.0)[:, :, None] * np.maximum(
                acc[:, :, :-1], acc[:, :, 1:]
            )  # (2, P, K)
            gap = _segment_distance(pa[p, i], pa[p, i + 1], pb[p, j], pb[p, j + 1])
            near = gap <= delta[0][p, i] + delta[1][p, j] + 1e-12
            p, i, j = p[near], i[near], j[near]
            size = np.maximum(ext[0][p, i], ext[1][p, j])
            done = size <= self.precision
            if done.any():
                pd, idn, jd = p[done], i[done], j[done]
                found_a.append(ga[pd] + 0.5 * (ua[pd, idn] + ua[pd, idn + 1]))
                found_b.append(gb[pd] + 0.5 * (ub[pd, jd] + ub[pd, jd + 1]))
                found_p.append(0.25 * (pa[pd, idn] + pa[pd, idn + 1] + pb[pd, jd] + pb[pd, jd + 1]))
            go = ~done
            if first_only and found_a:
                best = min(float(a.min()) for a in found_a)
                go &= ga[p] + ua[p, i] <= best  # a later-starting pair cannot give a smaller s_a
            p, i, j = p[go], i[go], j[go]
            sa, sb = sa[p], sb[p]
            ua0, ua1 = ua[p, i], ua[p, i + 1]
            ub0, ub1 = ub[p, j], ub[p, j + 1]
        if not found_a:
            return []
        A, B, Pt = np.concatenate(found_a), np.concatenate(found_b), np.concatenate(found_p)
        return self._crossings(A, B, Pt, first_only)

    @staticmethod
    def _crossings(
        A: NDArray[np.float64], B: NDArray[np.float64], Pt: NDArray[np.float64], first_only: bool
    ) -> list[Crossing]:
        """Crossings from the refinement's ``s_a``, ``s_b`` and points (the first one only:
        smallest ``s_a``, then largest ``s_b``)."""
        if len(A) == 0:
            return []
        if first_only:
            k = int(np.lexsort((-B, A))[0])  # smallest s_a, then largest s_b
            return [Crossing(s_a=float(A[k]), s_b=float(B[k]), point=Pt[k])]
        return [
            Crossing(s_a=float(a), s_b=float(b), point=pt)
            for a, b, pt in zip(A, B, Pt, strict=True)
        ]

    # ------------------------------------------------------------------ appending with loop removal
    def append(
        self,
        ax: NDArray[np.float64],
        ay: NDArray[np.float64],
        length: float,
        *,
        remove_loops: bool = True,
    ) -> list[LoopCut]:
        """Append a segment; with ``remove_loops`` cut every loop it closes (returns the cuts)."""
        if self.compiled:
            return self._append_compiled(
                np.asarray(ax, float), np.asarray(ay, float), float(length), remove_loops
            )
        k = self._push_segment(np.asarray(ax, float), np.asarray(ay, float), float(length))
        cuts: list[LoopCut] = []
        if not remove_loops:
            return cuts
        for _ in range(64):
            hits = self.find_crossings(k, first_only=True)
            if not hits:
                break
            best = min(hits, key=lambda c: (c.s_a, -c.s_b))
            sa, sb, x, y = self.exact_crossing(best.s_a, best.s_b)
            k = self._cut(Crossing(s_a=sa, s_b=sb, point=np.array([x, y])))
            cuts.append(self.cuts[-1])
        return cuts

    def _reserve(self, pieces: int) -> None:
        """Room for 2 more segments and ``pieces`` more pieces, in the arrays and in the tree
        (grown as ``_update_leaves`` grows it: the same boxes, all leaves rebuilt)."""
        self._grow_segments()
        need = self.n_piece + pieces
        if need > len(self._pseg):
            size = max(2 * len(self._pseg), need)
            self._pseg = np.resize(self._pseg, size)
            self._pu0 = np.resize(self._pu0, size)
            self._pu1 = np.resize(self._pu1, size)
        if need > self._cap:
            self._update_leaves(self.n_piece, need)

    def _append_compiled(
        self, ax: NDArray[np.float64], ay: NDArray[np.float64], length: float, remove_loops: bool
    ) -> list[LoopCut]:
        """``append`` in one kernel call per step: the push of the segment with its
        first crossing search (``_kernels.append_search``), then per loop the cut with the next
        search (``_kernels.cut_search``) - the same segments, pieces, boxes and crossings as
        ``_push_segment`` / ``find_crossings`` / ``_cut`` (the NumPy oracle, ``compiled``
        False), without their ~15 Python-level steps and 4 kernel calls per cut."""
        from navkit.path import _kernels

        self._reserve(5)  # a segment has at most 4 inner monotone breaks
        n_piece, found, s_a, s_b, x, y, truncated = _kernels.append_search(
            self._ax, self._ay, self._len, self._s0, self._seg_first_piece, self._pseg,
            self._pu0, self._pu1, self._lo, self._hi, self._cap, self.n_seg, self.n_piece,
            ax, ay, length, self._f, self.precision, self.min_loop_length, self.max_pairs,
            remove_loops,
        )  # fmt: skip
        self.n_seg += 1
        self.n_piece = n_piece
        cuts: list[LoopCut] = []
        for _ in range(64):
            if truncated:
                self._warn_truncated(truncated)
            if not found:
                break
            s_a, s_b, x, y = self.exact_crossing(s_a, s_b)
            # the chain before the cut, for the loop's polyline (its first kb + 1 segments)
            n = self.n_seg
            before = (self._len[:n].copy(), self._ax[:n].copy(), self._ay[:n].copy())
            self._reserve(10)  # the head and the tail of the cut
            kb, self.n_seg, self.n_piece, found_next, sa2, sb2, x2, y2, truncated = (
                _kernels.cut_search(
                    self._ax, self._ay, self._len, self._s0, self._seg_first_piece, self._pseg,
                    self._pu0, self._pu1, self._lo, self._hi, self._cap, self.n_seg,
                    self.n_piece, s_a, s_b, self._f, self.precision, self.min_loop_length,
                    self.max_pairs,
                )
            )  # fmt: skip
            cut = LoopCut(
                s_start=s_a,
                s_end=s_b,
                point=np.array([x, y]),
                segments=(before[0][: kb + 1], before[1][: kb + 1], before[2][: kb + 1]),
            )
            self.cuts.append(cut)
            cuts.append(cut)
            log.debug("loop cut: s in [%.4f, %.4f] (%.3f m)", s_a, s_b, s_b - s_a)
            found, s_a, s_b, x, y = found_next, sa2, sb2, x2, y2
        return cuts

    def _warn_truncated(self, truncated: int) -> None:
        log.warning(
            "loop search: more than %d overlapping sub-pairs (curves on top of each "
            "other?) in %d passes; kept those with the smallest s",
            self.max_pairs,
            truncated,
        )

    def _evaluator(self) -> Callable[[float], tuple[float, float, float, float]]:
        """``s -> (x, y, x', y')``: position and tangent of the chain at arc length ``s`` (plain
        floats; the segment is located as :meth:`_locate` does, on lists made once)."""
        n = self.n_seg
        s0 = self._s0[:n].tolist()
        lens = self._len[:n].tolist()
        ax, ay = self._ax[:n].tolist(), self._ay[:n].tolist()

        def point(s: float) -> tuple[float, float, float, float]:
            k = min(max(bisect.bisect_right(s0, s) - 1, 0), n - 1)
            u = min(max(s - s0[k], 0.0), lens[k])
            x0, x1, x2, x3 = ax[k]
            y0, y1, y2, y3 = ay[k]
            return (
                x0 + u * (x1 + u * (x2 + u * x3)),
                y0 + u * (y1 + u * (y2 + u * y3)),
                x1 + u * (2.0 * x2 + 3.0 * x3 * u),
                y1 + u * (2.0 * y2 + 3.0 * y3 * u),
            )

        return point

    def exact_crossing(self, s_a: float, s_b: float) -> tuple[float, float, float, float]:
        """The crossing the box search found near ``(s_a, s_b)``, solved on the cubics:
        ``(s_a, s_b, x, y)`` with ``C(s_a) = C(s_b)`` to rounding.

        The box search knows a crossing only to ``precision``, and where the two branches meet
        at a shallow angle ``theta`` that is ``precision / sin(theta)`` along each of them: cut
        there, the kept head can run past the crossing while the tail starts before it, and the
        two cross again in a loop shorter than ``min_loop_length`` that no later search sees.
        Newton's method solves ``G(a, b) = (C(b) - C(a)) / (b - a) = 0``: the divided
        difference has the crossings of ``C(a) = C(b)`` as its zeros but not the trivial ones
        ``a = b`` (there it is ``C'(a)``, never zero), so a tiny loop at a sharp knot (a
        reversal) converges to its crossing, not to the knot. With ``h = b - a`` and
        ``F = C(a) - C(b)`` the step solves ``[G - C'(a), C'(b) - G] d = F``; it is halved
        until ``|G|`` decreases. Where the branches pass within ``precision`` without crossing
        (the search counts that as a crossing) the answer is the closest approach found
        (the smallest ``|F|`` met) and the gap left is below ``precision``. Both ends stay
        within half the loop's length of where the search put them, so the solution is this
        crossing, not another one.
        """
        a0, b0 = float(s_a), float(s_b)
        window = 0.5 * (b0 - a0)
        total = self.total_length
        point = self._evaluator()
        a, b = a0, b0
        pa, pb = point(a), point(b)
        h = b - a
        err = math.hypot(pa[0] - pb[0], pa[1] - pb[1])
        g = err / h
        best = (err, a, b, pa, pb)  # the closest approach so far (|G| falls, |F| may not)
        scale = 4e-16 * (1.0 + abs(pa[0]) + abs(pa[1]))  # rounding of the positions
        for _ in range(60):
            if err <= scale:
                break
            xa, ya, dxa, dya = pa
            xb, yb, dxb, dyb = pb
            fx, fy = xa - xb, ya - yb
            gx, gy = -fx / h, -fy / h
            m11, m12, m21, m22 = gx - dxa, dxb - gx, gy - dya, dyb - gy
            det = m11 * m22 - m12 * m21
            c1, c2 = m11 * m11 + m21 * m21, m12 * m12 + m22 * m22
            if det * det > 1e-24 * c1 * c2:
                da = (fx * m22 - m12 * fy) / det
                db = (m11 * fy - m21 * fx) / det
            else:  # near-parallel branches: Levenberg-damped least squares
                mu = 1e-12 * (c1 + c2) + 1e-300
                r1, r2 = m11 * fx + m21 * fy, m12 * fx + m22 * fy
                c = m11 * m12 + m21 * m22
                dd = (c1 + mu) * (c2 + mu) - c * c
                da = ((c2 + mu) * r1 - c * r2) / dd
                db = ((c1 + mu) * r2 - c * r1) / dd
            t = 1.0
            for _ in range(40):  # backtracking: |G| must decrease
                na = min(max(a + t * da, a0 - window, 0.0), a0 + window)
                nb = min(max(b + t * db, b0 - window), b0 + window, total)
                nh = nb - na
                if nh > 0.0:
                    qa, qb = point(na), point(nb)
                    e = math.hypot(qa[0] - qb[0], qa[1] - qb[1])
                    if e / nh < g:
                        break
                t *= 0.5
            else:
                break
            a, b, h, pa, pb, err, g = na, nb, nh, qa, qb, e, e / nh
            if err < best[0]:
                best = (err, a, b, pa, pb)
        err, a, b, pa, pb = best
        return a, b, 0.5 * (pa[0] + pb[0]), 0.5 * (pa[1] + pb[1])

    def _locate(self, s: float) -> tuple[int, float]:
        # np.searchsorted(s0, s, side="right") - 1 and np.clip, on plain floats
        k = min(max(bisect.bisect_right(self._s0[: self.n_seg].tolist(), s) - 1, 0), self.n_seg - 1)
        return k, min(max(s - float(self._s0[k]), 0.0), float(self._len[k]))

    def _cut(self, c: Crossing) -> int:
        """Remove ``(s_a, s_b)``; returns the index of the segment holding what follows ``s_b``."""
        ka, ua = self._locate(c.s_a)
        kb, ub = self._locate(c.s_b)
        n = kb + 1  # the segments up to the one holding s_b (the polyline is sampled lazily)
        segments = (self._len[:n].copy(), self._ax[:n].copy(), self._ay[:n].copy())
        self.cuts.append(
            LoopCut(s_start=c.s_a, s_end=c.s_b, point=np.asarray(c.point), segments=segments)
        )
        tail = (
            cubic_shift(self._ax[kb], ub),
            cubic_shift(self._ay[kb], ub),
            float(self._len[kb] - ub),
        )
        head = (self._ax[ka].copy(), self._ay[ka].copy(), ua)
        self._truncate(ka)
        if head[2] > 1e-12:
            self._push_segment(*head)
        log.debug("loop cut: s in [%.4f, %.4f] (%.3f m)", c.s_a, c.s_b, c.s_b - c.s_a)
        return self._push_segment(*tail)


def find_crossings(
    spline: PathSpline, precision: float = 1e-4, min_loop_length: float = 1e-3
) -> list[Crossing]:
    """All self-intersections of a stored spline (no removal), via the box tree.

    Returns every refined box pair, so one crossing may appear a few times with ``s`` within
    ``precision`` of each other.
    """
    chain = LoopFreeChain(precision=precision, min_loop_length=min_loop_length)
    out: list[Crossing] = []
    for k in range(spline.n_segments):
        chain.append(spline.ax[k], spline.ay[k], spline.length[k], remove_loops=False)
        out.extend(chain.find_crossings(k))
    return out


def kept_intervals(cuts: Sequence[LoopCut], raw_length: float) -> NDArray[np.float64]:
    """``(K, 2)`` arc-length intervals ``[lo, hi]`` of the path before loop removal that the
    loop-free path is made of, in path order (their lengths add up to its length).

    A cut's ``s_start``, ``s_end`` refer to the chain as it was at that cut (the earlier cuts
    already removed); replaying the cuts in order maps each back to the path before removal.
    """
    kept: list[tuple[float, float]] = [(0.0, float(raw_length))]

    def to_raw(s: float) -> float:
        acc = 0.0
        for lo, hi in kept:
            if s <= acc + (hi - lo):
                return lo + max(s - acc, 0.0)
            acc += hi - lo
        return kept[-1][1] if kept else 0.0

    for c in cuts:
        ra, rb = to_raw(c.s_start), to_raw(c.s_end)
        out: list[tuple[float, float]] = []
        for lo, hi in kept:
            if hi <= ra or lo >= rb:
                out.append((lo, hi))
                continue
            if lo < ra:
                out.append((lo, ra))
            if hi > rb:
                out.append((rb, hi))
        kept = out
    return np.array(kept, dtype=np.float64).reshape(-1, 2)


def remove_loops(
    spline: PathSpline, precision: float = 1e-4, min_loop_length: float = 1e-3
) -> tuple[PathSpline, list[LoopCut]]:
    """Cut every loop out of a stored spline, segment by segment as the online recorder does."""
    chain = LoopFreeChain(precision=precision, min_loop_length=min_loop_length)
    for k in range(spline.n_segments):
        chain.append(spline.ax[k], spline.ay[k], spline.length[k])
    return chain.spline(tolerance=spline.tolerance, frame=spline.frame), chain.cuts
