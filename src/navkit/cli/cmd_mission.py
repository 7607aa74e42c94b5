"""``navkit mission run SCENE.toml --out DIR``: the integrated mission in a user's world."""

from __future__ import annotations

from pathlib import Path

import typer


def _progress():  # type: ignore[no-untyped-def]
    from navkit.cli.common import progress

    def wrap(items, description, total):  # type: ignore[no-untyped-def]
        return progress(items, description, total=total)

    return wrap


def register(app: typer.Typer) -> None:
    mission_app = typer.Typer(
        help="The integrated mission: out, map, localize, come back.", no_args_is_help=True
    )
    app.add_typer(mission_app, name="mission")

    @mission_app.command("run")
    def run(
        scene: str = typer.Argument(
            ..., help="Scene TOML file (or a built-in scene name, e.g. yard)."
        ),
        out: Path = typer.Option(Path("out/mission"), "--out", help="Output folder."),
        mission: Path = typer.Option(
            None,
            "--mission",  # type: ignore[assignment]
            help="Mission TOML (a route table: waypoints, room; a settings table: overrides). "
            "Default: <scene>.mission.toml beside the scene.",
        ),
        seed: int = typer.Option(None, "--seed", help="Seed of every random draw."),  # type: ignore[assignment]
        small: bool = typer.Option(
            False, "--small", help="Reduced sensor resolutions (quick runs)."
        ),
    ) -> None:
        """Drive the robot out along the route, map, localize, lose the link, come back; write
        report.html, metrics.json, trajectories (TUM), path.json and the obstacle map (PGM+YAML)."""
        from navkit.cli.common import cli_errors

        with cli_errors():
            from navkit.mission.demo import run_scene_file

            m = run_scene_file(
                scene, out, mission=mission, seed=seed, small=small, progress=_progress()
            )
            r = m["return"]
            typer.echo(
                f"{r['outcome']}: {r['final_distance_to_operator_m']:.2f} m from the operator; "
                f"report in {out / 'report.html'}"
            )
