"""The compiled scoring loop of the correlative matcher against its NumPy oracle.

The score sums are integers (uint8 field values), so the fixes must be identical - pose,
score, verdict - with a prior (tracking) and without one (global). Here on the Intel and ACES
logs; ``benchmarks/localization_kernels_vs_numpy.py`` checks all seven CARMEN logs.
"""

from __future__ import annotations

import numpy as np
import pytest

from navkit.localization import build_map_from_scans, match_scan
from navkit.localization import matcher as M

# the two smaller maps (building the map of a large log takes ~30-60 s on the loaded 2-core
# machine); every log is compared by benchmarks/localization_kernels_vs_numpy.py
LOGS = ("intel", "aces")


def _both(fld, pts, prior):  # type: ignore[no-untyped-def]
    out = []
    for compiled in (True, False):
        M._Search.compiled = compiled
        try:
            out.append(match_scan(fld, pts, prior))
        finally:
            M._Search.compiled = True
    return out


@pytest.mark.parametrize("name", LOGS)
def test_fixes_identical_on_recorded_logs(data_path, name):
    from navkit.io.carmen import read_carmen

    lg = read_carmen(data_path(f"laser2d/{name}-corrected.log.gz"))
    every = max(2, len(lg) // 600)
    m = build_map_from_scans(lg.ranges[::every], lg.bearings, lg.poses[::every], max_range=30.0)
    fld = m.likelihood_field(0.1)
    rng = np.random.default_rng(0)
    idx = np.linspace(0, len(lg) - 1, 3).astype(int)
    priors = lg.poses[idx] + rng.uniform(-1, 1, (len(idx), 3)) * [0.5, 0.5, np.radians(10)]
    cases: list = [(int(k), p) for k, p in zip(idx, priors, strict=True)]
    cases.append((int(idx[1]), None))
    for k, prior in cases:
        a, b = _both(fld, lg.points(k, 30.0), prior)
        assert np.array_equal(a.pose, b.pose)
        assert a.score == b.score and a.ok == b.ok
