"""First-call cost of navkit's compiled (Numba) kernels: a fresh process with an empty
``NUMBA_CACHE_DIR`` (compilation), then a second fresh process on the cache it left (loading).

Not a benchmark module of its own (no ``bench_`` prefix): the area benchmarks call
:func:`first_call_rows` with a snippet that sets up an input (``setup``) and runs the kernels
once (``call``).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks.common import Row

_TEMPLATE = """
import time
{setup}
t0 = time.perf_counter()
{call}
print(time.perf_counter() - t0)
"""


def _run(setup: str, call: str, cache: str) -> float:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache)
    src = str(Path(__file__).resolve().parents[1] / "src")
    env["PYTHONPATH"] = os.pathsep.join(
        [src, str(Path(__file__).resolve().parents[1]), env.get("PYTHONPATH", "")]
    )
    out = subprocess.run(
        [sys.executable, "-c", _TEMPLATE.format(setup=setup, call=call)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return float(out.stdout.strip().splitlines()[-1])


def first_call_rows(area: str, what: str, setup: str, call: str) -> list[Row]:
    """Two rows: the first call of ``call`` on an empty Numba cache (compilation, seconds) and
    the first call of a new process on the cache that run left (seconds), wall time."""
    with tempfile.TemporaryDirectory(prefix="navkit-numba-") as cache:
        cold = _run(setup, call, cache)
        warm = _run(setup, call, cache)
    return [
        Row(
            area,
            f"{what}: first call, empty Numba cache (compilation)",
            "s",
            cold,
            note="fresh process, NUMBA_CACHE_DIR empty; wall time of the first call",
        ),
        Row(
            area,
            f"{what}: first call of a new process, cache on disk",
            "s",
            warm,
            note="fresh process on the cache the previous run wrote; wall time of the first call",
        ),
    ]
