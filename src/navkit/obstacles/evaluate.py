"""Scores against labelled data: ground precision / recall / F1, obstacle-shape containment, and
the fused obstacle map against true footprints (:func:`score_obstacle_map`).

Map score: a true obstacle is *found* when a map component comes within ``tolerance`` of its
footprint; a component matching nothing is a *phantom*. Recall is counted over the obstacles the
sensor actually hit (the caller passes their indices), so an obstacle never in view is not held
against the detector.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError
from navkit.geometry.polygons import points_in_polygon
from navkit.obstacles.mapper import ObstacleGrid

__all__ = [
    "PATCHWORK_EXCLUDED",
    "PATCHWORK_GROUND",
    "VEGETATION",
    "GroundScores",
    "distance_to_polygon",
    "ground_scores",
    "score_obstacle_map",
    "shape_contains",
]

PATCHWORK_GROUND = frozenset({40, 44, 48, 49, 60, 72})
"""SemanticKITTI classes counted as ground (road, parking, sidewalk, other-ground,
lane-marking, terrain) in the Patchwork / Patchwork++ evaluation."""
PATCHWORK_EXCLUDED = frozenset({0, 1})
"""Classes left out of the scores (unlabeled, outlier)."""
VEGETATION = 70
"""Vegetation: left out of P/R/F1 (ambiguous low vegetation) and reported separately."""


@dataclass(frozen=True)
class GroundScores:
    """Per-point ground segmentation scores.

    Attributes
    ----------
    precision, recall, f1 : float
        Over the scored points (ground classes vs every other scored class).
    n_scored : int
        Points scored (not unlabeled / outlier / vegetation).
    vegetation_as_ground : float
        Fraction of vegetation points predicted as ground (NaN when there is none).
    """

    precision: float
    recall: float
    f1: float
    n_scored: int
    vegetation_as_ground: float


def ground_scores(
    predicted_ground: ArrayLike, semantic: ArrayLike, *, source: str = "labels"
) -> GroundScores:
    """Ground P/R/F1 under the Patchwork++ protocol (see :data:`PATCHWORK_GROUND`).

    Parameters
    ----------
    predicted_ground : (N,) bool
        The prediction per point.
    semantic : (N,) int
        SemanticKITTI class per point (``label & 0xFFFF``).

    Raises
    ------
    InputError
        If the two arrays differ in length.
    """
    pred = np.asarray(predicted_ground, dtype=bool).reshape(-1)
    sem = np.asarray(semantic).reshape(-1)
    if pred.shape != sem.shape:
        raise InputError(
            f"has {sem.size} labels for {pred.size} points",
            source=source,
            field="semantic",
            expected="one label per point",
        )
    gt = np.isin(sem, list(PATCHWORK_GROUND))
    scored = ~np.isin(sem, [*PATCHWORK_EXCLUDED, VEGETATION])
    tp = int(np.count_nonzero(pred & gt & scored))
    fp = int(np.count_nonzero(pred & ~gt & scored))
    fn = int(np.count_nonzero(~pred & gt & scored))
    p = tp / (tp + fp) if tp + fp else float("nan")
    r = tp / (tp + fn) if tp + fn else float("nan")
    f1 = 2 * p * r / (p + r) if tp else 0.0
    veg = sem == VEGETATION
    return GroundScores(
        p, r, f1, int(scored.sum()), float(pred[veg].mean()) if veg.any() else float("nan")
    )


def shape_contains(
    obstacles: Iterable[object],
    points_xy: ArrayLike,
    names: Sequence[str] = ("A1",),
    *,
    guaranteed: bool = False,
    tol: float = 1e-6,
) -> NDArray[np.bool_]:
    """``(N,)`` mask of points inside at least one obstacle's shape among ``names``.

    ``obstacles`` are :class:`~navkit.obstacles.Obstacle`; ``guaranteed=True`` uses their A7
    shapes (over obstacle + shadows).
    """
    P = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    inside = np.zeros(len(P), dtype=bool)
    for ob in obstacles:
        shapes = ob.guaranteed if guaranteed else ob.shapes  # type: ignore[attr-defined]
        for name in names:
            if name in shapes:
                inside |= shapes[name].contains(P, tol)
    return inside


def distance_to_polygon(
    points: NDArray[np.float64], poly: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Distance ``(N,)`` of points ``(N, 2)`` to a polygon ``(K, 2)`` (0 inside), metres."""

    A, B = poly, np.roll(poly, -1, axis=0)
    AB = B - A
    L2 = np.maximum((AB**2).sum(1), 1e-12)
    t = np.clip(np.einsum("nkd,kd->nk", points[:, None, :] - A[None], AB) / L2, 0.0, 1.0)
    proj = A[None] + t[..., None] * AB[None]
    d = np.hypot(*(points[:, None, :] - proj).transpose(2, 0, 1)).min(axis=1)
    inside = points_in_polygon(points, poly)
    return np.where(inside, 0.0, d)


