"""Run a mission into an output folder: the report, the metrics and the maps in standard formats.

Outputs of :func:`run_to_dir` (every file written atomically):

- ``report.html`` - one self-contained page (figures embedded), when a ``report`` writer is
  given (the CLI passes :func:`navkit.viz.mission.write_report`; the mission never imports viz);
- ``metrics.json`` - the mission's figures (:func:`navkit.mission.metrics.mission_metrics`);
- ``settings.toml`` - the resolved settings and the route; ``summary.json`` - the key figures;
- ``truth.tum``, ``vo.tum``, ``estimate.tum`` - trajectories (TUM format, z = 0);
- ``path.json`` - the stored spline (paper 4);
- ``obstacle_map.pgm`` + ``obstacle_map.yaml`` - the fused obstacle map (ROS map_server);
- with a ``sink`` (the CLI passes :class:`navkit.runtime.mission_sink.MissionSink`): what it
  writes from the per-step records, ``results.mcap`` (and an ``.rrd`` with a Rerun logger).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from navkit.mission.settings import (
    MissionSettings,
    Route,
    builtin_route_path,
    load_route,
    read_config,
)

__all__ = [
    "load_scene_file",
    "run_demo",
    "run_scene_file",
    "run_to_dir",
    "summary_of",
    "write_outputs",
]

log = logging.getLogger(__name__)

ProgressFn = Callable[[Iterator[int], str, int], Iterator[int]]


def summary_of(metrics: dict[str, Any]) -> dict[str, Any]:
    """The headline figures of a run (``summary.json``)."""
    pe, ob, ret = metrics["pose_error"], metrics["obstacles"], metrics["return"]
    return {
        "scene": metrics["scene"],
        "outcome": ret["outcome"],
        "final_distance_to_operator_m": ret["final_distance_to_operator_m"],
        "position_error_mean_m": {
            "raw_vo": pe["raw_vo_m"]["mean"],
            "corrected": pe["corrected_m"]["mean"],
        },
        "obstacle_recall": ob["recall"],
        "obstacle_recall_larger_than_robot": ob["recall_larger_than_robot"],
        "obstacle_precision": ob["precision"],
        "phantoms": ob["phantoms"],
        "wall_seconds": metrics.get("wall_seconds"),
    }


ReportFn = Callable[[Any, dict[str, Any], Path], Any]
"""``report(log, metrics, path)`` writes ``report.html`` (:func:`navkit.viz.mission.write_report`;
the CLI passes it: the mission never imports the plotting layer)."""


def write_outputs(
    lg: Any, metrics: dict[str, Any], out: Path, report: ReportFn | None = None
) -> list[str]:
    """Write the metrics, the maps and (with ``report``) the report of a run into ``out``;
    returns the file names."""
    from navkit.io.atomic import write_json
    from navkit.io.maps import write_occupancy_grid
    from navkit.io.pathjson import write_path_json
    from navkit.io.trajectory import Trajectory, write_tum

    files = []
    write_json(out / "metrics.json", metrics)
    files.append("metrics.json")
    for name, arr in (("truth", lg.truth), ("vo", lg.vo), ("estimate", lg.estimate)):
        c, s = np.cos(arr[:, 2]), np.sin(arr[:, 2])
        T = np.tile(np.eye(4), (len(arr), 1, 1))
        T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = c, -s, s, c
        T[:, 0, 3], T[:, 1, 3] = arr[:, 0], arr[:, 1]
        write_tum(out / f"{name}.tum", Trajectory(lg.time.astype(np.float64), T))
        files.append(f"{name}.tum")
    if lg.path is not None and lg.path.n_segments:
        write_path_json(out / "path.json", lg.path)
        files.append("path.json")
    g = lg.obstacle_grid
    occ = np.full(g.shape, -1, dtype=np.int8)
    occ[g.seen > 0] = 0
    occ[g.occupied] = 100
    write_occupancy_grid(out / "obstacle_map", occ, g.resolution, g.origin)
    files += ["obstacle_map.pgm", "obstacle_map.yaml"]
    if report is not None:
        report(lg, metrics, out / "report.html")
        files.append("report.html")
    return files


def run_to_dir(
    scene: Any,
    route: Route,
    settings: MissionSettings,
    out: str | Path,
    progress: ProgressFn | None = None,
    report: ReportFn | None = None,
    sink: Any = None,
) -> dict[str, Any]:
    """Run the mission and write every output into ``out``; returns the metrics.

    ``sink``: a :class:`~navkit.mission.run.StepSink` fed every step's record during the run
    and the log at the end (its files are listed in ``summary.json``)."""
    from navkit.errors import InputError
    from navkit.mission.metrics import mission_metrics
    from navkit.mission.run import run_mission

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(
            "exists and is not a folder", source=out, field="--out", expected="an output folder"
        )
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    lg = run_mission(scene, route, settings, progress, sink.step if sink is not None else None)
    sink_files = sink.finish(lg) if sink is not None else []
    metrics = mission_metrics(lg)
    metrics["wall_seconds_mission"] = time.perf_counter() - t0
    files = write_outputs(lg, metrics, out, report) + list(sink_files)
    metrics["wall_seconds"] = time.perf_counter() - t0
    # the metrics file holds the total time too (rewritten atomically with it)
    from navkit.io.atomic import write_json, write_run_files

    write_json(out / "metrics.json", metrics)
    summary = summary_of(metrics)
    summary["outputs"] = [*files, "settings.toml", "summary.json"]
    write_run_files(out, {"mission": settings, "route": route, "scene": scene.name}, summary)
    return metrics


def load_scene_file(
    scene_path: str | Path,
    *,
    mission: str | Path | None = None,
    seed: int | None = None,
    small: bool = False,
    start: tuple[float, float, float] | None = None,
    config: str | Path | None = None,
) -> tuple[Any, Route, MissionSettings]:
    """Read and check everything a mission run needs: the scene, its route and the settings.

    The mission file is ``mission`` if given, else ``<scene stem>.mission.toml`` beside the
    scene, else the built-in ``mission_<name>.toml`` for a built-in scene. ``start`` overrides
    the scene's start pose ``(x, y, theta)`` (the operator's place; the route is joined to it).
    ``config``: a settings TOML whose ``[mission]`` table overrides the mission file's settings
    (:func:`~navkit.mission.settings.read_config`); ``seed`` overrides both.
    """
    from navkit.errors import DataNotFoundError
    from navkit.sim import Scene, load_scene

    scene = load_scene(scene_path)
    if start is not None:
        scene = Scene(scene.primitives, name=scene.name, start=start)
    if mission is None:
        p = Path(scene_path)
        beside = p.with_name(f"{p.stem}.mission.toml")
        builtin = builtin_route_path(p.stem if p.suffix else p.name)
        if beside.is_file():
            mission = beside
        elif builtin.is_file():
            mission = builtin
        else:
            raise DataNotFoundError(
                f"{scene_path}: no mission file; pass --mission FILE or put {beside.name} beside the scene "
                "([route] waypoints = [[x, y], ...], optional room = [xmin, ymin, xmax, ymax])"
            )
    route, overrides = load_route(mission)
    base = MissionSettings.small() if small else MissionSettings()
    settings = base.with_overrides(overrides, source=str(mission))
    if config is not None:
        settings = settings.with_overrides(read_config(config), source=str(config))
    if seed is not None:
        settings = dataclasses.replace(settings, seed=int(seed))
    return scene, route, settings


def run_scene_file(
    scene_path: str | Path,
    out: str | Path,
    *,
    mission: str | Path | None = None,
    seed: int | None = None,
    small: bool = False,
    start: tuple[float, float, float] | None = None,
    progress: ProgressFn | None = None,
    report: ReportFn | None = None,
    config: str | Path | None = None,
    sink: Any = None,
) -> dict[str, Any]:
    """``navkit mission run``: a scene TOML (or built-in name) and its mission file
    (:func:`load_scene_file`), run into ``out``."""
    scene, route, settings = load_scene_file(
        scene_path, mission=mission, seed=seed, small=small, start=start, config=config
    )
    return run_to_dir(scene, route, settings, out, progress, report, sink)


def run_demo(
    out: str | Path,
    seed: int = 0,
    progress: ProgressFn | None = None,
    *,
    scene: str | Path = "yard",
    small: bool = False,
    start: tuple[float, float, float] | None = None,
    report: ReportFn | None = None,
    config: str | Path | None = None,
    sink: Any = None,
) -> dict[str, Any]:
    """The built-in mission (``navkit demo``): the yard world and its route, into ``out``.

    Parameters
    ----------
    out : path
        Output folder (``report.html``, ``metrics.json``, ...; see the module docstring).
    seed : int
        Seed of every random draw.
    progress : callable, optional
        ``progress(iterable, description, total)``, e.g. :func:`navkit.cli.common.progress`.
    scene, small, start
        Another built-in or TOML world (with its mission file), reduced resolutions, another
        start pose.
    report, config, sink
        See :func:`run_scene_file` and :func:`run_to_dir`.
    """
    return run_scene_file(
        scene,
        out,
        seed=seed,
        small=small,
        start=start,
        progress=progress,
        report=report,
        config=config,
        sink=sink,
    )
