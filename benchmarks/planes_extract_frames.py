"""Organised plane extraction, CPU time per 640 x 480 frame, on the benchmark's frames, every 10th
7-Scenes frame or the CAPE tunnel frame; Open3D's ``segment_plane`` loop timed beside it.

The extraction (default settings and ``refine="full"``) and Open3D's loop (asked for as many
planes as navkit found) are timed interleaved in one process: CPU time medians of 3 x
``--repeats``. The requirement is at most 5 ms per real frame.

Run from the repository root::

    PYTHONPATH=.:src .venv/bin/python benchmarks/planes_extract_frames.py [--repeats 9]
        [--frames benchmark|7scenes|cape] [--no-open3d]
"""

from __future__ import annotations

import argparse

import numpy as np

from benchmarks.bench_planes import _cpu_median, _o3d, _segment_plane_loop, extraction_frames
from navkit.planes import ExtractionSettings, extract_planes_organized


def _frames(which: str) -> list[tuple[str, np.ndarray]]:
    """``(name, (H, W, 3) grid)`` of the chosen frames."""
    if which == "benchmark":
        return [(name, f.points()) for name, f in extraction_frames()]
    from navkit import datasets
    from navkit.io.rgbd import open_rgbd_sequence, read_cape_frame

    if which == "cape":
        return [("CAPE tunnel", read_cape_frame(datasets.find("rgbd/cape-tunnel")).points)]
    seq = open_rgbd_sequence(datasets.find("rgbd/7scenes-tsdf"))
    return [(f"7-Scenes #{i}", seq.frame(i).points()) for i in range(0, len(seq), 10)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument(
        "--frames",
        choices=("benchmark", "7scenes", "cape"),
        default="benchmark",
        help="the benchmark's frames (simulated + slambook), every 10th 7-Scenes frame, or CAPE",
    )
    parser.add_argument("--no-open3d", action="store_true", help="skip Open3D's loop (slow)")
    args = parser.parse_args()
    o3d = None if args.no_open3d else _o3d()
    full = ExtractionSettings(refine="full")
    print(
        "| frame | planes | CPU ms | CPU ms, refine=full | Open3D loop CPU ms | Open3D / navkit |\n"
        "|---|---|---|---|---|---|"
    )
    for name, grid in _frames(args.frames):
        n = len(extract_planes_organized(grid))
        flat = grid.reshape(-1, 3)
        flat = flat[np.all(np.isfinite(flat), axis=1)]
        t: dict[str, list[float]] = {"now": [], "full": [], "o3d": []}
        for _ in range(3):
            t["now"].append(_cpu_median(lambda g=grid: extract_planes_organized(g), args.repeats))
            t["full"].append(
                _cpu_median(lambda g=grid: extract_planes_organized(g, full), args.repeats)
            )
            if o3d is not None:
                t["o3d"].append(
                    _cpu_median(
                        lambda flat=flat, n=n: _segment_plane_loop(o3d, flat, n),
                        max(1, args.repeats // 3),
                    )
                )
        m = {k: 1000 * float(np.median(v)) if v else float("nan") for k, v in t.items()}
        print(
            f"| {name} | {n} | {m['now']:.1f} | {m['full']:.1f} | {m['o3d']:.0f} | "
            f"{m['o3d'] / m['now']:.0f}x |",
            flush=True,
        )


if __name__ == "__main__":
    main()
