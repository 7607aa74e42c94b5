"""Localization: how loose are the rotation groups' bounds of the global search, and what could a
tighter bound cut?

For global fixes on the CARMEN logs (the maps of ``benchmarks.bench_localization``, 20 scans spread
over each log) the coarse branch-and-bound runs on the NumPy oracle
(``navkit.jit.use("numpy")``: the same nodes as the compiled search) and every batch of rotation
-group nodes it expands is recorded with the pruning threshold of that moment. Per pyramid level
it prints:

- ``parents``: group nodes expanded (their bound was above the threshold), and the look-ups the
  compiled ``expand_sums`` spends on them (a group split into single rotations: one look-up per
  point and rotation for the rotation's bound on the parent's block, four per point for each
  rotation whose bound passes; otherwise four per point and sub-group);
- how many of those nodes each candidate bound would have pruned (bound <= threshold), all
  admissible (never below the best leaf under the node):

  - ``now``: the search's bound (``_Search._group_tables``);
  - ``ideal``: per point the exact maximum over the union of its blocks at the group's rotations
    (``sum_i max_r L_h(q_ri + t)``) - the tightest bound of one value per point;
  - ``split``: the best of the group's single rotations' level bounds (``max_r sum_i``), what
    splitting the group costs ``g`` look-ups per point for;
  - ``rect``: per point the exact bounding rectangle of its cells over the group, widened by the
    block (one look-up per point if a window of every width pair existed);
  - ``square``: the same as a square (``2^h + max(spread x, spread y)`` wide, at the cells'
    minimum corner): one look-up per point into a window of that exact width;
  - ``sq1.5``: that square rounded up to the stack's widths ``2^h, 1.5 x 2^h, 2^(h+1)``;
  - ``sq1.25``: rounded up to steps of a quarter of ``2^h``.

The prunable counts are of the recorded nodes only (pruning a node also saves its subtree, not
counted). Run from the repository root (``NAVKIT_DATA`` set; ~1-3 min per log and scan)::

    PYTHONPATH=.:src .venv/bin/python benchmarks/localization_group_bounds.py \
        [--logs acapulco freiburg-079] [--global-scans 2]
"""

from __future__ import annotations

import argparse

import numpy as np

from navkit import jit
from navkit.localization import build_map_from_scans
from navkit.localization import matcher as M


def _forward_max(a: np.ndarray, w: int, axis: int) -> np.ndarray:
    """``out[c] = max(a[c : c + w])`` along ``axis`` (zero beyond the end)."""
    out = a.copy()
    for j in range(1, w):
        if axis == 1:
            np.maximum(out[:, :-j], a[:, j:], out=out[:, :-j])
        else:
            np.maximum(out[:-j], a[j:], out=out[:-j])
    return out


def _round_up(w: np.ndarray, block: int, steps: list[float]) -> np.ndarray:
    """``w`` rounded up to the widths ``ceil(block x steps)`` (the last one if beyond)."""
    c = np.array(sorted({int(np.ceil(block * m)) for m in steps}))
    return c[np.minimum(np.searchsorted(c, w), len(c) - 1)]


def _record(fld, pts):  # type: ignore[no-untyped-def]
    """A global fix on the NumPy oracle; the group batches expanded by its coarse search."""
    rec = []
    orig = M._Search._expand

    def wrapped(self, h, k, ix, iy, exclude, threshold=-np.inf):  # type: ignore[no-untyped-def]
        if self.FG and np.isfinite(threshold) and self.a[h]:
            rec.append((self, h, k.copy(), ix.copy(), iy.copy(), threshold))
        return orig(self, h, k, ix, iy, exclude, threshold)

    M._Search._expand = wrapped  # type: ignore[method-assign]
    try:
        with jit.use("numpy"):
            M.match_scan(fld, pts, None)
    finally:
        M._Search._expand = orig  # type: ignore[method-assign]
    return rec


