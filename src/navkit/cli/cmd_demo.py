"""``navkit demo``: the built-in mission - out, map, localize, come back - and its report.

Runs :func:`navkit.mission.run_demo` (the "yard" world by default: the robot is driven out
through the yard into the room, the link is lost, it returns along its stored path) and writes
``report.html``, ``metrics.json``, the trajectories, the stored path, the obstacle map and
``results.mcap`` (the runtime's result topics, :mod:`navkit.runtime.mission_sink`; an ``.rrd``
with ``--rerun-save``, the live viewer with ``--rerun``) into ``--out``; then, as before, one picture per simulated sensor at the start pose (lidar, tilting
scanner, RGB-D, stereo, the world) with the truth. ``settings.toml`` / ``summary.json`` hold both.
"""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

import typer

from navkit.cli.common import RERUN, RERUN_SAVE, cli_errors, option, progress, write_run_files
from navkit.domains import SEED, Domain

#: A position in the world frame: either sign.
WORLD_COORDINATE = Domain(note="world frame, either sign")

log = logging.getLogger(__name__)


def register(app: typer.Typer) -> None:
    @app.command("demo")
    def demo(
        out: Path = typer.Option(
            Path("out/demo"),
            "--out",
            "-o",
            help="Folder for the report, metrics, maps and pictures.",
        ),
        overwrite: bool = typer.Option(
            False, "--overwrite", help="Replace the outputs of an earlier run in --out."
        ),
        config: Path = typer.Option(
            None,  # type: ignore[assignment]
            "--config",
            help="Settings TOML: its [mission] table (as in the settings.toml a run writes) "
            "overrides the mission's settings.",
        ),
        seed: int = option(0, "--seed", domain=SEED, help="Seed of the sensor noise."),
        scene: str = typer.Option(
            "yard", "--scene", help="Built-in world name or a scene TOML file."
        ),
        x: float = option(
            None, "--x", domain=WORLD_COORDINATE, help="Robot x (m); default: the world's start."
        ),
        y: float = option(
            None, "--y", domain=WORLD_COORDINATE, help="Robot y (m); default: the world's start."
        ),
        heading_deg: float = option(
            None,
            "--heading-deg",
            domain=Domain(lo=-360.0, hi=360.0, note="signed: counter-clockwise from x"),
            help="Robot heading (deg).",
        ),
        small: bool = typer.Option(False, "--small", help="Low resolution (fast; for tests)."),
        rerun: bool = RERUN,
        rerun_save: Path | None = RERUN_SAVE,
    ) -> None:
        """Run the built-in mission (out, map, localize, come back) into report.html, metrics.json
        and maps; then save a picture of every simulated sensor at the start, with the truth.

        Example: navkit demo --out out/demo --small
        """
        with cli_errors():
            import math

            from navkit.cli.common import check_out_dir
            from navkit.io.atomic import read_json
            from navkit.mission import run_demo
            from navkit.mission.settings import DemoSettings, tomllib
            from navkit.runtime.mission_sink import open_mission_sink
            from navkit.sim import load_scene
            from navkit.viz.demo import render_sensor_pictures
            from navkit.viz.mission import write_report

            check_out_dir(out, overwrite)
            start = load_scene(scene).start
            pose = (
                start[0] if x is None else x,
                start[1] if y is None else y,
                start[2] if heading_deg is None else math.radians(heading_deg),
            )
            settings = DemoSettings.make(scene, seed, small, pose)
            sink = open_mission_sink(out, rerun, rerun_save)
            # the mission (report.html, metrics.json, maps, results.mcap) ...
            metrics = run_demo(
                out,
                seed,
                progress,
                scene=scene,
                small=small,
                start=pose,
                report=write_report,
                config=config,
                sink=sink,
            )
            mission_summary = read_json(out / "summary.json")
            mission_settings = tomllib.loads((out / "settings.toml").read_text(encoding="utf-8"))
            # ... and the sensor pictures at the start pose
            summary = render_sensor_pictures(out, settings, progress)
            summary["mission"] = {
                k: v
                for k, v in mission_summary.items()
                if k not in ("navkit_version", "argv", "kernels")
            }
            write_run_files(out, {**dataclasses.asdict(settings), **mission_settings}, summary)
            r = metrics["return"]
            typer.echo(
                f"mission {r['outcome']}: {r['final_distance_to_operator_m']:.2f} m from the operator; "
                f"report in {out / 'report.html'}; {len(summary['outputs'])} sensor pictures"
            )
