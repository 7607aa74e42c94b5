"""Stereo (paper 3): ``compute_disparity`` with its compiled kernels (fill, forward warp, left-right
check) against the same code with their NumPy oracles, against the previous check (a second SGBM
run on the mirrored pair, ``lr_method="rematch"``), and one plain OpenCV SGBM run (the issue's
reference), interleaved in one process on the Middlebury Q pair, one OpenCV thread, CPU time
medians; plus each variant's bad-2.0 on the non-occluded mask.

Run from the repository root::

    PYTHONPATH=. .venv/bin/python benchmarks/stereo_kernels_vs_numpy.py [--repeats 7]
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from functools import partial

import numpy as np

import navkit.stereo.disparity as D
from navkit import jit


def main() -> None:
    import cv2

    from navkit import datasets
    from navkit.io.images import read_image, read_pfm

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    root = datasets.find("stereo/middlebury2014-motorcycle-q")
    L, R = read_image(root / "im0.png"), read_image(root / "im1.png")
    gt = read_pfm(root / "disp0GT.pfm").astype(np.float64)
    gt[~np.isfinite(gt)] = np.nan
    mask = read_image(root / "mask0nocc.png") == 255
    g0, g1 = cv2.cvtColor(L, cv2.COLOR_RGB2GRAY), cv2.cvtColor(R, cv2.COLOR_RGB2GRAY)
    s = D.DisparitySettings(num_disparities=80, block_size=3, fill="background")
    sgbm = cv2.StereoSGBM_create(0, 80, 5)

    def navkit(compiled: bool, settings: D.DisparitySettings) -> D.DisparityResult:
        with jit.use("eager" if compiled else "numpy"):
            return D.compute_disparity(L, R, settings)

    runs = {
        "rematch": partial(navkit, True, replace(s, lr_method="rematch")),
        "numpy": partial(navkit, False, s),
        "compiled": partial(navkit, True, s),
        "sgbm": lambda: sgbm.compute(g0, g1),
    }
    t: dict[str, list[float]] = {k: [] for k in runs}
    out = {k: f() for k, f in runs.items()}
    for _ in range(args.repeats):
        for k, f in runs.items():
            c0 = time.process_time()
            f()
            t[k].append(time.process_time() - c0)
    m = {k: 1e3 * float(np.median(v)) for k, v in t.items()}
    same = np.array_equal(out["numpy"].disparity, out["compiled"].disparity, equal_nan=True)
    print(
        f"compute_disparity: previous check (second SGBM run) {m['rematch']:.1f} ms; "
        f"warped check NumPy {m['numpy']:.1f} ms -> compiled {m['compiled']:.1f} ms "
        f"(same map: {same}); one SGBM {m['sgbm']:.1f} ms; navkit / SGBM "
        f"{m['rematch'] / m['sgbm']:.2f}x -> {m['compiled'] / m['sgbm']:.2f}x"
    )
    for k in ("rematch", "compiled"):
        r = out[k]
        kept = np.isfinite(r.checked[mask & np.isfinite(gt)]).mean()
        print(
            f"  {k:8s} bad-2.0 filled {D.bad_pixel_rate(r.disparity, gt, 2.0, mask)[0]:.2f} %, "
            f"bad-4.0 {D.bad_pixel_rate(r.disparity, gt, 4.0, mask)[0]:.2f} %; unfilled: "
            f"{100 * kept:.1f} % of scored pixels kept, "
            f"{D.bad_pixel_rate(r.checked, gt, 2.0, mask)[1]:.2f} % of them off by > 2 px"
        )


if __name__ == "__main__":
    main()
