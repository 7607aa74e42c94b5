"""Organised plane extraction, per compiled kernel: this working tree against a git revision's.

The revision's extraction and kernels are loaded beside the working tree's as in
``benchmarks/planes_extract_vs_rev.py``; every kernel of both versions is wrapped by a CPU-time
counter and the two extractions run alternately over the chosen frames (``--rounds`` times), so
that both see the same machine load. Prints the median CPU ms per frame of each version and
each kernel's share (mean ms per frame). The wrappers add a few microseconds per call.

Run from the repository root::

    PYTHONPATH=.:src python benchmarks/planes_kernels_vs_rev.py [--rev HEAD] [--rounds 20]
        [--frames benchmark|7scenes|cape]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from collections.abc import Callable
from types import ModuleType

import numpy as np

from benchmarks.planes_extract_vs_rev import _frames, _load_revision
from navkit.planes import extract_planes_organized


def _wrap(module: ModuleType, acc: dict[str, float]) -> None:
    """Replace every public compiled kernel of ``module`` by a wrapper adding its CPU time to
    ``acc[name]``."""
    for name in dir(module):
        kernel = getattr(module, name)
        if name.startswith("_") or not hasattr(kernel, "py_func"):
            continue

        def timed(*args: object, _k: Callable[..., object] = kernel, _n: str = name) -> object:
            t0 = time.process_time()
            out = _k(*args)
            acc[_n] += time.process_time() - t0
            return out

        setattr(module, name, timed)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rev", default="HEAD", help="git revision to compare with")
    parser.add_argument("--rounds", type=int, default=20)
    parser.add_argument("--frames", choices=("benchmark", "7scenes", "cape"), default="benchmark")
    args = parser.parse_args()
    before = _load_revision(args.rev)
    from navkit.planes import _kernels

    grids = [P for _, P in _frames(args.frames)]
    for P in grids:  # compile / load both versions' kernels before timing
        extract_planes_organized(P)
        before.extract_planes_organized(P)
    acc: dict[str, dict[str, float]] = {"now": defaultdict(float), "rev": defaultdict(float)}
    _wrap(_kernels, acc["now"])
    _wrap(sys.modules["rev_kernels"], acc["rev"])
    runs = {"now": extract_planes_organized, "rev": before.extract_planes_organized}
    per_frame: dict[str, list[float]] = {"now": [], "rev": []}
    for _ in range(args.rounds):
        for tag, run in runs.items():
            t0 = time.process_time()
            for P in grids:
                run(P)
            per_frame[tag].append((time.process_time() - t0) / len(grids))
    n = args.rounds * len(grids)
    now, rev = (1000 * float(np.median(per_frame[t])) for t in ("now", "rev"))
    print(
        f"{len(grids)} frames x {args.rounds}: CPU ms per frame {args.rev} {rev:.2f} -> now {now:.2f}"
    )
    print(f"kernel | {args.rev} ms | now ms")
    for name in sorted(acc["rev"], key=lambda k: -acc["rev"][k]):
        print(f"{name} | {1000 * acc['rev'][name] / n:.3f} | {1000 * acc['now'][name] / n:.3f}")


if __name__ == "__main__":
    main()
