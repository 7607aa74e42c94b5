"""The kernel policy (navkit.jit): which implementation a process runs, the one switch
(``jit.use``), the stamp, the one background warm-up the command line starts. The warm-up's own
coverage is tested in tests/runtime/test_warmup.py."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from navkit import jit
from navkit.errors import ConfigError

SRC = Path(__file__).resolve().parents[2] / "src"

# A process under the policy ``auto`` with its own empty cache folder: a NumPy-tier obstacle
# detection, then what it decided, whether Numba was ever imported, and the warm-up's lock.
_PROBE = """
import json, os, sys
import numpy as np
from navkit import jit
if os.environ.get("PROBE_HOOK") == "cli":  # what the command line registers
    from navkit.runtime.warmup import start_background
    jit.on_missing_kernels(start_background)
from navkit.obstacles import detect_obstacles
from navkit.sim import Box, Ground, Scene, SpinningLidar, render_scan
T = np.eye(4)
T[2, 3] = 1.0
scene = Scene([Ground(), Box((4, 0, 0.5), (1, 1, 1))])
det = detect_obstacles(render_scan(scene, SpinningLidar(n_beams=16, n_columns=360), T).scan)
lock = jit.stamp_path().with_suffix(".lock")
print(json.dumps({
    "enabled": jit.kernels_enabled(),
    "numba": "numba" in sys.modules,
    "obstacles": len(det.obstacles),
    "lock": lock.read_text().strip() if lock.exists() else None,
}))
"""


def _probe(cache: Path, policy: str = "auto", hook: str = "cli") -> dict:
    env = dict(
        os.environ,
        NUMBA_CACHE_DIR=str(cache),
        NAVKIT_JIT=policy,
        PYTHONPATH=str(SRC),
        PROBE_HOOK=hook,
    )
    out = subprocess.run(
        [sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def _stop(pid: int) -> None:
    """Stop a background warm-up (its own session) before it compiles anything for long."""
    try:
        os.killpg(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


@pytest.fixture
def fresh(monkeypatch, tmp_path):
    """This process's decision undone, the cache (and so the stamp) in an empty folder, and the
    command line's hook registered (it starts the background warm-up)."""
    from navkit.runtime.warmup import start_background

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(jit, "_decision", None)
    monkeypatch.setattr(jit, "_override", [])
    monkeypatch.setattr(jit, "_on_missing", start_background)
    return tmp_path


def test_mode_reads_the_environment_and_refuses_unknown_values(monkeypatch):
    monkeypatch.delenv("NAVKIT_JIT", raising=False)
    assert jit.mode() == "auto"
    monkeypatch.setenv("NAVKIT_JIT", " NumPy ")
    assert jit.mode() == "numpy"
    monkeypatch.setenv("NAVKIT_JIT", "gpu")
    with pytest.raises(ConfigError) as e:
        jit.mode()
    assert "NAVKIT_JIT" in str(e.value) and "'eager'" in str(e.value)


@pytest.mark.parametrize(("policy", "enabled"), [("eager", True), ("numpy", False)])
def test_explicit_policies_decide_the_implementation(fresh, monkeypatch, policy, enabled):
    monkeypatch.setenv("NAVKIT_JIT", policy)
    assert jit.kernels_enabled() is enabled
    with pytest.raises(ConfigError, match="implementation"):
        jit.use("fast")
    assert not list(fresh.iterdir())  # nothing started, nothing written


def test_the_stamp_is_keyed_by_the_cache_folder(fresh, monkeypatch, tmp_path_factory):
    first = jit.stamp_path()
    assert first.parent == fresh and first.name.startswith("navkit-jit-")
    other = tmp_path_factory.mktemp("other")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(other))
    assert jit.stamp_path().parent == other and jit.stamp_path().name != first.name


def test_auto_with_a_stamp_runs_the_kernels_and_starts_nothing(fresh, monkeypatch):
    monkeypatch.setenv("NAVKIT_JIT", "auto")
    jit.write_stamp()
    assert jit.kernels_enabled() is True
    assert jit.status().compiled and not jit.status().warming
    assert not jit.stamp_path().with_suffix(".lock").exists()


