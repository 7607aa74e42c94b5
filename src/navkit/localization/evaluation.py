"""Scoring a sequence of :class:`~navkit.localization.localizer.Localizer` results against
reference poses (a log's corrected poses, a simulator's truth).

Decision: only accepted fixes are results. ``success_rate`` counts the scans with an accepted
fix within ``success_m`` and ``success_deg`` of the reference; the position / heading error
statistics are those of the accepted fixes. The rejected candidates are scored apart
(``candidate_*``: every attempted scan's best pose, accepted or not - what ``navkit map locate``
reported as ``success_rate`` / ``position_error_m_median`` before the Localizer).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError
from navkit.geometry import wrap_angle
from navkit.localization.localizer import Fix, LocalizationFailure

__all__ = ["evaluate_fixes", "pose_errors", "reported_poses"]


def reported_poses(results: Sequence[Fix | LocalizationFailure]) -> NDArray[np.float64]:
    """``(K, 3)`` poses: a fix's pose, a failure's rejected candidate (NaN when none)."""
    out = np.full((len(results), 3), np.nan)
    for k, r in enumerate(results):
        out[k] = r.pose if isinstance(r, Fix) else r.candidate
    return out


def pose_errors(
    poses: ArrayLike, reference: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Position error (m) and absolute heading error (degrees, wrapped) of ``(K, 3)`` poses
    against ``(K, 3)`` reference poses (NaN where a pose is NaN)."""
    E = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    R = np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    if E.shape != R.shape:
        raise InputError(
            f"has {len(R)} poses for {len(E)} results",
            field="reference",
            expected="one reference pose per result",
        )
    pos = np.hypot(E[:, 0] - R[:, 0], E[:, 1] - R[:, 1])
    head = np.degrees(np.abs(wrap_angle(E[:, 2] - R[:, 2])))
    return pos, head


def _median(x: NDArray[np.float64]) -> float:
    return float(np.median(x)) if len(x) else float("nan")


def _p95(x: NDArray[np.float64]) -> float:
    return float(np.percentile(x, 95)) if len(x) else float("nan")


def evaluate_fixes(
    results: Sequence[Fix | LocalizationFailure],
    reference: ArrayLike,
    *,
    success_m: float = 0.3,
    success_deg: float = 5.0,
) -> dict[str, float]:
    """Rates, errors and timings of a localized sequence (see the module docstring).

    Parameters
    ----------
    results : sequence of Fix or LocalizationFailure
        One per scan, in order.
    reference : (K, 3) array
        Reference ``(x, y, theta)`` per scan.
    success_m, success_deg : float
        A fix within both of its reference is a success.

    Returns
    -------
    dict
        ``fixes``, ``ok_rate``, ``success_rate``, ``success_rate_of_ok``, ``false_fix_rate``,
        ``ambiguous_rate`` (of the attempted scans), ``refined_rate``, ``position_error_m_median``
        / ``_p95`` and ``heading_error_deg_median`` (accepted fixes), ``candidate_success_rate``
        and ``candidate_position_error_m_median`` (every candidate), ``ms_per_fix_median`` /
        ``_mean`` / ``_p95`` (attempted scans).
    """
    poses = reported_poses(results)
    pos_err, head_err = pose_errors(poses, reference)
    attempted = np.all(np.isfinite(poses), axis=1)
    ok = np.array([r.ok for r in results], dtype=bool)
    within = attempted & (pos_err <= success_m) & (head_err <= success_deg)
    success = ok & within
    ms = np.array([1e3 * r.seconds for r, a in zip(results, attempted, strict=True) if a])
    amb = np.array([r.ambiguous for r, a in zip(results, attempted, strict=True) if a])
    n = max(len(results), 1)
    return {
        "fixes": len(results),
        "ms_per_fix_median": _median(ms),
        "ms_per_fix_mean": float(np.mean(ms)) if len(ms) else float("nan"),
        "ms_per_fix_p95": _p95(ms),
        "refined_rate": float(np.sum([r.refined for r in results]) / n),
        "ok_rate": float(ok.sum() / n),
        "success_rate": float(success.sum() / n),
        "success_rate_of_ok": float(success[ok].mean()) if ok.any() else float("nan"),
        "false_fix_rate": float((ok & ~within).sum() / n),
        "ambiguous_rate": float(amb.mean()) if len(amb) else float("nan"),
        "position_error_m_median": _median(pos_err[ok]),
        "position_error_m_p95": _p95(pos_err[ok]),
        "heading_error_deg_median": _median(head_err[ok]),
        "candidate_success_rate": float(within.sum() / n),
        "candidate_position_error_m_median": _median(pos_err[attempted]),
    }
