"""Path memory (paper 4): KITTI sequence 00's ground-truth trajectory stored as a cubic spline.

Records the trajectory of the recorded data (NAVKIT_DATA) point by point with tolerance eps,
removing the loops (the car ends near where it started, so the way back is short), and reports
how many spline segments keep every kept point within eps.

    python examples/path_kitti.py [--tolerance 0.5]
"""

from __future__ import annotations

import argparse

import numpy as np

from navkit import datasets
from navkit.io.trajectory import read_trajectory
from navkit.path import ApproximatorSettings, approximate
from navkit.path.track import ground_plane, to_plane


def main(argv: list[str] | None = None) -> dict[str, float]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tolerance", type=float, default=0.5, help="eps (m)")
    args = ap.parse_args(argv)

    traj = read_trajectory(datasets.find("trajectories/KITTI_00_gt.txt"), "kitti")
    P = traj.positions
    xy = to_plane(P, ground_plane(P, "auto"))  # the fitted ground plane's 2D coordinates
    result = approximate(xy, ApproximatorSettings(tolerance=args.tolerance), timed=False)
    spline = result.spline
    out = {
        "points": float(len(xy)),
        "segments": float(spline.n_segments),
        "length_m": float(spline.total_length),
        "max_deviation_m": float(result.max_deviation),
    }
    raw = float(np.hypot(*np.diff(xy, axis=0).T).sum())
    out["raw_length_m"] = raw
    print(
        f"{len(xy)} poses, {raw:.0f} m driven; with its {len(result.loops)} loops removed the way "
        f"back is {spline.total_length:.0f} m -> {spline.n_segments} segments "
        f"({len(xy) / max(spline.n_segments, 1):.0f} poses per segment), max deviation "
        f"{result.max_deviation:.3f} m <= eps {args.tolerance} m"
    )
    assert np.isfinite(out["max_deviation_m"])
    return out


if __name__ == "__main__":
    main()
