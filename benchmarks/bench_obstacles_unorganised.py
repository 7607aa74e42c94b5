"""Ground / non-ground on unorganised airborne clouds: navkit's unorganised path against SMRF
and CSF on the shared ISPRS "Comparison of Filters" samples (per-point ground truth).

Every method runs in this process on the same points, with one parameter set for every sample:

- navkit: :func:`navkit.obstacles.unorganised.detect_unorganised` with the default
  :class:`~navkit.obstacles.unorganised.UnorganisedSettings`, run twice: ``nk-grnd`` with
  ``ground_only=True`` (spacing, noise, ground surface and per-point labels: the job SMRF and
  CSF do, so its CPU is the one to compare with theirs) and ``navkit`` (the whole pipeline:
  ground, mesh, rules, separate obstacles, boundaries and the shapes of every obstacle, trees
  included; same labels, more work);
- SMRF (``pysmrf.smrf``) with the paper's single parameter set: cell 1 m, window 18,
  slope 0.15, elevation threshold 0.5 m, scaler 1.25 (Pingel et al. 2013);
- CSF (``cloth-simulation-filter``) with its defaults for flat terrain and slope
  post-processing (cloth resolution 0.5 m, rigidness 3, class threshold 0.5 m).

Figures per sample: total error, type I, type II (%), kappa (%) and CPU seconds per million
points (``time.process_time`` of one call; BLAS / OpenMP pools held to one thread so that the
CPU time is the work, not idle spinning on a shared machine). Before the first sample navkit
runs once on a small synthetic cloud with two boxes, so that every stage has run (stage 8's
compiled kernels loaded) and no sample's CPU holds a first call. The CPU rows compare each
sample's navkit runs with SMRF's in the same process: the figure to read is their ratio, the
absolute seconds move with the machine's load. SMRF and CSF come from the ``bench`` extra; a
missing one is reported and left out.

    python -m benchmarks obstacles_unorganised
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

from benchmarks.common import Row  # noqa: E402

SAMPLES = ("samp11", "samp12", "samp21", "samp22", "samp23", "samp24", "samp31")
AREA = "obstacles_unorganised"


def _load(name: str) -> tuple[np.ndarray, np.ndarray] | None:
    from navkit.datasets import find
    from navkit.errors import DataNotFoundError
    from navkit.io.pointcloud import read_pcd
    from navkit.obstacles.unorganised import reference_ground

    try:
        folder = find("lidar/isprs-terrain")
    except DataNotFoundError:
        return None
    cloud, ground = folder / f"{name}-utm.pcd", folder / f"{name}-utm-ground.pcd"
    if not cloud.exists() or not ground.exists():
        return None
    P = np.asarray(read_pcd(cloud).points, dtype=np.float64)[:, :3]
    G = np.asarray(read_pcd(ground).points, dtype=np.float64)[:, :3]
    return P, reference_ground(P, G)


def _warm_up_cloud() -> np.ndarray:
    """Flat ground with two boxes (4 m and 8 m high): every stage runs, stage 8 included."""
    rng = np.random.default_rng(0)
    xy = rng.uniform(0.0, 80.0, (6000, 2))
    box = (np.abs(xy[:, 0] - 25.0) < 6.0) & (np.abs(xy[:, 1] - 25.0) < 6.0)
    hall = (np.abs(xy[:, 0] - 55.0) < 8.0) & (np.abs(xy[:, 1] - 50.0) < 5.0)
    z = 4.0 * box + 8.0 * hall + rng.normal(0.0, 0.03, len(xy))
    return np.column_stack([xy, z])


def _navkit(P: np.ndarray) -> np.ndarray:
    from navkit.obstacles.unorganised import detect_unorganised

    return detect_unorganised(P).ground


def _navkit_ground(P: np.ndarray) -> np.ndarray:
    from navkit.obstacles.unorganised import detect_unorganised

    return detect_unorganised(P, ground_only=True).ground


def _smrf(P: np.ndarray) -> np.ndarray:
    import warnings

    import pysmrf

    with warnings.catch_warnings():  # pysmrf's use of affine's deprecated operator
        warnings.simplefilter("ignore")
        out = pysmrf.smrf(
            P[:, 0],
            P[:, 1],
            P[:, 2],
            cellsize=1.0,
            windows=18,
            slope_threshold=0.15,
            elevation_threshold=0.5,
            elevation_scaler=1.25,
        )
    return ~np.asarray(out[3], dtype=bool)


def _csf(P: np.ndarray) -> np.ndarray:
    import CSF

    f = CSF.CSF()
    f.params.bSloopSmooth = True
    f.params.cloth_resolution = 0.5
    f.params.rigidness = 3
    f.params.class_threshold = 0.5
    f.params.time_step = 0.65
    f.params.interations = 500
    f.setPointCloud((P - P.min(axis=0)).tolist())
    ground, non_ground = CSF.VecInt(), CSF.VecInt()
    f.do_filtering(ground, non_ground, False)
    out = np.zeros(len(P), dtype=bool)
    out[np.asarray(ground, dtype=np.int64)] = True
    return out


def _methods() -> list[tuple[str, Callable[[np.ndarray], np.ndarray]]]:
    methods: list[tuple[str, Callable[[np.ndarray], np.ndarray]]] = [
        ("nk-grnd", _navkit_ground),
        ("navkit", _navkit),
    ]
    for name, module, fn in (("SMRF", "pysmrf", _smrf), ("CSF", "CSF", _csf)):
        try:
            __import__(module)
        except ImportError:
            print(f"{name}: not installed (pip install 'navkit[bench]'); left out")
            continue
        methods.append((name, fn))
    return methods


def table(quick: bool = False) -> list[dict[str, Any]]:
    """One record per (sample, method): scores and CPU."""
    from navkit.obstacles.unorganised import filter_scores

    records = []
    samples = SAMPLES[:2] if quick else SAMPLES
    methods = _methods()
    _navkit(_warm_up_cloud())  # imports, first calls (with obstacles: the shapes' kernels)
    for name in samples:
        loaded = _load(name)
        if loaded is None:
            print(f"{name}: not in NAVKIT_DATA/lidar/isprs-terrain; left out")
            continue
        P, truth = loaded
        for method, fn in methods:
            t = time.process_time()
            pred = fn(P)
            cpu = time.process_time() - t
            s = filter_scores(pred, truth)
            records.append(
                {
                    "sample": name,
                    "method": method,
                    "n_points": len(P),
                    "total": s.total,
                    "type_i": s.type_i,
                    "type_ii": s.type_ii,
                    "kappa": s.kappa,
                    "cpu_s": cpu,
                    "cpu_s_per_mpt": cpu / len(P) * 1e6,
                }
            )
    return records


def _print(records: list[dict[str, Any]]) -> None:
    print(
        f"{'sample':8} {'method':7} {'points':>7} {'total%':>7} {'typeI%':>7} {'typeII%':>7} "
        f"{'kappa%':>7} {'CPU s':>6} {'s/Mpt':>7}"
    )
    for r in records:
        print(
            f"{r['sample']:8} {r['method']:7} {r['n_points']:7d} {r['total']:7.2f} "
            f"{r['type_i']:7.2f} {r['type_ii']:7.2f} {r['kappa']:7.2f} {r['cpu_s']:6.2f} "
            f"{r['cpu_s_per_mpt']:7.1f}"
        )
    for method in dict.fromkeys(r["method"] for r in records):
        rs = [r for r in records if r["method"] == method]
        print(
            f"{'mean':8} {method:7} {'':7} {np.mean([r['total'] for r in rs]):7.2f} "
            f"{np.mean([r['type_i'] for r in rs]):7.2f} "
            f"{np.mean([r['type_ii'] for r in rs]):7.2f} "
            f"{np.mean([r['kappa'] for r in rs]):7.2f} "
            f"{np.mean([r['cpu_s'] for r in rs]):6.2f}"
        )


def run(quick: bool = False) -> list[Row]:
    records = table(quick)
    _print(records)
    rows = []
    by = {(r["sample"], r["method"]): r for r in records}
    for sample in dict.fromkeys(r["sample"] for r in records):
        nk = by[(sample, "navkit")]
        ng = by[(sample, "nk-grnd")]
        for peer in ("SMRF", "CSF"):
            pr = by.get((sample, peer))
            rows.append(
                Row(
                    AREA,
                    f"{sample} total error vs {peer}",
                    "%",
                    nk["total"],
                    pr["total"] if pr else None,
                    peer,
                    pr["total"] / nk["total"] if pr and nk["total"] else None,
                    f"type I {nk['type_i']:.2f} / II {nk['type_ii']:.2f}, kappa "
                    f"{nk['kappa']:.1f}; ratio = peer / navkit (> 1: navkit better)",
                )
            )
            rows.append(
                Row(
                    AREA,
                    f"{sample} CPU vs {peer}",
                    "s / Mpt",
                    nk["cpu_s_per_mpt"],
                    pr["cpu_s_per_mpt"] if pr else None,
                    peer,
                    pr["cpu_s"] / nk["cpu_s"] if pr and nk["cpu_s"] else None,
                    "whole pipeline (with obstacles and shapes); ratio = peer / navkit "
                    "(> 1: navkit faster)",
                )
            )
            rows.append(
                Row(
                    AREA,
                    f"{sample} ground labels CPU vs {peer}",
                    "s / Mpt",
                    ng["cpu_s_per_mpt"],
                    pr["cpu_s_per_mpt"] if pr else None,
                    peer,
                    pr["cpu_s"] / ng["cpu_s"] if pr and ng["cpu_s"] else None,
                    "ground labels only (ground_only=True); ratio = peer / navkit",
                )
            )
    for method in dict.fromkeys(r["method"] for r in records):
        rs = [r for r in records if r["method"] == method]
        if method == "nk-grnd":  # same labels as navkit
            continue
        rows.append(
            Row(
                AREA,
                f"mean total error, {len(rs)} samples",
                "%",
                float(np.mean([r["total"] for r in rs])) if method == "navkit" else None,
                float(np.mean([r["total"] for r in rs])) if method != "navkit" else None,
                method if method != "navkit" else "",
                None,
                "one parameter set for every sample",
            )
        )
    return rows


if __name__ == "__main__":
    _print(table())
