"""``navkit run``: stream a recording (ROS bag, MCAP, KITTI, CARMEN, RGB-D, trajectory) through
the online capabilities; results as ``results.mcap`` (ROS 2 messages), per-capability files,
``frames.jsonl`` and ``summary.json`` (see ``docs/runtime.md``)."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import typer

from navkit.cli.common import RERUN, RERUN_SAVE, STATE, check_out_dir, cli_errors, option
from navkit.domains import POSITIVE

log = logging.getLogger(__name__)


def _read_config(path: Path | None) -> dict[str, Any]:
    if path is None:
        return {}
    from navkit.io.textfiles import load_toml_file

    return load_toml_file(path, "a pipeline TOML file")


def _intrinsics(text: str | None) -> tuple[float, float, float, float] | None:
    from navkit.errors import ConfigError

    if text is None:
        return None
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != 4:
        raise ConfigError(f"= {text!r}", field="--intrinsics", expected="FX,FY,CX,CY in pixels")
    return vals  # type: ignore[return-value]


def register(app: typer.Typer) -> None:
    """Add ``navkit run``."""
    app.command("run")(run_cmd)


def run_cmd(
    recording: Path = typer.Argument(
        ...,
        help="ROS 1 .bag, ROS 2 bag folder, .mcap, KITTI sequence folder, CARMEN log, "
        "TUM RGB-D / 7-Scenes folder or trajectory file.",
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder."),
    map_json: Path | None = typer.Option(
        None,
        "--map",
        help="Wall map (map.json of navkit map build): laser scans are localized in it.",
    ),
    config: Path | None = typer.Option(
        None,
        "--config",
        help="Pipeline TOML with the tables topics, obstacles, laser, planes, path and run.",
    ),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="Replace earlier outputs in the folder."
    ),
    resume: bool = typer.Option(
        False, "--resume", help="Continue a killed run from its last checkpoint."
    ),
    rerun: bool = RERUN,
    rerun_save: Path | None = RERUN_SAVE,
    intrinsics: str | None = typer.Option(
        None, "--intrinsics", help="RGB-D folders without intrinsics: FX,FY,CX,CY (pixels)."
    ),
    depth_scale: float = option(
        1000.0, "--depth-scale", domain=POSITIVE, help="16-bit depth: raw units per metre."
    ),
) -> None:
    """Stream a recording through the online capabilities; results.mcap, frames.jsonl, summary.json.

    Example: navkit run "$NAVKIT_DATA/lidar/semantickitti-seq00" --out out/run-kitti
    """
    with cli_errors():
        from navkit.runtime import run_recording

        if not resume:
            check_out_dir(out, overwrite)
        logger = None
        if rerun or rerun_save is not None:
            from navkit.viz.rerun_logger import RerunLogger

            logger = RerunLogger(spawn=rerun, save=rerun_save)
        with _Progress() as bar:
            summary = run_recording(
                recording,
                out,
                _read_config(config),
                map_path=map_json,
                resume=resume,
                logger=logger,
                on_progress=bar.update,
                intrinsics=_intrinsics(intrinsics),
                depth_scale=depth_scale,
                config_source=str(config or "--config"),
            )
        caps = ", ".join(
            f"{k} {v['ms_per_message']:.1f} ms/msg (x{v['real_time_factor'] or 0:.2f} real time)"
            for k, v in summary["capabilities"].items()
        )
        typer.echo(f"{summary['messages']} messages: {caps} -> {out}")


class _Progress:
    """A progress bar over the recording's time (seconds), on stderr when it is a terminal."""

    def __enter__(self) -> _Progress:
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        console = Console(stderr=True)
        self.bar = Progress(
            TextColumn("[bold]run"),
            BarColumn(),
            TextColumn("{task.completed:.1f} / {task.total:.1f} s of recording"),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            console=console,
            disable=STATE.quiet or not console.is_terminal,
        )
        self.bar.__enter__()
        self.task = self.bar.add_task("run", total=None)
        return self

    def update(self, done_s: float, total_s: float) -> None:
        self.bar.update(self.task, completed=done_s, total=total_s)

    def __exit__(self, *exc: object) -> None:
        self.bar.__exit__(None, None, None)
