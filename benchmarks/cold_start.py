"""The first ``navkit demo`` on a fresh machine: what the kernels' compilation costs under each
policy of :mod:`navkit.jit`.

Each case is a fresh process ``python -m navkit demo`` with ``NUMBA_CACHE_DIR`` set to its own
folder (so "empty cache" means what a fresh clone has), rounds interleaved:

- ``numpy``: the NumPy twins throughout (``NAVKIT_JIT=numpy``), the reference for the others;
- ``auto, empty cache``: the default on a fresh machine - the NumPy twins for the
  whole run while a background process compiles the kernels (it runs on the other core; the
  script waits for it after the demo and reports how long it took);
- ``auto, compiled``: the next run on that machine (the stamp found: the kernels);
- ``eager, empty cache``: compiling in the process on first use.

``--kernels-vs-twins`` runs another comparison instead, of this code only: ``navkit compile``
once into a fresh cache, then rounds alternating the demo on the compiled kernels (``auto`` with
the stamp found: every kernel loaded from the cache, as on every run after the first) and on the
NumPy twins (``NAVKIT_JIT=numpy``). It answers whether loading the kernels costs more than they
save in the demo.

Wall time is what the requirement is about (the first ``make demo`` on a fresh clone is not slower
than the demo on the NumPy twins); CPU time of the demo process is reported too (the background
compilation's CPU is not in it). Run from the repository root::

    PYTHONPATH=.:src .venv/bin/python benchmarks/cold_start.py [--rounds 2] \
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
        for r in range(args.rounds):
            c = t / f"cache-numpy-{r}"
            rows.setdefault("numpy (twins), empty cache", []).append(
                _demo(ROOT / "src", c, "numpy", t / f"o-numpy-{r}")
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
    _print(rows, "this code")


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
