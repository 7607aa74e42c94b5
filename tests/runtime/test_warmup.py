"""``navkit compile`` (navkit.runtime.warmup) covers what the demo runs: after it, a new process
under the default policy finds the stamp, runs the compiled kernels and compiles nothing."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

SRC = Path(__file__).resolve().parents[2] / "src"

# the demo's mission (small resolutions, as ``navkit demo --small``) under NAVKIT_JIT=auto,
# then the process's decision and its kernels' cache misses (= compilations) and hits
_MISSION = """
import json
from navkit import jit
from navkit.mission import Mission, MissionSettings
from navkit.mission.settings import builtin_route_path, load_route
from navkit.runtime.warmup import compiled_kernels
from navkit.sim import load_scene
route, overrides = load_route(builtin_route_path("yard"))
settings = MissionSettings.small().with_overrides(overrides)
log = Mission(load_scene("yard"), route, settings).run()
k = compiled_kernels()
print(json.dumps({
    "enabled": jit.kernels_enabled(),
    "outcome": log.outcome,
    "misses": {n: m for n, (_, m, _) in k.items() if m},
    "hits": sum(h for _, _, h in k.values()),
}))
"""


def _env(**extra: str) -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(SRC), MPLBACKEND="Agg", **extra)


def test_compile_then_the_mission_loads_every_kernel_and_compiles_none():
    done = subprocess.run(
        [sys.executable, "-m", "navkit", "-q", "compile"],
        env=_env(),
        capture_output=True,
        text=True,
        check=True,
    )
    assert "stamp" in done.stdout, done.stdout + done.stderr
    status = subprocess.run(
        [sys.executable, "-m", "navkit", "compile", "--status"],
        env=_env(NAVKIT_JIT="auto"),
        capture_output=True,
        text=True,
        check=True,
    )
    assert status.stdout.startswith("kernels: compiled"), status.stdout
    out = subprocess.run(
        [sys.executable, "-c", _MISSION],
        env=_env(NAVKIT_JIT="auto"),
        capture_output=True,
        text=True,
        check=True,
    )
    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert res["enabled"] is True
    assert res["outcome"] == "returned"
    assert res["misses"] == {}, f"compiled in the process despite the warm-up: {res['misses']}"
    assert res["hits"] >= 30  # every capability's kernels came from the cache
