"""The per-input functions a batch runs: one input in, files under ``out_dir``, figures out.

Each is a module-level function (Dask pickles it by reference), reads its input itself by path
(nothing large goes through the scheduler), writes through :mod:`navkit.io` (atomically) and
returns a small dict of key figures for the manifest.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

__all__ = ["path_record_job"]


def path_record_job(
    out_dir: Path, *, trajectory: str, tolerance: float = 0.05, fmt: str = "auto"
) -> dict[str, Any]:
    """``navkit path record`` for one trajectory file: ``path.json`` and the figures.

    Timing figures (microseconds per point) are left out of the returned figures so that the
    manifest of a batch is reproducible; they stay in the approximator's own summary.
    """
    from navkit.io.pathjson import write_path_json
    from navkit.io.trajectory import read_trajectory
    from navkit.path import ApproximatorSettings, approximate
    from navkit.path.track import clean_track, ground_plane, to_plane

    traj = read_trajectory(trajectory, fmt)  # type: ignore[arg-type]
    _, P = clean_track(traj.timestamps, traj.positions, source=trajectory)
    xy = to_plane(P, ground_plane(P, "auto"))
    result = approximate(xy, ApproximatorSettings(tolerance=tolerance))
    write_path_json(out_dir / "path.json", result.spline)
    s = result.summary()
    return {
        k: s[k] for k in ("points", "segments", "loops_removed", "length_m", "max_deviation_m")
    } | {"within_tolerance": bool(s["max_deviation_m"] <= tolerance + 1e-12)}
