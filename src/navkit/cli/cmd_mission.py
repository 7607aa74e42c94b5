"""``navkit mission run SCENE --out DIR`` (the integrated mission in a user's world) and
``navkit mission sweep SCENE --seeds A:B`` (one run per seed, outcomes with 95 % intervals)."""

from __future__ import annotations

from pathlib import Path

import typer

from navkit.cli.batching import RESUME, SCHEDULER, WORKERS, exit_if_failed, run_inputs
from navkit.cli.common import RERUN, RERUN_SAVE, option
from navkit.domains import SEED

mission_app = typer.Typer(
    help="The integrated mission: out, map, localize, come back.", no_args_is_help=True
)


def register(app: typer.Typer) -> None:
    app.add_typer(mission_app, name="mission")


def _progress():  # type: ignore[no-untyped-def]
    from navkit.cli.common import progress

    def wrap(items, description, total):  # type: ignore[no-untyped-def]
        return progress(items, description, total=total)

    return wrap


@mission_app.command("run")
def run(
    scene: str = typer.Argument(..., help="Scene TOML file (or a built-in scene name, e.g. yard)."),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder."),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="Replace the outputs of an earlier run in --out."
    ),
    mission: Path = typer.Option(
        None,
        "--mission",  # type: ignore[assignment]
        help="Mission TOML (a route table: waypoints, room; a settings table: overrides). "
        "Default: <scene>.mission.toml beside the scene.",
    ),
    config: Path = typer.Option(
        None,  # type: ignore[assignment]
        "--config",
        help="Settings TOML: its [mission] table (as in the settings.toml a run writes) "
        "overrides the mission file's settings.",
    ),
    seed: int = option(None, "--seed", domain=SEED, help="Seed of every random draw."),
    small: bool = typer.Option(False, "--small", help="Reduced sensor resolutions (quick runs)."),
    rerun: bool = RERUN,
    rerun_save: Path | None = RERUN_SAVE,
) -> None:
    """Drive the robot out along the route, map, localize, lose the link, come back; write
    report.html, metrics.json, trajectories (TUM), path.json, the obstacle map (PGM+YAML) and
    results.mcap (ROS 2 messages; --rerun-save FILE.rrd for Rerun).

    Example: navkit mission run yard --out out/mission --small
    """
    from navkit.cli.common import check_out_dir, cli_errors

    with cli_errors():
        from navkit.mission.demo import run_scene_file
        from navkit.runtime.mission_sink import open_mission_sink
        from navkit.viz.mission import write_report

        check_out_dir(out, overwrite)
        sink = open_mission_sink(out, rerun, rerun_save)
        m = run_scene_file(
            scene,
            out,
            mission=mission,
            seed=seed,
            small=small,
            progress=_progress(),
            report=write_report,
            config=config,
            sink=sink,
        )
        r = m["return"]
        typer.echo(
            f"{r['outcome']}: {r['final_distance_to_operator_m']:.2f} m from the operator; "
            f"report in {out / 'report.html'}"
        )


@mission_app.command("sweep")
def sweep(
    scene: str = typer.Argument(..., help="Scene TOML file (or a built-in scene name, e.g. yard)."),
    seeds: str = typer.Option(
        "0:10", "--seeds", help="Seeds: START:STOP (STOP excluded) or a list 1,5,9."
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder (one folder per seed)."),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="Replace the outputs of an earlier sweep in --out."
    ),
    mission: Path = typer.Option(
        None,  # type: ignore[assignment]
        "--mission",
        help="Mission TOML. Default: <scene>.mission.toml beside the scene.",
    ),
    config: Path = typer.Option(
        None,  # type: ignore[assignment]
        "--config",
        help="Settings TOML whose mission table overrides the mission file's settings.",
    ),
    small: bool = typer.Option(False, "--small", help="Reduced sensor resolutions (quick runs)."),
    workers: int = WORKERS,
    scheduler: str = SCHEDULER,
    resume: bool = RESUME,
) -> None:
    """Run the mission once per seed and summarise the outcomes with 95 % intervals
    (batch.jsonl, batch_summary.json; each seed's metrics.json under seed-N/).

    Example: navkit mission sweep yard --seeds 0:20 --small --workers 2 --out out/sweep
    """
    from navkit.cli.common import check_out_dir, cli_errors

    with cli_errors():
        from navkit.batch import mission_sweep_tasks, parse_seeds

        tasks = mission_sweep_tasks(
            scene,
            parse_seeds(seeds),
            mission=mission,
            small=small,
            config=config,
        )
        check_out_dir(out, overwrite or resume)  # --resume continues in the same folder
        summary = run_inputs(
            tasks,
            out,
            workers=workers,
            scheduler=scheduler,
            resume=resume,
            description="missions",
        )
    exit_if_failed(summary)
