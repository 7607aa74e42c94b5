"""Obstacles, stages 6-8 (split, boundaries, map with the default shapes): CPU time and page
faults per stage, Patchwork++ timed in the same processes.

``python -m benchmarks.obstacles_map_stages [--rounds N] [--repeats N]`` runs ``N`` rounds of one
fresh process each on the SemanticKITTI frames: median CPU time (``time.process_time``) and minor
page faults (``getrusage``'s ``ru_minflt``) per stage over the repeats after a warm-up. Prints a
Markdown table. Not a ``bench_`` module: ``make bench`` does not run it.
"""

from __future__ import annotations

import argparse

from benchmarks.obstacles_stages import round_medians

_CHILD = r"""
import json, resource, sys, time
import numpy as np
from navkit.experiments.obstacles import KITTI_FRAMES, kitti_frame, patchwork_ground
from navkit.obstacles import Mounting, ObstacleSettings, detect_obstacles_in_grid
from navkit.obstacles.grids import cloud_to_grid
from navkit.obstacles import detector
import pypatchworkpp as pwpp

FAULTS = {}


def counted(stage, fn):
    def wrapper(*a, **k):
        f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        out = fn(*a, **k)
        FAULTS[stage] = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0
        return out
    return wrapper


detector._compiled_split = counted("split", detector._compiled_split)
detector._compiled_vertices = counted("boundaries", detector._compiled_vertices)
detector._build_compiled = counted("map", detector._build_compiled)

reps = int(sys.argv[1])
params = pwpp.Parameters(); params.verbose = False; params.sensor_height = 1.73
pw = pwpp.patchworkpp(params)
st = ObstacleSettings()
out = {}
for name in KITTI_FRAMES:
    pts = kitti_frame(name)[0]
    grid = cloud_to_grid(pts)
    for _ in range(3):
        detect_obstacles_in_grid(grid, Mounting(1.73), st)
        patchwork_ground(pw, pts)
    rows = {}
    for _ in range(reps):
        c = time.process_time(); patchwork_ground(pw, pts)
        rows.setdefault("Patchwork++", []).append(time.process_time() - c)
        det = detect_obstacles_in_grid(grid, Mounting(1.73), st)
        for k in ("split", "boundaries", "map"):
            rows.setdefault(k, []).append(det.cpu_timings[k])
            rows.setdefault("faults " + k, []).append(FAULTS[k] * 1e-3)
    out[name] = {k: 1e3 * float(np.median(v)) for k, v in rows.items()}
print(json.dumps(out))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=15)
    args = ap.parse_args()
    meds = round_medians(args.rounds, args.repeats, _CHILD)
    stages = ["split", "boundaries", "map"]
    print(f"CPU ms, median over {args.rounds} rounds of the medians of {args.repeats}")
    print(
        "| frame | "
        + " | ".join(stages)
        + " | stages 6-8 | faults split / boundaries / map | Patchwork++ | 6-8 / PW++ |"
    )
    print("|---" * (len(stages) + 5) + "|")
    for frame, med in meds.items():
        total = sum(med[s] for s in stages)
        pw = med["Patchwork++"]
        cells = " | ".join(f"{med[s]:.2f}" for s in stages)
        faults = " / ".join(f"{med['faults ' + s]:.0f}" for s in stages)
        print(f"| {frame} | {cells} | {total:.2f} | {faults} | {pw:.2f} | {total / pw:.2f}x |")


if __name__ == "__main__":
    main()
