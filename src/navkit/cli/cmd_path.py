"""``navkit path``: record a trajectory as a spline path, simulate the return to the operator.

- ``navkit path record TRAJECTORY --tolerance 0.05 --out DIR`` -> ``path.json``, ``path.png``,
  ``summary.json``, ``settings.toml``;
- ``navkit path return PATH_JSON --runs 40 --out DIR`` -> ``returns.json``, ``returns.png``,
  ``summary.json``, ``settings.toml``;
- ``navkit path simulate --out DIR`` -> a simulated drive (true and VO-estimated TUM files) to
  try the two commands on.

The closed-loop return simulation lives in :mod:`navkit.sim.return_sim` (the path capability does
not import the simulator).
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any

import typer

from navkit.cli.batching import (
    EXIT_SOME_FAILED,
    RESUME,
    SCHEDULER,
    WORKERS,
    exit_if_failed,
    run_inputs,
)
from navkit.cli.common import check_out_dir, cli_errors, option, progress, write_run_files
from navkit.domains import NON_NEGATIVE, POSITIVE, SEED, Domain

log = logging.getLogger(__name__)

path_app = typer.Typer(
    help="Path memory and return to the operator (paper 4).", no_args_is_help=True
)


class TrajFormat(str, Enum):
    auto = "auto"
    tum = "tum"
    kitti = "kitti"
    euroc = "euroc"
    odometry = "odometry"


class PlaneChoice(str, Enum):
    auto = "auto"
    xy = "xy"
    xz = "xz"
    yz = "yz"


class VariantChoice(str, Enum):
    start = "start"
    start_tangent = "start_tangent"
    endpoints = "endpoints"
    endpoints_tangent = "endpoints_tangent"


@dataclass(frozen=True)
class RecordInput:
    """Resolved input of ``path record`` (written to ``settings.toml``)."""

    trajectory: str
    format: str
    plane: str


OUT_HELP = "Output folder (refused if it holds files, unless --overwrite)."
OVERWRITE_HELP = "Replace outputs already in --out."


@path_app.command("record")
def record(
    trajectories: list[str] = typer.Argument(
        ...,
        help="Trajectory file(s): TUM, KITTI, EuRoC or a 'time v omega' log (paths or fsspec "
        "URLs). Several files: one output folder each, named after the file.",
    ),
    tolerance: float = option(
        0.05,
        "--tolerance",
        "-e",
        domain=POSITIVE,
        help="eps: max distance of a point from the spline (m).",
    ),
    out: Path = typer.Option(..., "--out", "-o", help=OUT_HELP),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
    format: TrajFormat = typer.Option(TrajFormat.auto, "--format", help="Input format."),
    plane: PlaneChoice = typer.Option(
        PlaneChoice.auto,
        "--plane",
        help="Ground plane: fitted (auto) or two coordinates as they are.",
    ),
    variant: VariantChoice = typer.Option(
        VariantChoice.endpoints, "--variant", help="Segment constraints (paper fig. 1)."
    ),
    keep_loops: bool = typer.Option(
        False, "--keep-loops", help="Store the path without loop removal."
    ),
    precision: float = option(
        1e-4, "--precision", domain=POSITIVE, help="Loop search precision (m)."
    ),
    workers: int | None = WORKERS,
    scheduler: str | None = SCHEDULER,
    resume: bool = RESUME,
) -> None:
    """Record a trajectory point by point as a cubic spline over arc length (mode 1).

    \b
    Example:
      navkit path record "$NAVKIT_DATA/trajectories/KITTI_00_gt.txt" \\
          --tolerance 0.5 -o out/kitti-path
    """
    with cli_errors():
        from navkit.batch.path_record import record_path
        from navkit.path import ApproximatorSettings

        settings = ApproximatorSettings(
            tolerance=tolerance,
            variant=variant.value,
            remove_loops=not keep_loops,
            loop_precision=precision,
        )
        check_out_dir(out, overwrite or resume)
        if len(trajectories) > 1 or workers or scheduler or resume:
            summary = _record_batch(
                trajectories, out, settings, format.value, plane.value, workers, scheduler, resume
            )
        else:
            trajectory = trajectories[0]
            result, summary = record_path(
                out,
                trajectory,
                settings,
                format.value,
                plane.value,
                iterate=lambda items, n: progress(items, "recording", total=n),
            )
            typer.echo(
                f"{result.spline.n_segments} segments, {len(result.loops)} loops removed, "
                f"L = {result.spline.total_length:.3f} m, max deviation "
                f"{result.max_deviation:.4g} m, {summary['mean_us_per_point']:.1f} us/point mean"
                f" -> {out / 'path.json'}"
            )
        inputs = [RecordInput(str(t), format.value, plane.value) for t in trajectories]
        write_run_files(
            out,
            {"input": inputs[0] if len(inputs) == 1 else inputs, "approximator": settings},
            summary,
            reference="the input trajectory itself: deviations are of the spline from the "
            "recorded points, not from the true path",
        )
    exit_if_failed(summary)


def _record_batch(
    trajectories: list[str],
    out: Path,
    settings: Any,
    fmt: str,
    plane: str,
    workers: int | None,
    scheduler: str | None,
    resume: bool,
) -> dict[str, Any]:
    """Every trajectory as one task of a batch (``out/<file stem>/path.json``, ``path.png``)."""
    from navkit.batch import BatchTask, settings_hash
    from navkit.batch.path_record import record_path_job
    from navkit.io.urls import input_identity, url_name

    keys = [Path(url_name(t)).stem for t in trajectories]
    keys = [k if keys.count(k) == 1 else f"{k}_{i}" for i, k in enumerate(keys)]
    tasks = [
        BatchTask(
            key,
            record_path_job,
            {"trajectory": str(t), "settings": settings, "fmt": fmt, "plane": plane},
            settings_hash(input_identity(t), settings, fmt, plane),
        )
        for key, t in zip(keys, trajectories, strict=True)
    ]
    return run_inputs(
        tasks, out, workers=workers, scheduler=scheduler, resume=resume, description="paths"
    )


RUN_COUNT = Domain(integer=True, lo=1, hi=10_000)
VO_SCALE_SIGMA = option(
    0.02, "--vo-scale-sigma", domain=NON_NEGATIVE, help="VO per-step relative scale noise."
)
VO_HEADING_SIGMA_DEG = option(
    0.2, "--vo-heading-sigma-deg", domain=NON_NEGATIVE, help="VO per-step heading noise (deg)."
)
RUNS_PER_TASK = option(
    25, "--runs-per-task", domain=RUN_COUNT, help="Runs simulated together in one task."
)
TURN_DEG = Domain(lo=0.0, hi=360.0, note="the turns alternate left and right")


@path_app.command("return")
def return_(
    path_json: str = typer.Argument(
        ..., help="A path.json written by 'navkit path record' (a path or an fsspec URL)."
    ),
    runs: int = option(
        40, "--runs", domain=RUN_COUNT, help="Number of simulated returns (paper: 40)."
    ),
    out: Path = typer.Option(..., "--out", "-o", help=OUT_HELP),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
    seed: int = option(0, "--seed", domain=SEED, help="Random seed."),
    vo_rate_hz: float = option(
        10.0, "--vo-rate-hz", domain=POSITIVE, help="VO (and control) rate (Hz)."
    ),
    vo_scale_sigma: float = VO_SCALE_SIGMA,
    vo_scale_bias: float = option(
        0.0,
        "--vo-scale-bias",
        domain=Domain(lo=-1.0, lo_open=True, note="signed: VO under- or over-estimates"),
        help="VO relative scale bias.",
    ),
    vo_heading_sigma_deg: float = VO_HEADING_SIGMA_DEG,
    vo_heading_bias_deg_per_m: float = option(
        0.0,
        "--vo-heading-bias-deg-per-m",
        domain=Domain(note="signed: drift to either side"),
        help="VO heading drift (deg/m).",
    ),
    delta: float = option(0.3, "--delta", domain=POSITIVE, help="Look-ahead along the path (m)."),
    speed: float = option(0.3, "--speed", domain=POSITIVE, help="Linear speed (m/s)."),
    stop_radius: float = option(
        0.05, "--stop-radius", domain=POSITIVE, help="Stop radius around the start (m)."
    ),
    runs_per_task: int = RUNS_PER_TASK,
    workers: int | None = WORKERS,
    scheduler: str | None = SCHEDULER,
    resume: bool = RESUME,
) -> None:
    """Simulate returns from the end of a stored path to its start (mode 2, paper fig. 4).

    The runs go in tasks of --runs-per-task (OUT/runs-FIRST-LAST/, batch.jsonl, rates with
    95 % intervals in batch_summary.json); every run has its own random stream from (--seed,
    run index), so no run depends on how they are chunked or split across --workers or a
    --scheduler's cluster.

    \b
    Example:
      navkit path return out/kitti-path/path.json --runs 40 -o out/kitti-return
    """
    with cli_errors():
        import numpy as np

        from navkit.batch.path_return import (
            ReturnSweepSpec,
            collect_returns,
            read_return_path,
            return_sweep_tasks,
        )
        from navkit.path.control import PathFollowerSettings
        from navkit.sensors import VisualOdometryNoise
        from navkit.sim.return_sim import simulate_returns

        spline = read_return_path(path_json)
        vo = VisualOdometryNoise(
            rate_hz=vo_rate_hz,
            scale_bias=vo_scale_bias,
            scale_sigma=vo_scale_sigma,
            heading_bias_per_m=np.radians(vo_heading_bias_deg_per_m),
            heading_sigma=np.radians(vo_heading_sigma_deg),
        )
        ctrl = PathFollowerSettings(delta=delta, v_max=speed, stop_radius=stop_radius)
        # every check of the controller and the simulator (time limit, step bound) before any
        # run starts or anything is written: a return that starts at the path's start stops at
        # once, so this costs one control cycle
        start = spline.start
        simulate_returns(
            spline, runs=1, settings=ctrl, vo=vo, initial_true=[start[0], start[1], 0.0], rng=0
        )
        check_out_dir(out, overwrite or resume)
        sweep = ReturnSweepSpec(vo=vo, controller=ctrl, seed=seed)
        bs = run_inputs(
            return_sweep_tasks(path_json, runs, sweep, runs_per_task),
            out,
            workers=workers,
            scheduler=scheduler,
            resume=resume,
            description="returns",
        )
        rows = [json.loads(line) for line in (out / "batch.jsonl").read_text().splitlines()]
        sim, detail = collect_returns(out, rows)
        if sim is None:  # every run failed: the manifest says why, exit code 3
            typer.echo(f"no run completed -> {out / 'batch.jsonl'}", err=True)
            raise typer.Exit(code=EXIT_SOME_FAILED)
        _write_returns(out, spline, sim, detail, bs, path_json, runs, seed, vo, ctrl)
    exit_if_failed(bs)


def _write_returns(
    out: Path,
    spline: Any,
    sim: Any,
    detail: list[dict[str, Any]],
    bs: dict[str, Any],
    path_json: str,
    runs: int,
    seed: int,
    vo: Any,
    ctrl: Any,
) -> None:
    """``returns.json``, ``returns.png``, ``settings.toml`` / ``summary.json`` of a sweep."""
    from navkit.io.atomic import write_json
    from navkit.viz.path import plot_returns

    summary = {**sim.summary(), "failed_runs": bs["failed"], "rates": bs["rates"]}
    write_json(
        out / "returns.json",
        {
            **summary,
            "start": sim.start,
            "seeds": f"run i: numpy default_rng(SeedSequence([{seed}, i]))",
            "runs_detail": detail,
        },
    )
    plot_returns(spline, sim, out / "returns.png", stop_radius=ctrl.stop_radius)
    write_run_files(
        out,
        {"path": str(path_json), "runs": runs, "seed": seed, "vo": vo, "controller": ctrl},
        {
            "input": str(path_json),
            **summary,
            "reference": "simulator ground truth: the true final position of each simulated "
            "return against the path's start",
        },
    )
    typer.echo(
        f"{summary['runs']} returns over L = {summary['path_length_m']:.3f} m: final error mean "
        f"{summary['final_error_mean_pct']:.2f} %, p95 {summary['final_error_p95_pct']:.2f} % of L; "
        f"lateral mean {summary['lateral_error_mean_m']:.3f} m -> {out / 'returns.json'}"
    )


@path_app.command("simulate")
def simulate(
    out: Path = typer.Option(..., "--out", "-o", help=OUT_HELP),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
    legs: int = option(7, "--legs", domain=RUN_COUNT, help="Number of straight legs."),
    leg_length: float = option(
        0.5,
        "--leg-length",
        domain=Domain(lo=0.0, hi=100.0, lo_open=True),
        help="Leg length (m) (paper: 0.5).",
    ),
    turn_deg: float = option(
        90.0, "--turn-deg", domain=TURN_DEG, help="Turn between legs (deg) (paper: 90)."
    ),
    random_turns: bool = typer.Option(
        False, "--random-turns", help="Turn left or right at random."
    ),
    seed: int = option(0, "--seed", domain=SEED, help="Random seed."),
    vo_scale_sigma: float = VO_SCALE_SIGMA,
    vo_heading_sigma_deg: float = VO_HEADING_SIGMA_DEG,
) -> None:
    """Drive a simulated robot (legs and turns, like the paper's experiment): true.tum and vo.tum.

    \b
    Example:
      navkit path simulate --legs 7 -o out/path-sim
    """
    with cli_errors():
        import numpy as np

        from navkit.geometry import se3_from_rt
        from navkit.io.trajectory import Trajectory, write_tum
        from navkit.sensors import VisualOdometryNoise
        from navkit.sim.return_sim import leg_drive

        rng = np.random.default_rng(seed)
        vo = VisualOdometryNoise(
            scale_sigma=vo_scale_sigma, heading_sigma=np.radians(vo_heading_sigma_deg)
        )
        true = leg_drive(
            legs, leg_length, turn_deg, rng=rng, random_turns=random_turns, rate_hz=vo.rate_hz
        )
        est = vo.corrupt(true, rng)
        t = np.arange(len(true)) / vo.rate_hz
        check_out_dir(out, overwrite)

        def traj(p: Any) -> Any:
            c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
            R = np.zeros((len(p), 3, 3))
            R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
            return Trajectory(t, se3_from_rt(R, np.c_[p[:, :2], np.zeros(len(p))]))

        write_tum(out / "true.tum", traj(true))
        write_tum(out / "vo.tum", traj(est))
        length = float(np.hypot(*np.diff(true[:, :2], axis=0).T).sum())
        write_run_files(
            out,
            {
                "legs": legs,
                "leg_length": leg_length,
                "turn_deg": turn_deg,
                "random_turns": random_turns,
                "seed": seed,
                "vo": vo,
            },
            {
                "poses": len(true),
                "length_m": length,
                "vo_end_error_m": float(np.hypot(*(est[-1, :2] - true[-1, :2]))),
                "reference": "simulator ground truth (true.tum)",
            },
        )
        typer.echo(f"{len(true)} poses, {length:.2f} m -> {out / 'true.tum'}, {out / 'vo.tum'}")


def register(app: typer.Typer) -> None:
    """Add the ``path`` command group."""
    app.add_typer(path_app, name="path")
