"""Options and the loop shared by every command that takes many inputs (``navkit.batch``).

``--workers N`` runs the inputs on a Dask ``LocalCluster`` of N processes, ``--scheduler ADDR``
on an existing cluster, neither in this process; ``--resume`` skips inputs already complete.
Exit codes: 0 every input ok, 3 when any input failed (its row in ``batch.jsonl`` says why).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import typer

from navkit.cli.common import option
from navkit.domains import Domain

__all__ = [
    "EXIT_SOME_FAILED",
    "RESUME",
    "SCHEDULER",
    "WORKERS",
    "exit_if_failed",
    "expand_sources",
    "run_inputs",
]

EXIT_SOME_FAILED = 3

WORKERS = option(
    None,
    "--workers",
    domain=Domain(integer=True, lo=1, hi=1024),
    help="Run the inputs on a local Dask cluster of N worker processes (needs the cluster extra).",
)
SCHEDULER = typer.Option(
    None,
    "--scheduler",
    help="Run the inputs on an existing Dask cluster, e.g. tcp://head:8786 (needs the cluster extra).",
)
RESUME = typer.Option(
    False,
    "--resume",
    help="Skip inputs whose outputs in --out are complete for the same settings.",
)


def run_inputs(
    tasks: Sequence[Any],
    out: Path,
    *,
    workers: int | None,
    scheduler: str | None,
    resume: bool,
    description: str,
) -> dict[str, Any]:
    """Run ``tasks`` (:class:`navkit.batch.BatchTask`) with a progress bar as inputs complete,
    write ``batch_summary.json``, print failures; returns the summary (see
    :func:`exit_if_failed` for the exit code).
    """
    from navkit.batch import BatchSettings, iter_batch, summarize
    from navkit.cli.common import progress
    from navkit.io.atomic import write_json

    settings = BatchSettings(workers=workers, scheduler=scheduler, resume=resume)
    if settings.distributed:
        from navkit.errors import require_module

        require_module("distributed", "cluster", "--workers / --scheduler")
    rows = list(progress(iter_batch(tasks, out, settings), description, total=len(tasks)))
    summary = summarize(rows)
    write_json(out / "batch_summary.json", summary)
    for f in summary["failures"]:
        typer.echo(f"failed: {f['key']}: {f['error']}", err=True)
    typer.echo(
        f"{summary['ok']} ok, {summary['skipped']} skipped (complete), {summary['failed']} failed"
        f" -> {out / 'batch.jsonl'}"
    )
    for name, rate in summary["rates"].items():
        typer.echo(f"{name.replace('_', ' ')}: {rate['text']}")
    return summary


def exit_if_failed(summary: dict[str, Any]) -> None:
    """Exit with code 3 when any input of the batch failed."""
    if summary.get("failed"):
        raise typer.Exit(code=EXIT_SOME_FAILED)


def expand_sources(inputs: Sequence[str], suffixes: Sequence[str]) -> list[Any]:
    """Like :func:`navkit.cli.common.expand_inputs` (files, folders, globs -> paths), and an
    fsspec URL (``file://``, ``memory://``, ``s3://``...) -> the URLs of the file, folder or
    glob it names (strings, read by the workers through :func:`navkit.io.urls.local_copy`).
    The inputs keep their order; each one's files are sorted."""
    from navkit.cli.common import expand_inputs
    from navkit.io.urls import expand_url, is_url

    found: list[Any] = []
    for item in inputs:
        if is_url(item):
            found.extend(expand_url(item, tuple(suffixes)))
        else:
            found.extend(expand_inputs([item], suffixes))
    return found
