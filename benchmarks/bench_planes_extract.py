"""Planes (paper 2), organised plane extraction alone: the extraction rows of
:mod:`benchmarks.bench_planes` (navkit vs Open3D's ``segment_plane`` loop, CPU time in one run)
without the motion comparisons, so they can be rerun in a minute.

Run: ``python -m benchmarks planes_extract`` (``--quick``: 5 repeats instead of 15).

Also the compiled kernels against their NumPy oracles in the same run and the kernels' first-call cost on an empty Numba cache.
"""

from __future__ import annotations

import numpy as np

from benchmarks.bench_planes import AREA, _cpu_median, _extraction_rows, _o3d, extraction_frames
from benchmarks.common import Row, time_ratio
from benchmarks.compile_cost import first_call_rows


def _kernel_rows(frames, repeats: int) -> list[Row]:  # type: ignore[no-untyped-def]
    """Compiled extraction against the same code with the NumPy oracles of its kernels
    (``extract._extract(..., compiled=False)``), interleaved, CPU time medians."""
    from navkit.planes.extract import _extract

    rows = []
    for name, f in frames:
        P = f.points()
        t_c, t_n = [], []
        for _ in range(3):
            t_c.append(_cpu_median(lambda P=P: _extract(P, None, compiled=True), repeats))
            t_n.append(_cpu_median(lambda P=P: _extract(P, None, compiled=False), repeats))
        c, n = float(np.median(t_c)), float(np.median(t_n))
        rows.append(
            Row(
                AREA,
                f"plane extraction 640x480 ({name}): compiled kernels vs their NumPy oracles",
                "ms",
                1000 * c,
                1000 * n,
                "navkit NumPy path",
                time_ratio(c, n),
                "process_time medians, interleaved; target <= 5 ms per real frame",
            )
        )
    return rows


def run(quick: bool = False) -> list[Row]:
    frames = extraction_frames()
    repeats = 5 if quick else 15
    rows = _kernel_rows(frames, repeats)
    rows += _extraction_rows(_o3d(), frames, repeats)
    rows += first_call_rows(
        AREA,
        "plane extraction kernels",
        "import numpy as np\n"
        "from navkit.planes import extract_planes_organized\n"
        "v, u = np.mgrid[0:480, 0:640]\n"
        "P = np.stack([(u - 320) / 500, (v - 240) / 500, np.ones((480, 640))], axis=2) * 2.0",
        "extract_planes_organized(P)",
    )
    return rows
