"""Obstacles, stages 1-5 (grid recovery, points, mesh, classes): CPU time per stage, this tree
against an earlier revision, with Patchwork++ timed in the same processes.

``python -m benchmarks.obstacles_stages [--base REV] [--rounds N] [--repeats N]`` extracts
``src/`` of ``REV`` (default ``cf36993``, before the fused stage 2-5 kernel) with ``git archive``
and runs the two trees in turn, ``N`` rounds of one fresh process each (so that both see the
same machine load), on the SemanticKITTI frames: median CPU time (``time.process_time``) per
stage over the repeats after a warm-up, and Patchwork++'s ground segmentation on the same
frames in the same process. Prints a Markdown table with the ratios to Patchwork++. Not a
``bench_`` module: ``make bench`` does not run it.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

_CHILD = r"""
import json, sys, time
import numpy as np
from navkit.experiments.obstacles import KITTI_FRAMES, kitti_frame, patchwork_ground
from navkit.obstacles import Mounting, ObstacleSettings, cloud_to_grid, detect_obstacles_in_grid
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


def _extract(rev: str, into: Path) -> Path:
    data = subprocess.run(
        ["git", "-C", str(ROOT), "archive", rev, "src"], capture_output=True, check=True
    ).stdout
    tar = into / "src.tar"
    tar.write_bytes(data)
    with tarfile.open(tar) as t:
        t.extractall(into, filter="data")
    return into / "src"


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


def ab_medians(
    base: str, rounds: int, repeats: int, child: str = _CHILD
) -> dict[str, dict[str, dict[str, float]]]:
    """``child`` on the tree of git revision ``base`` ("before") and on this tree ("after"),
    alternating fresh processes for ``rounds`` rounds: ``{tree: {frame: {figure: median over
    the rounds}}}``."""
    with tempfile.TemporaryDirectory(prefix="navkit-base-") as tmp:
        base_src = _extract(base, Path(tmp))
        runs: dict[str, list[dict[str, dict[str, float]]]] = {"before": [], "after": []}
        for _ in range(rounds):
            runs["before"].append(_run(base_src, repeats, child))
            runs["after"].append(_run(ROOT / "src", repeats, child))
    return {
        tree: {
            frame: {k: float(np.median([r[frame][k] for r in rs])) for k in rs[0][frame]}
            for frame in rs[0]
        }
        for tree, rs in runs.items()
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", default="cf36993")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=15)
    args = ap.parse_args()
    meds = ab_medians(args.base, args.rounds, args.repeats)
    stages = ["cloud_to_grid", "points", "mesh", "classes", "split", "boundaries"]
    print(f"before = {args.base}, after = this tree; CPU ms, median over {args.rounds} rounds")
    print(
        "| frame | tree | " + " | ".join(stages) + " | grid..classes | stages 1-7 "
        "| Patchwork++ | grid..classes / PW++ | 1-7 / PW++ |"
    )
    print("|---" * (len(stages) + 7) + "|")
    for frame in meds["after"]:
        for tree in ("before", "after"):
            med = meds[tree][frame]
            part = sum(med[s] for s in ("cloud_to_grid", "points", "mesh", "classes"))
            pw = med["Patchwork++"]
            cells = " | ".join(f"{med[s]:.2f}" for s in stages)
            print(
                f"| {frame} | {tree} | {cells} | {part:.2f} | {med['stages 1-7']:.2f} | {pw:.2f} "
                f"| {part / pw:.2f}x | {med['stages 1-7'] / pw:.2f}x |"
            )


if __name__ == "__main__":
    main()
