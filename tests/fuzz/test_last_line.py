"""The CLI's last line of defence and its output transaction, on a command made to fail."""

from __future__ import annotations

from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from navkit.cli.common import cli_errors
from navkit.errors import InputError
from navkit.io.atomic import write_text

from .conftest import record

app = typer.Typer()


@app.command()
def fail(kind: str, out: Path = typer.Option(..., "--out")) -> None:
    with cli_errors():
        write_text(out / "first.txt", "written before the failure")
        write_text(out / "keep.txt", "new contents")
        if kind == "bug":
            raise KeyError("no such key")
        if kind == "interrupt":
            raise KeyboardInterrupt
        if kind == "bad":
            raise InputError("is -1", source="x.toml", field="rate", expected="> 0")
        if kind == "oserror":
            open(out / "no" / "such" / "file")
        if kind == "decode":
            b"\xff".decode("utf-8")
        if kind == "memory":
            raise MemoryError
        if kind == "exit3":  # the command decides its own exit code: its outputs stay
            raise typer.Exit(3)


@pytest.mark.parametrize(
    ("kind", "code", "text"),
    [
        ("ok", 0, ""),
        ("exit3", 3, ""),
        ("bug", 1, "internal error: KeyError: 'no such key' (command: "),
        ("interrupt", 130, "interrupted"),
        ("bad", 2, "error: x.toml: field 'rate': is -1 (expected > 0)"),
        ("oserror", 2, "No such file or directory"),
        ("decode", 2, "error: an input could not be read (UnicodeDecodeError"),
        ("memory", 2, "more memory than is available"),
    ],
)
def test_one_line_exit_code_and_untouched_out(tmp_path: Path, kind: str, code: int, text: str):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("old contents")
    res = CliRunner().invoke(app, [kind, "--out", str(out)], catch_exceptions=False)
    record("cli", "valid" if code in (0, 3) else "errors")
    assert res.exit_code == code, res.output
    assert text in res.output
    assert "Traceback" not in res.output and len(res.output.strip().splitlines()) <= 1
    if code in (0, 3):
        assert (out / "keep.txt").read_text() == "new contents"
        assert sorted(p.name for p in out.iterdir()) == ["first.txt", "keep.txt"]
    else:  # everything the failed run wrote is gone, the old file is back, no temporary left
        assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]
        assert (out / "keep.txt").read_text() == "old contents"


def test_failed_run_removes_the_out_folder_it_created(tmp_path: Path):
    out = tmp_path / "new" / "deeper"
    res = CliRunner().invoke(app, ["bug", "--out", str(out)], catch_exceptions=False)
    assert res.exit_code == 1
    assert not (tmp_path / "new").exists()
