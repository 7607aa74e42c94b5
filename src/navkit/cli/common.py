"""Conventions every ``navkit`` command follows.

- Outputs go to ``--out DIR``; each run writes its resolved settings (``settings.toml``) and a
  ``summary.json`` of its key figures there (:func:`write_run_files`).
- Bad input exits with code 2 and one line ``error: ...`` naming the file / field and what was
  expected; a bug exits with code 1 and one line ``internal error: ...``; the traceback only
  with ``navkit --debug`` (:func:`cli_errors`).
- A command's outputs are all-or-nothing: a failed run leaves ``--out`` as it was
  (:func:`cli_errors` opens a :func:`navkit.io.atomic.output_transaction`).
- Long work shows a progress bar (:func:`progress`), on stderr, hidden when not a terminal.
- Heavy imports happen inside the command functions, so ``navkit --help`` stays fast.
"""

from __future__ import annotations

import dataclasses
import logging
import sys
from collections.abc import Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any, TypeVar

import typer

from navkit.errors import InputError, NavkitError

__all__ = [
    "STATE",
    "check_finite_options",
    "check_out_path",
    "cli_errors",
    "expand_inputs",
    "progress",
    "settings_to_toml",
    "write_run_files",
]

T = TypeVar("T")
log = logging.getLogger(__name__)


@dataclasses.dataclass
class _State:
    debug: bool = False
    quiet: bool = False


STATE = _State()


def _context() -> Any:
    """click's context of the running command, or None outside one."""
    try:  # typer >= 0.17 vendors click as typer._click
        from typer._click.globals import get_current_context
    except ImportError:  # pragma: no cover - older typer uses click itself
        from click import get_current_context  # type: ignore[no-redef]

    return get_current_context(silent=True)


def _out_dirs() -> list[Path]:
    """The ``--out`` folder(s) of the running command, from click's context (none outside one)."""
    ctx = _context()
    if ctx is None:
        return []
    return [
        Path(value)
        for name, value in ctx.params.items()
        if name in ("out", "out_dir", "output") and isinstance(value, (str, Path))
    ]


#: Bound on any numeric option (as for settings, :data:`navkit.geometry._validate.MAX_SETTING_MAGNITUDE`):
#: nothing a robot measures or counts is beyond 1e9 in SI units; seeds are exempt.
MAX_OPTION_MAGNITUDE = 1e9


def check_finite_options() -> None:
    """Refuse NaN, infinite and absurdly large values of the running command's numeric options.

    Every command gets this through :func:`cli_errors`, whatever its options: no navkit option
    means anything with NaN, and "no limit" is written as a large number, never ``inf``
    (decision: one rule for every command beats per-option callbacks that a new option forgets).

    Raises
    ------
    InputError
        Naming the option and its value.
    """
    import math

    ctx = _context()
    if ctx is None:
        return
    names = {
        p.name: (p.opts[0] if getattr(p, "opts", None) else p.name) for p in ctx.command.params
    }
    for name, value in ctx.params.items():
        values = value if isinstance(value, (list, tuple)) else [value]
        for v in values:
            if isinstance(v, float) and not math.isfinite(v):
                raise InputError(
                    f"is {v}", source=names.get(name, name), expected="a finite number"
                )
            if (
                isinstance(v, (int, float))
                and not isinstance(v, bool)
                and "seed" not in name
                and abs(v) > MAX_OPTION_MAGNITUDE
            ):
                raise InputError(
                    f"is {v}",
                    source=names.get(name, name),
                    expected=f"a magnitude of at most {MAX_OPTION_MAGNITUDE:.0e}",
                )


def check_out_path(out: Path) -> None:
    """Refuse an ``--out`` that is a file or lies under a file, before anything runs.

    Raises
    ------
    InputError
        Naming the file that is in the way.
    """
    for d in (out, *out.parents):
        if d.exists():
            if not d.is_dir():
                where = "is a file" if d == out else f"lies under the file {d}"
                raise InputError(
                    f"the output folder {where}, not a folder",
                    source=out,
                    field="--out",
                    expected="a folder, or a path that does not exist yet",
                )
            return


def _command_line() -> str:
    return " ".join(["navkit", *sys.argv[1:]])


