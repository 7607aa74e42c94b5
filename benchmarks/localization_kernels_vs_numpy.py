"""Localization (paper 3): the correlative matcher with the compiled scoring loop against the
same code with its NumPy oracle, on every CARMEN log of ``benchmarks.bench_localization``: the
fixes must be identical (integer score sums); CPU time per tracking fix (prior 0.5 m / 10 deg)
and per global fix (no prior), both modes interleaved in one process, medians.

Run from the repository root::

    PYTHONPATH=. .venv/bin/python benchmarks/localization_kernels_vs_numpy.py [--scans 30]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks.bench_localization import LOGS
from navkit import jit
from navkit.localization import build_map_from_scans, match_scan


def main() -> None:
    from navkit import datasets
    from navkit.io.carmen import read_carmen

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=30, help="tracking fixes per log")
    parser.add_argument("--global-scans", type=int, default=5, help="global fixes per log")
    args = parser.parse_args()
    print("log | identical | tracking ms NumPy -> compiled | global ms NumPy -> compiled")
    for name in LOGS:
        lg = read_carmen(datasets.find(f"laser2d/{name}-corrected.log.gz"))
        every = max(2, len(lg) // 1200)
        m = build_map_from_scans(lg.ranges[::every], lg.bearings, lg.poses[::every], max_range=30.0)
        fld = m.likelihood_field(0.1)
        rng = np.random.default_rng(0)
        idx = np.linspace(0, len(lg) - 1, args.scans).astype(int)
        prior = lg.poses[idx] + rng.uniform(-1, 1, (len(idx), 3)) * [0.5, 0.5, np.radians(10)]
        gidx = idx[:: max(1, len(idx) // args.global_scans)][: args.global_scans]
        cases = [(int(k), p, "track") for k, p in zip(idx, prior, strict=True)]
        cases += [(int(k), None, "global") for k in gidx]
        for compiled in (True, False):  # the per-map caches and the kernels' first call
            with jit.use("eager" if compiled else "numpy"):
                match_scan(fld, lg.points(int(idx[0]), 30.0), prior[0])
                match_scan(fld, lg.points(int(idx[0]), 30.0), None)
        t: dict[tuple[str, bool], list[float]] = {}
        same = True
        for k, p, kind in cases:
            pts = lg.points(k, 30.0)
            fixes = {}
            for compiled in (False, True):
                with jit.use("eager" if compiled else "numpy"):
                    c0 = time.process_time()
                    fixes[compiled] = match_scan(fld, pts, p)
                    t.setdefault((kind, compiled), []).append(time.process_time() - c0)
            a, b = fixes[True], fixes[False]
            same &= bool(np.array_equal(a.pose, b.pose) and a.score == b.score and a.ok == b.ok)
        med = {key: 1e3 * float(np.median(v)) for key, v in t.items()}
        print(
            f"{name} | {same} | {med['track', False]:.2f} -> {med['track', True]:.2f} | "
            f"{med['global', False]:.1f} -> {med['global', True]:.1f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
