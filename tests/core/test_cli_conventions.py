"""The CLI conventions: -q / --debug anywhere, help that reads at 80 columns with units
and an example, progress as log lines off a terminal, outputs never replaced silently."""

from __future__ import annotations

import io
import json
import logging
import re

import pytest
import typer
from typer.testing import CliRunner

from navkit.cli import common
from navkit.cli.common import STATE, check_out_dir, configure_logging, progress
from navkit.cli.main import app
from navkit.errors import InputError

# commands whose help carries an example (the others gain theirs as they are rewritten)
WITH_EXAMPLES = (
    ("obstacles", "detect"),
    ("path", "record"),
    ("path", "return"),
    ("path", "simulate"),
    ("stereo", "disparity"),
    ("stereo", "simulate"),
)


def _commands(group, prefix: tuple[str, ...] = ()):
    ctx = typer.Context(group)
    for name in group.list_commands(ctx):
        cmd = group.get_command(ctx, name)
        if hasattr(cmd, "list_commands"):
            yield from _commands(cmd, (*prefix, name))
        else:
            yield (*prefix, name), cmd


ROOT = typer.main.get_command(app)
ALL = dict(_commands(ROOT))


@pytest.fixture(autouse=True)
def _restore_state():
    saved = (STATE.debug, STATE.quiet)
    yield
    STATE.debug, STATE.quiet = saved


@pytest.mark.parametrize("path", sorted(ALL), ids=" ".join)
def test_help_reads_at_80_columns(path):
    r = CliRunner().invoke(app, [*path, "--help"], env={"COLUMNS": "80"})
    assert r.exit_code == 0, r.output
    lines = r.stdout.splitlines()
    assert max(len(line) for line in lines) <= 80
    for param in ALL[path].params:  # every option's name printed whole
        for opt in param.opts:
            if opt.startswith("-"):
                assert opt in r.stdout, opt
    eaten = re.findall(r"\S \.(?:\s|$)", r.stdout)  # "pixel size ." : a [unit] eaten by markup
    assert not eaten


@pytest.mark.parametrize("path", WITH_EXAMPLES, ids=" ".join)
def test_help_has_an_example_and_out_is_required(path):
    r = CliRunner().invoke(app, [*path, "--help"], env={"COLUMNS": "80"})
    flat = " ".join(r.stdout.replace("\\", " ").split())
    assert "Example:" in flat and "navkit " + " ".join(path) in flat.split("Example:")[1]
    opts = {o: p for p in ALL[path].params for o in p.opts}
    assert opts["--out"].required and "-o" in opts and "--overwrite" in opts


def test_quiet_and_debug_anywhere_on_the_line(tmp_path):
    r = CliRunner().invoke(
        app, ["obstacles", "detect", str(tmp_path / "none.bin"), "-o", str(tmp_path / "o"), "-q"]
    )
    assert r.exit_code == 2 and STATE.quiet and "none.bin" in r.stderr
    r = CliRunner().invoke(
        app,
        ["obstacles", "detect", str(tmp_path / "none.bin"), "-o", str(tmp_path / "o"), "--debug"],
    )
    assert r.exit_code == 1 and isinstance(r.exception, InputError)  # the traceback, not a line
    assert STATE.debug
    # after "--" a "-q" is an argument, not the flag
    r = CliRunner().invoke(app, ["obstacles", "detect", "-o", str(tmp_path / "o"), "--", "-q"])
    assert r.exit_code == 2 and "-q" in r.stderr and not STATE.quiet


def test_progress_logs_periodic_lines_off_a_terminal(caplog):
    STATE.quiet = False
    with caplog.at_level(logging.INFO, logger="navkit.progress"):
        assert list(progress(range(4), "frames", log_every_s=0.0)) == [0, 1, 2, 3]
    lines = [r.getMessage() for r in caplog.records if r.name == "navkit.progress"]
    assert len(lines) == 4 and lines[-1].startswith("frames: 4/4 done (100 %)")
    caplog.clear()
    STATE.quiet = True
    with caplog.at_level(logging.INFO, logger="navkit.progress"):
        assert list(progress(range(3), "frames", log_every_s=0.0)) == [0, 1, 2]
    assert not caplog.records


def test_log_lines_share_the_progress_bar_console(monkeypatch):
    from rich.console import Console
    from rich.logging import RichHandler

    console = Console(file=io.StringIO(), force_terminal=True, width=80)
    monkeypatch.setattr(common, "_CONSOLE", console)
    root = logging.getLogger()
    before = list(root.handlers)
    try:
        configure_logging(logging.INFO)
        mine = [h for h in root.handlers if h not in before]
        assert len(mine) == 1 and isinstance(mine[0], RichHandler)
        assert mine[0].console is console  # the bar's console: lines print above the bar
        configure_logging(logging.INFO)  # replaces, does not stack
        assert len([h for h in root.handlers if isinstance(h, RichHandler)]) == 1
    finally:
        for h in list(root.handlers):
            if h not in before:
                root.removeHandler(h)


def test_check_out_dir(tmp_path):
    out = check_out_dir(tmp_path / "new" / "run", overwrite=False)
    assert out.is_dir()
    assert check_out_dir(out, overwrite=False) == out  # empty: fine
    (out / "summary.json").write_text("{}")
    with pytest.raises(InputError, match=r"already holds outputs \(summary.json\)") as info:
        check_out_dir(out, overwrite=False)
    assert info.value.source == str(out) and "--overwrite" in str(info.value)
    assert check_out_dir(out, overwrite=True) == out
    assert (out / "summary.json").read_text() == "{}"  # nothing deleted
    with pytest.raises(InputError, match="is a file"):
        check_out_dir(out / "summary.json", overwrite=True)


def test_summary_says_what_its_figures_are_measured_against(tmp_path, cli, monkeypatch):
    from navkit import jit
    from navkit.cli.common import write_run_files

    monkeypatch.setattr(jit, "_decision", None)  # as in a new process
    write_run_files(tmp_path / "a", {"x": 1}, {"success_rate": 1.0}, reference="simulator truth")
    s = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert list(s)[:3] == ["navkit_version", "argv", "reference"]
    assert s["reference"] == "simulator truth" and s["success_rate"] == 1.0
    assert s["kernels"] == "no kernel needed"  # this process ran no hot path yet
    # the path commands' headline figures name their reference, and the implementation that
    # produced their timings (the suite runs the compiled kernels: NAVKIT_JIT=eager)
    r = cli("path", "simulate", "-o", tmp_path / "sim", "--legs", "3")
    assert r.exit_code == 0, r.output
    s = json.loads((tmp_path / "sim" / "summary.json").read_text())
    assert s["reference"].startswith("simulator ground truth")
    assert s["kernels"] in ("compiled kernels", "no kernel needed")
