"""One trajectory of ``navkit path record``: read, approximate, write ``path.json`` and
``path.png``.

The per-input function of the command, alone or in a batch (``--workers`` / ``--scheduler`` /
``--resume``, :mod:`navkit.batch`): the same code writes the same files either way.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

__all__ = ["record_path", "record_path_job"]

DETERMINISTIC = (
    "points",
    "points_used",
    "segments",
    "loops_removed",
    "length_m",
    "tolerance_m",
    "max_deviation_m",
    "stored_numbers",
)
"""The summary's figures that depend on the input and the settings only (not on timing)."""


def record_path(
    out_dir: Path,
    trajectory: str | Path,
    settings: Any,
    fmt: str = "auto",
    plane: str = "auto",
    iterate: Callable[[Iterable[Any], int], Iterator[Any]] | None = None,
) -> tuple[Any, dict[str, Any]]:
    """Record ``trajectory`` (a path or an fsspec URL) with ``settings`` (:class:`~navkit.path.ApproximatorSettings`) and
    write ``path.json`` and ``path.png`` into ``out_dir``; returns the result and its summary.

    ``iterate(items, n)`` wraps the loop over the ``n`` points (a progress bar).

    Raises
    ------
    InputError
        The trajectory has fewer than two distinct positions.
    """
    from navkit.errors import InputError
    from navkit.io.pathjson import write_path_json
    from navkit.io.trajectory import load_planar_track
    from navkit.io.urls import local_copy, url_name
    from navkit.path import approximate
    from navkit.viz.path import plot_record

    with local_copy(trajectory) as local:  # a path as it is; a URL through a private copy
        _, xy, frame, used = load_planar_track(local, fmt, plane)
    if isinstance(frame, dict) and frame.get("source") == str(local):
        frame = {**frame, "source": str(trajectory)}  # the URL, not the private copy
    wrap = None if iterate is None else (lambda items: iterate(items, len(xy)))
    result = approximate(xy, settings, frame=frame, iterate=wrap)
    if result.spline.n_segments == 0 or result.spline.total_length <= 0:
        raise InputError(
            f"{len(result.points)} distinct point(s): the path has zero length",
            source=trajectory,
            field="positions",
            expected="at least two distinct positions",
        )
    write_path_json(out_dir / "path.json", result.spline)
    plot_record(
        result,
        out_dir / "path.png",
        raw_points=xy,
        title=f"{url_name(trajectory)}: eps = {settings.tolerance:g} m",
    )
    summary = {"input": str(trajectory), "format": used, **result.summary()}
    return result, summary


def record_path_job(
    out_dir: Path, *, trajectory: str, settings: Any, fmt: str = "auto", plane: str = "auto"
) -> dict[str, Any]:
    """:func:`record_path` as a batch task: its deterministic figures (no timings), and whether
    every accepted point lies within the tolerance."""
    _, s = record_path(out_dir, trajectory, settings, fmt, plane)
    figures = {k: s[k] for k in DETERMINISTIC}
    figures["within_tolerance"] = bool(s["max_deviation_m"] <= settings.tolerance + 1e-12)
    return figures