@contextmanager
def cli_errors() -> Iterator[None]:
    """Run a command body as one transaction, with the CLI's error handling.

    - The body's outputs are all-or-nothing (:func:`navkit.io.atomic.output_transaction`): a
      failed or interrupted run leaves ``--out`` exactly as it was. A ``typer.Exit`` raised by
      the body is the command's own decision (any code): its outputs are kept.
    - A navkit error (bad input) prints ``error: ...`` and exits 2; so do operating-system errors
      on a named file, undecodable text and inputs too large for memory.
    - Ctrl-C exits 130.
    - Anything else is a bug: one line ``internal error: <type>: <message> (command: ...; run with
      --debug for the traceback)`` and exit code 1, never 0.

    With ``navkit --debug`` every exception propagates with its traceback (after the rollback).
    """
    from navkit.io.atomic import output_transaction

    try:
        check_finite_options()
        outs = _out_dirs()
        for out in outs:
            check_out_path(out)
        deliberate: typer.Exit | None = None
        with output_transaction(*outs):
            try:
                yield
            except typer.Exit as exc:  # the command chose its exit code: keep what it wrote
                deliberate = exc
        if deliberate is not None:
            raise deliberate
    except (typer.Exit, typer.Abort):
        raise
    except Exception as exc:
        if _is_click_exception(exc) or STATE.debug:
            raise
        _report(exc)
    except KeyboardInterrupt:
        if STATE.debug:
            raise
        typer.echo("interrupted: no output was changed", err=True)
        raise typer.Exit(code=130) from None


def _is_click_exception(exc: BaseException) -> bool:
    """Click's own control flow (usage errors, exit, abort), vendored by typer or not."""
    return any(cls.__module__.split(".")[0] in ("click", "typer") for cls in type(exc).__mro__[:-2])


def _unreadable_input_types() -> tuple[type[BaseException], ...]:
    import json

    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    import zipfile

    return (
        UnicodeDecodeError,
        json.JSONDecodeError,
        tomllib.TOMLDecodeError,
        RecursionError,
        EOFError,
        zipfile.BadZipFile,
    )


_UNREADABLE_INPUT = _unreadable_input_types()


def _report(exc: Exception) -> None:
    """Print one line for ``exc`` and exit: 2 for bad input, 1 for a bug."""
    if isinstance(exc, NavkitError):
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(code=2) from None
    if isinstance(exc, OSError) and exc.filename is not None:
        where = exc.filename if exc.filename2 is None else f"{exc.filename} -> {exc.filename2}"
        typer.echo(f"error: {where}: {exc.strerror or exc}", err=True)
        raise typer.Exit(code=2) from None
    if isinstance(exc, _UNREADABLE_INPUT):
        # a parser deep inside a reader met a user file it cannot read: still bad input
        message = " ".join(str(exc).split())[:200] or type(exc).__name__
        typer.echo(
            f"error: an input could not be read ({type(exc).__name__}: {message}; "
            f"command: {_command_line()})",
            err=True,
        )
        raise typer.Exit(code=2) from None
    if isinstance(exc, MemoryError):
        typer.echo(
            f"error: the input needs more memory than is available (command: {_command_line()})",
            err=True,
        )
        raise typer.Exit(code=2) from None
    _internal_error(exc)  # the last line of defence: a bug, reported in one line


def internal_error_line(exc: BaseException) -> str:
    """The one line printed for an unexpected exception (a bug, not a bad input)."""
    message = " ".join(str(exc).split())[:300]
    return (
        f"internal error: {type(exc).__name__}: {message} "
        f"(command: {_command_line()}; run with --debug for the traceback)"
    )


def _internal_error(exc: BaseException) -> None:
    typer.echo(internal_error_line(exc), err=True)
    raise typer.Exit(code=1) from None


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


def settings_to_toml(settings: Any) -> str:
    """TOML text of a settings dataclass (or a dict of them), nested tables for nested dataclasses."""
    import tomli_w

    from navkit.io.atomic import to_jsonable

    def clean(value: Any) -> Any:
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items() if v is not None}
        if isinstance(value, list):
            return [clean(v) for v in value if v is not None]
        return value

    return tomli_w.dumps(clean(to_jsonable(settings)))


def write_run_files(out: Path, settings: Any, summary: dict[str, Any]) -> None:
    """Write ``settings.toml`` and ``summary.json`` into ``out`` (atomically)."""
    from navkit import __version__
    from navkit.io.atomic import write_json, write_text

    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "settings.toml", settings_to_toml(settings))
    write_json(
        out / "summary.json", {"navkit_version": __version__, "argv": sys.argv[1:], **summary}
    )
