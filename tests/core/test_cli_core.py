"""The CLI's shared conventions: --help, --version, error lines and exit codes, run files."""

import json

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib
from dataclasses import dataclass

import pytest
import typer
from typer.testing import CliRunner

import navkit
from navkit.cli.common import STATE, cli_errors, expand_inputs, write_run_files
from navkit.errors import InputError


def test_help_and_version(cli):
    r = cli("--help")
    assert r.exit_code == 0 and "navkit" in r.stdout
    r = cli("--version")
    assert r.exit_code == 0 and r.stdout.strip() == f"navkit {navkit.__version__}"


def _app():
    app = typer.Typer()

    @app.command()
    def boom(path: str) -> None:
        with cli_errors():
            raise InputError("cannot read", source=path, field="ranges", expected="2-D array")

    return app


def test_navkit_error_becomes_one_line_and_exit_2():
    r = CliRunner().invoke(_app(), ["scan.npz"])
    assert r.exit_code == 2
    assert r.stderr.strip() == "error: scan.npz: field 'ranges': cannot read (expected 2-D array)"


def test_debug_shows_the_exception(monkeypatch):
    monkeypatch.setattr(STATE, "debug", True)
    r = CliRunner().invoke(_app(), ["scan.npz"])
    assert r.exit_code == 1 and isinstance(r.exception, InputError)


def test_expand_inputs(tmp_path):
    for name in ("b.bin", "a.bin", "c.txt"):
        (tmp_path / name).write_text("x")
    assert [p.name for p in expand_inputs([str(tmp_path)], [".bin"])] == ["a.bin", "b.bin"]
    assert [p.name for p in expand_inputs([str(tmp_path / "*.txt")], [".bin"])] == ["c.txt"]
    with pytest.raises(InputError, match="no such file"):
        expand_inputs([str(tmp_path / "missing.bin")], [".bin"])


@dataclass(frozen=True)
class _Inner:
    c0_deg: float = 20.0


@dataclass(frozen=True)
class _Settings:
    tolerance: float = 0.05
    name: str = "x"
    inner: _Inner = _Inner()


def test_run_files(tmp_path):
    write_run_files(tmp_path, _Settings(), {"frames": 3})
    settings = tomllib.loads((tmp_path / "settings.toml").read_text())
    assert settings == {"tolerance": 0.05, "name": "x", "inner": {"c0_deg": 20.0}}
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["frames"] == 3 and summary["navkit_version"] == navkit.__version__
