"""Stereo: disparity ms and bad-pixel % on the real Middlebury 2014 pair vs plain OpenCV SGBM / BM.

navkit = ``compute_disparity`` with its defaults for this pair (SGBM, 3 px window, left-right
check, background fill, ``num_disparities`` from the file's ``ndisp``); peers = OpenCV's
``StereoSGBM_create(0, 80, 5)`` and ``StereoBM_create(80, 21)`` with nothing else set (what a user
gets from the documentation's one-liner). Scored on the non-occluded mask, invalid pixels count as
bad (Middlebury's convention), at the stored quarter resolution (thresholds in quarter-size pixels).
"""

from __future__ import annotations

import numpy as np

from benchmarks.common import Row, median_time, time_ratio


def run(quick: bool = False) -> list[Row]:
    import cv2

    from navkit import datasets
    from navkit.io.images import read_image, read_pfm
    from navkit.stereo import DisparitySettings, compute_disparity
    from navkit.stereo.disparity import bad_pixel_rate

    root = datasets.find("stereo/middlebury2014-motorcycle-q")
    L, R = read_image(root / "im0.png"), read_image(root / "im1.png")
    gt = read_pfm(root / "disp0GT.pfm").astype(np.float64)
    gt[~np.isfinite(gt)] = np.nan
    mask = read_image(root / "mask0nocc.png") == 255
    g0, g1 = cv2.cvtColor(L, cv2.COLOR_RGB2GRAY), cv2.cvtColor(R, cv2.COLOR_RGB2GRAY)
    repeats = 3 if quick else 7

    settings = DisparitySettings(num_disparities=80, block_size=3, fill="background")
    ours = compute_disparity(L, R, settings).disparity
    t_ours = median_time(lambda: compute_disparity(L, R, settings), repeats)
    sgbm = cv2.StereoSGBM_create(0, 80, 5)
    bm = cv2.StereoBM_create(80, 21)

    def plain(m):  # type: ignore[no-untyped-def]
        d = m.compute(g0, g1).astype(np.float64) / 16.0
        d[d < 0] = np.nan
        return d

    d_sgbm, d_bm = plain(sgbm), plain(bm)
    t_sgbm = median_time(lambda: sgbm.compute(g0, g1), repeats)
    rows = [
        Row(
            "stereo",
            "disparity time, Middlebury motorcycle (741x497)",
            "ms",
            1e3 * t_ours,
            1e3 * t_sgbm,
            "OpenCV SGBM default",
            time_ratio(t_ours, t_sgbm),
            "one SGBM run, warped left-right check, texture mask, fill",
        )
    ]
    for thr in (2.0, 4.0):
        b_ours = bad_pixel_rate(ours, gt, thr, mask)[0]
        b_sgbm = bad_pixel_rate(d_sgbm, gt, thr, mask)[0]
        b_bm = bad_pixel_rate(d_bm, gt, thr, mask)[0]
        rows.append(
            Row(
                "stereo",
                f"bad-{thr:.1f} % (non-occluded, invalid = bad)",
                "%",
                b_ours,
                b_sgbm,
                "OpenCV SGBM default",
                b_sgbm / b_ours if b_ours > 0 else None,
                "ratio = peer / navkit (> 1: navkit better)",
            )
        )
        rows.append(
            Row(
                "stereo",
                f"bad-{thr:.1f} % vs BM",
                "%",
                b_ours,
                b_bm,
                "OpenCV BM default",
                b_bm / b_ours if b_ours > 0 else None,
                "ratio = peer / navkit (> 1: navkit better)",
            )
        )
    return rows
