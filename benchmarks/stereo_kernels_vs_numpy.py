"""Stereo (paper 3): ``compute_disparity`` with the compiled fill and left-right check against
the same code with their NumPy oracles, and one plain OpenCV SGBM run (the issue's reference),
interleaved in one process on the Middlebury Q pair, one OpenCV thread, CPU time medians.

Run from the repository root::

    PYTHONPATH=. .venv/bin/python benchmarks/stereo_kernels_vs_numpy.py [--repeats 7]
"""

from __future__ import annotations

import argparse
import time
from functools import partial

import numpy as np

import navkit.stereo.disparity as D


def main() -> None:
    import cv2

    from navkit import datasets
    from navkit.io.images import read_image

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    root = datasets.find("stereo/middlebury2014-motorcycle-q")
    L, R = read_image(root / "im0.png"), read_image(root / "im1.png")
    g0, g1 = cv2.cvtColor(L, cv2.COLOR_RGB2GRAY), cv2.cvtColor(R, cv2.COLOR_RGB2GRAY)
    s = D.DisparitySettings(num_disparities=80, block_size=3, fill="background")
    sgbm = cv2.StereoSGBM_create(0, 80, 5)
    fill, lr = D.fill_background, D.lr_consistency

    def navkit(compiled: bool) -> None:
        D.fill_background = partial(fill, compiled=compiled)  # type: ignore[assignment]
        D.lr_consistency = partial(lr, compiled=compiled)  # type: ignore[assignment]
        try:
            D.compute_disparity(L, R, s)
        finally:
            D.fill_background, D.lr_consistency = fill, lr

    runs = {"numpy": partial(navkit, False), "compiled": partial(navkit, True)}
    runs["sgbm"] = lambda: sgbm.compute(g0, g1)
    t: dict[str, list[float]] = {k: [] for k in runs}
    for f in runs.values():
        f()
    for _ in range(args.repeats):
        for k, f in runs.items():
            c0 = time.process_time()
            f()
            t[k].append(time.process_time() - c0)
    m = {k: 1e3 * float(np.median(v)) for k, v in t.items()}
    print(
        f"compute_disparity NumPy {m['numpy']:.1f} ms -> compiled {m['compiled']:.1f} ms "
        f"({m['numpy'] / m['compiled']:.2f}x); one SGBM {m['sgbm']:.1f} ms; "
        f"navkit / SGBM {m['compiled'] / m['sgbm']:.2f}x"
    )


if __name__ == "__main__":
    main()
