"""Localization outputs: ``fixes.csv`` (every scan, fix or failure) and ``poses.tum`` (the
accepted fixes only).

``fixes.csv`` columns: ``index`` (scan / first frame of the group in the input), ``timestamp``
(s), ``x, y, theta`` (the fix, or a failure's rejected candidate; empty when the scan had too
few points), ``score``, ``ok`` (an accepted fix), ``ambiguous``, ``reason`` (why a failure was
refused; empty for a fix), ``direction_x, direction_y`` (the match peak's major axis),
``extent_m``, ``second_score``, ``exact``, ``ms``, ``refined``, ``refine_rms_m``,
``refine_sigma_weak_m``, ``ref_x, ref_y, ref_theta`` (reference pose), ``position_error_m``,
``heading_error_deg`` (of the reported pose against the reference).

``poses.tum``: ``timestamp x y 0 qx qy qz qw`` per accepted fix (planar pose, z = 0); a
failure is never written there.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from navkit.geometry import se3_from_rt
from navkit.io.atomic import atomic_write
from navkit.io.trajectory import Trajectory, write_tum
from navkit.localization.evaluation import pose_errors, reported_poses
from navkit.localization.localizer import Fix, LocalizationFailure

__all__ = ["FIXES_HEADER", "write_fix_poses", "write_fixes_csv"]

FIXES_HEADER = (
    "index,timestamp,x,y,theta,score,ok,ambiguous,reason,direction_x,direction_y,extent_m,"
    "second_score,exact,ms,refined,refine_rms_m,refine_sigma_weak_m,"
    "ref_x,ref_y,ref_theta,position_error_m,heading_error_deg"
)


def write_fixes_csv(
    path: str | os.PathLike[str],
    results: Sequence[Fix | LocalizationFailure],
    indices: ArrayLike,
    timestamps: ArrayLike,
    reference: ArrayLike,
) -> None:
    """Write ``fixes.csv`` (columns in the module docstring), atomically.

    Parameters
    ----------
    path : path
    results : sequence of Fix or LocalizationFailure
        One per scan.
    indices : (K,) int array
        The scans' indices in the input.
    timestamps : (K,) array
        Seconds.
    reference : (K, 3) array
        Reference ``(x, y, theta)`` per scan.
    """
    idx = np.asarray(indices).reshape(-1)
    stamps = np.asarray(timestamps, dtype=np.float64).reshape(-1)
    ref = np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    poses = reported_poses(results)
    pos_err, head_err = pose_errors(poses, ref)
    with atomic_write(path) as fh:
        fh.write(FIXES_HEADER + "\n")
        for k, r in enumerate(results):
            e, g = poses[k], ref[k]
            refcols = f"{g[0]:.4f},{g[1]:.4f},{g[2]:.5f}"
            if not np.all(np.isfinite(e)):
                fh.write(f"{idx[k]},{stamps[k]:.6f},,,,,False,,{r.reason},,,,,,,,,,{refcols},,\n")
                continue
            rf = r.refinement
            rcols = f"{r.refined},{rf.rms:.4f},{rf.sigma_weak:.4f}" if rf is not None else "False,,"
            d = r.direction
            fh.write(
                f"{idx[k]},{stamps[k]:.6f},{e[0]:.4f},{e[1]:.4f},{e[2]:.5f},{r.score:.4f},"
                f"{r.ok},{r.ambiguous},{r.reason},{d[0]:.4f},{d[1]:.4f},{r.extent:.3f},"
                f"{r.second_score:.4f},{r.exact},{1e3 * r.seconds:.2f},{rcols},{refcols},"
                f"{pos_err[k]:.4f},{head_err[k]:.3f}\n"
            )


def write_fix_poses(
    path: str | os.PathLike[str],
    results: Sequence[Fix | LocalizationFailure],
    timestamps: ArrayLike,
) -> None:
    """Write the accepted fixes' planar poses as a TUM trajectory (z = 0), atomically."""
    stamps = np.asarray(timestamps, dtype=np.float64).reshape(-1)
    ok = np.array([isinstance(r, Fix) for r in results], dtype=bool)
    P = np.array([r.pose for r in results if isinstance(r, Fix)]).reshape(-1, 3)
    c, s = np.cos(P[:, 2]), np.sin(P[:, 2])
    R = np.zeros((len(P), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    T = se3_from_rt(R, np.column_stack([P[:, 0], P[:, 1], np.zeros(len(P))]))
    write_tum(path, Trajectory(stamps[ok], T))
