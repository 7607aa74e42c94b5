"""The NumPy twins are the kernels' oracles in the whole closed loop, not only call by call: the
small mission gives the same figures, to the last bit, under ``NAVKIT_JIT=numpy`` (twins, Numba
never imported) and ``NAVKIT_JIT=eager`` (kernels).

A closed loop (plane motion -> estimate -> map -> fixes -> estimate) turns a one-ulp difference
of any call into centimetres a few hundred steps later, so this holds only because every kernel
and its twin run the same IEEE operations in the same order (``docs/kernels.md``, "The
equivalence contract"). Each process runs in its own interpreter: the choice is per process.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

_RUN = """
import json, math
from navkit.mission import MissionSettings, mission_metrics, run_mission
from tests.mission.conftest import small_route, small_scene

def strip(v):
    if isinstance(v, dict):
        return {k: strip(x) for k, x in v.items() if k not in ("timing",) and "seconds" not in k}
    if isinstance(v, (list, tuple)):
        return [strip(x) for x in v]
    if isinstance(v, float):
        return repr(v)  # every bit, NaN included
    return v

lg = run_mission(small_scene(), small_route(), MissionSettings.small(seed=3))
print(json.dumps({"metrics": strip(mission_metrics(lg)), "estimate": [repr(float(x)) for x in lg.estimate.ravel()]}))
"""


def _run(mode: str) -> dict:
    env = dict(
        os.environ,
        NAVKIT_JIT=mode,
        PYTHONPATH=os.pathsep.join([str(ROOT / "src"), str(ROOT)]),
        MPLBACKEND="Agg",
    )
    out = subprocess.run(
        [sys.executable, "-c", _RUN], env=env, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_mission_on_twins_equals_the_mission_on_kernels():
    twins, kernels = _run("numpy"), _run("eager")
    est_t, est_k = twins["estimate"], kernels["estimate"]
    first = next(
        (i // 3 for i, (a, b) in enumerate(zip(est_t, est_k, strict=True)) if a != b), None
    )
    assert first is None, f"the estimates part at control step {first}"
    assert twins["metrics"] == kernels["metrics"]
