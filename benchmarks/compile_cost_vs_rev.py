"""Compile cost of the path and plane-extraction kernels: this tree against an earlier revision.

``python benchmarks/compile_cost_vs_rev.py [--rev REV] [--rounds N]`` extracts ``src/`` of ``REV``
(``git archive``) and, for each area, runs a small first call (a 3,000-point looping trajectory
through ``navkit.path.approximate``; a 640 x 480 organised cloud through
``extract_planes_organized``) in a fresh process with an empty ``NUMBA_CACHE_DIR``, then again on
the cache it left. The compile cost is the difference of the two processes' CPU time (import
and the call itself cancel out). Rounds alternate the two trees. Not a ``bench_`` module: ``make
bench`` does not run it (a minute of compilation per tree and area).
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

SNIPPETS = {
    "path": (
        "import numpy as np\nfrom navkit.path import approximate\n"
        "t = np.linspace(0, 60, 3000)\n"
        "approximate(np.c_[np.cos(t) * (10 + t / 10), np.sin(2 * t) * 5 + t / 7])"
    ),
    "planes": (
        "import numpy as np\nfrom navkit.planes import extract_planes_organized\n"
        "v, u = np.mgrid[0:480, 0:640]\n"
        "P = np.stack([(u - 320) / 500, (v - 240) / 500, np.ones((480, 640))], axis=2) * 2.0\n"
        "extract_planes_organized(P)"
    ),
}


def _cpu(src: Path, code: str, cache: str) -> float:
    """CPU seconds of one fresh process running ``code`` with ``src`` on the path."""
    env = dict(os.environ, PYTHONPATH=str(src), NUMBA_CACHE_DIR=cache, NAVKIT_JIT="eager")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, "-c", code], env=env, check=True, capture_output=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rev", default="0d1b12f", help="the earlier revision (default: %(default)s)")
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="navkit-rev-") as tmp:
        archive = Path(tmp) / "src.tar"
        with open(archive, "wb") as fh:
            subprocess.run(["git", "archive", args.rev, "src"], cwd=ROOT, stdout=fh, check=True)
        with tarfile.open(archive) as tar:
            tar.extractall(tmp, filter="data")
        trees = ((args.rev, Path(tmp) / "src"), ("this tree", ROOT / "src"))
        print("| area | tree | round | empty cache (CPU s) | warm cache (CPU s) | compile (s) |")
        print("|---|---|---|---|---|---|")
        for area, code in SNIPPETS.items():
            for r in range(args.rounds):
                for name, src in trees:
                    with tempfile.TemporaryDirectory(prefix="navkit-numba-") as cache:
                        cold = _cpu(src, code, cache)
                        warm = _cpu(src, code, cache)
                    print(
                        f"| {area} | {name} | {r} | {cold:.1f} | {warm:.1f} | {cold - warm:.1f} |",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
