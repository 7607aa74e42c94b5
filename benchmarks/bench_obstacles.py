"""Obstacles (paper 1): the paper's experiments in the simulator, and navkit against Patchwork++.

``python -m benchmarks obstacles`` (``--quick``: fewer seeds, repeats and frames) measures

1. the noise sweep of paper 1's experiments (box, hemisphere, the four-obstacle map with a prism
   steeper than c0) with a SICK-LMS-200-like tilting scanner (1 deg) and a 64-beam spinning
   lidar, range noise 0-3 % of range: obstacles found / true, phantoms, boundary error, shape
   containment of the true footprint and area overhead;
2. on the SemanticKITTI frames: ms per frame for navkit (grid recovery + eight stages + shapes)
   and pypatchworkpp, median of repeats after a warm-up, in the same process, and the ground
   P/R/F1 of both under the Patchwork++ protocol; navkit's time per stage;
3. obstacle recall of the labelled cars of the SqueezeSeg frames.

Times are reported twice: CPU time (``time.process_time``, all threads of the process) and wall
time (``time.perf_counter``), each the median over repeats after a warm-up; the CPU time is the
fairer figure on a loaded machine. The scene builders, :func:`run_experiment` and the real-data
helpers live in :mod:`navkit.experiments.obstacles` (shared with ``tests/obstacles``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np

from benchmarks.common import Row, time_ratio
from navkit.experiments.obstacles import (
    KITTI_FRAMES,
    NOISE_LEVELS,
    SENSOR_HEIGHT_KITTI,
    car_recall,
    format_sweep,
    kitti_frame,
    navkit_ground,
    noise_sweep,
    patchwork_ground,
)

__all__ = ["AREA", "NOISE_LEVELS", "cpu_wall_time", "run"]

AREA = "obstacles"


def cpu_wall_time(fn: Callable[[], Any], repeats: int = 7, warmup: int = 1) -> tuple[float, float]:
    """Median CPU time (``time.process_time``) and median wall time of ``fn()``, seconds."""
    for _ in range(warmup):
        fn()
    cpu, wall = [], []
    for _ in range(repeats):
        c0, w0 = time.process_time(), time.perf_counter()
        fn()
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - w0)
    return float(np.median(cpu)), float(np.median(wall))


# ------------------------------------------------------------------------------------------
# compiled kernels against the NumPy twin and Patchwork++ (docs/kernels.md, "Obstacles")

_COMPILE_SCRIPT = """
import json, time, numpy as np
t0 = time.perf_counter(); c0 = time.process_time()
from navkit.obstacles import ObstacleSettings, Mounting, detect_obstacles_in_grid
from navkit.obstacles.grids import cloud_to_grid
from navkit.obstacles import _kernels_grid, _kernels_map, _kernels_mesh  # imports numba
t_import = time.perf_counter() - t0
from navkit.experiments.obstacles import kitti_frame
pts = kitti_frame("000000")[0]
out = {"import_s": t_import}
for tag, st in (("stages 1-7", ObstacleSettings(build_map=False)),
                ("all 8 stages", ObstacleSettings())):
    for k in ("first", "second"):
        c = time.process_time(); w = time.perf_counter()
        detect_obstacles_in_grid(cloud_to_grid(pts), Mounting(1.73), st)
        out[f"{tag} {k} call cpu s"] = time.process_time() - c
        out[f"{tag} {k} call wall s"] = time.perf_counter() - w
