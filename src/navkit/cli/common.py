"""Conventions every ``navkit`` command follows.

- Outputs go to ``--out DIR``; each run writes its resolved settings (``settings.toml``) and a
  ``summary.json`` of its key figures there (:func:`write_run_files`), with a ``"reference"``
  field saying what its headline figures are measured against.
- Every numeric option declares its domain where it is defined (:func:`option` with a
  :class:`navkit.domains.Domain`: positive, an integer range, ...); one check
  (:func:`check_option_domains`) refuses a value outside it before the command body runs.
- Bad input exits with code 2 and one line ``error: ...`` naming the file / field and what was
  expected; a bug exits with code 1 and one line ``internal error: ...``; the traceback only
  with ``navkit --debug`` (:func:`cli_errors`).
- A command's outputs are all-or-nothing: a failed run leaves ``--out`` as it was
  (:func:`cli_errors` opens a :func:`navkit.io.atomic.output_transaction`).
- Existing outputs are never replaced silently: a command calls :func:`check_out_dir` once,
  which refuses a non-empty ``--out`` folder unless ``--overwrite`` is given.
- Long work shows a progress bar (:func:`progress`) on stderr in a terminal, and periodic log
  lines (``INFO``) when stderr is not a terminal (a log file, CI); log lines go through rich's
  handler on the same console, so they print above the bar instead of over it
  (:func:`configure_logging`).
- ``-q`` / ``--quiet`` and ``--debug`` may stand anywhere on the command line.
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

from navkit.domains import Domain
from navkit.errors import InputError, NavkitError

__all__ = [
    "STATE",
    "check_finite_options",
    "check_option_domains",
    "check_out_dir",
    "check_out_path",
    "cli_errors",
    "configure_logging",
    "expand_inputs",
    "option",
    "option_domain",
    "option_name",
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


def _context() -> Any:
    """click's context of the running command, or None outside one."""
    # typer >= 0.26 (the floor in pyproject.toml) vendors click as typer._click; earlier typer
    # depended on click itself, which navkit would then import without declaring it
    from typer._click.globals import get_current_context

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


def option(default: Any, *names: str, domain: Domain, help: str, **kwargs: Any) -> Any:
    """A numeric ``typer.Option`` with its :class:`~navkit.domains.Domain`.

    The domain is shown at the end of the option's help and enforced, with every other
    option's, by :func:`check_option_domains` before the command body runs. Every numeric
    option of every command is declared with this (``tests/fuzz/test_cli.py`` checks it).
    """
    info = typer.Option(default, *names, help=f"{help} [{domain.describe()}]", **kwargs)
    info.navkit_domain = domain  # type: ignore[attr-defined]
    return info


def option_domain(param: Any) -> Domain | None:
    """The :class:`~navkit.domains.Domain` declared with :func:`option` for a click parameter
    of a typer command, or None."""
    info = getattr(getattr(param, "type_descriptor", None), "parameter_info", None)
    return getattr(info, "navkit_domain", None)


def option_name(param: Any) -> str:
    """An option's longest spelling (``--rings``), or an argument's name."""
    opts = getattr(param, "opts", None) or [param.name]
    return max(opts, key=len)


def check_option_domains() -> None:
    """Refuse any option value of the running command outside its declared domain.

    Every command gets this through :func:`cli_errors`, whatever its options: a numeric option
    declared with :func:`option` is checked against its domain; any other number must be finite
    and at most :data:`navkit.domains.MAX_MAGNITUDE` in magnitude (no navkit option means
    anything with NaN, and "no limit" is written as a large number, never ``inf``). A value left
    at None (the option's "not given") is not checked.

    Raises
    ------
    InputError
        Naming the option, its value and its domain (``--rings: is 0 (expected an integer
        >= 1)``).
    """
    ctx = _context()
    if ctx is None:
        return
    for param in ctx.command.params:
        if param.name not in ctx.params:
            continue
        value = ctx.params[param.name]
        values = value if isinstance(value, (list, tuple)) else [value]
        domain = option_domain(param)
        for v in values:
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                continue
            (domain or _ANY_NUMBER).check(v, option_name(param))


_ANY_NUMBER = Domain()


check_finite_options = check_option_domains  # the earlier name of the same check


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
        check_option_domains()
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


def _console() -> Any:
    """The one rich console on stderr shared by the progress bar and the log handler."""
    global _CONSOLE
    if _CONSOLE is None:
        from rich.console import Console

        _CONSOLE = Console(stderr=True)
    return _CONSOLE


