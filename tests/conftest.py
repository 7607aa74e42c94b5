"""Shared fixtures: the recorded data (skipped with a reason where absent), seeded RNGs, the CLI."""

from __future__ import annotations

import os
from pathlib import Path

# The tests compare the compiled kernels with their NumPy twins and pin results: every process
# of the suite (and the CLI subprocesses it starts) runs the kernels, compiling on first use,
# whatever the machine's cache holds (navkit.jit; tests/core/test_jit.py tests the policy).
os.environ.setdefault("NAVKIT_JIT", "eager")

import numpy as np
import pytest
from hypothesis import HealthCheck, settings

from navkit import datasets
from navkit.errors import DataNotFoundError

# Hypothesis' per-example deadline measures wall time, which on a loaded 2-core CI machine says
# nothing about correctness: speed lives in the benchmarks. Examples stay deterministic per run.
settings.register_profile(
    "navkit", deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True
)
settings.load_profile("navkit")


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture
def data_path():
    """``data_path("lidar/semantickitti-seq00/000000.bin")`` -> Path, or skip with the reason."""

    def _find(relative: str) -> Path:
        try:
            return datasets.find(relative)
        except DataNotFoundError as exc:
            pytest.skip(f"recorded data absent: {exc}")

    return _find


@pytest.fixture
def cli():
    """Run ``navkit ARGS...`` in-process; returns the click Result (exit_code, stdout, stderr)."""
    from typer.testing import CliRunner

    from navkit.cli.main import app

    runner = CliRunner()

    def _run(*args: str):
        return runner.invoke(app, [str(a) for a in args], catch_exceptions=False)

    return _run


_WARMUP_FILE = "tests/runtime/test_warmup.py"


def pytest_collection_modifyitems(session, config, items):
    """Hand ``tests/runtime/test_warmup.py`` out before the other ``tests/runtime`` files.

    Its one test runs ``navkit compile`` and a mission in subprocesses (~3 min on a 2-core
    machine) in a single worker (``make test`` hands out whole files, ``--dist loadfile``).
    Collected last, it ran alone while the other worker idled (the suite's last ~2 min); first, on
    an empty cache, it compiled every kernel while the other worker compiled the same ones (11 min
    11 s against 10 min 26 s, ``docs/benchmarks.md``). Before ``tests/runtime`` the capabilities'
    test files have filled the cache, and ``tests/runtime``, ``sim``, ``stereo`` and ``viz`` run on
    the other worker meanwhile. Only the order changes, never what runs."""
    warm = [it for it in items if it.nodeid.startswith(_WARMUP_FILE)]
    if not warm:
        return
    rest = [it for it in items if not it.nodeid.startswith(_WARMUP_FILE)]
    at = next((i for i, it in enumerate(rest) if it.nodeid.startswith("tests/runtime/")), len(rest))
    items[:] = rest[:at] + warm + rest[at:]
