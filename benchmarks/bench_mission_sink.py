"""The cost of publishing the mission through the runtime's sinks (``navkit demo``'s
``results.mcap`` and ``--rerun-save``): the demo's mission (the yard, seed 0; ``--quick``: the
``--small`` resolutions) run without a sink, with :class:`navkit.runtime.mission_sink.MissionSink`
writing ``results.mcap``, and with that sink plus the Rerun logger recording an ``.rrd``;
alternated in one process, median wall times; ratio = with / without (the issue's bound for
logging: <= 1.10). On a loaded machine the wall times of whole runs scatter by more than the
overhead, so the note also gives the sink's own time (measured inside the run) over the rest of
the run's. The mission's figures (outcome, distance to the operator) must not change.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import Row


def _list(v: list[float], digits: int = 1) -> str:
    return ", ".join(f"{x:.{digits}f}" for x in v)


def run(quick: bool = False) -> list[Row]:
    from navkit.mission.demo import load_scene_file
    from navkit.mission.metrics import mission_metrics
    from navkit.mission.run import run_mission
    from navkit.runtime.mission_sink import MissionSink
    from navkit.viz.rerun_logger import RerunLogger

    scene, route, settings = load_scene_file("yard", small=quick, seed=0)
    tmp = Path(tempfile.mkdtemp(prefix="bench_mission_sink_"))
    times: dict[str, list[float]] = {"none": [], "mcap": [], "mcap+rrd": []}
    figures: dict[str, set[tuple[str, float]]] = {k: set() for k in times}
    sizes: dict[str, float] = {}
    own: dict[str, list[float]] = {"mcap": [], "mcap+rrd": []}  # the sink's own seconds / run
    try:
        for k in range(2 if quick else 3):
            for variant in times:
                out = tmp / f"{variant}-{k}"
                sink = None
                if variant != "none":
                    logger = RerunLogger(save=out / "run.rrd") if variant == "mcap+rrd" else None
                    sink = MissionSink(out, logger)
                t0 = time.perf_counter()
                lg = run_mission(scene, route, settings, None, sink.step if sink else None)
                if sink is not None:
                    sink.finish(lg)
                times[variant].append(time.perf_counter() - t0)
                r = mission_metrics(lg)["return"]
                figures[variant].add((r["outcome"], round(r["final_distance_to_operator_m"], 6)))
                if sink is not None:
                    own[variant].append(sink.seconds / (times[variant][-1] - sink.seconds))
                    sizes[variant] = (out / "results.mcap").stat().st_size / 1e6
                    if variant == "mcap+rrd":
                        sizes["rrd"] = (out / "run.rrd").stat().st_size / 1e6
                shutil.rmtree(out, ignore_errors=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    base = float(np.median(times["none"]))
    same = figures["none"] == figures["mcap"] == figures["mcap+rrd"]
    name = "demo mission" + (" (--small)" if quick else "")
    rows = []
    for variant, note in (
        ("mcap", f"results.mcap {sizes['mcap']:.1f} MB"),
        ("mcap+rrd", f"results.mcap + .rrd {sizes['rrd']:.1f} MB"),
    ):
        v = float(np.median(times[variant]))
        rows.append(
            Row(
                "mission_sink",
                f"{name}: {variant} logging overhead",
                "s per run",
                v,
                peer=base,
                peer_name="no sink",
                ratio=v / base,
                note=f"median of {len(times[variant])} alternated runs (s: {_list(times[variant])}, "
                f"no sink: {_list(times['none'])}); the sink's own time / the rest of the run: "
                f"{_list(own[variant], 3)}; {note}; figures unchanged: {same} "
                f"{sorted(figures[variant])}",
            )
        )
    return rows
