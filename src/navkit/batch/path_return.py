"""``navkit path return`` as a sweep: every simulated return is one batch task with its own seed.

Run ``i`` of a sweep with ``--seed S`` draws its VO noise from
``numpy.random.default_rng(numpy.random.SeedSequence([S, i]))``, so a run's result depends on
``(S, i)`` only: not on how many runs there are, nor on how they are split across workers or
processes, nor on which of them ``--resume`` skipped. (Before this, the ``--runs`` returns were
simulated in lock-step from one stream ``default_rng(S)``; the per-run streams, and therefore
the individual runs, differ from that one. The distribution of the figures is the same.)

Each task writes ``run-NNN/run.json`` (its figures and final position) and
``run-NNN/true_xy.npy`` (its true track, ``(K, 2)`` metres, one row per control cycle);
:func:`collect_returns` reads them back into one
:class:`~navkit.sim.return_sim.ReturnSimResult` for ``returns.json`` and ``returns.png``.

Figures per run (the manifest's columns): final error (m and % of the path length L), lateral
error mean / max, duration, and three outcomes summarised as rates with 95 % Wilson intervals:

- ``stopped_within_the_stop_radius``: the controller stopped (its VO estimate of the position
  inside the stop radius) before the time limit;
- ``ended_within_the_stop_radius``: the *true* final position is inside the stop radius;
- ``final_error_within_1_percent_of_L``: the true final error is at most 1 % of L (the paper
  reports the final error in % of the path length).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "ERROR_RATE_PCT",
    "ReturnSweepSettings",
    "collect_returns",
    "return_run_job",
    "return_sweep_tasks",
    "run_rng",
]

ERROR_RATE_PCT = 1.0
"""The final error (% of the path length) the sweep's rate ``final_error_within_1_percent_of_L``
counts against."""


@dataclass(frozen=True)
class ReturnSweepSettings:
    """What one simulated return needs besides its run index: the VO model and the controller
    (:class:`~navkit.sensors.VisualOdometryNoise`, :class:`~navkit.path.control.ReturnSettings`)
    and the sweep's seed."""

    vo: Any
    controller: Any
    seed: int = 0


def run_rng(seed: int, run: int) -> np.random.Generator:
    """The random generator of run ``run`` of a sweep seeded ``seed`` (independent streams)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(run)]))


def return_run_job(
    out_dir: Path, *, path_json: str, run: int, settings: ReturnSweepSettings
) -> dict[str, Any]:
    """Simulate run ``run`` of a sweep: write ``run.json`` and ``true_xy.npy``; its figures."""
    from navkit.errors import ConfigError
    from navkit.io.atomic import atomic_path, write_json
    from navkit.io.pathjson import read_path_json
    from navkit.io.urls import local_copy
    from navkit.sim.return_sim import simulate_returns

    with local_copy(path_json) as local:
        spline = read_path_json(local)
    if spline.n_segments == 0 or spline.total_length <= 0:
        raise ConfigError(
            "the stored path has zero length",
            source=path_json,
            field="segments",
            expected="at least one segment of positive length",
        )
    sim = simulate_returns(
        spline,
        runs=1,
        settings=settings.controller,
        vo=settings.vo,
        rng=run_rng(settings.seed, run),
    )
    stop_radius = float(settings.controller.stop_radius)
    err, pct = float(sim.final_error[0]), float(sim.final_error_pct[0])
    duration = float(sim.duration[0])
    figures: dict[str, Any] = {
        "run": int(run),
        "final_error_m": err,
        "final_error_pct": pct,
        "lateral_mean_m": float(sim.lateral_mean[0]),
        "lateral_max_m": float(sim.lateral_max[0]),
        "duration_s": duration if np.isfinite(duration) else None,
        "stopped_within_the_stop_radius": bool(sim.stopped[0]),
        "ended_within_the_stop_radius": bool(err <= stop_radius),
        "final_error_within_1_percent_of_L": bool(pct <= ERROR_RATE_PCT),
    }
    with atomic_path(out_dir / "true_xy.npy") as tmp:
        np.save(tmp, sim.true_xy[:, 0, :])
    write_json(
        out_dir / "run.json",
        {
            **figures,
            "seed": [int(settings.seed), int(run)],
            "path_length_m": sim.path_length,
            "start": sim.start,
            "final_xy": sim.final_true[0],
        },
    )
    return figures


def return_sweep_tasks(
    path_json: str, runs: int, settings: ReturnSweepSettings, first: int = 0
) -> list[Any]:
    """One :class:`~navkit.batch.BatchTask` per run ``first .. first + runs - 1`` (folder
    ``run-NNN``), hashed on the navkit version, the path file, the settings and the run."""
    from navkit import __version__
    from navkit.batch.engine import BatchTask, settings_hash
    from navkit.io.urls import input_identity

    ident = input_identity(path_json)
    width = max(3, len(str(first + runs - 1)))
    return [
        BatchTask(
            f"run-{i:0{width}d}",
            return_run_job,
            {"path_json": str(path_json), "run": i, "settings": settings},
            settings_hash(__version__, ident, settings, i),
        )
        for i in range(first, first + runs)
    ]


def collect_returns(out: Path, rows: list[dict[str, Any]], max_tracks: int = 200) -> Any:
    """The completed runs of a sweep as one :class:`~navkit.sim.return_sim.ReturnSimResult`.

    Tracks of different lengths are padded with their last position (a stopped robot stays
    where it stopped, as in the lock-step simulation); only the first ``max_tracks`` tracks are
    kept (for the figure), every run's final figures are.

    Returns ``(result, runs_detail)``, or ``(None, [])`` when no run completed.
    """
    from navkit.io.arrays import read_npy
    from navkit.io.atomic import read_json
    from navkit.sim.return_sim import ReturnSimResult

    done = [r for r in rows if r.get("status") in ("ok", "skipped")]
    if not done:
        return None, []
    details = [
        read_json(out / r["key"] / "run.json", what="a run.json of a return sweep") for r in done
    ]
    tracks = [read_npy(out / r["key"] / "true_xy.npy") for r in done[:max_tracks]]
    k = max(len(t) for t in tracks)
    true_xy = np.stack([np.vstack([t, np.repeat(t[-1:], k - len(t), axis=0)]) for t in tracks], 1)
    final = np.array([d["final_xy"] for d in details], dtype=np.float64)
    duration = np.array(
        [np.nan if d["duration_s"] is None else d["duration_s"] for d in details], dtype=np.float64
    )
    sim = ReturnSimResult(
        path_length=float(details[0]["path_length_m"]),
        start=np.asarray(details[0]["start"], dtype=np.float64),
        final_true=final,
        final_error=np.array([d["final_error_m"] for d in details], dtype=np.float64),
        lateral_mean=np.array([d["lateral_mean_m"] for d in details], dtype=np.float64),
        lateral_max=np.array([d["lateral_max_m"] for d in details], dtype=np.float64),
        duration=duration,
        stopped=np.array([d["stopped_within_the_stop_radius"] for d in details], dtype=bool),
        true_xy=true_xy,
        est_xy=np.empty((0, len(tracks), 2)),
    )
    runs_detail = [
        {
            "run": d["run"],
            "seed": d["seed"],
            "final_xy": d["final_xy"],
            "final_error_m": d["final_error_m"],
            "final_error_pct": d["final_error_pct"],
            "lateral_mean_m": d["lateral_mean_m"],
            "lateral_max_m": d["lateral_max_m"],
            "duration_s": d["duration_s"],
            "stopped": d["stopped_within_the_stop_radius"],
        }
        for d in details
    ]
    return sim, runs_detail
