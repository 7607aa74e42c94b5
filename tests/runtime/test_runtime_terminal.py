"""Every command with a progress bar, run in a pseudo-terminal (where rich draws the bar) and with
stderr piped (where it logs lines instead): exit 0, no traceback, no internal error.

The inputs are a few frames of the shared recordings; the kernels' NumPy twins run (the bar, not
the arithmetic, is under test), except for ``navkit compile`` whose subject is the kernels.
"""

from __future__ import annotations

import os
import pty
import re
import select
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
CLI = REPO / "src" / "navkit" / "cli"
BAD = re.compile(r"Traceback|internal error|Error:|error:")


def _env(**extra: str) -> dict[str, str]:
    env = dict(os.environ, PYTHONPATH=str(REPO / "src"), MPLBACKEND="Agg", TERM="xterm-256color")
    env.update(COLUMNS="120", LINES="40", NAVKIT_JIT="numpy")
    env.pop("NO_COLOR", None)
    env.update(extra)
    return env


def run_in_pty(args: list[str], timeout: float = 600.0, **env: str) -> tuple[int, str]:
    """``python -m navkit ARGS`` with stdin, stdout and stderr on a pseudo-terminal; returns
    the exit code and everything the terminal received."""
    master, slave = pty.openpty()
    proc = subprocess.Popen(
        [sys.executable, "-m", "navkit", *args],
        stdin=slave,
        stdout=slave,
        stderr=slave,
        env=_env(**env),
        cwd=REPO,
        close_fds=True,
    )
    os.close(slave)
    chunks: list[bytes] = []
    t0 = time.monotonic()
    try:
        while True:
            if time.monotonic() - t0 > timeout:
                proc.kill()
                pytest.fail(f"navkit {' '.join(args)} took more than {timeout} s in a terminal")
            ready, _, _ = select.select([master], [], [], 0.2)
            if ready:
                try:
                    data = os.read(master, 65536)
                except OSError:  # the terminal closed: the process ended
                    data = b""
                if not data:
                    break
                chunks.append(data)
            elif proc.poll() is not None:
                break
    finally:
        os.close(master)
        proc.wait(timeout=60)
    return proc.returncode, b"".join(chunks).decode("utf-8", "replace")


