"""Room map and localization (paper 3) on the Intel lab laser log of the recorded data.

Builds a wall map from every other scan with the log's corrected poses, then localizes a few
scans globally (no prior) by correlation. The map comes from the same log, so this is a
self-consistency check (does the matcher find the pose the map was built with?), not accuracy.

    python examples/localization_intel.py [--scans 5]
"""

from __future__ import annotations

import argparse

import numpy as np

from navkit import datasets
from navkit.io.carmen import read_carmen
from navkit.localization import build_map_from_scans, match_scan


def main(argv: list[str] | None = None) -> dict[str, float]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=5, help="scans to localize")
    args = ap.parse_args(argv)

    log = read_carmen(datasets.find("laser2d/intel-corrected.log.gz"))
    wall_map = build_map_from_scans(log.ranges[::2], log.bearings, log.poses[::2])
    field = wall_map.likelihood_field(sigma=0.1)
    picks = np.linspace(10, len(log.ranges) - 10, args.scans).astype(int)
    errors = []
    for i in picks:
        fix = match_scan(field, log.points(int(i), max_range=30.0), prior=None)
        err = float(np.hypot(*(np.asarray(fix.pose)[:2] - log.poses[i][:2])))
        errors.append(err)
        print(
            f"scan {i}: fix {np.round(fix.pose, 3)} ok={fix.ok}, {100 * err:.1f} cm from the log's pose"
        )
    median = float(np.median(errors))
    print(
        f"median {100 * median:.1f} cm from the poses the map was built with "
        "(reference: the same log - a self-consistency check, not accuracy)"
    )
    return {"median_error_m": median, "n": float(len(errors))}


if __name__ == "__main__":
    main()
