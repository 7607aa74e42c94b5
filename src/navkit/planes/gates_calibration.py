"""Calibrate the dense step's gates on a sequence with reference poses, and check them on another.

:class:`~navkit.planes.odometry.DenseGates` decide when a dense alignment counts as measured.
Their thresholds are in the sensor's noise units so that one set serves every sequence; this
module is how that claim is checked (``benchmarks/planes_gates.py`` runs it on both shared
sequences, ``tests/planes/test_gate_transfer.py`` asserts what transfers):

1. :func:`spoiled_alignments`: pairs of frames are aligned from their reference motion spoiled
   by 0, 2, 10, 20, 40 and 80 cm (0-20 deg, random directions); each result is *right* (within
   3 cm / 1.5 deg) or *wrong* (off by more than 5 cm or 2 deg), :func:`right_wrong`.
2. :func:`gates_from`: gates from one sequence's right results - geometric RMS 1.25 x their
   largest, overlap and inliers 0.9 x their smallest, photometric RMS 1.25 x its largest.
3. :func:`passes`: which results of another sequence those gates accept.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from navkit.planes.odometry import DenseGates

__all__ = ["FIELDS", "SPOILS", "gates_from", "passes", "right_wrong", "spoiled_alignments"]

SPOILS = ((0.0, 0.0), (0.02, 0.5), (0.1, 2.5), (0.2, 5.0), (0.4, 10.0), (0.8, 20.0))
"""(metres, degrees) by which the reference motion is spoiled before each alignment."""
FIELDS = ("err_m", "err_deg", "geometric", "photometric", "overlap", "inliers")
"""Columns of :func:`spoiled_alignments`' rows."""


def spoiled_alignments(
    frame_at: Callable[[int], Any],
    reference: NDArray[np.float64],
    starts: Sequence[int],
    seed: int = 0,
) -> NDArray[np.float64]:
    """``(N, 6)`` rows of :data:`FIELDS`: pairs ``(k, k + 1)`` and ``(k, k + 10)`` for ``k`` in
    ``starts``, each aligned from the reference motion spoiled by each of :data:`SPOILS`.

    ``frame_at(i)``: RGB-D frame ``i`` (``.color``, ``.depth``, ``.camera``; e.g. an
    :class:`~navkit.io.rgbd.RGBDSequence`'s ``frame``); ``reference``: ``(n, 4, 4)`` poses of
    the sequence's frames, NaN where there is none (such pairs are skipped)."""
    from navkit.geometry import se3_from_rt, se3_inverse
    from navkit.planes.dense import DenseFrame, dense_align
    from navkit.planes.texture import to_gray

    rng = np.random.default_rng(seed)
    cache: dict[int, DenseFrame] = {}

    def dense(i: int) -> DenseFrame:
        if i not in cache:
            f = frame_at(i)
            cache[i] = DenseFrame.build(to_gray(f.color), f.depth, f.camera)
        return cache[i]

    G = np.asarray(reference, dtype=np.float64)
    out = []
    for k in starts:
        for gap in (1, 10):
            a, b = k, k + gap
            if b >= len(G) or not (np.isfinite(G[a]).all() and np.isfinite(G[b]).all()):
                continue
            truth = se3_inverse(G[a]) @ G[b]
            for dist, deg in SPOILS:
                d, w = rng.normal(size=3), rng.normal(size=3)
                spoil = se3_from_rt(
                    Rotation.from_rotvec(np.radians(deg) * w / np.linalg.norm(w)).as_matrix(),
                    dist * d / np.linalg.norm(d),
                )
                r = dense_align(dense(a), dense(b), truth @ spoil)
                E = se3_inverse(truth) @ r.T
                out.append(
                    (
                        float(np.linalg.norm(E[:3, 3])),
                        float(np.degrees(Rotation.from_matrix(E[:3, :3]).magnitude())),
                        r.geometric_sigmas,
                        r.photometric_sigmas,
                        r.overlap,
                        r.inliers,
                    )
                )
    return np.array(out, dtype=np.float64).reshape(-1, len(FIELDS))


def right_wrong(A: NDArray[np.float64]) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Rows within 3 cm / 1.5 deg of the reference, and rows off by more than 5 cm or 2 deg."""
    right = (A[:, 0] <= 0.03) & (A[:, 1] <= 1.5)
    wrong = (A[:, 0] > 0.05) | (A[:, 1] > 2.0)
    return right, wrong


def gates_from(A: NDArray[np.float64], photometric: bool = True) -> DenseGates:
    """Gates from the right results of one sequence (module docstring); ``photometric=False``
    leaves the photometric RMS ungated."""
    right, _ = right_wrong(A)
    R = A[right]
    return DenseGates(
        max_geometric_sigmas=1.25 * float(np.nanmax(R[:, 2])),
        max_photometric_sigmas=1.25 * float(np.nanmax(R[:, 3])) if photometric else 1e9,
        min_overlap=0.9 * float(np.nanmin(R[:, 4])),
        min_inliers=0.9 * float(np.nanmin(R[:, 5])),
    )


def passes(gates: DenseGates, A: NDArray[np.float64]) -> NDArray[np.bool_]:
    """Which rows ``gates`` accept (NaN figures fail, as :meth:`DenseGates.check`)."""
    with np.errstate(invalid="ignore"):
        return (
            (A[:, 2] <= gates.max_geometric_sigmas)
            & (A[:, 3] <= gates.max_photometric_sigmas)
            & (A[:, 4] >= gates.min_overlap)
            & (A[:, 5] >= gates.min_inliers)
        )
