"""Planes (paper 2), organised plane extraction alone: the extraction rows of
:mod:`benchmarks.bench_planes` (navkit vs Open3D's ``segment_plane`` loop, CPU time in one run)
without the motion comparisons, so they can be rerun in a minute.

Run: ``python -m benchmarks planes_extract`` (``--quick``: 5 repeats instead of 15).
"""

from __future__ import annotations

from benchmarks.bench_planes import _extraction_rows, _o3d, extraction_frames
from benchmarks.common import Row


def run(quick: bool = False) -> list[Row]:
    return _extraction_rows(_o3d(), extraction_frames(), 5 if quick else 15)
