"""Path memory (paper 4): worst and mean CPU time per point, this working tree against a git
revision's ``navkit.path``, interleaved in one process (issue 12: worst point <= 1 ms at every
tolerance on KITTI 00, TUM and MRCLAM).

The revision's ``src/navkit/path/*.py`` are written to a temporary folder as the package
``rev_navkit_path`` (its imports of ``navkit.path`` redirected there, so it runs its own compiled
kernels; Numba caches beside them) and both versions record every trajectory of
``benchmarks.bench_path`` at every tolerance, alternating run by run. A point's time is the
median over the runs of the thread-CPU clock around ``add`` (its own cost, not a moment the
scheduler took the CPU away). Python's garbage collector stays on; the time of the collections
that ran inside each ``add`` is recorded (``gc.callbacks``) and the worst point is also given
without it, so a collection that happens to land on a point is told apart from the point's work.
Both versions must give the same segments, loop cuts and accepted points (checked every run).

Run from the repository root::

    PYTHONPATH=src:. .venv/bin/python benchmarks/path_worst_vs_rev.py [--rev main] [--runs 5]
        [--only "KITTI 00 gt" ...]
"""

from __future__ import annotations

import argparse
import gc
import importlib
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

import navkit.path as tree
from benchmarks.bench_path import TOLERANCES, TRAJECTORIES, _load


def load_revision(rev: str) -> ModuleType:
    """The revision's ``navkit.path`` as the package ``rev_navkit_path`` (a temporary folder)."""
    folder = Path(tempfile.mkdtemp(prefix="navkit-path-rev-"))
    pkg = folder / "rev_navkit_path"
    pkg.mkdir()
    names = subprocess.run(
        ["git", "ls-tree", "--name-only", f"{rev}:src/navkit/path"],
        capture_output=True, text=True, check=True,
    ).stdout.split()  # fmt: skip
    for name in names:
        if name.endswith(".py"):
            text = subprocess.run(
                ["git", "show", f"{rev}:src/navkit/path/{name}"],
                capture_output=True, text=True, check=True,
            ).stdout  # fmt: skip
            text = text.replace("from navkit.path import", "from rev_navkit_path import")
            (pkg / name).write_text(text.replace("navkit.path.", "rev_navkit_path."))
    sys.path.insert(0, str(folder))
    return importlib.import_module("rev_navkit_path")


class _GcClock:
    """Thread-CPU seconds spent in garbage collections (``gc.callbacks``)."""

    def __init__(self) -> None:
        self.total = 0.0
        self._t0 = 0.0

    def __call__(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            self._t0 = time.thread_time()
        else:
            self.total += time.thread_time() - self._t0


def _record(mod: ModuleType, xy: np.ndarray, eps: float, clock: _GcClock) -> tuple[Any, ...]:
    a = mod.OnlineApproximator(mod.ApproximatorSettings(tolerance=eps))
    t = np.zeros(len(xy))
    g = np.zeros(len(xy))
    for i, p in enumerate(xy):
        g0 = clock.total
        c0 = time.thread_time()
        a.add(p)
        t[i] = time.thread_time() - c0
        g[i] = clock.total - g0
    r = a.finish()
    key = (
        len(a._raw), a._chain.n_seg, len(a._chain.cuts), r.n_cheap, r.n_refit_fallbacks,
        r.points.tobytes(),
    )  # fmt: skip
    n = a._chain.n_seg
    floats = np.concatenate(
        [a._chain._ax[:n].ravel(), a._chain._ay[:n].ravel(), a._chain._len[:n], r.point_s]
        + [np.r_[c.s_start, c.s_end, c.point] for c in a._chain.cuts]
    )
    return t, g, (key, floats)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rev", default="main")
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--only", nargs="*", help="trajectory names (default: all)")
    args = parser.parse_args()
    rev = load_revision(args.rev)
    clock = _GcClock()
    gc.callbacks.append(clock)
    print(
        f"{args.rev} -> this tree, CPU us per point (median of {args.runs} runs per point)\n"
        "trajectory | eps (m) | worst | mean | worst without gc | points > 1 ms | gc in the "
        "worst point | same segments, cuts, points (floats 1e-9)"
    )
    for name in args.only or list(TRAJECTORIES):
        xy = _load(TRAJECTORIES[name])
        for mod in (rev, tree):  # compile / load the kernels
            _record(mod, xy[:300], 0.05, clock)
        for eps in TOLERANCES:
            t: dict[str, list[np.ndarray]] = {"rev": [], "tree": []}
            g: dict[str, list[np.ndarray]] = {"rev": [], "tree": []}
            keys: list[tuple[Any, np.ndarray]] = []
            for _ in range(args.runs):
                for label, mod in (("rev", rev), ("tree", tree)):
                    tt, gg, key = _record(mod, xy, eps, clock)
                    t[label].append(tt)
                    g[label].append(gg)
                    keys.append(key)
            # the same segments, cuts and points; floats within 1e-9 relative (the tests' bound)
            same = all(k[0] == keys[0][0] for k in keys) and all(
                np.allclose(k[1], keys[0][1], rtol=1e-9, atol=1e-12) for k in keys
            )
            med = {k: np.median(v, axis=0) * 1e6 for k, v in t.items()}
            net = {k: np.median(np.subtract(t[k], g[k]), axis=0) * 1e6 for k in t}
            gcw = {k: float(np.median(np.asarray(g[k])[:, np.argmax(med[k])]) * 1e6) for k in t}
            print(
                f"{name} | {eps:g} | {med['rev'].max():.0f} -> **{med['tree'].max():.0f}** | "
                f"{med['rev'].mean():.0f} -> {med['tree'].mean():.0f} | "
                f"{net['rev'].max():.0f} -> {net['tree'].max():.0f} | "
                f"{int((med['rev'] > 1000).sum())} -> {int((med['tree'] > 1000).sum())} | "
                f"{gcw['rev']:.0f} -> {gcw['tree']:.0f} | {'yes' if same else 'NO'}",
                flush=True,
            )


if __name__ == "__main__":
    main()
