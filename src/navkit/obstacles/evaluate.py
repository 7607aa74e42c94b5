"""Scores against labelled data: ground precision / recall / F1, and obstacle-shape containment."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError

__all__ = [
    "PATCHWORK_EXCLUDED",
    "PATCHWORK_GROUND",
    "VEGETATION",
    "GroundScores",
    "ground_scores",
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