def _find(relative: str) -> Path:
    from navkit import datasets
    from navkit.errors import DataNotFoundError

    try:
        return datasets.find(relative)
    except DataNotFoundError as exc:
        pytest.skip(f"recorded data absent: {exc}")


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A 60-pose trajectory, 2 KITTI clouds, the first 120 scans of a CARMEN log, an RGB-D folder."""
    import gzip
    import shutil

    d = tmp_path_factory.mktemp("terminal")
    traj = _find("trajectories/fr2_desk_groundtruth.txt")
    lines = [ln for ln in traj.read_text().splitlines() if not ln.startswith("#")]
    (d / "traj.txt").write_text("\n".join(lines[:60]) + "\n")
    kitti = _find("lidar/semantickitti-seq00")
    for b in sorted(kitti.glob("*.bin"))[:2]:
        shutil.copy(b, d / b.name)
    log_gz = _find("laser2d/freiburg-101-corrected.log.gz")
    with gzip.open(log_gz, "rt", encoding="utf-8", errors="replace") as fh:
        log_lines = fh.read().splitlines()
    scans = [i for i, ln in enumerate(log_lines) if ln.startswith("FLASER")]
    (d / "short.log").write_text("\n".join(log_lines[: scans[120]]) + "\n")
    rgbd = _find("rgbd/7scenes-tsdf")
    return d, rgbd


def _cases(d: Path, rgbd: Path) -> dict[str, list[list[str]]]:
    """Per command module, the command lines that draw its progress bars (run in order)."""
    o = d / "out"
    bins = [str(p) for p in sorted(d.glob("*.bin"))]
    return {
        "cmd_run": [["run", str(d / "traj.txt"), "-o", str(o / "run")]],
        "cmd_path": [["path", "record", str(d / "traj.txt"), "-o", str(o / "path")]],
        "cmd_obstacles": [
            ["obstacles", "detect", *bins, "-o", str(o / "obs")],
            ["obstacles", "detect", *bins, "-o", str(o / "obs_batch"), "--resume"],
        ],
        "cmd_map": [
            ["map", "build", str(d / "short.log"), "-o", str(o / "map")],
            [
                "map",
                "locate",
                str(o / "map" / "map.json"),
                str(d / "short.log"),
                "-o",
                str(o / "locate"),
                "--every",
                "10",
            ],
        ],
        "cmd_stereo": [["stereo", "simulate", "rectangle", "--width", "64", "-o", str(o / "st")]],
        "cmd_planes": [
            ["planes", "odometry", str(rgbd), "-o", str(o / "planes"), "--max-frames", "3"]
        ],
    }


SLOW_CASES = {
    "cmd_demo": [["demo", "--small", "--seed", "3"]],
    # a short route out of the yard's start (the bar draws the same either way)
    "cmd_mission": [["mission", "run", "yard", "--small", "--mission", "SHORT_ROUTE"]],
    "cmd_compile": [["compile"]],
}
SHORT_ROUTE = "[route]\nwaypoints = [[0.0, 0.0], [3.0, -0.3]]\n"


def _modules_with_progress() -> set[str]:
    """The command modules that draw a progress bar (``progress(``, ``run_inputs(`` or a rich
    ``Progress``), found in the source so a new one cannot go untested."""
    pat = re.compile(r"\bprogress\b|run_inputs\(|_Progress\(")
    return {
        f.stem
        for f in CLI.glob("cmd_*.py")
        if pat.search(re.sub(r'""".*?"""', "", f.read_text(), flags=re.S))
    }


def test_every_command_with_a_progress_bar_is_run_in_a_terminal(tmp_path):
    covered = set(_cases(tmp_path, tmp_path)) | set(SLOW_CASES)
    assert _modules_with_progress() <= covered, _modules_with_progress() - covered


def _check(args: list[str], code: int, text: str) -> None:
    assert code == 0, f"navkit {' '.join(args)} exited {code}:\n{text[-3000:]}"
    assert not BAD.search(text), f"navkit {' '.join(args)}:\n{text[-3000:]}"


@pytest.mark.realdata
@pytest.mark.parametrize(
    "module", ["cmd_run", "cmd_path", "cmd_obstacles", "cmd_map", "cmd_stereo", "cmd_planes"]
)
def test_progress_bars_in_a_terminal(inputs, module):
    d, rgbd = inputs
    for args in _cases(d, rgbd)[module]:
        code, text = run_in_pty(args)
        _check(args, code, text)
        if module == "cmd_run":  # the bar was drawn, with the recording's duration
            assert re.search(r"/ \d+\.\d s of recording", text), text[-2000:]


@pytest.mark.slow
@pytest.mark.parametrize("module", sorted(SLOW_CASES))
def test_progress_bars_in_a_terminal_slow(tmp_path, module):
    route = tmp_path / "short.toml"
    route.write_text(SHORT_ROUTE)
    for args in SLOW_CASES[module]:
        args = [str(route) if a == "SHORT_ROUTE" else a for a in args]
        if args[0] in ("demo", "mission"):
            args = [*args, "-o", str(tmp_path / "out")]
        env = {"NAVKIT_JIT": "eager"} if args[0] == "compile" else {}
        code, text = run_in_pty(args, **env)
        _check(args, code, text)


@pytest.mark.realdata
def test_run_piped_logs_a_line_every_few_seconds(inputs, tmp_path):
    """With stderr piped, a slow run logs its progress at most ``log_every_s`` apart (a
    heartbeat, so a slow frame does not silence it), and no numexpr chatter."""
    d, _ = inputs
    bins = sorted(d.glob("*.bin"))
    # 2 KITTI clouds through obstacle detection on the NumPy twins: several seconds
    args = [sys.executable, "-m", "navkit", "run", str(d), "-o", str(tmp_path / "o")]
    env = _env()
    t0 = time.monotonic()
    r = subprocess.run(args, env=env, capture_output=True, text=True, timeout=600)
    wall = time.monotonic() - t0
    assert r.returncode == 0, r.stderr
    assert "numexpr" not in r.stderr, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if "navkit.cli.cmd_run: run:" in ln]
    assert lines, r.stderr
    assert "s of recording" in lines[-1] and "(100 %)" in lines[-1], lines
    # one heartbeat per 5 s of the run plus the last line (the count of whole 5 s periods
    # after the bar started, which is within the process's wall time)
    assert len(lines) <= wall / 5.0 + 1, (wall, lines)
    assert len(bins) == 2


def test_piped_progress_is_a_heartbeat(caplog):
    """Off a terminal the run's progress is logged every ``log_every_s`` even while one frame
    takes longer than that, and once at the end with the fraction done."""
    import logging

    from navkit.cli.cmd_run import _Progress

    caplog.set_level(logging.INFO, logger="navkit.cli.cmd_run")
    every = 0.05
    with _Progress(log_every_s=every) as bar:
        bar.update(1.0, 4.0)
        time.sleep(12 * every)  # one slow frame
        bar.update(4.0, 4.0)
    lines = [r.getMessage() for r in caplog.records if r.name == "navkit.cli.cmd_run"]
    # a thread woken every 50 ms on a loaded machine: at least a few of the 12 beats arrive
    assert len(lines) >= 4, lines
    assert lines[0].startswith("run: 1.0 / 4.0 s of recording (25 %)"), lines
    assert lines[-1].startswith("run: 4.0 / 4.0 s of recording (100 %)"), lines
