"""The fuzz suite's harness: every case ends in a navkit error or a valid result, within bounds.

:func:`check` runs one case under :mod:`tracemalloc` and classifies it; anything else than a
:class:`navkit.errors.NavkitError` or a return (a NumPy traceback, a ``KeyError``, ...) fails the
test, and so does a peak of traced memory above :data:`MEMORY_BOUND`. The counts by area
(cases, clean errors, valid results, failures) and the largest peak are printed at the end of
the run (``pytest tests/fuzz -q``) and written to ``out/fuzz-summary.json`` when ``out/`` exists.
"""

from __future__ import annotations

import json
import tracemalloc
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from navkit.errors import NavkitError

#: Peak traced memory one case may use: the inputs are a few kB, so anything near this is an
#: allocation driven by a lying size field.
MEMORY_BOUND = 256 * 2**20

COUNTS: dict[str, dict[str, float]] = defaultdict(
    lambda: {"cases": 0, "errors": 0, "valid": 0, "failures": 0, "peak_mb": 0.0}
)


def check(area: str, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """Run ``fn(*args, **kwargs)``; return its result, or None after a navkit error.

    Raises
    ------
    AssertionError
        If ``fn`` raised anything but a navkit error, or its traced peak exceeded the bound.
    """
    counts = COUNTS[area]
    counts["cases"] += 1
    started = not tracemalloc.is_tracing()
    if started:
        tracemalloc.start()
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    outcome = "failures"
    try:
        result = fn(*args, **kwargs)
        outcome = "valid"
        return result
    except NavkitError:
        outcome = "errors"
        return None
    except Exception as exc:
        raise AssertionError(
            f"{area}: {getattr(fn, '__name__', fn)} raised {type(exc).__name__}: {exc}"
        ) from exc
    finally:
        peak = tracemalloc.get_traced_memory()[1] - base
        if started:
            tracemalloc.stop()
        counts["peak_mb"] = max(counts["peak_mb"], peak / 2**20)
        if peak > MEMORY_BOUND:
            outcome = "failures"
        counts[outcome] += 1
        assert peak <= MEMORY_BOUND, f"{area}: peak {peak / 2**20:.0f} MB > bound"


def record(area: str, outcome: str, peak_mb: float = 0.0) -> None:
    """Count a case checked elsewhere (the CLI cases, run through click's runner)."""
    counts = COUNTS[area]
    counts["cases"] += 1
    counts[outcome] += 1
    counts["peak_mb"] = max(counts["peak_mb"], peak_mb)


def pytest_terminal_summary(terminalreporter: Any) -> None:
    if not COUNTS:
        return
    tr = terminalreporter
    tr.section("navkit fuzz suite")
    tr.write_line(
        f"{'area':<12} {'cases':>7} {'errors':>7} {'valid':>7} {'failures':>8} {'peak MB':>8}"
    )
    for area, c in sorted(COUNTS.items()):
        tr.write_line(
            f"{area:<12} {c['cases']:>7.0f} {c['errors']:>7.0f} {c['valid']:>7.0f} "
            f"{c['failures']:>8.0f} {c['peak_mb']:>8.1f}"
        )
    out = Path("out")
    if out.is_dir():
        (out / "fuzz-summary.json").write_text(json.dumps(COUNTS, indent=2) + "\n")


@pytest.fixture(scope="session")
def fuzz_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("fuzz")
