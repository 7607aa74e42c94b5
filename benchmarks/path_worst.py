"""Path memory (paper 4): worst and mean CPU time per point at every tolerance, on the recorded
trajectories of ``benchmarks.bench_path`` (requirement: worst point <= 1 ms at every tolerance on
KITTI 00, TUM and MRCLAM).

Every trajectory is recorded ``--runs`` times at every tolerance. A point's time is the median
over the runs of the thread-CPU clock around ``add`` (its own cost, not a moment the scheduler
took the CPU away). Python's garbage collector stays on; the time of the collections that ran
inside each ``add`` is recorded (``gc.callbacks``) and the worst point is also given without it,
so that a collection landing on a point is told apart from the point's work. The runs must give
the same segments, loop cuts and accepted points (checked; floats within 1e-9 relative).

Run from the repository root::

    PYTHONPATH=src:. .venv/bin/python benchmarks/path_worst.py [--runs 5] [--only "KITTI 00 gt" ...]
"""

from __future__ import annotations

import argparse
import gc
import time
from typing import Any

import numpy as np

from benchmarks.bench_path import TOLERANCES, TRAJECTORIES, _load
from navkit.path import ApproximatorSettings, OnlineApproximator


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


def _record(xy: np.ndarray, eps: float, clock: _GcClock) -> tuple[Any, ...]:
    a = OnlineApproximator(ApproximatorSettings(tolerance=eps))
    t = np.zeros(len(xy))
    g = np.zeros(len(xy))
    for i, p in enumerate(xy):
        g0 = clock.total
        c0 = time.thread_time()
        a.update(p)
        t[i] = time.thread_time() - c0
        g[i] = clock.total - g0
    r = a.finish()
    key = (len(r.points), r.n_cheap, r.n_refit_fallbacks, r.points.tobytes())
    floats = np.concatenate([r.point_s, r.points.ravel()])
    return t, g, (key, floats)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--only", nargs="*", help="trajectory names (default: all)")
    args = parser.parse_args()
    clock = _GcClock()
    gc.callbacks.append(clock)
    print(
        f"CPU us per point (median of {args.runs} runs per point)\n"
        "| trajectory | eps (m) | worst | mean | worst without gc | points > 1 ms "
        "| gc in the worst point | runs agree |\n|---|---|---|---|---|---|---|---|"
    )
    for name in args.only or list(TRAJECTORIES):
        xy = _load(TRAJECTORIES[name])
        _record(xy[:300], 0.05, clock)  # compile / load the kernels
        for eps in TOLERANCES:
            runs = [_record(xy, eps, clock) for _ in range(args.runs)]
            t = np.asarray([r[0] for r in runs])
            g = np.asarray([r[1] for r in runs])
            keys = [r[2] for r in runs]
            same = all(k[0] == keys[0][0] for k in keys) and all(
                np.allclose(k[1], keys[0][1], rtol=1e-9, atol=1e-12, equal_nan=True) for k in keys
            )
            med = np.median(t, axis=0) * 1e6
            net = np.median(t - g, axis=0) * 1e6
            gcw = float(np.median(g[:, int(np.argmax(med))]) * 1e6)
            print(
                f"| {name} | {eps:g} | {med.max():.0f} | {med.mean():.0f} | {net.max():.0f} | "
                f"{int((med > 1000).sum())} | {gcw:.0f} | {'yes' if same else 'NO'} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
