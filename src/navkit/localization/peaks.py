"""The shape of the score around a fix (:mod:`navkit.localization.matcher`, step 6): the
translations within ``peak_tolerance`` of the best, found by the same branch-and-bound
(:mod:`navkit.localization.search`), give the peak's direction and extent (a straight
featureless wall is flat along itself) and the covariance of the fix.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.geometry._validate import as_points
from navkit.localization.field import LikelihoodField
from navkit.localization.matcher_settings import _DEFAULT_SETTINGS, MatcherSettings
from navkit.localization.search import _Search


def analyse_peak(
    fld: LikelihoodField,
    points: ArrayLike,
    pose: ArrayLike,
    settings: MatcherSettings | None = None,
    *,
    angular_step: float | None = None,
) -> tuple[NDArray[np.float64], float, float, NDArray[np.float64], float]:
    """Shape of the score peak around ``pose``.

    Scores all translations within ``ambiguity_window`` (one cell apart; the best of three
    headings ``theta - step, theta, theta + step`` each); the near-optimal set is those within
    ``peak_tolerance`` of the best. Its score-weighted covariance's major axis is the peak's
    direction; the extents are the spread of the set's projections on the two axes.

    Returns
    -------
    direction : (2,) array
    extent, extent_minor : float
        Metres.
    covariance : (2, 2) array
    best : float
        The best score in the neighbourhood.
    """
    s = settings or _DEFAULT_SETTINGS
    P = as_points(points, 2)
    x0 = np.asarray(pose, dtype=np.float64).reshape(3)
    r = fld.resolution
    n = int(np.ceil(s.ambiguity_window / r))
    step = (
        angular_step
        if angular_step is not None
        else r / max(np.percentile(np.linalg.norm(P, axis=1), 95), r)
    )
    search = _Search(
        fld,
        P,
        np.asarray(x0[2] + np.array([-step, 0.0, step]), dtype=np.float64),
        x0[:2] - n * r,
        2 * n + 1,
    )
    # The near-optimal set by branch-and-bound instead of scoring the whole window: pruning at
    # a hair under (1 - peak_tolerance) x the best keeps every leaf of the set (run(keep=...)
    # collects all leaves above keep x the optimum); the same set as exhaustive scoring. The
    # search starts from the score of the pose itself (the window's centre leaf, which it finds
    # again): the optimum is at least that, so the pruning from the first level on stays exact
    # (instead of the top levels expanded whole from a bound of -1).
    centre = np.array([1, n, n])
    s0 = float(search.scores(0, centre[:1], centre[1:2], centre[2:])[0])
    keep = (1.0 - s.peak_tolerance) * (1 - 1e-9)
    res, _ = search.run(len(search.flat), float(np.nextafter(s0, -np.inf)), 10**12, keep=keep)
    assert res is not None
    top = float(res[0])
    if top > 0:
        ls, _lk, lx, ly = (np.concatenate(a) for a in zip(*search.leaves, strict=True))
        sel = ls >= (1.0 - s.peak_tolerance) * top
        # the best of the three headings per translation
        key = lx[sel] * (2 * n + 1) + ly[sel]
        ukey, inv = np.unique(key, return_inverse=True)
        w = np.zeros(len(ukey))
        np.maximum.at(w, inv, ls[sel])
        T: NDArray[np.float64] = (
            np.stack([ukey // (2 * n + 1) - n, ukey % (2 * n + 1) - n], axis=1) * float(r)
        ).astype(np.float64)
    else:  # the scan touches nothing in the window: every offset is equally good
        IX, IY = np.meshgrid(np.arange(-n, n + 1), np.arange(-n, n + 1), indexing="ij")
        T = (np.stack([IX.ravel(), IY.ravel()], axis=1) * float(r)).astype(np.float64)
        w = np.ones(len(T))
    mu = (w[:, None] * T).sum(0) / w.sum()
    C = ((w[:, None] * (T - mu)).T @ (T - mu)) / w.sum()
    _, evecs = np.linalg.eigh(C)
    major, minor = evecs[:, 1], evecs[:, 0]
    pm, pn = T @ major, T @ minor
    return major, float(pm.max() - pm.min()) + r, float(pn.max() - pn.min()) + r, C, top