def test_auto_without_a_stamp_runs_numpy_and_one_background_warmup(tmp_path):
    first = _probe(tmp_path)
    assert first["lock"] is not None, first
    pid = int(first["lock"])
    try:
        # the whole process ran the NumPy twins: Numba was never imported, the detection worked
        assert first["enabled"] is False and first["numba"] is False
        assert first["obstacles"] == 1
        # the warm-up is navkit's (its log beside the lock) and a second process starts no other
        cmdline = Path(f"/proc/{pid}/cmdline")
        if cmdline.exists():
            assert b"navkit.runtime.warmup" in cmdline.read_bytes()
        assert list(tmp_path.glob("navkit-jit-*.log"))
        second = _probe(tmp_path)
        assert second["enabled"] is False and second["lock"] == first["lock"]
    finally:
        _stop(pid)


def test_a_library_process_without_a_stamp_runs_the_twins_and_starts_nothing(tmp_path):
    """Only an application (the command line) starts a background compilation; a library call
    never does."""
    got = _probe(tmp_path, hook="none")
    assert got["enabled"] is False and got["numba"] is False and got["obstacles"] == 1
    assert got["lock"] is None and not list(tmp_path.glob("navkit-jit-*"))


def test_use_switches_for_a_block_or_the_process(fresh, monkeypatch):
    monkeypatch.setenv("NAVKIT_JIT", "eager")
    assert jit.kernels_enabled() is True
    with jit.use("numpy"):
        assert jit.kernels_enabled() is False
        with jit.use("eager"):
            assert jit.kernels_enabled() is True and jit.implementation() == "compiled kernels"
        assert jit.kernels_enabled() is False and jit.implementation() == "NumPy twins"
    assert jit.kernels_enabled() is True
    jit.use("numpy")  # for the rest of the process (here: the test; the fixture restores it)
    assert jit.kernels_enabled() is False
    with pytest.raises(ConfigError, match="implementation"):
        jit.use("gpu")


def test_a_stale_lock_is_replaced(fresh, monkeypatch):
    monkeypatch.setenv("NAVKIT_JIT", "auto")
    lock = jit.stamp_path().with_suffix(".lock")
    lock.write_text("999999999\n")
    old = time.time() - 2 * jit._STALE_LOCK_S
    os.utime(lock, (old, old))
    assert jit.status().warming is False
    try:
        assert jit.kernels_enabled() is False
        pid = int(lock.read_text())
        assert pid != 999999999
    finally:
        _stop(int(lock.read_text()))
        from navkit.runtime import warmup

        if warmup._background is not None:
            warmup._background.wait()


def test_the_stamp_covers_every_module_with_kernels():
    """A module with Numba kernels missing from KERNEL_MODULES would leave its cache out of the
    stamp's key (a changed kernel would not be re-warmed)."""
    pkg = SRC / "navkit"
    with_kernels = {str(p.relative_to(pkg)) for p in pkg.rglob("*.py") if "@njit" in p.read_text()}
    assert with_kernels == set(jit.KERNEL_MODULES)


def test_a_failed_warmup_is_not_started_again(fresh, monkeypatch):
    monkeypatch.setenv("NAVKIT_JIT", "auto")
    jit.failed_path().write_text("Traceback ...\n")
    assert jit.kernels_enabled() is False  # the NumPy twins, and ...
    assert not jit.stamp_path().with_suffix(".lock").exists()  # ... no new warm-up
    assert jit.status().failed


def test_a_warmup_that_cannot_start_leaves_no_lock_and_compiles_here(fresh, monkeypatch):
    monkeypatch.setenv("NAVKIT_JIT", "auto")

    def no_process(*args, **kwargs):
        raise PermissionError("no new processes here")

    from navkit.runtime import warmup

    monkeypatch.setattr(warmup.subprocess, "Popen", no_process)
    assert jit.kernels_enabled() is True  # as before the policy: compile in this process
    assert not jit.stamp_path().with_suffix(".lock").exists()


def test_a_numpy_process_refuses_to_warm_up(fresh, monkeypatch):
    """A warm-up would run the twins there and stamp kernels it never compiled."""
    from navkit.errors import NavkitError
    from navkit.runtime.warmup import warm_up

    monkeypatch.setenv("NAVKIT_JIT", "numpy")
    assert jit.kernels_enabled() is False
    with pytest.raises(NavkitError, match="navkit compile"):
        warm_up()
    assert not jit.stamp_path().exists()
