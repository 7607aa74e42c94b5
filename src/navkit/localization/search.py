"""The branch-and-bound search of the correlative matcher (:mod:`navkit.localization.matcher`,
steps 2-4): per-rotation cell offsets of the scan, the max-pooled ``uint8`` pyramid of the
likelihood field, and the depth-first search over ``(rotation, x, y)`` nodes with an optimistic
first bound (Olson, ICRA 2009; Cartographer's "good initial score bound"). On the global search
the upper levels' nodes also cover blocks of rotations (``_Search._group_tables``).

The inner loops run in :mod:`navkit.localization._kernels` when the process runs the kernels
(:mod:`navkit.jit`), their NumPy twins otherwise: the same nodes, scores and fixes.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from navkit.errors import ConfigError
from navkit.jit import kernels_enabled
from navkit.localization.field import LikelihoodField, _pyramid

log = logging.getLogger(__name__)

_GLOBAL_TOP_BLOCKS = 8  # global search: top pyramid level ~ map / 8 per axis (see match_scan)
_REGION_BLOCK = 64  # cells; cached search regions are grown to multiples of this
_CACHE_ENTRIES = 2  # cached region pyramids per coarse field
_PAD_WINDOW = 64  # cells; windows up to this use the per-map padded pyramid (see _Search)
_ROT_GROUPS = 3  # global search: nodes cover up to 2^3 rotations (see _Search._group_tables)
_ROT_START = 3  # ... from this pyramid level up (2^(h-1) rotations at level h)
_ROT_LAG = 1
_GROUP_EXTRA_LEVELS = 2  # pyramid levels beyond the search's for the rotation groups' bounds
_NO_TABLE = np.zeros((0, 1), dtype=np.int32)  # expand_sums: no early bound of sub-groups


def _p95(x: NDArray[np.float64]) -> float:
    """``np.percentile(x, 95)`` of a non-empty 1-D float array without NaN, the same value: the
    linear method's virtual index ``(n - 1) * 0.95``, the two order statistics around it
    (``np.partition``) and NumPy's interpolation step by step (``a + (b - a) t``, or
    ``b - (b - a) (1 - t)`` from ``t = 0.5`` on) - without the generic quantile machinery
    (~70 us of a ~2 ms tracking fix)."""
    n = len(x)
    vi = (n - 1) * 0.95
    i0 = int(np.floor(vi))
    if vi >= n - 1:  # NumPy takes the last element for both
        return float(np.max(x))
    part = np.partition(x, (i0, i0 + 1))
    a, b = float(part[i0]), float(part[i0 + 1])
    t = vi - i0
    d = b - a
    return b - d * (1 - t) if t >= 0.5 else a + d * t


def _widen(level: NDArray[np.float32], s: int) -> NDArray[np.float32]:
    """Max over ``3 s``-wide blocks from a ``2 s``-wide max-pooled level (zero beyond)."""
    H, W = level.shape
    pad = np.zeros((H + s, W + s), dtype=level.dtype)
    pad[:H, :W] = level
    return np.maximum(
        np.maximum(pad[:H, :W], pad[s : s + H, :W]),
        np.maximum(pad[:H, s : s + W], pad[s : s + H, s : s + W]),
    )


def _rotate(theta: NDArray[np.float64], pts: NDArray[np.float64]) -> NDArray[np.float64]:
    """Points ``(N, 2)`` rotated by each angle ``(K,)``: ``(K, N, 2)`` (broadcast, no einsum)."""
    c, s = np.cos(theta)[:, None], np.sin(theta)[:, None]
    x, y = pts[None, :, 0], pts[None, :, 1]
    return np.stack([c * x - s * y, s * x + c * y], axis=-1)


@dataclass
class _BnBState:
    """Mutable state of one branch-and-bound: best exact score so far, its node, the budget."""

    lower: float
    best: tuple[float, int, int, int] | None
    budget: int
    seen: tuple[float, int, int, int] = (-np.inf, 0, 0, 0)  # best leaf visited, any score


def _better(score: float, key: tuple[int, int, int], than: tuple[float, int, int, int]) -> bool:
    """A leaf beats ``than`` (``(score, k, ix, iy)``): a higher score, or the same score and a
    lower ``(k, ix, iy)`` - the explicit tie-break that makes the search's answer the map's and
    the scan's, not the visiting order's (``_Search.run``)."""
    return score > than[0] or (score == than[0] and key < (than[1], than[2], than[3]))


def _argbest(cb: NDArray[np.float64], ck, cx, cy) -> int:  # type: ignore[no-untyped-def]
    """Index of the best leaf of a batch: the highest score, of those the lowest ``(k, ix, iy)``."""
    top = np.flatnonzero(cb == cb.max())
    if len(top) == 1:
        return int(top[0])
    return int(top[np.lexsort((cy[top], cx[top], ck[top]))[0]])


class _Search:
    """One branch-and-bound search over a rotation list and a square translation window.

    Translations are ``base + (ix, iy) * resolution`` with ``0 <= ix, iy < n_cells``. The
    pyramid is copied into zero-padded flat arrays large enough that every look-up of the search
    is in range, so a score is one gather: ``grid[F[k] + iy * W + ix]``.
    """

    batch = 2048  # nodes expanded per vectorised step of the depth-first search
    beam = 64  # width of the beam search that seeds the lower bound (see run)
    breadth = 4096  # nodes: levels are expanded whole while they stay this small (see run)
    optimism = 0.03  # the first pass assumes a leaf within this fraction of the top bound

    def __init__(
        self,
        fld: LikelihoodField,
        pts: NDArray[np.float64],
        thetas: NDArray[np.float64],
        base: NDArray[np.float64],
        n_cells: int,
        *,
        cache: list[tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.uint8]]] | None = None,
        levels: int | None = None,
        rot_groups: int = 0,
    ) -> None:
        # the kernels or their NumPy twins (navkit.jit), decided when the search is built
        self.compiled = kernels_enabled()
        self.f = fld
        self.thetas = thetas
        self.base = base
        self.n = n_cells
        H, W = fld.shape
        levels = len(fld.pyramid) if levels is None else levels
        self.evaluated = 0
        # leaves collected by run(keep < 1): chunks of (score, k, ix, iy)
        self.leaves: list[
            tuple[NDArray[np.float64], NDArray[np.intp], NDArray[np.intp], NDArray[np.intp]]
        ] = []
        # Rotation groups (see _group_tables): a node of level h covers 2^a[h] consecutive
        # rotations; a = 0 everywhere is the plain search (one rotation per node).
        self.a = [0] * levels
        self.FG: dict[int, NDArray[np.integer]] = {}
        if cache is None and n_cells <= _PAD_WINDOW and levels <= len(fld.pyramid):
            self._padded_window(pts, levels)
            return
        cx, cy, ext = self._cells(thetas, pts)  # (K, N) each, [min x, min y, max x, max y]
        grouped = rot_groups > 0 and cache is not None and len(thetas) > 1 and levels > 1
        extra = _GROUP_EXTRA_LEVELS if grouped else 0
        if grouped:
            dth = float(thetas[1] - thetas[0])
            res = fld.resolution
            rmax = float(np.max(np.linalg.norm(pts, axis=1)))

            def dil(a: int) -> int:  # cells a point at rmax moves within a group of 2^a steps
                return int(np.ceil(rmax * (2**a - 1) / 2 * abs(dth) / res))

            top = levels + extra - 1  # the coarsest pyramid level built
            a_top = min(levels - 2, rot_groups)
            while a_top > 0 and 2 ** (levels - 1) + 2 * dil(a_top) > 2**top:
                a_top -= 1
            self.a[levels - 1] = a_top
            for h in range(levels - 2, -1, -1):
                self.a[h] = min(h - _ROT_LAG, self.a[h + 1]) if h >= _ROT_START else 0
            dmax = dil(self.a[levels - 1])
        # The region of cells any look-up of this search can touch: [lo, hi) per axis. The
        # pyramid is pooled on this region (zeros outside the map), so a block that starts
        # outside the map but reaches into it keeps its true maximum; the look-up is then one
        # gather, grid[F[k] + iy * Wr + ix].
        lo = ext[:2].copy()
        hi = ext[2:] + n_cells
        if grouped:  # a group's look-ups reach dmax cells beyond its rotations' cells
            lo, hi = lo - dmax, hi + dmax
        flat = None
        n_stack = 2 * (levels + extra) - 2 if grouped else levels
        if cache is not None:
            # A region that a cached pyramid covers is reused (global searches of one map);
            # otherwise the region is grown to multiples of _REGION_BLOCK cells so that the
            # next scans (similar reach) hit the cache. Zero padding beyond the map changes no
            # look-up value, so the scores are those of the tight region.
            for c_lo, c_hi, c_flat in cache:
                if len(c_flat) == n_stack and np.all(c_lo <= lo) and np.all(hi <= c_hi):
                    lo, hi, flat = c_lo, c_hi, c_flat
                    break
            else:
                # a miss: the new region also covers the latest cached one (of this stack), so
                # the cache converges to one region that serves every scan of the map instead
                # of rebuilding for scans that reach a little farther in another direction
                for c_lo, c_hi, c_flat in cache:
                    if len(c_flat) == n_stack:
                        lo, hi = np.minimum(lo, c_lo), np.maximum(hi, c_hi)
                        break
                lo = np.floor_divide(lo, _REGION_BLOCK) * _REGION_BLOCK
                hi = -np.floor_divide(-hi, _REGION_BLOCK) * _REGION_BLOCK
        Wr, Hr = int(hi[0] - lo[0]), int(hi[1] - lo[1])
        if Wr * Hr > 60_000_000:
            raise ConfigError(
                f"the search spans {Hr} x {Wr} cells",
                field="linear_window",
                expected="a smaller search window, a coarser map or shorter ranges",
            )
        if flat is None:
            region = np.zeros((Hr, Wr), dtype=np.float32)
            x0, y0 = max(0, int(lo[0])), max(0, int(lo[1]))
            x1, y1 = min(W, int(hi[0])), min(H, int(hi[1]))
            if x1 > x0 and y1 > y0:
                region[y0 - lo[1] : y1 - lo[1], x0 - lo[0] : x1 - lo[0]] = fld.values[y0:y1, x0:x1]
            # uint8 copies of the pooled levels (rounded up, so level bounds stay upper bounds).
            pyr = _pyramid(region, levels + extra)
            if grouped:  # + the 1.5 x 2^h windows of the rotation groups (_group_tables)
                pyr += [_widen(pyr[h], 2 ** (h - 1)) for h in range(1, levels + extra - 1)]
            flat = np.stack([np.ceil(g * 255.0).astype(np.uint8).ravel() for g in pyr])
            if cache is not None:
                cache.insert(0, (lo, hi, flat))
                del cache[_CACHE_ENTRIES:]
        self.Wp = Wr
        zero = np.zeros(len(pts), dtype=np.int64)
        self.F = self._table(cx, cy, zero, zero, lo, np.int32)  # (K, N)
        self.flat = flat
        if grouped:
            self._group_tables(pts, lo, dth, levels)

    def _cells(
        self, thetas: NDArray[np.float64], pts: NDArray[np.float64]
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64]]:
        """Cells x, y ``(K, N)`` of the points rotated by ``thetas`` and moved to the window's
        base, and their extremes ``[min x, min y, max x, max y]``; compiled:
        :func:`navkit.localization._kernels.rotated_cells` (the same cells)."""
        f = self.f
        if self.compiled:
            from navkit.localization import _kernels

            return _kernels.rotated_cells(  # type: ignore[no-any-return]
                np.cos(thetas), np.sin(thetas), np.ascontiguousarray(pts),
                float(self.base[0]), float(self.base[1]), float(f.origin[0]),
                float(f.origin[1]), float(f.resolution),
            )  # fmt: skip
        off = np.floor((_rotate(thetas, pts) + self.base - f.origin) / f.resolution)
        cx, cy = off[..., 0].astype(np.int64), off[..., 1].astype(np.int64)
        return cx, cy, np.array([cx.min(), cy.min(), cx.max(), cy.max()], dtype=np.int64)

    def _table(  # type: ignore[no-untyped-def]
        self,
        cx: NDArray[np.int64],
        cy: NDArray[np.int64],
        d: NDArray[np.int64],
        add: NDArray[np.int64],
        lo: NDArray[np.int64],
        dtype,
    ) -> NDArray[np.integer]:
        """Flat look-up table ``add + (cy - d - lo_y) Wp + (cx - d - lo_x)`` (``d``, ``add``
        per point) in ``dtype``; compiled: :func:`navkit.localization._kernels.flat_table`."""
        if self.compiled:
            from navkit.localization import _kernels

            out = np.empty(cx.shape, dtype=dtype)
            _kernels.flat_table(cx, cy, d, add, int(lo[0]), int(lo[1]), int(self.Wp), out)
            return out
        return (add + (cy - d - lo[1]) * self.Wp + (cx - d - lo[0])).astype(dtype)

    def _padded_window(self, pts: NDArray[np.float64], levels: int) -> None:
        """The look-up table of a window searched around a prior (tracking, the global fine
        stage, the peak analysis) on the per-map padded pyramid, built once
        (:meth:`LikelihoodField.padded_pyramid_u8`), instead of a pyramid of this search's
        region per fix.

        A point whose look-ups over the window would leave the padded grid on some axis sees
        only zeros there (with this pad: beyond the grid, or more than ``2^(lv-1)`` cells
        before it, where no block reaches the grid): it is sent to the padded corner, an
        all-zero ``n x n`` block at every level. Compiled: one loop
        (:func:`navkit.localization._kernels.window_offsets`, the same table exactly).
        """
        fld, n_cells = self.f, self.n
        H, W = fld.shape
        lv = len(fld.pyramid)
        pad = _PAD_WINDOW + 2 ** (lv - 1)
        flat_all, Wp = fld.padded_pyramid_u8(lv, pad)
        lim = np.array([W, H]) + pad - n_cells
        self.Wp = Wp
        self.flat = flat_all[:levels]
        if self.compiled:
            from navkit.localization import _kernels

            self.F = _kernels.window_offsets(
                np.cos(self.thetas), np.sin(self.thetas), np.ascontiguousarray(pts),
                float(self.base[0]), float(self.base[1]), float(fld.origin[0]),
                float(fld.origin[1]), float(fld.resolution), pad, Wp, int(lim[0]), int(lim[1]),
            )  # fmt: skip
            return
        off = np.floor((_rotate(self.thetas, pts) + self.base - fld.origin) / fld.resolution)
        inside = np.all((off >= -pad) & (off <= lim), axis=-1)  # (K, N)
        F = (off[..., 1].astype(np.int64) + pad) * Wp + off[..., 0].astype(np.int64) + pad
        self.F = np.where(inside, F, 0).astype(np.int32)

    def _group_tables(
        self, pts: NDArray[np.float64], lo: NDArray[np.int64], dth: float, levels: int
    ) -> None:
        """Look-up tables of the rotation groups: an exact bound over a block of rotations.

        A node of level ``h`` covers translations ``[ix, ix + 2^h) x [iy, iy + 2^h)`` and the
        rotations ``[k, k + g)``, ``g = 2^a[h]``. Rotated by the group's central angle, point
        ``i`` is at most ``|p_i| (g - 1) / 2 dtheta`` (the arc) from its place at any rotation
        of the group, so its cell at any of them is within ``d_i = ceil(that / resolution)``
        cells per axis. The maximum of the field over the ``(2^h + 2 d_i)``-wide window from
        ``(q_i - d_i)`` bounds its value at every leaf of the node; the max-pooled level
        ``l_i = ceil(log2(2^h + 2 d_i))`` at that corner covers the window (forward blocks).
        So ``FG[h][group, i]`` indexes level ``l_i`` of the flattened pyramid, and a node's
        bound is one gather, as for a single rotation. Exact: the bound is an upper bound of
        every leaf below (the leaves themselves are single rotations, ``a[0] = 0``).
        """
        res = self.f.resolution
        K = len(self.thetas)
        radius = np.linalg.norm(pts, axis=1)
        cells = self.flat.shape[1]
        # the windows on the stack: level h of the pyramid (2^h wide) at index h, and
        # 1.5 x 2^h (_widen) at index nP + h - 1
        nP = (len(self.flat) + 2) // 2
        widths_all = np.array(
            [2.0**h for h in range(nP)] + [1.5 * 2.0**h for h in range(1, nP - 1)]
        )
        order = np.argsort(widths_all, kind="stable")
        widths, which = widths_all[order], order
        self.flat_all = self.flat.reshape(-1)
        dtype = np.int32 if self.flat.size < 2**31 - 1 else np.int64
        for h in range(1, levels):
            g = 2 ** self.a[h]
            if g == 1:
                continue
            k0 = np.arange(0, K, g)
            centre = self.thetas[0] + (k0 + (g - 1) / 2) * dth
            qx, qy, _ = self._cells(centre, pts)  # (G, N) each
            d = np.ceil(radius * (g - 1) / 2 * abs(dth) / res).astype(np.int64)  # (N,)
            j = np.searchsorted(widths, 2**h + 2 * d)  # the narrowest window that covers
            assert j.max() < len(widths)
            lvl = which[j]
            self.FG[h] = self._table(qx, qy, d, (lvl * cells).astype(np.int64), lo, dtype)

    def scores(
        self, level: int, k: NDArray[np.intp], ix: NDArray[np.intp], iy: NDArray[np.intp]
    ) -> NDArray[np.float64]:
        """Mean level-``level`` values of the scan at rotations ``k`` and translations ``(ix, iy)``."""
        self.evaluated += len(k)
        # int32 flat indices (a grid is < 60 M cells): half the index traffic of int64
        shift = (iy.astype(np.int64) * self.Wp + ix).astype(np.int32)
        if self.a[level]:
            return self._sums_group(level, k, shift) / (255.0 * self.F.shape[1])
        return self._sums(level, k, shift) / (255.0 * self.F.shape[1])

    def _sums_group(
        self, level: int, k: NDArray[np.intp], shift: NDArray[np.int32]
    ) -> NDArray[np.int64]:
        """As ``_sums`` for nodes covering a rotation group (``FG``, see _group_tables)."""
        FG = self.FG[level]
        g = k >> self.a[level]
        if self.compiled:  # the same integer sums without the (candidates x points) index array
            from navkit.localization import _kernels

            return _kernels.gather_sums(self.flat_all, FG, g, shift)  # type: ignore[no-any-return]
        out = np.empty(len(k), dtype=np.int64)
        step = max(1, 4_000_000 // max(FG.shape[1], 1))
        for c in range(0, len(k), step):
            d = min(len(k), c + step)
            idx = FG[g[c:d]]
            idx += shift[c:d, None]
            out[c:d] = np.take(self.flat_all, idx).sum(axis=1, dtype=np.uint32)
        return out

    def _sums(self, level: int, k: NDArray[np.intp], shift: NDArray[np.int32]) -> NDArray[np.int64]:
        """``sum_i L_level[F[k_c, i] + shift_c]`` per candidate ``c`` (uint8 units), NumPy."""
        grid = self.flat[level]
        if self.compiled:  # the same integer sums without the (candidates x points) index array
            from navkit.localization import _kernels

            return _kernels.gather_sums(grid, self.F, k, shift)  # type: ignore[no-any-return]
        out = np.empty(len(k), dtype=np.int64)
        N = self.F.shape[1]
        step = max(1, 4_000_000 // max(N, 1))
        for c in range(0, len(k), step):
            d = min(len(k), c + step)
            # one gather over all candidates of the chunk: score[c] = sum_i L[F[k_c, i] + shift_c]
            idx = self.F[k[c:d]]
            idx += shift[c:d, None]
            out[c:d] = np.take(grid, idx).sum(axis=1, dtype=np.uint32)
        return out

    def pose(self, k: int, ix: int, iy: int) -> NDArray[np.float64]:
        r = self.f.resolution
        return np.array([self.base[0] + ix * r, self.base[1] + iy * r, float(self.thetas[k])])

    def _children(self, h: int, k: NDArray[np.intp], ix: NDArray[np.intp], iy: NDArray[np.intp]):  # type: ignore[no-untyped-def]
        s = 2 ** (h - 1)
        if self.a[h] > self.a[h - 1]:  # the rotation group splits as well
            split = 2 ** (self.a[h] - self.a[h - 1])
            k = (k[:, None] + np.arange(split) * 2 ** self.a[h - 1]).ravel()
            ix, iy = np.repeat(ix, split), np.repeat(iy, split)
            ok = k < len(self.thetas)
            k, ix, iy = k[ok], ix[ok], iy[ok]
        k4 = np.repeat(k, 4)
        ix4 = (ix[:, None] + np.array([0, s, 0, s])).ravel()
        iy4 = (iy[:, None] + np.array([0, 0, s, s])).ravel()
        ok = (ix4 < self.n) & (iy4 < self.n)
        if ok.all():
            return k4, ix4, iy4
        return k4[ok], ix4[ok], iy4[ok]

    def _expand(  # type: ignore[no-untyped-def]
        self,
        h: int,
        k: NDArray[np.intp],
        ix: NDArray[np.intp],
        iy: NDArray[np.intp],
        exclude,
        threshold: float = -np.inf,
    ):
        """Children ``(k, ix, iy)`` of level-``h`` nodes (those ``exclude`` leaves) and their
        level ``h - 1`` scores. Compiled (without ``exclude``): one pass
        (:func:`navkit.localization._kernels.expand_sums`, the same children in the same order
        and the same integer sums), which may leave out children whose score cannot be above
        ``threshold`` (the caller drops those: the search is the same; fewer nodes are counted
        in ``evaluated``); otherwise ``_children``, ``_drop``, ``scores``."""
        if not self.compiled or exclude is not None:
            ck, cx, cy = self._drop(h - 1, self._children(h, k, ix, iy), exclude)
            return ck, cx, cy, self.scores(h - 1, ck, cx, cy)
        from navkit.localization import _kernels

        lv = h - 1
        a = self.a[lv]
        grid, table = (self.flat_all, self.FG[lv]) if a else (self.flat[lv], self.F)
        split = 2 ** (self.a[h] - a)
        # single rotations split from a group are bounded on the parent's level first (see
        # expand_sums); for a split into smaller groups that bound was measured not to pay
        # (Acapulco: 6 % fewer nodes for the extra pass), so none
        grid_up, table_up = (self.flat_all, _NO_TABLE) if a else (self.flat[h], self.F)
        ck, cx, cy, sums = _kernels.expand_sums(
            grid, table, a, k, ix, iy, 2 ** (h - 1), split, 2**a, len(self.thetas), self.n,
            self.Wp, grid_up, table_up, float(threshold),
        )  # fmt: skip
        self.evaluated += len(ck)
        return ck, cx, cy, sums / (255.0 * self.F.shape[1])

    def _depth_first(  # type: ignore[no-untyped-def]
        self, h: int, k, ix, iy, bound, keep: float, state: _BnBState
    ) -> None:
        """``run``'s ``descend`` from level ``h`` as one compiled loop
        (:func:`navkit.localization._kernels.depth_first`: the same nodes in the same order,
        the same best leaf, the same collected leaves in the same order); updates ``state``,
        ``self.leaves`` and ``self.evaluated``."""
        from navkit.localization import _kernels

        levels = len(self.a)
        K, N = self.F.shape
        tables, start = [self.F], np.zeros(levels, np.int64)
        stop = np.empty(levels, np.int64)
        stop[:] = K
        rows = K
        for lv in range(levels):
            if self.a[lv]:
                t = self.FG[lv]
                start[lv], stop[lv] = rows, rows + len(t)
                rows += len(t)
                tables.append(t)
        table = tables[0] if len(tables) == 1 else np.concatenate(tables)
        # int32 tables: a region is < 60 M cells, its stack < 2^31 cells (see _group_tables)
        assert table.dtype == np.int32
        best = np.array(state.best if state.best is not None else (-np.inf, 0, 0, 0), float)
        seen = np.array(state.seen, dtype=np.float64)
        lower, budget, ev, ls, lk, lx, ly = _kernels.depth_first(
            self.flat.reshape(-1), self.flat.shape[1], table, start, stop,
            np.array(self.a, dtype=np.int64), len(self.thetas), self.n, self.Wp, h,
            k.astype(np.int64), ix.astype(np.int64), iy.astype(np.int64), bound, keep,
            float(state.lower), best, seen, int(state.budget), self.batch, 255.0 * N,
        )  # fmt: skip
        state.lower, state.budget = float(lower), int(budget)
        self.evaluated += int(ev)
        if np.isfinite(best[0]):
            state.best = (float(best[0]), int(best[1]), int(best[2]), int(best[3]))
        state.seen = (float(seen[0]), int(seen[1]), int(seen[2]), int(seen[3]))
        if keep < 1.0:
            self.leaves = [(ls, lk, lx, ly)]

    def _order(self, bound: NDArray[np.float64]) -> NDArray[np.intp]:
        """``np.argsort(-bound, kind="stable")``; compiled, for large batches: the same
        permutation by a counting sort on the integer sums
        (:func:`navkit.localization._kernels.order_desc`)."""
        if self.compiled and len(bound) >= 512:
            from navkit.localization import _kernels

            order = _kernels.order_desc(bound, 255.0 * self.F.shape[1])
            if len(order) == len(bound):
                return order  # type: ignore[no-any-return]
        return np.argsort(-bound, kind="stable")

    def _drop(self, level: int, nodes, exclude):  # type: ignore[no-untyped-def]
        """The nodes ``(k, ix, iy)`` of ``level`` that ``exclude`` does not remove whole."""
        k, ix, iy = nodes
        if exclude is None or not len(k):
            return k, ix, iy
        if self.a[level]:  # a rotation group: never dropped whole (allowed: errs towards keep)
            return k, ix, iy
        keep = ~exclude(k, ix, iy, 2**level)
        return k[keep], ix[keep], iy[keep]

    def run(  # type: ignore[no-untyped-def]
        self, levels: int, lower: float, cap: int, exclude=None, seeds: int = 8, keep: float = 1.0
    ):
        """Best leaf ``(score, k, ix, iy)`` with score > ``lower`` (or None) and an exactness flag.

        ``exclude(k, ix, iy, size) -> bool mask``: the nodes (``size x size`` translations from
        ``(ix, iy)`` at rotation ``k``) whose every leaf is excluded; they are dropped unscored
        (the runner-up search: the winner's neighbourhood). It must be exact for ``size = 1``
        and may only err towards False for blocks.
        ``keep < 1``: nodes are pruned only when their bound is ``<= keep * best``, and every leaf
        scoring above that is collected in ``self.leaves`` (arrays ``score, k, ix, iy``): all
        leaves within ``keep`` of the optimum, so a runner-up search needs no second pass.

        Stages: the top levels expanded whole while small (``breadth``), a beam search from
        there (``beam`` nodes per level) for a first bound, then the depth-first search, first
        from an optimistic bound (``optimism``; exact, see the comment there). ``seeds`` is
        no longer used (the beam replaced the greedy descents).

        Of leaves with the same (integer) score the lowest ``(k, ix, iy)`` is the answer
        (``_better``; the kernel's ``_before``): with ``keep < 1`` every leaf of the best score is
        visited, so the answer does not depend on the visiting order (a reordered search returns
        the same leaf); with ``keep = 1`` a tie in a pruned branch is not seen.
        """
        self.leaves = []
        L = levels - 1
        step = 2**L
        g = np.arange(0, self.n, step)
        # the (rotation, x, y) grid of the top level, rotation slowest and y fastest (meshgrid
        # "ij" raveled: the same arrays without its broadcasting machinery)
        kr = np.arange(0, len(self.thetas), 2 ** self.a[L])
        k = np.repeat(kr, len(g) * len(g))
        ix = np.tile(np.repeat(g, len(g)), len(kr))
        iy = np.tile(g, len(kr) * len(g))
        bound = self.scores(L, k, ix, iy)
        best: tuple[float, int, int, int] | None = None
        if L == 0:
            if exclude is not None:
                bound[exclude(k, ix, iy, 1)] = -1.0
            j = int(np.argmax(bound))
            m0 = bound > keep * max(lower, float(bound[j]))
            self.leaves.append((bound[m0], k[m0], ix[m0], iy[m0]))
            return (
                (float(bound[j]), int(k[j]), int(ix[j]), int(iy[j])) if bound[j] > lower else best
            ), True
        # Breadth-first while the levels are small: the top levels' bounds are saturated on a
        # global search (a 64-cell block holds a wall for nearly every point), so their order
        # says little; a level of a few 10^4 nodes is where the bounds start to rank.
        h = L
        while h > 1 and 4 * len(k) <= self.breadth:
            k, ix, iy, bound = self._expand(h, k, ix, iy, exclude, keep * lower)
            h -= 1
            live = bound > keep * lower
            k, ix, iy, bound = k[live], ix[live], iy[live], bound[live]
        # Seed the lower bound by a beam search from that level: the `beam` best nodes of each
        # level are expanded, down to the leaves (a beam can switch branches, greedy descents
        # cannot). The sooner the bound is the optimum, the fewer nodes the exact search below
        # expands.
        top = np.argsort(-bound, kind="stable")[: self.beam]
        sk, sx, sy = k[top], ix[top], iy[top]
        for hh in range(h, 0, -1):
            ck, cx, cy, cb = self._expand(hh, sk, sx, sy, exclude)
            if not len(ck):
                break
            if hh == 1:
                j = _argbest(cb, ck, cx, cy)
                if cb[j] > lower:
                    lower = float(cb[j])
                    best = (lower, int(ck[j]), int(cx[j]), int(cy[j]))
            else:
                top = np.argsort(-cb, kind="stable")[: self.beam]
                sk, sx, sy = ck[top], cx[top], cy[top]
        # Depth-first branch-and-bound in batches (Cartographer's order, vectorised): nodes of a
        # level sorted by bound, expanded a batch at a time down to the leaves, so good leaves
        # raise the lower bound early and prune the rest.
        state = _BnBState(lower, best, cap)

        def descend(
            h: int,
            k: NDArray[np.intp],
            ix: NDArray[np.intp],
            iy: NDArray[np.intp],
            bound: NDArray[np.float64],
        ) -> None:
            order = self._order(bound)
            k, ix, iy, bound = k[order], ix[order], iy[order], bound[order]
            for a in range(0, len(k), self.batch):
                if bound[a] <= keep * state.lower or state.budget <= 0:
                    return
                sl = slice(a, a + self.batch)
                live = bound[sl] > keep * state.lower
                ck, cx, cy, cb = self._expand(
                    h, k[sl][live], ix[sl][live], iy[sl][live], exclude, keep * state.lower
                )
                state.budget -= len(ck)
                if h == 1:
                    if len(cb):
                        j = _argbest(cb, ck, cx, cy)
                        key = (int(ck[j]), int(cx[j]), int(cy[j]))
                        if _better(float(cb[j]), key, state.seen):
                            state.seen = (float(cb[j]), *key)
                        if cb[j] > state.lower or (
                            state.best is not None and _better(float(cb[j]), key, state.best)
                        ):
                            state.lower = float(cb[j])
                            state.best = (float(cb[j]), *key)
                        if keep < 1.0:
                            m = cb > keep * state.lower
                            self.leaves.append((cb[m], ck[m], cx[m], cy[m]))
                else:
                    m = cb > keep * state.lower
                    if m.any():
                        descend(h - 1, ck[m], cx[m], cy[m], cb[m])

        def search(start: float, start_best: tuple[float, int, int, int] | None) -> None:
            state.lower, state.best = start, start_best
            self.leaves = []
            live = bound > keep * start
            if self.compiled and exclude is None:
                self._depth_first(h, k[live], ix[live], iy[live], bound[live], keep, state)
            else:
                descend(h, k[live], ix[live], iy[live], bound[live])

        # An optimistic start: the bounds of the frontier cap the optimum, and a global fix's
        # optimum is usually within a few % of that cap (coarse scores of 0.96-1.0 on the real
        # logs). Searching as if a leaf of score tau = (1 - optimism) x cap were known prunes
        # from the start what a bound found late would prune only after the waste (up to 7x
        # fewer nodes on the Acapulco log). Still exact: every node pruned has a bound
        # <= keep x tau, so every leaf above keep x tau is visited; if one beats tau the
        # search is complete, if the best visited leaf b lies in (keep x tau, tau] it is the
        # optimum and a second pass from b collects the leaves in (keep x b, keep x tau];
        # if none is above keep x tau the plain search runs from the beam's bound.
        tau = (1.0 - self.optimism) * float(bound.max()) if len(bound) else lower
        if tau > lower:
            search(tau, None)
            if state.best is not None:
                return state.best, bool(state.budget > 0)
            if state.budget <= 0:  # out of budget: the beam's leaf is the best known
                return best, False
            found = [a[0] for a in self.leaves if len(a[0])]
            b = float(max(np.max(a) for a in found)) if found else -1.0
            if b > max(keep * tau, lower):
                # b is the optimum: search again from just under it (the leaf is found again)
                search(np.nextafter(b, -np.inf), None)
                return state.best, bool(state.budget > 0)
            if state.seen[0] > lower:
                # the best leaf the pass visited (an exact score) is a better start than the
                # beam's
                lower, best = state.seen[0], state.seen
        search(lower, best)
        return state.best, bool(state.budget > 0)


#: Most headings one search may try: a circle at the angular step of a scan reaching 800 m on a
#: 5 cm field (1e5), far beyond any indoor or outdoor scan matched here; more is a scan whose
#: ranges are corrupt (or a field too fine for them), refused before the search allocates.
