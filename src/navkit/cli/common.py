"""Conventions every ``navkit`` command follows.

- Outputs go to ``--out DIR``; each run writes its resolved settings (``settings.toml``) and a
  ``summary.json`` of its key figures there (:func:`write_run_files`).
- Bad input exits with code 2 and one line ``error: ...`` naming the file / field and what was
  expected; the traceback only with ``navkit --debug`` (:func:`cli_errors`).
- Long work shows a progress bar (:func:`progress`), on stderr, hidden when not a terminal.
- Heavy imports happen inside the command functions, so ``navkit --help`` stays fast.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TypeVar

import typer

from navkit.errors import InputError, NavkitError

__all__ = [
    "STATE",
    "cli_errors",
    "expand_inputs",
    "progress",
    "write_run_files",
]

T = TypeVar("T")
log = logging.getLogger(__name__)


@dataclasses.dataclass
class _State:
    debug: bool = False
    quiet: bool = False


STATE = _State()


@contextmanager
def cli_errors() -> Iterator[None]:
    """Turn navkit errors into ``error: ...`` on stderr and exit code 2 (traceback with --debug)."""
    try:
        yield
    except NavkitError as exc:
        if STATE.debug:
            raise
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=2) from None
    except (FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        if STATE.debug:
            raise
        typer.echo(f"error: {exc.filename or ''}: {exc.strerror}", err=True)
        raise typer.Exit(code=2) from None


def progress(
    items: Sequence[T] | Iterable[T], description: str, total: int | None = None
) -> Iterator[T]:
    """Iterate with a rich progress bar on stderr (silent when stderr is not a terminal)."""
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    if total is None and hasattr(items, "__len__"):
        total = len(items)  # type: ignore[arg-type]
    console = Console(stderr=True)
    disable = STATE.quiet or not console.is_terminal
    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        disable=disable,
        transient=False,
    ) as bar:
        task = bar.add_task(description, total=total)
        for item in items:
            yield item
            bar.advance(task)


def expand_inputs(inputs: Sequence[str], suffixes: Sequence[str]) -> list[Path]:
    """Files from a mix of files, folders (their files with the given suffixes) and globs, sorted.

    Raises
    ------
    InputError
        If an input matches nothing, or nothing usable is found at all.
    """
    import glob

    found: list[Path] = []
    for item in inputs:
        path = Path(item)
        if path.is_dir():
            found.extend(sorted(p for p in path.iterdir() if p.suffix.lower() in suffixes))
        elif path.is_file():
            found.append(path)
        else:
            matches = sorted(Path(m) for m in glob.glob(item) if Path(m).is_file())
            if not matches:
                raise InputError(
                    "no such file, folder or matching glob",
                    source=item,
                    expected=f"files ending in {', '.join(suffixes)}",
                )
            found.extend(matches)
    if not found:
        raise InputError(
            "no input files found",
            source=", ".join(inputs),
            expected=f"files ending in {', '.join(suffixes)}",
        )
    return found


from navkit.io.atomic import write_run_files  # noqa: E402  (one writer, in navkit.io)
