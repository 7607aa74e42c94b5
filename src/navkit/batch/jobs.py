"""The per-input functions a batch runs: one input in, files under ``out_dir``, figures out.

Each is a module-level function (Dask pickles it by reference), reads its input itself by path
(nothing large goes through the scheduler), writes through :mod:`navkit.io` (atomically) and
returns a small dict of key figures for the manifest.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["mission_job", "mission_sweep_tasks", "parse_seeds"]


def mission_job(
    out_dir: Path,
    *,
    scene: str,
    seed: int,
    mission: str | None = None,
    small: bool = False,
    config: str | None = None,
) -> dict[str, Any]:
    """One seed of ``navkit mission sweep``: the mission's outputs (no report) and its figures.

    The figures are the run's outcome as booleans (rates with intervals in the batch summary)
    and its key errors; wall times are left out so a sweep's manifest is reproducible.
    """
    from navkit.mission.demo import run_scene_file

    m = run_scene_file(scene, out_dir, mission=mission, seed=seed, small=small, config=config)
    ret, pe, ob = m["return"], m["pose_error"], m["obstacles"]
    d = float(ret["final_distance_to_operator_m"])
    return {
        "seed": int(seed),
        "returned": ret["outcome"] == "returned",
        "returned_within_1m": bool(d <= 1.0),
        "final_distance_to_operator_m": d,
        "position_error_mean_m": pe["corrected_m"]["mean"],
        "raw_vo_position_error_mean_m": pe["raw_vo_m"]["mean"],
        "obstacle_recall": ob["recall"],
        "phantoms": ob["phantoms"],
    }


def parse_seeds(text: str) -> list[int]:
    """``"0:100"`` (start included, stop excluded), ``"7"`` or ``"1,5,9"`` -> a list of seeds.

    >>> parse_seeds("3:6"), parse_seeds("1,5")
    ([3, 4, 5], [1, 5])
    """
    from navkit.errors import ConfigError

    bad = ConfigError(
        f"= {text!r}",
        field="--seeds",
        expected="START:STOP with 0 <= START < STOP <= 10,000,000, or a list like 1,5,9",
    )
    try:
        if ":" in text:
            a, b = (int(v) for v in text.split(":", 1))
            seeds = list(range(a, b))
        else:
            seeds = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise bad from None
    if not seeds or min(seeds) < 0 or max(seeds) >= 10_000_000 or len(set(seeds)) != len(seeds):
        raise bad
    return seeds


def mission_sweep_tasks(
    scene: str,
    seeds: list[int],
    *,
    mission: str | Path | None = None,
    small: bool = False,
    config: str | Path | None = None,
) -> list[Any]:
    """One :class:`~navkit.batch.BatchTask` per seed (folder ``seed-N``), hashed on the scene,
    mission and config files, the settings and the navkit version."""
    from navkit import __version__
    from navkit.batch.engine import BatchTask, settings_hash
    from navkit.mission.demo import load_scene_file

    # every input read and checked once, before any seed runs or writes
    load_scene_file(scene, mission=mission, seed=seeds[0], small=small, config=config)

    def ident(p: str | Path | None) -> Any:
        return None if p is None else (Path(p) if Path(p).is_file() else str(p))

    width = len(str(max(seeds)))
    return [
        BatchTask(
            f"seed-{seed:0{width}d}",
            mission_job,
            {
                "scene": str(scene),
                "seed": seed,
                "mission": None if mission is None else str(mission),
                "small": small,
                "config": None if config is None else str(config),
            },
            settings_hash(__version__, ident(scene), ident(mission), ident(config), small, seed),
        )
        for seed in seeds
    ]
