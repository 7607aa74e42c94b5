"""Obstacles, stages 1-7 (grid recovery, points, mesh, classes, split, boundaries): CPU time per
stage, with Patchwork++ timed in the same processes.

``python -m benchmarks.obstacles_stages [--rounds N] [--repeats N]`` runs ``N`` rounds of one
fresh process each on the SemanticKITTI frames: median CPU time (``time.process_time``) per stage
over the repeats after a warm-up, and Patchwork++'s ground segmentation on the same frames in the
same process; the table gives the median over the rounds and the ratios to Patchwork++. Not a
``bench_`` module: ``make bench`` does not run it.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

_CHILD = r"""
import json, sys, time
import numpy as np
from navkit.experiments.obstacles import KITTI_FRAMES, kitti_frame, patchwork_ground
from navkit.obstacles import Mounting, ObstacleSettings, detect_obstacles_in_grid
from navkit.obstacles.grids import cloud_to_grid
import pypatchworkpp as pwpp

reps = int(sys.argv[1])
params = pwpp.Parameters(); params.verbose = False; params.sensor_height = 1.73
pw = pwpp.patchworkpp(params)
st = ObstacleSettings(shapes=(), guaranteed_shapes=())
out = {}
for name in KITTI_FRAMES:
    pts = kitti_frame(name)[0]
    for _ in range(3):
        detect_obstacles_in_grid(cloud_to_grid(pts), Mounting(1.73), st)
        patchwork_ground(pw, pts)
    rows = {}
    for _ in range(reps):
        c = time.process_time(); patchwork_ground(pw, pts); rows.setdefault("Patchwork++", []).append(time.process_time() - c)
        c0 = time.process_time()
        g = cloud_to_grid(pts)
        c1 = time.process_time()
        det = detect_obstacles_in_grid(g, Mounting(1.73), st)
        c2 = time.process_time()
        rows.setdefault("cloud_to_grid", []).append(c1 - c0)
        for k, v in det.cpu_timings.items():
            rows.setdefault(k, []).append(v)
        rows.setdefault("stages 1-7", []).append(c2 - c0 - det.cpu_timings["map"])
    out[name] = {k: 1e3 * float(np.median(v)) for k, v in rows.items()}
print(json.dumps(out))
"""


def _run(src: Path, repeats: int, child: str = _CHILD) -> dict[str, dict[str, float]]:
    """Run ``child`` (a timing script printing JSON last) on the navkit under ``src``."""
    env = {**os.environ, "PYTHONPATH": str(src)}
    res = subprocess.run(
        [sys.executable, "-c", child, str(repeats)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(res.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def round_medians(rounds: int, repeats: int, child: str = _CHILD) -> dict[str, dict[str, float]]:
    """``child`` in ``rounds`` fresh processes on this tree: ``{frame: {figure: median over the
    rounds}}``."""
    runs = [_run(ROOT / "src", repeats, child) for _ in range(rounds)]
    return {
        frame: {k: float(np.median([r[frame][k] for r in runs])) for k in runs[0][frame]}
        for frame in runs[0]
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=15)
    args = ap.parse_args()
    meds = round_medians(args.rounds, args.repeats)
    stages = ["cloud_to_grid", "points", "mesh", "classes", "split", "boundaries"]
    print(f"CPU ms, median over {args.rounds} rounds of the medians of {args.repeats}")
    print(
        "| frame | " + " | ".join(stages) + " | grid..classes | stages 1-7 "
        "| Patchwork++ | grid..classes / PW++ | 1-7 / PW++ |"
    )
    print("|---" * (len(stages) + 6) + "|")
    for frame, med in meds.items():
        part = sum(med[s] for s in ("cloud_to_grid", "points", "mesh", "classes"))
        pw = med["Patchwork++"]
        cells = " | ".join(f"{med[s]:.2f}" for s in stages)
        print(
            f"| {frame} | {cells} | {part:.2f} | {med['stages 1-7']:.2f} | {pw:.2f} "
            f"| {part / pw:.2f}x | {med['stages 1-7'] / pw:.2f}x |"
        )


if __name__ == "__main__":
    main()
