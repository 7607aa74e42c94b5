"""The ``navkit`` command.

Each capability contributes a module ``navkit/cli/cmd_<name>.py`` that defines
``register(app: typer.Typer) -> None`` (adding its sub-command group or commands); modules are
found automatically, so a capability lands without editing this file.
"""

from __future__ import annotations

import importlib
import logging
import pkgutil
from typing import Any, Optional

import typer
from typer.core import TyperGroup

import navkit.cli
from navkit import __version__, jit
from navkit.cli.common import STATE, configure_logging

GLOBAL_FLAGS = ("-q", "--quiet", "--debug")
"""Options of the ``navkit`` command itself that may also be written after the sub-command."""


class _GlobalFlagsAnywhere(TyperGroup):
    """The root group: moves ``-q`` / ``--quiet`` / ``--debug`` from anywhere on the line
    (up to a ``--``) to before the sub-command, so ``navkit obstacles detect ... -q`` works."""

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:  # typer's own click Context
        end = args.index("--") if "--" in args else len(args)
        flags = [a for a in args[:end] if a in GLOBAL_FLAGS]
        rest = [a for a in args[:end] if a not in GLOBAL_FLAGS]
        return super().parse_args(ctx, flags + rest + args[end:])


app = typer.Typer(
    cls=_GlobalFlagsAnywhere,
    name="navkit",
    help="See, map, localize and come home without satellite navigation.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"navkit {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    version: Optional[bool] = typer.Option(  # noqa: UP045 - typer needs Optional on 3.10
        None, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
    debug: bool = typer.Option(False, "--debug", help="Show tracebacks and debug logging."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bars, warnings only."),
) -> None:
    """navkit: obstacles, planes, stereo room maps, localization and path memory for robots.

    -q / --quiet and --debug may be given anywhere on the line. Every command writes into
    --out DIR and refuses to replace earlier outputs there unless --overwrite is given.
    """
    STATE.debug, STATE.quiet = debug, quiet
    level = logging.DEBUG if debug else (logging.WARNING if quiet else logging.INFO)
    configure_logging(level)
    # a command on a machine whose kernels were never compiled runs their NumPy twins and starts
    # their compilation in the background for the next runs (navkit.jit, "auto")
    jit.on_missing_kernels(_start_background_warmup)


def _start_background_warmup() -> bool:
    from navkit.runtime.warmup import start_background

    return start_background()


def _register_commands() -> None:
    for info in sorted(pkgutil.iter_modules(navkit.cli.__path__), key=lambda m: m.name):
        if info.name.startswith("cmd_"):
            importlib.import_module(f"navkit.cli.{info.name}").register(app)


_register_commands()


def run() -> None:
    """The ``navkit`` entry point: :data:`app` with a last line of defence around it.

    Command bodies handle their errors in :func:`navkit.cli.common.cli_errors`; this catches what
    escapes outside a body (option callbacks, command registration): one ``internal error: ...``
    line and exit code 1, Ctrl-C exit code 130; with ``--debug`` the traceback.
    """
    import sys

    from navkit.cli.common import internal_error_line

    try:
        app()  # standalone: click prints usage errors and exits itself
    except Exception as exc:
        if STATE.debug or "--debug" in sys.argv[1:]:
            raise
        typer.echo(internal_error_line(exc), err=True)
        sys.exit(1)


if __name__ == "__main__":  # pragma: no cover
    run()
