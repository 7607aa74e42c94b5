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
