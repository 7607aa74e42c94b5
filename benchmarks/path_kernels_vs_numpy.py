"""Path memory (paper 4): worst and mean CPU time per point with the compiled kernels against
the same code with their NumPy oracles, interleaved in one process.

For every recorded trajectory of ``benchmarks.bench_path`` and every tolerance, the approximator
runs ``--runs`` times in each mode, alternating; each point's time is the median over the runs
of the approximator's own thread-CPU clock around ``add`` (so a point's figure is its own cost,
not a moment the scheduler took the CPU away). Target: worst point <= 1 ms at every tolerance on
KITTI 00, TUM and MRCLAM.

Run from the repository root::

    PYTHONPATH=. .venv/bin/python benchmarks/path_kernels_vs_numpy.py [--runs 3] [--quick]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks.bench_path import TOLERANCES, TRAJECTORIES, _load
from navkit.path import ApproximatorSettings, OnlineApproximator


def _per_point(xy: np.ndarray, eps: float, compiled: bool) -> np.ndarray:
    a = OnlineApproximator(ApproximatorSettings(tolerance=eps))
    a.compiled = a._chain.compiled = compiled
    t = np.zeros(len(xy))
    for i, p in enumerate(xy):
        c0 = time.thread_time()
        a.update(p)
        t[i] = time.thread_time() - c0
    return t


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="KITTI 00 gt and TUM fr1_xyz only")
    parser.add_argument("--only", nargs="*", help="trajectory names (default: all)")
    args = parser.parse_args()
    names = ["KITTI 00 gt", "TUM fr1_xyz gt"] if args.quick else list(TRAJECTORIES)
    if args.only:
        names = args.only
    print("trajectory | eps (m) | worst us NumPy -> compiled | mean us NumPy -> compiled")
    for name in names:
        xy = _load(TRAJECTORIES[name])
        _per_point(xy[:300], 0.05, True)  # compile / load the kernels
        for eps in TOLERANCES:
            runs: dict[bool, list[np.ndarray]] = {True: [], False: []}
            for _ in range(args.runs):
                for compiled in (False, True):
                    runs[compiled].append(_per_point(xy, eps, compiled))
            pp = {k: np.median(v, axis=0) * 1e6 for k, v in runs.items()}
            print(
                f"{name} | {eps:g} | {pp[False].max():.0f} -> {pp[True].max():.0f} | "
                f"{pp[False].mean():.0f} -> {pp[True].mean():.0f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