print(json.dumps(out))
"""


def compile_cost() -> dict[str, dict[str, float]]:
    """First-call and warm cost of the compiled backend, in fresh processes.

    Run twice with ``NUMBA_CACHE_DIR`` set to a new temporary folder: ``"empty cache"`` compiles
    every kernel (and writes the cache), ``"warm cache"`` loads them from disk. Each process
    times the first and the second detection on a SemanticKITTI frame.
    """
    import json
    import os
    import subprocess
    import sys
    import tempfile

    out: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory(prefix="navkit-numba-") as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        for label in ("empty cache", "warm cache"):
            res = subprocess.run(
                [sys.executable, "-c", _COMPILE_SCRIPT],
                env=env,
                capture_output=True,
                text=True,
                check=True,
            )
            out[label] = json.loads(res.stdout.strip().splitlines()[-1])
    return out


def backend_comparison(
    frames: list[Any], pw: Any, repeats: int = 7
) -> list[dict[str, float | str]]:
    """CPU ms per frame (median of ``repeats`` after a warm-up): the compiled and the NumPy
    backend (grid recovery + stages 1-7, and all 8 stages with the default shapes), the
    compiled stages 1-7 with stage 8's outlines (``"1-7+o"``: what earlier rounds timed as
    "stages 1-7" - no shapes, but the obstacle records with their hulls) and Patchwork++,
    frame by frame in the same run."""
    from navkit import jit
    from navkit.obstacles import Mounting, ObstacleSettings, detect_obstacles_in_grid
    from navkit.obstacles.grids import cloud_to_grid

    def run_nav(pts: Any, st: Any, implementation: str) -> None:
        with jit.use("eager" if implementation == "compiled" else "numpy"):
            grid = cloud_to_grid(pts)
            detect_obstacles_in_grid(grid, Mounting(SENSOR_HEIGHT_KITTI), st)

    stages_1_7 = ObstacleSettings(build_map=False)
    outlines = ObstacleSettings(shapes=(), guaranteed_shapes=())
    full = ObstacleSettings()
    table: list[dict[str, float | str]] = []
    for k, pts in enumerate(frames):
        row: dict[str, float | str] = {"frame": KITTI_FRAMES[k]}
        row["pw"] = 1e3 * cpu_wall_time(partial(patchwork_ground, pw, pts), repeats)[0]
        for tag, st, backends in (
            ("1-7", stages_1_7, ("compiled", "numpy")),
            ("1-7+o", outlines, ("compiled",)),
            ("all", full, ("compiled", "numpy")),
        ):
            for be in backends:
                fn = partial(run_nav, pts, st, be)
                row[f"{tag} {be}"] = 1e3 * cpu_wall_time(fn, repeats)[0]
        row["pw again"] = 1e3 * cpu_wall_time(partial(patchwork_ground, pw, pts), repeats)[0]
        table.append(row)
    return table


def format_backends(table: list[dict[str, float | str]]) -> str:
    """Markdown table of :func:`backend_comparison` (ratios = navkit / Patchwork++)."""
    lines = [
        "| frame | Patchwork++ | 1-7 compiled | 1-7 NumPy | 1-7 + outlines compiled "
        "| all 8 compiled | all 8 NumPy | 1-7 compiled / PW++ | 1-7 + outlines / PW++ "
        "| all 8 compiled / PW++ | compiled speed-up 1-7 / all 8 |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in table:
        pw = 0.5 * (float(r["pw"]) + float(r["pw again"]))
        a, b = float(r["1-7 compiled"]), float(r["1-7 numpy"])
        o = float(r["1-7+o compiled"])
        c, d = float(r["all compiled"]), float(r["all numpy"])
        lines.append(
            f"| {r['frame']} | {pw:.1f} | {a:.1f} | {b:.1f} | {o:.1f} | {c:.1f} | {d:.1f} "
            f"| {a / pw:.2f}x | {o / pw:.2f}x | {c / pw:.2f}x | {b / a:.1f}x / {d / c:.1f}x |"
        )
    return "\n".join(lines)


def kernel_rows(quick: bool = False) -> list[Row]:
    """Rows of the backend comparison and the compile cost (section 4 of the docs)."""
    from navkit.errors import require_module

    frames = [kitti_frame(n)[0] for n in (KITTI_FRAMES[:1] if quick else KITTI_FRAMES)]
    pwpp = require_module("pypatchworkpp", "bench", "the Patchwork++ comparison")
    params = pwpp.Parameters()
    params.verbose = False
    params.sensor_height = SENSOR_HEIGHT_KITTI
    pw = pwpp.patchworkpp(params)
    rows: list[Row] = []
    table = backend_comparison(frames, pw, 3 if quick else 7)
    for r in table:
        pw_ms = 0.5 * (float(r["pw"]) + float(r["pw again"]))
        names = {"1-7": "stages 1-7", "1-7+o": "stages 1-7 + outlines", "all": "all 8 stages"}
        for tag in ("1-7", "1-7+o", "all"):
            for be in ("compiled", "numpy"):
                if f"{tag} {be}" not in r:
                    continue
                ms = float(r[f"{tag} {be}"])
                rows.append(
                    Row(
                        AREA,
                        f"KITTI {r['frame']} CPU ms: {names[tag]} ({be})",
                        "ms",
                        ms,
                        pw_ms,
                        "pypatchworkpp",
                        time_ratio(ms, pw_ms),
                        "grid recovery included; time.process_time, median",
                    )
                )
    for label, res in compile_cost().items():
        for key, val in res.items():
            rows.append(Row(AREA, f"compiled backend, {label}: {key}", "s", val))
    from pathlib import Path

    from navkit.io.atomic import write_text

    write_text(Path("out/bench/obstacles_backends.md"), format_backends(table) + "\n")
    return rows


# ------------------------------------------------------------------------------------------
# the benchmark


def run(quick: bool = False) -> list[Row]:
    """All obstacle benchmarks (see the module docstring)."""
    import logging

    from navkit.errors import DataNotFoundError
    from navkit.obstacles import Mounting, ObstacleSettings, detect_obstacles_in_grid
    from navkit.obstacles.evaluate import ground_scores
    from navkit.obstacles.grids import cloud_to_grid
    from navkit.obstacles.rules import GROUND

    log = logging.getLogger(__name__)
    rows: list[Row] = []

    # 1. noise sweep in the simulator
    sweep = noise_sweep(seeds=(0,) if quick else (0, 1, 2))
    for r in sweep:
        tag = f"{r['scanner']} noise {100 * r['noise']:.1f}%"
        rows.append(
            Row(
                AREA,
                f"sim {tag}: found/true",
                "count",
                r["found"],
                None,
                "",
                None,
                f"of {r['true']}",
            )
        )
        rows.append(Row(AREA, f"sim {tag}: phantoms", "count", r["phantoms"]))
        rows.append(Row(AREA, f"sim {tag}: boundary error", "m", r["boundary_error_m"]))
        for s in ("A1", "A6", "MVEE", "A7:A1"):
            rows.append(
                Row(AREA, f"sim {tag}: {s} containment", "fraction", r["containment"].get(s))
            )
            rows.append(
                Row(AREA, f"sim {tag}: {s} area / footprint", "ratio", r["area_ratio"].get(s))
            )
    log.info("noise sweep:\n%s", format_sweep(sweep))
    sweep_md = format_sweep(sweep)

    # 2. SemanticKITTI against Patchwork++
    try:
        frames = [kitti_frame(n) for n in (KITTI_FRAMES[:1] if quick else KITTI_FRAMES)]
    except DataNotFoundError as exc:
        log.warning("SemanticKITTI frames absent: %s", exc)
        frames = []
    if frames:
        from navkit.errors import require_module

        pwpp = require_module("pypatchworkpp", "bench", "the Patchwork++ comparison")
        params = pwpp.Parameters()
        params.verbose = False
        params.sensor_height = SENSOR_HEIGHT_KITTI
        pw = pwpp.patchworkpp(params)
        repeats = 3 if quick else 7
        settings_full = ObstacleSettings()
        settings_nomap = ObstacleSettings(build_map=False)  # stops after stage 7
        settings_paper = ObstacleSettings(
            shapes=("A1", "A2", "A3", "A4", "A5", "MEC"), guaranteed_shapes=("A1",)
        )
        variants = {
            "stages 1-7 (classes + instances + boundaries)": (settings_nomap, "no stage 8"),
            "8 stages + A1-A5, MEC, A7(A1)": (settings_paper, "A6 and MVEE skipped"),
            "all 8 stages + A1-A7 + MEC + MVEE": (settings_full, "Patchwork++: ground only"),
        }
        times: dict[str, list[tuple[float, float]]] = {k: [] for k in variants}
        t_pw: list[tuple[float, float]] = []
        sc_nav, sc_pw = [], []
        stages: dict[str, list[float]] = {}
        stages_cpu: dict[str, list[float]] = {}
        for pts, sem in frames:
            t_pw.append(cpu_wall_time(partial(patchwork_ground, pw, pts), repeats))
            for name, (st, _) in variants.items():
                times[name].append(cpu_wall_time(partial(navkit_ground, pts, st), repeats))
            per_run: dict[str, list[float]] = {}
            per_run_cpu: dict[str, list[float]] = {}
            for _ in range(repeats):
                c0, w0 = time.process_time(), time.perf_counter()
                grid = cloud_to_grid(pts)
                c1, w1 = time.process_time(), time.perf_counter()
                det = detect_obstacles_in_grid(grid, Mounting(SENSOR_HEIGHT_KITTI), settings_full)
                for stage, sec in {"cloud -> grid": w1 - w0, **det.timings}.items():
                    per_run.setdefault(stage, []).append(sec)
                for stage, sec in {"cloud -> grid": c1 - c0, **det.cpu_timings}.items():
                    per_run_cpu.setdefault(stage, []).append(sec)
            g_nav = grid.per_point(det.vertex_labels) == GROUND
            for stage, secs in per_run.items():
                stages.setdefault(stage, []).append(float(np.median(secs)))
            for stage, secs in per_run_cpu.items():
                stages_cpu.setdefault(stage, []).append(float(np.median(secs)))
            sc_nav.append(ground_scores(g_nav, sem))
            sc_pw.append(ground_scores(patchwork_ground(pw, pts), sem))
        pw_cpu = 1e3 * float(np.mean([c for c, _ in t_pw]))
        pw_wall = 1e3 * float(np.mean([w for _, w in t_pw]))
        for name, (_, note) in variants.items():
            cpu = 1e3 * float(np.mean([c for c, _ in times[name]]))
            wall = 1e3 * float(np.mean([w for _, w in times[name]]))
            rows.append(
                Row(
                    AREA,
                    f"KITTI CPU ms/frame: {name}",
                    "ms",
                    cpu,
                    pw_cpu,
                    "pypatchworkpp",
                    time_ratio(cpu, pw_cpu),
                    note + "; time.process_time",
                )
            )
            rows.append(
                Row(
                    AREA,
                    f"KITTI wall ms/frame: {name}",
                    "ms",
                    wall,
                    pw_wall,
                    "pypatchworkpp",
                    time_ratio(wall, pw_wall),
                    note + "; time.perf_counter",
                )
            )
        for key in ("precision", "recall", "f1"):
            a = float(np.mean([getattr(s, key) for s in sc_nav]))
            b = float(np.mean([getattr(s, key) for s in sc_pw]))
            rows.append(
                Row(
                    AREA,
                    f"KITTI ground {key}",
                    "fraction",
                    a,
                    b,
                    "pypatchworkpp",
                    a / b if b else None,
                    "navkit / peer",
                )
            )
        rows.append(
            Row(
                AREA,
                "KITTI vegetation predicted ground",
                "fraction",
                float(np.mean([s.vegetation_as_ground for s in sc_nav])),
                float(np.mean([s.vegetation_as_ground for s in sc_pw])),
                "pypatchworkpp",
                None,
                "not scored",
            )
        )
        for stage, secs in stages_cpu.items():
            rows.append(
                Row(
                    AREA,
                    f"KITTI stage CPU time: {stage}",
                    "ms",
                    1e3 * float(np.mean(secs)),
                    note="full settings, median over repeats; 'points' includes the mounting",
                )
            )
        for stage, secs in stages.items():
            rows.append(
                Row(
                    AREA,
                    f"KITTI stage wall time: {stage}",
                    "ms",
                    1e3 * float(np.mean(secs)),
                    note="full settings, median over repeats",
                )
            )

    # 2b. compiled kernels against the NumPy twin, and the compile cost
    if frames:
        rows.extend(kernel_rows(quick))

    # 3. cars of the SqueezeSeg frames
    try:
        found, total, _ = car_recall()
        rows.append(
            Row(
                AREA,
                "SqueezeSeg cars (>=50 pts) inside an obstacle's A1",
                "count",
                found,
                None,
                "",
                None,
                f"of {total}",
            )
        )
    except DataNotFoundError as exc:
        log.warning("SqueezeSeg frames absent: %s", exc)
    from pathlib import Path

    from navkit.io.atomic import write_text

    write_text(Path("out/bench/obstacles_noise_sweep.md"), sweep_md + "\n")
    return rows


if __name__ == "__main__":  # only the kernel comparison: python -m benchmarks.bench_obstacles
    import sys

    for row in kernel_rows(quick="--quick" in sys.argv):
        print(f"{row.benchmark}: {row.navkit:.4g} {row.unit}", end="")
        print(
            f"  (peer {row.peer:.4g}, navkit/peer {row.navkit / row.peer:.2f})" if row.peer else ""
        )
    print(open("out/bench/obstacles_backends.md").read())
