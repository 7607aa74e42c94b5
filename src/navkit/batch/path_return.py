"""``navkit path return`` as a sweep: the runs in chunks of tasks, every run its own seed.

Run ``i`` of a sweep with ``--seed S`` draws its VO noise from
``numpy.random.default_rng(numpy.random.SeedSequence([S, i]))``, so a run's result depends on
``(S, i)`` only: not on how many runs there are, nor on how they are chunked into tasks or split
across workers or processes, nor on which chunks ``--resume`` skipped. (Before this, the
``--runs`` returns were simulated in lock-step from one stream ``default_rng(S)``; the per-run
streams, and therefore the individual runs, differ from that one. The distribution of the
figures is the same.)

A task simulates :data:`RUNS_PER_TASK` consecutive runs (``--runs-per-task``) in lock-step,
vectorised over the runs (:func:`navkit.sim.return_sim.simulate_returns` with one generator per
run): one run alone costs about as much Python per control cycle as 40 together, so one task per
run would be several times slower. The chunk ``runs-FIRST-LAST`` writes ``runs.json`` (every
run's figures and final position) and ``true_xy.npy`` (``(K, n, 2)`` metres: the true track of
each of its ``n`` runs, one row per control cycle; a stopped run stays where it stopped);
:func:`collect_returns` reads them back into one
:class:`~navkit.sim.return_sim.ReturnSimResult` for ``returns.json`` and ``returns.png``.

Figures per run (lists, one entry per run, in the manifest's rows): final error (m and % of the
path length L), lateral error mean / max, duration, and three outcomes summarised over all runs
as rates with 95 % Wilson intervals (:func:`navkit.batch.summary.summarize` counts every list
element as a trial):

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
from numpy.typing import NDArray

__all__ = [
    "ERROR_RATE_PCT",
    "RUNS_PER_TASK",
    "ReturnSweepSpec",
    "collect_returns",
    "read_return_path",
    "return_runs_job",
    "return_sweep_tasks",
    "run_rng",
]

RUNS_PER_TASK = 25
"""Default runs per task: 40 runs make 2 tasks (both workers of a 2-core machine busy), 10,000
runs make 400 (a few per worker of a large cluster, each well above the scheduler's overhead)."""

ERROR_RATE_PCT = 1.0
"""The final error (% of the path length) the sweep's rate ``final_error_within_1_percent_of_L``
counts against."""


@dataclass(frozen=True)
class ReturnSweepSpec:
    """What one simulated return needs besides its run index: the VO model and the controller
    (:class:`~navkit.sensors.VisualOdometryNoise`, :class:`~navkit.path.control.PathFollowerSettings`)
    and the sweep's seed."""

    vo: Any
    controller: Any
    seed: int = 0


def run_rng(seed: int, run: int) -> np.random.Generator:
    """The random generator of run ``run`` of a sweep seeded ``seed`` (independent streams)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), int(run)]))


def read_return_path(path_json: str) -> Any:
    """The stored path a return drives back along (a ``path.json``, local or an fsspec URL);
    :class:`~navkit.errors.ConfigError` when it has no length to drive."""
    from navkit.errors import ConfigError
    from navkit.io.pathjson import read_path_json
    from navkit.io.urls import local_copy

    with local_copy(path_json) as local:
        spline = read_path_json(local)
    if spline.n_segments == 0 or spline.total_length <= 0:
        raise ConfigError(
            "the stored path has zero length",
            source=path_json,
            field="segments",
            expected="at least one segment of positive length",
        )
    return spline


def return_runs_job(
    out_dir: Path, *, path_json: str, first: int, count: int, settings: ReturnSweepSpec
) -> dict[str, Any]:
    """Simulate runs ``first .. first + count - 1`` of a sweep in lock-step, one stream per run:
    write ``runs.json`` and ``true_xy.npy``; their figures (one list entry per run)."""
    from navkit.io.atomic import atomic_path, write_json
    from navkit.sim.return_sim import simulate_returns

    spline = read_return_path(path_json)
    run_ids = list(range(first, first + count))
    sim = simulate_returns(
        spline,
        runs=count,
        settings=settings.controller,
        vo=settings.vo,
        rng=[run_rng(settings.seed, i) for i in run_ids],
    )
    stop_radius = float(settings.controller.stop_radius)
    err, pct = sim.final_error, sim.final_error_pct
    figures: dict[str, Any] = {
        "final_error_m": [float(v) for v in err],
        "final_error_pct": [float(v) for v in pct],
        "lateral_mean_m": [float(v) for v in sim.lateral_mean],
        "lateral_max_m": [float(v) for v in sim.lateral_max],
        "duration_s": [float(v) if np.isfinite(v) else None for v in sim.duration],
        "stopped_within_the_stop_radius": [bool(v) for v in sim.stopped],
        "ended_within_the_stop_radius": [bool(v <= stop_radius) for v in err],
        "final_error_within_1_percent_of_L": [bool(v <= ERROR_RATE_PCT) for v in pct],
    }
    with atomic_path(out_dir / "true_xy.npy") as tmp:
        np.save(tmp, sim.true_xy)
    runs = [
        {
            "run": i,
            "seed": [int(settings.seed), i],
            "final_xy": sim.final_true[j],
            **{name: vals[j] for name, vals in figures.items()},
        }
        for j, i in enumerate(run_ids)
    ]
    write_json(
        out_dir / "runs.json",
        {"path_length_m": sim.path_length, "start": sim.start, "runs": runs},
    )
    return figures


def return_sweep_tasks(
    path_json: str,
    runs: int,
    settings: ReturnSweepSpec,
    runs_per_task: int = RUNS_PER_TASK,
) -> list[Any]:
    """One :class:`~navkit.batch.BatchTask` per chunk of ``runs_per_task`` runs (folder
    ``runs-FIRST-LAST``), hashed on the navkit version, the path file, the settings and the
    chunk's runs."""
    from navkit import __version__
    from navkit.batch.engine import BatchTask, settings_hash
    from navkit.errors import ConfigError
    from navkit.io.urls import input_identity

    if runs_per_task < 1:
        raise ConfigError(f"is {runs_per_task}", field="--runs-per-task", expected="at least 1")
    ident = input_identity(path_json)
    width = max(4, len(str(runs - 1)))
    tasks = []
    for first in range(0, runs, runs_per_task):
        count = min(runs_per_task, runs - first)
        tasks.append(
            BatchTask(
                f"runs-{first:0{width}d}-{first + count - 1:0{width}d}",
                return_runs_job,
                {"path_json": str(path_json), "first": first, "count": count, "settings": settings},
                settings_hash(__version__, ident, settings, first, count),
            )
        )
    return tasks


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
    chunks = [
        read_json(out / r["key"] / "runs.json", what="a runs.json of a return sweep") for r in done
    ]
    details = [d for c in chunks for d in c["runs"]]
    tracks: list[NDArray[np.float64]] = []
    for r in done:
        if len(tracks) >= max_tracks:
            break
        xy = read_npy(out / r["key"] / "true_xy.npy")
        tracks.extend(xy[:, j, :] for j in range(min(xy.shape[1], max_tracks - len(tracks))))
    k = max(len(t) for t in tracks)
    true_xy = np.stack([np.vstack([t, np.repeat(t[-1:], k - len(t), axis=0)]) for t in tracks], 1)
    final = np.array([d["final_xy"] for d in details], dtype=np.float64)
    duration = np.array(
        [np.nan if d["duration_s"] is None else d["duration_s"] for d in details], dtype=np.float64
    )
    sim = ReturnSimResult(
        path_length=float(chunks[0]["path_length_m"]),
        start=np.asarray(chunks[0]["start"], dtype=np.float64),
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