def analyse(rec) -> dict[int, dict[str, int]]:  # type: ignore[no-untyped-def]
    """Per level: parents, compiled look-ups, and the nodes each bound would prune."""
    s = rec[0][0]
    N, K, Wr = s.F.shape[1], len(s.thetas), s.Wp
    L0 = s.flat[0].reshape(-1, Wr).astype(np.int64)
    Fy, Fx = np.divmod(s.F.astype(np.int64), Wr)
    windows: dict[tuple[int, int], np.ndarray] = {}

    def window(wx: int, wy: int) -> np.ndarray:
        if (wx, wy) not in windows:
            windows[wx, wy] = _forward_max(_forward_max(L0, wx, 1), wy, 0).ravel()
        return windows[wx, wy]

    out: dict[int, dict[str, int]] = {}
    for h in sorted({r[1] for r in rec}, reverse=True):
        g, block = 2 ** s.a[h], 2**h
        sel = [r for r in rec if r[1] == h]
        k = np.concatenate([r[2] for r in sel])
        ix = np.concatenate([r[3] for r in sel])
        iy = np.concatenate([r[4] for r in sel])
        T = np.concatenate([np.full(len(r[2]), r[5] * 255.0 * N) for r in sel])
        shift = iy * Wr + ix
        now = s._sums_group(h, k, shift.astype(np.int32))
        kr = np.minimum(k[:, None] + np.arange(g)[None], K - 1)  # (P, g); a short last group
        V = s.flat[h][s.F[kr] + shift[:, None, None]].astype(np.int64)  # (P, g, N)
        cx, cy = Fx[kr], Fy[kr]
        mx, my = cx.min(axis=1), cy.min(axis=1)
        sx, sy = cx.max(axis=1) - mx, cy.max(axis=1) - my
        sq = np.maximum(sx, sy)

        at = (my + iy[:, None]) * Wr + mx + ix[:, None]  # the cells' minimum corners, (P, N)

        def windowed(WX: np.ndarray, WY: np.ndarray, at: np.ndarray = at) -> np.ndarray:
            tot = np.zeros(len(at), np.int64)
            for wx, wy in set(zip(WX.ravel().tolist(), WY.ravel().tolist(), strict=True)):
                m = (WX == wx) & (WY == wy)
                tot += np.where(m, window(wx, wy)[np.where(m, at, 0)], 0).sum(axis=1)
            return tot

        bounds = {
            "now": now,
            "ideal": V.max(axis=1).sum(axis=1),
            "split": V.sum(axis=2).max(axis=1),
            "rect": windowed(block + sx, block + sy),
            "square": windowed(block + sq, block + sq),
            "sq1.5": windowed(*2 * (_round_up(block + sq, block, [1, 1.5, 2, 3, 4]),)),
            "sq1.25": windowed(
                *2 * (_round_up(block + sq, block, [1, 1.25, 1.5, 1.75, 2, 2.5, 3, 4]),)
            ),
        }
        ideal = bounds["ideal"]
        for name, b in bounds.items():  # admissible: never below the exact per-point maxima
            assert name == "split" or np.all(b >= ideal), name
        split = 2 ** (s.a[h] - s.a[h - 1])
        if s.a[h - 1] == 0:  # single rotations: their bound on the parent's block first
            ks = k[:, None] + np.arange(split)[None]
            ok = ks < K
            up = s.flat[h][s.F[np.minimum(ks, K - 1)] + shift[:, None, None]].sum(axis=2)
            lookups = int(ok.sum()) * N + 4 * N * int(((up > T[:, None]) & ok).sum())
        else:
            lookups = len(k) * split * 4 * N
        row = {"parents": len(k), "lookups": lookups}
        row.update({name: int(np.sum(b <= T)) for name, b in bounds.items()})
        out[h] = row
    return out


def main() -> None:
    from navkit import datasets
    from navkit.io.carmen import read_carmen

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="*", default=["acapulco", "freiburg-079"])
    parser.add_argument("--global-scans", type=int, default=2)
    args = parser.parse_args()
    for name in args.logs:
        lg = read_carmen(datasets.find(f"laser2d/{name}-corrected.log.gz"))
        every = max(2, len(lg) // 1200)
        m = build_map_from_scans(lg.ranges[::every], lg.bearings, lg.poses[::every], max_range=30.0)
        fld = m.likelihood_field(0.1)
        idx = np.linspace(0, len(lg) - 1, 20).astype(int)  # 20 scans spread over the log
        gidx = idx[:: max(1, len(idx) // args.global_scans)][: args.global_scans]
        total: dict[int, dict[str, int]] = {}
        for k in gidx:
            for h, row in analyse(_record(fld, lg.points(int(k), 30.0))).items():
                t = total.setdefault(h, dict.fromkeys(row, 0))
                for key, v in row.items():
                    t[key] += v
        print(f"{name} ({len(gidx)} global fixes): level | parents | look-ups (M) | pruned by ...")
        for h in sorted(total, reverse=True):
            t = total[h]
            pr = " ".join(
                f"{key} {100.0 * t[key] / max(t['parents'], 1):.0f} %"
                for key in t
                if key not in ("parents", "lookups")
            )
            print(f"  h={h} | {t['parents']} | {t['lookups'] / 1e6:.2f} | {pr}", flush=True)


if __name__ == "__main__":
    main()
