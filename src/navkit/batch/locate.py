"""One input of ``navkit map locate``: a CARMEN log or a stereo frame folder localized in a wall
map with :class:`navkit.localization.Localizer`, its outputs written.

The per-input function of the command, alone or in a batch (several inputs, ``--workers`` /
``--scheduler`` / ``--resume``, :mod:`navkit.batch`): the same code writes the same files.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["LocateInput", "localizer_settings", "locate_input", "locate_job", "map_source"]

SELF_CONSISTENCY = (
    "self-consistency: the map was built from this log's poses and the fixes are compared with "
    "those same poses: it measures the matcher, not localization accuracy"
)


@dataclass(frozen=True)
class LocateInput:
    """How an input is read, localized and scored (the ``[input]`` table of ``settings.toml``)."""

    map: str
    input: str
    kind: str = ""
    every: int = 1
    group: int = 1
    prior: str = "none"
    max_range: float = 30.0
    success_m: float = 0.3
    success_deg: float = 5.0
    known_heading: bool = False
    localizer: Mapping[str, Any] = field(default_factory=dict)
    """The ``[localizer]`` table (from ``--config`` and the options); per-input defaults fill
    the rest (:func:`localizer_settings`)."""


def localizer_settings(table: Mapping[str, Any], seq: Any, source: str = "options") -> Any:
    """LocalizerSettings from a ``[localizer]`` table; not set there: refinement on for stereo
    frames, the input's own range error model."""
    from navkit.localization import LocalizerSettings

    data = dict(table)
    data.setdefault("refine", seq.kind == "stereo")
    data.setdefault("range_sigma_coefficient", seq.range_sigma_coefficient)
    return LocalizerSettings.from_dict(data, source=source)


def map_source(map_json: str | Path) -> str | None:
    """The input a ``map.json`` was built from (its ``source`` field), if it says."""
    from navkit.io.atomic import read_json
    from navkit.io.urls import local_copy

    with local_copy(map_json) as local:
        data = read_json(local)
    src = data.get("source") if isinstance(data, dict) else None
    return str(src) if src else None


def _grid_files(map_json: str) -> tuple[str, ...]:
    """The grid files a URL ``map.json`` names (its ``grid`` YAML and that YAML's ``.pgm``, as
    ``navkit map build`` writes them); none for a plain path, read where it is."""
    from navkit.io.urls import is_url

    if not is_url(map_json):
        return ()
    from navkit.io.atomic import read_json
    from navkit.io.urls import local_copy

    with local_copy(map_json) as local:
        data = read_json(local, what="a map.json written by navkit map build")
    grid = data.get("grid") if isinstance(data, dict) else None
    if not isinstance(grid, str) or not grid:
        return ()
    return (grid, str(Path(grid).with_suffix(".pgm")))


def _reference(inp: LocateInput, kind: str) -> str:
    from navkit.io.urls import is_url

    src = map_source(inp.map)
    if src and (is_url(src) or is_url(inp.input)) and src == inp.input:
        return SELF_CONSISTENCY
    if src and Path(src).resolve() == Path(inp.input).resolve():
        return SELF_CONSISTENCY
    if kind == "stereo":
        return "the frames' poses.tum (simulator ground truth for navkit stereo simulate)"
    return "the log's corrected poses (a SLAM estimate, not ground truth)"


def locate_input(
    out_dir: Path,
    inp: LocateInput,
    iterate: Callable[[Iterable[int], int], Iterator[int]] | None = None,
) -> tuple[dict[str, Any], Any]:
    """Localize every (N-th) scan of ``inp.input`` and write ``poses.tum``, ``fixes.csv``,
    ``locate.png``; returns the summary and the resolved LocalizerSettings."""
    import numpy as np

    from navkit.io.fixes import write_fix_poses, write_fixes_csv
    from navkit.io.scan_sequence import read_scan_sequence
    from navkit.io.urls import local_copy, url_name
    from navkit.io.wallmap import read_wall_map
    from navkit.localization import Localizer, evaluate_fixes
    from navkit.localization.evaluation import reported_poses
    from navkit.viz.maps import plot_map

    # paths as they are; fsspec URLs (a map with its grid files, a CARMEN log) through private
    # copies
    with local_copy(inp.map, siblings=_grid_files(inp.map)) as local:
        wall_map = read_wall_map(local)
    with local_copy(inp.input) as local:
        seq = read_scan_sequence(local, every=inp.every, group=inp.group, max_range=inp.max_range)
    settings = localizer_settings(inp.localizer, seq)
    loc = Localizer(wall_map, settings, view=seq.view)
    tracking = inp.prior == "odometry"
    steps: Iterable[int] = range(len(seq))
    if iterate is not None:
        steps = iterate(steps, len(seq))
    results = [
        loc.update(
            seq.points(k),
            odometry_delta=seq.odometry_delta(k) if tracking else None,
            heading=float(seq.reference[k, 2]) if inp.known_heading else None,
        )
        for k in steps
    ]
    out_dir.mkdir(parents=True, exist_ok=True)
    write_fix_poses(out_dir / "poses.tum", results, seq.timestamps)
    write_fixes_csv(out_dir / "fixes.csv", results, seq.indices, seq.timestamps, seq.reference)
    stats = evaluate_fixes(
        results, seq.reference, success_m=inp.success_m, success_deg=inp.success_deg
    )
    summary: dict[str, Any] = {
        "input": inp.input,
        "input_kind": seq.kind,
        "prior": inp.prior,
        "method": "known heading (paper 3)" if inp.known_heading else "correlative matching",
        "reference": _reference(inp, seq.kind),
        **stats,
    }
    if wall_map.walls:
        size = float(np.linalg.norm(np.subtract(*wall_map.bounds[::-1])))
        summary["map_diagonal_m"] = size
        summary["position_error_relative_median"] = stats["position_error_m_median"] / size
    title = f"{url_name(inp.input)}: {100 * stats['success_rate']:.0f}% within {inp.success_m} m"
    est = np.where([[r.ok] for r in results], reported_poses(results), np.nan)
    plot_map(wall_map, out_dir / "locate.png", poses=est, truth=seq.reference, title=title)
    return summary, settings


def locate_job(out_dir: Path, *, inp: LocateInput) -> dict[str, Any]:
    """:func:`locate_input` as a batch task: the evaluation's figures without timings."""
    summary, _ = locate_input(out_dir, inp)
    return {
        k: v
        for k, v in summary.items()
        if not k.startswith(("ms_", "seconds")) and isinstance(v, (int, float, str, bool))
    }
