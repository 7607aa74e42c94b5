"""``navkit run``: stream a recording (ROS bag, MCAP, KITTI, CARMEN, RGB-D, trajectory) through
the online capabilities; results as ``results.mcap`` (ROS 2 messages), per-capability files,
``frames.jsonl`` and ``summary.json`` (see ``docs/runtime.md``)."""

from __future__ import annotations

import logging
import threading
import time
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
        from navkit.runtime.run import RunInterrupted, run_recording

        if not resume:
            check_out_dir(out, overwrite)
        logger = None
        if rerun or rerun_save is not None:
            from navkit.viz.rerun_logger import RerunLogger

            logger = RerunLogger(spawn=rerun, save=rerun_save)
        try:
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
        except RunInterrupted as exc:
            of = f" of {exc.n_items}" if exc.n_items else ""
            typer.echo(
                f"interrupted after item {exc.item}{of}: the run in {out} is saved; "
                f"continue it with: {_resume_command()}",
                err=True,
            )
            raise typer.Exit(code=130) from None
        except KeyboardInterrupt:  # a second Ctrl-C, or one outside the item loop
            _hard_interrupt(out)
        caps = ", ".join(_rate(k, v) for k, v in summary["capabilities"].items())
        typer.echo(f"{summary['messages']} messages: {caps} -> {out}")


def _resume_command() -> str:
    """This command line with ``--resume`` (and without ``--overwrite``)."""
    import shlex
    import sys

    args = [a for a in sys.argv[1:] if a != "--overwrite"]
    if "--resume" not in args:
        args.append("--resume")
    return shlex.join(["navkit", *args])


def _hard_interrupt(out: Path) -> None:
    """Ctrl-C that stopped the run at once: keep a run ``--resume`` can continue (its last
    checkpoint, and the outputs of the items before it), or undo the run when it has none."""
    from navkit.io.atomic import current_transaction
    from navkit.runtime.run import STATE_DIR, interrupted_state

    item = interrupted_state(out)
    if item is not None:
        typer.echo(
            f"interrupted: the run in {out} continues from its last checkpoint (item {item}) "
            f"with: {_resume_command()}",
            err=True,
        )
        raise typer.Exit(code=130)  # the command's own decision: its outputs are kept
    import shutil

    if (out / STATE_DIR).is_dir():  # the loop had started: its partial lines and segments
        shutil.rmtree(out / STATE_DIR, ignore_errors=True)
        (out / "frames.jsonl").unlink(missing_ok=True)
    txn = current_transaction()
    if txn is not None:
        txn.rollback()
    typer.echo(
        f"interrupted before the first checkpoint: nothing to resume; the run's outputs in "
        f"{out} were removed",
        err=True,
    )
    raise typer.Exit(code=130)


def _rate(name: str, figures: dict[str, Any]) -> str:
    """``obstacles 62.0 ms/frame at 10.0 Hz (x1.61 real time)``: the work per frame of the
    capability against its sensor's rate."""
    ms, period, rtf = (
        figures.get(k) for k in ("ms_per_frame", "sensor_period_s", "real_time_factor")
    )
    if ms is None:
        return f"{name} no frames"
    if not period or rtf is None:
        return f"{name} {ms:.1f} ms/frame"
    return f"{name} {ms:.1f} ms/frame at {1.0 / period:.1f} Hz (x{rtf:.2f} real time)"


class _Progress:
    """Progress over the recording's time (seconds), on stderr.

    In a terminal: a rich bar on the console the log handler shares (log lines print above it).
    Otherwise (a pipe, a log file, CI): an ``INFO`` line ``run: a / b s of recording (p %), t s
    elapsed, about r s left`` every ``log_every_s`` seconds from a heartbeat thread, so a slow
    frame (a first compilation, a large cloud) never leaves the log silent, and one line at the
    end. Nothing with ``-q``.
    """

    def __init__(self, log_every_s: float = 5.0) -> None:
        self.log_every_s = log_every_s
        self.done_s = 0.0
        self.total_s: float | None = None
        self.bar: Any = None
        self.thread: threading.Thread | None = None
        self.stop = threading.Event()

    def __enter__(self) -> _Progress:
        from navkit.cli.common import _console

        self.t0 = time.perf_counter()
        if STATE.quiet:
            return self
        console = _console()
        if not console.is_terminal:
            self.thread = threading.Thread(target=self._heartbeat, name="navkit-run-progress")
            self.thread.daemon = True
            self.thread.start()
            return self
        from rich.progress import (
            BarColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self.bar = Progress(
            TextColumn("[bold]run"),
            BarColumn(),
            TextColumn("{task.fields[text]}"),
            TimeElapsedColumn(),
            TimeRemainingColumn(),
            console=console,
        )
        self.bar.__enter__()
        # the duration is known once the recording is open: until then the bar pulses
        self.task = self.bar.add_task("run", total=None, text=self.line_text())
        return self

    def line_text(self) -> str:
        """``a / b s of recording`` (``a s of recording`` before the duration is known)."""
        if self.total_s is None:
            return f"{self.done_s:.1f} s of recording"
        return f"{self.done_s:.1f} / {self.total_s:.1f} s of recording"

    def log_line(self) -> str:
        """The line logged when stderr is not a terminal."""
        elapsed = time.perf_counter() - self.t0
        text = f"run: {self.line_text()}"
        if self.total_s:
            frac = min(self.done_s / self.total_s, 1.0)
            text += f" ({100.0 * frac:.0f} %)"
            text += f", {elapsed:.0f} s elapsed"
            if frac > 0:
                text += f", about {elapsed * (1.0 - frac) / frac:.0f} s left"
            return text
        return f"{text}, {elapsed:.0f} s elapsed"

    def _heartbeat(self) -> None:
        while not self.stop.wait(self.log_every_s):
            log.info("%s", self.log_line())

    def update(self, done_s: float, total_s: float) -> None:
        self.done_s, self.total_s = done_s, total_s
        if self.bar is not None:
            self.bar.update(self.task, completed=done_s, total=total_s, text=self.line_text())

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.__exit__(None, None, None)
        if self.thread is not None:
            self.stop.set()
            self.thread.join()
            if exc[0] is None:
                log.info("%s", self.log_line())
