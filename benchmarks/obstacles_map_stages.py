"""Obstacles, stages 6-8 (split, boundaries, map with the default shapes): CPU time and page
faults per stage, this tree against an earlier revision, Patchwork++ timed in the same processes.

``python -m benchmarks.obstacles_map_stages [--base REV] [--rounds N] [--repeats N]`` extracts
``src/`` of ``REV`` (default ``4b98332``, round 1 of stages 6-8) with ``git archive`` and runs
the two trees in turn, ``N`` rounds of one fresh process each, on the SemanticKITTI frames:
median CPU time (``time.process_time``) and minor page faults (``getrusage``'s ``ru_minflt``)
per stage over the repeats after a warm-up. Prints a Markdown table. Not a ``bench_`` module:
``make bench`` does not run it.
"""

from __future__ import annotations

import argparse

from benchmarks.obstacles_stages import ab_medians

_CHILD = r"""
import json, resource, sys, time
import numpy as np
from navkit.experiments.obstacles import KITTI_FRAMES, kitti_frame, patchwork_ground
from navkit.obstacles import Mounting, ObstacleSettings, cloud_to_grid, detect_obstacles_in_grid
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
if hasattr(detector, "_build_compiled"):
    detector._build_compiled = counted("map", detector._build_compiled)
else:
    detector._build_obstacles = counted("map", detector._build_obstacles)

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
    ap.add_argument("--base", default="4b98332")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=15)
    args = ap.parse_args()
    meds = ab_medians(args.base, args.rounds, args.repeats, _CHILD)
    stages = ["split", "boundaries", "map"]
    print(f"before = {args.base}, after = this tree; CPU ms, median over {args.rounds} rounds")
    print(
        "| frame | tree | "
        + " | ".join(stages)
        + " | stages 6-8 | faults split / boundaries / map | Patchwork++ | 6-8 / PW++ |"
    )
    print("|---" * (len(stages) + 6) + "|")
    for frame in meds["after"]:
        for tree in ("before", "after"):
            med = meds[tree][frame]
            total = sum(med[s] for s in stages)
            pw = med["Patchwork++"]
            cells = " | ".join(f"{med[s]:.2f}" for s in stages)
            faults = " / ".join(f"{med['faults ' + s]:.0f}" for s in stages)
            print(
                f"| {frame} | {tree} | {cells} | {total:.2f} | {faults} | {pw:.2f} "
                f"| {total / pw:.2f}x |"
            )


if __name__ == "__main__":
    main()
