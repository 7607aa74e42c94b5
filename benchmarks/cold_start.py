"""The first ``navkit demo`` on a fresh machine (issue 12, item 3): what the kernels' compilation
costs, under each policy of :mod:`navkit.jit`, against the code of an earlier revision.

Each case is a fresh process ``python -m navkit demo`` with ``NUMBA_CACHE_DIR`` set to its own
folder (so "empty cache" means what a fresh clone has), rounds interleaved:

- ``before``: the demo of ``--before`` (a git revision, checked out into a temporary worktree;
  default ``4f29c21``, the last revision without kernels), empty cache;
- ``auto, empty cache``: this revision's default on a fresh machine - the NumPy twins for the
  whole run while a background process compiles the kernels (it runs on the other core; the
  script waits for it after the demo and reports how long it took);
- ``auto, compiled``: the next run on that machine (the stamp found: the kernels);
- ``eager, empty cache``: compiling in the process on first use (what this code did before the
  policy existed).

``--kernels-vs-twins`` runs another comparison instead, of this code only: ``navkit compile``
once into a fresh cache, then rounds alternating the demo on the compiled kernels (``auto`` with
the stamp found: every kernel loaded from the cache, as on every run after the first) and on the
NumPy twins (``NAVKIT_JIT=numpy``). It answers whether loading the kernels costs more than they
save in the demo.

Wall time is what the issue's rule is about ("``make demo`` on a fresh clone must not get
slower"); CPU time of the demo process is reported too (the background compilation's CPU is not
in it). Run from the repository root::

    PYTHONPATH=.:src .venv/bin/python benchmarks/cold_start.py [--before 4f29c21] [--rounds 2] \
        [--no-eager | --kernels-vs-twins]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _demo(src: Path, cache: Path, policy: str, out: Path) -> tuple[float, float]:
    """Wall and CPU seconds of one ``navkit demo`` (the process and its waited-for children)."""
    env = dict(os.environ, PYTHONPATH=str(src), NUMBA_CACHE_DIR=str(cache), NAVKIT_JIT=policy)
    env["MPLBACKEND"] = "Agg"
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "navkit", "-q", "demo", "--out", str(out)],
        env=env,
        cwd=src.parent,
        check=True,
        capture_output=True,
    )
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def _wait_for_warmup(cache: Path, limit_s: float = 900.0) -> float:
    """Seconds until the background warm-up's lock is gone (it removes it when done)."""
    t0 = time.perf_counter()
    while list(cache.glob("navkit-jit-*.lock")) and time.perf_counter() - t0 < limit_s:
        time.sleep(0.5)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--before", default="4f29c21")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument(
        "--no-eager", action="store_true", help="skip the eager case (the longest, ~1.5 min CPU)"
    )
    ap.add_argument(
        "--kernels-vs-twins",
        action="store_true",
        help="this code only: kernels loaded from a warm cache against the NumPy twins",
    )
    args = ap.parse_args()
    if args.kernels_vs_twins:
        _print(_kernels_vs_twins(args.rounds), "this code")
        return
    rows: dict[str, list[tuple[float, float]]] = {}
    with tempfile.TemporaryDirectory(prefix="navkit-cold-") as tmp:
        t = Path(tmp)
        old = t / "before"
        subprocess.run(
            ["git", "worktree", "add", "-q", "--detach", str(old), args.before],
            cwd=ROOT,
            check=True,
        )
        try:
            for r in range(args.rounds):
                c = t / f"cache-before-{r}"
                rows.setdefault("before, empty cache", []).append(
                    _demo(old / "src", c, "auto", t / f"o-before-{r}")
                )
                c = t / f"cache-auto-{r}"
                rows.setdefault("auto, empty cache", []).append(
                    _demo(ROOT / "src", c, "auto", t / f"o-auto-{r}")
                )
                w = _wait_for_warmup(c)
                rows.setdefault("(background warm-up left after the demo)", []).append((w, 0.0))
                rows.setdefault("auto, compiled (next run)", []).append(
                    _demo(ROOT / "src", c, "auto", t / f"o-next-{r}")
                )
                if not args.no_eager:
                    c = t / f"cache-eager-{r}"
                    rows.setdefault("eager, empty cache", []).append(
                        _demo(ROOT / "src", c, "eager", t / f"o-eager-{r}")
                    )
                print(f"round {r + 1} done", file=sys.stderr)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(old)], cwd=ROOT)
    _print(rows, f"before = {args.before}")


def _kernels_vs_twins(rounds: int) -> dict[str, list[tuple[float, float]]]:
    """The demo on kernels loaded from a warm cache against the NumPy twins, rounds
    interleaved (the cache filled once by ``navkit compile``)."""
    rows: dict[str, list[tuple[float, float]]] = {}
    with tempfile.TemporaryDirectory(prefix="navkit-twins-") as tmp:
        t = Path(tmp)
        cache = t / "cache"
        env = dict(os.environ, PYTHONPATH=str(ROOT / "src"), NUMBA_CACHE_DIR=str(cache))
        env.pop("NAVKIT_JIT", None)
        subprocess.run(
            [sys.executable, "-m", "navkit", "-q", "compile"],
            env=env,
            cwd=ROOT,
            check=True,
            capture_output=True,
        )
        for r in range(rounds):
            rows.setdefault("compiled kernels (auto, stamp found)", []).append(
                _demo(ROOT / "src", cache, "auto", t / f"o-kernels-{r}")
            )
            rows.setdefault("NumPy twins (NAVKIT_JIT=numpy)", []).append(
                _demo(ROOT / "src", cache, "numpy", t / f"o-twins-{r}")
            )
            print(f"round {r + 1} done", file=sys.stderr)
    return rows


def _print(rows: dict[str, list[tuple[float, float]]], what: str) -> None:
    print(f"| case ({what}) | wall s per round | CPU s per round |")
    print("|---|---|---|")
    for name, vals in rows.items():
        walls = ", ".join(f"{w:.1f}" for w, _ in vals)
        cpus = ", ".join(f"{c:.1f}" for _, c in vals)
        print(f"| {name} | {walls} | {cpus} |")


if __name__ == "__main__":
    main()
