"""Stereo (paper 3): the left-right check options on the Middlebury Q pair - accuracy
of each (bad-2.0 / bad-4.0 of the background-filled map; without the fill: share of the scored
pixels kept and share of those off by more than 2 px), one SGBM run (80 disparities, 3 px
window), the texture mask as ``compute_disparity`` applies it.

Options: SGBM's own output (its built-in check: OpenCV 5's SGBM gives the same map for
``disp12MaxDiff`` -1, 0 and 1, checked below), the second SGBM run on the mirrored pair (``lr_method="rematch"``), the forward-warped
right disparity (``lr_method="warp"``) at three tolerances, OpenCV's built-in ``disp12MaxDiff``
(right disparity from SGBM's cost volume), and the built-in check followed by the warped one.

Run from the repository root::

    PYTHONPATH=. .venv/bin/python benchmarks/stereo_check_options.py
"""

from __future__ import annotations

import numpy as np

import navkit.stereo.disparity as D


def main() -> None:
    import cv2

    from navkit import datasets
    from navkit.io.images import read_image, read_pfm

    cv2.setNumThreads(1)
    root = datasets.find("stereo/middlebury2014-motorcycle-q")
    L, R = read_image(root / "im0.png"), read_image(root / "im1.png")
    gt = read_pfm(root / "disp0GT.pfm").astype(np.float64)
    gt[~np.isfinite(gt)] = np.nan
    mask = read_image(root / "mask0nocc.png") == 255
    scored = mask & np.isfinite(gt)
    g0, g1 = cv2.cvtColor(L, cv2.COLOR_RGB2GRAY), cv2.cvtColor(R, cv2.COLOR_RGB2GRAY)
    s = D.DisparitySettings(num_disparities=80, block_size=3)
    g = g0.astype(np.float64)
    k = (s.block_size, s.block_size)
    flat = cv2.blur(g * g, k) - cv2.blur(g, k) ** 2 < s.min_texture**2

    def report(name: str, raw: np.ndarray, keep: np.ndarray) -> None:
        d = np.where(keep & ~flat, raw, np.nan)
        filled = D.fill_background(d)
        print(
            f"{name:34s} bad-2.0 {D.bad_pixel_rate(filled, gt, 2.0, mask)[0]:5.2f} %  "
            f"bad-4.0 {D.bad_pixel_rate(filled, gt, 4.0, mask)[0]:5.2f} %  "
            f"kept {100 * np.isfinite(d[scored]).mean():5.1f} %  "
            f"kept off > 2 px {D.bad_pixel_rate(d, gt, 2.0, mask)[1]:5.2f} %"
        )

    m = D._matcher(s)
    raw = D._run(m, g0, g1, s)
    mirrored = D._run(m, np.ascontiguousarray(g1[:, ::-1]), np.ascontiguousarray(g0[:, ::-1]), s)
    report("SGBM alone (disp12MaxDiff = -1)", raw, np.ones(raw.shape, bool))
    report("rematch (second SGBM run), 1 px", raw, D.lr_consistency(raw, mirrored[:, ::-1], 1.0))
    warped = D.warp_right_disparity(raw)
    for tol in (0.5, 1.0, 2.0):
        report(f"warp, {tol} px", raw, D.lr_consistency(raw, warped, tol))
    for tol in (0, 1, 2):
        m.setDisp12MaxDiff(tol)
        builtin = D._run(m, g0, g1, s)
        same = np.array_equal(builtin, raw, equal_nan=True)
        print(f"disp12MaxDiff = {tol}: the same map as -1: {same}")
        report(f"OpenCV disp12MaxDiff = {tol}", builtin, np.ones(raw.shape, bool))
        if tol == 1:
            both = D.lr_consistency(builtin, D.warp_right_disparity(builtin), 1.0)
            report("disp12MaxDiff = 1, then warp 1 px", builtin, both)


if __name__ == "__main__":
    main()