def score_obstacle_map(
    grid: ObstacleGrid,
    footprints: Sequence[Any],
    seen_indices: set[int],
    *,
    min_height: float,
    robot_width: float,
    tolerance: float,
) -> dict[str, Any]:
    """Recall, precision and phantoms of the fused map against the true footprints.

    Parameters
    ----------
    grid : ObstacleGrid
        The map (:meth:`navkit.obstacles.ObstacleMapper.grid`).
    footprints : sequence of footprints
        The truth, with attributes ``index``, ``name``, ``kind``, ``polygon`` ``(K, 2)``,
        ``height`` and ``extent`` (:func:`navkit.sim.footprints.true_footprints`).
    seen_indices : set of int
        Primitives the lidar actually hit during the mission.
    min_height : float
        True obstacles lower than this (a curb) are traversable: not expected, and a component on
        them counts as a phantom.
    robot_width : float
        "Larger than the robot": largest horizontal extent at least this, metres.
    tolerance : float
        Matching distance, metres.

    Returns
    -------
    dict
        ``recall``, ``recall_larger_than_robot``, ``precision``, ``phantoms``, per-obstacle rows
        (``obstacles``), per-component rows (``components``), and ``cell_error_*``: distances of
        obstacle cells of matched components to the true footprint (map error), metres.
    """
    labels, n = grid.components()
    rows, cols = np.nonzero(labels)
    lab = labels[rows, cols]
    C = grid.centres(rows, cols)
    expected = [f for f in footprints if f.height >= min_height]
    D = (
        np.stack([distance_to_polygon(C, f.polygon) for f in expected], axis=1)
        if expected and len(C)
        else np.zeros((len(C), 0))
    )
    comp_rows = []
    matched_comp = np.zeros(n + 1, dtype=bool)
    cell_err: list[NDArray[np.float64]] = []
    for k in range(1, n + 1):
        m = lab == k
        if D.shape[1]:
            dmin = D[m].min(axis=0)  # closest approach of the component to each footprint
            j = int(np.argmin(dmin))
            ok = bool(dmin[j] <= tolerance)
        else:
            ok, j = False, -1
        matched_comp[k] = ok
        if ok:
            cell_err.append(D[m].min(axis=1))
        centre = C[m].mean(axis=0)
        comp_rows.append(
            {
                "id": k,
                "cells": int(m.sum()),
                "centre": centre.tolist(),
                "area_m2": float(m.sum() * grid.resolution**2),
                "matches": expected[j].name if ok else None,
            }
        )
    obst_rows = []
    for j, f in enumerate(expected):
        found = bool(D.shape[1] and len(C) and (D[:, j] <= tolerance).any())
        obst_rows.append(
            {
                "name": f.name,
                "kind": f.kind,
                "height_m": f.height,
                "extent_m": f.extent,
                "seen": f.index in seen_indices,
                "found": found,
                "larger_than_robot": f.extent >= robot_width,
            }
        )
    seen_rows = [r for r in obst_rows if r["seen"]]
    large = [r for r in seen_rows if r["larger_than_robot"]]
    n_found = sum(1 for r in seen_rows if r["found"])
    n_found_large = sum(1 for r in large if r["found"])
    errs = np.concatenate(cell_err) if cell_err else np.zeros(0)
    return {
        "true_obstacles": len(expected),
        "seen_obstacles": len(seen_rows),
        "found": n_found,
        "recall": n_found / len(seen_rows) if seen_rows else float("nan"),
        "recall_larger_than_robot": n_found_large / len(large) if large else float("nan"),
        "larger_than_robot_missed": [r["name"] for r in large if not r["found"]],
        "components": n,
        "precision": float(matched_comp[1:].sum() / n) if n else float("nan"),
        "phantoms": int(n - matched_comp[1:].sum()),
        "cell_error_median_m": float(np.median(errs)) if len(errs) else float("nan"),
        "cell_error_p95_m": float(np.percentile(errs, 95)) if len(errs) else float("nan"),
        "obstacles": obst_rows,
        "component_list": comp_rows,
    }