_CONSOLE: Any = None
_HANDLER_TAG = "_navkit_cli_handler"


class _StderrHandler(logging.StreamHandler):  # type: ignore[type-arg]
    """Writes to whatever ``sys.stderr`` is at each record (test runners swap and close it)."""

    def emit(self, record: logging.LogRecord) -> None:
        self.stream = sys.stderr
        super().emit(record)


def configure_logging(level: int) -> None:
    """Send log records to stderr: rich's handler on the progress bar's console in a terminal
    (so a log line prints above the bar, not over it), plain ``LEVEL name: message`` lines
    otherwise. Replaces the handler an earlier call installed; other handlers are left alone."""
    root = logging.getLogger()
    for h in list(root.handlers):
        if getattr(h, _HANDLER_TAG, False):
            root.removeHandler(h)
    console = _console()
    handler: logging.Handler
    if console.is_terminal:
        from rich.logging import RichHandler

        handler = RichHandler(console=console, show_path=False, show_time=False)
        handler.setFormatter(logging.Formatter("%(name)s: %(message)s"))
    else:
        handler = _StderrHandler()
        handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    setattr(handler, _HANDLER_TAG, True)
    root.addHandler(handler)
    root.setLevel(level)
    # numexpr (imported by pandas) announces its thread count at INFO on every import
    logging.getLogger("numexpr.utils").setLevel(max(level, logging.WARNING))


def progress(
    items: Sequence[T] | Iterable[T],
    description: str,
    total: int | None = None,
    *,
    log_every_s: float = 5.0,
) -> Iterator[T]:
    """Iterate with progress reports on stderr.

    In a terminal: a rich progress bar. Otherwise (a log file, CI): an ``INFO`` log line
    ``description: k/n done (p %), t s elapsed, about r s left`` at most every ``log_every_s``
    seconds and one when the work is done. Nothing with ``-q``.
    """
    import time

    if total is None and hasattr(items, "__len__"):
        total = len(items)  # type: ignore[arg-type]
    console = _console()
    if STATE.quiet:
        yield from items
        return
    if not console.is_terminal:
        plog = logging.getLogger("navkit.progress")
        t0 = last = time.perf_counter()
        done = 0
        for item in items:
            yield item
            done += 1
            now = time.perf_counter()
            if now - last >= log_every_s or (total is not None and done == total):
                last = now
                plog.info("%s", _progress_line(description, done, total, now - t0))
        if total is None or done != total:
            plog.info("%s", _progress_line(description, done, done, time.perf_counter() - t0))
        return
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console,
        transient=False,
    ) as bar:
        task = bar.add_task(description, total=total)
        for item in items:
            yield item
            bar.advance(task)


def _progress_line(description: str, done: int, total: int | None, elapsed_s: float) -> str:
    if not total:
        return f"{description}: {done} done, {elapsed_s:.1f} s elapsed"
    left = elapsed_s / done * (total - done) if done else float("nan")
    return (
        f"{description}: {done}/{total} done ({100.0 * done / total:.0f} %), "
        f"{elapsed_s:.1f} s elapsed, about {left:.0f} s left"
    )


RERUN = typer.Option(False, "--rerun", help="Stream the run to the Rerun viewer (extra 'rerun').")
RERUN_SAVE = typer.Option(
    None,
    "--rerun-save",
    help="Record the run to this .rrd file for the Rerun viewer (headless).",
)
"""``--rerun`` / ``--rerun-save FILE.rrd`` of ``navkit run``, ``demo`` and ``mission run``."""


def check_out_dir(out: Path, overwrite: bool) -> Path:
    """Make ``out`` ready for a command's outputs; refuse to replace earlier ones silently.

    A missing folder is created; an empty one is used as is. A folder that already holds
    anything is refused with an :class:`~navkit.errors.InputError` naming it and a few of its
    entries, unless ``overwrite`` is true; then files of the same names are replaced as they are
    written and other files in it are left alone (nothing is deleted).

    Raises
    ------
    InputError
        ``out`` is a file, or a non-empty folder and ``overwrite`` is false.
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError("is a file", source=out, field="--out", expected="a folder (new or empty)")
    if out.is_dir() and not overwrite:
        entries = sorted(p.name for p in out.iterdir())
        if entries:
            shown = ", ".join(entries[:5]) + (", ..." if len(entries) > 5 else "")
            raise InputError(
                f"already holds outputs ({shown})",
                source=out,
                field="--out",
                expected="a new or empty folder, or --overwrite to replace them",
            )
    out.mkdir(parents=True, exist_ok=True)
    return out


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
