"""The compiled loops of the correlative matcher against their NumPy oracles.

The score sums are integers (uint8 field values), the search tables integers, and the sub-cell
scores (bicubic and bilinear) the same float operations in the same order in both, so the fixes
must be identical - pose, score, verdict - with a prior (tracking) and without one (global).
Here on a simulated field and the Intel and ACES logs;
``benchmarks/localization_kernels_vs_numpy.py`` checks all seven CARMEN logs.
"""

from __future__ import annotations

import numpy as np
import pytest

from navkit import jit
from navkit.localization import build_map_from_scans, match_scan
from navkit.localization import matcher as M

# the two smaller maps (building the map of a large log takes ~30-60 s on the loaded 2-core
# machine); every log is compared by benchmarks/localization_kernels_vs_numpy.py
LOGS = ("intel", "aces")


def _both(fld, pts, prior):  # type: ignore[no-untyped-def]
    return _modes(lambda: match_scan(fld, pts, prior))


def _modes(f):  # type: ignore[no-untyped-def]
    """``f()`` on the compiled kernels, then on their NumPy twins (navkit.jit.use)."""
    out = []
    for implementation in ("eager", "numpy"):
        with jit.use(implementation):
            out.append(f())
    return out


@pytest.mark.twin("window_offsets", "cubic_pose_scores", "bilinear_pose_scores")
def test_window_tables_and_subcell_scores_identical(rng):
    from navkit.localization.field import LikelihoodField

    walls = np.concatenate(
        [np.c_[np.linspace(0, 8, 400), np.full(400, y)] for y in (0.0, 5.0)]
        + [np.c_[np.full(250, x), np.linspace(0, 5, 250)] for x in (0.0, 8.0, 3.3)]
    )
    fld = LikelihoodField.from_points(walls, 0.05, 0.1)
    pts = M._thin(walls[::3] - [4.0, 2.5] + rng.normal(0, 0.01, (len(walls[::3]), 2)), 0.1)
    poses = np.c_[rng.uniform(-1, 9, (300, 2)), rng.uniform(-np.pi, np.pi, 300)]
    poses[:10, :2] += 50.0  # the scan beyond the grid: zeros
    for f in (M._fine_scores, M._bilinear_scores):
        a, b = _modes(lambda f=f: f(fld, pts, poses))
        assert np.array_equal(a, b)
    for n_cells, th in ((41, 0.1 + 0.004 * np.arange(101)), (61, np.array([-0.01, 0.0, 0.01]))):
        for base in (np.array([2.0, 1.5]), np.array([-5.0, 7.0])):  # inside, partly beyond
            a, b = _modes(lambda n=n_cells, t=th, o=base: M._Search(fld, pts, t, o, n).F)
            assert a.dtype == b.dtype == np.int32 and np.array_equal(a, b)


@pytest.mark.twin("gather_sums", "expand_sums", "depth_first", "order_desc")
@pytest.mark.twin("rotated_cells", "flat_table", "window_offsets", "cubic_pose_scores")
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


@pytest.mark.twin("rotated_cells", "flat_table", "gather_sums", "expand_sums", "depth_first")
def test_global_search_tables_sums_and_leaves_identical(rng):
    """A global search's pieces on the kernels and on their twins: the region's cells and flat
    tables (single rotations and rotation groups), the integer sums of nodes at every level,
    the children of a batch of nodes with their sums (all of them, and those above a pruning
    threshold), and the depth-first search's best leaf and collected leaves in order."""
    from navkit.localization.field import LikelihoodField
    from navkit.localization.search import _Search

    walls = np.concatenate(
        [np.c_[np.linspace(0, 8, 400), np.full(400, y)] for y in (0.0, 5.0)]
        + [np.c_[np.full(250, x), np.linspace(0, 5, 250)] for x in (0.0, 8.0, 3.3)]
    )
    fld = LikelihoodField.from_points(walls, 0.05, 0.1)
    pts = M._thin(walls[::3] - [4.0, 2.5] + rng.normal(0, 0.01, (len(walls[::3]), 2)), 0.1)
    K, n = 96, 64
    thetas = -np.pi + np.arange(K) * (2 * np.pi / K)  # the whole turn, as a global search
    searches = []
    for implementation in ("eager", "numpy"):
        with jit.use(implementation):
            searches.append(
                _Search(fld, pts, thetas, np.array([2.4, 1.0]), n, cache=[], levels=7, rot_groups=3)
            )
    a, b = searches
    assert a.compiled and not b.compiled and max(a.a) > 0  # rotation groups in use
    assert a.a == b.a and a.Wp == b.Wp and np.array_equal(a.flat, b.flat)
    assert a.F.dtype == b.F.dtype and np.array_equal(a.F, b.F)
    assert a.FG.keys() == b.FG.keys() and len(a.FG) > 0
    for h, t in a.FG.items():
        assert t.dtype == b.FG[h].dtype and np.array_equal(t, b.FG[h])
    for h in range(7):
        m = 3000
        k = rng.integers(0, K, m) >> a.a[h] << a.a[h]  # a group's first rotation
        ix, iy = rng.integers(0, n, m) >> h << h, rng.integers(0, n, m) >> h << h
        assert np.array_equal(a.scores(h, k, ix, iy), b.scores(h, k, ix, iy)), h
    for h in range(1, 7):
        m = 500  # nodes of level h: a group's first rotation, 2^h-aligned blocks
        k = rng.integers(0, K, m) >> a.a[h] << a.a[h]
        ix, iy = rng.integers(0, n, m) >> h << h, rng.integers(0, n, m) >> h << h
        kb, xb, yb, sb = b._expand(h, k, ix, iy, None)
        for thr in (-np.inf, float(np.median(sb))):
            ka, xa, ya, sa = a._expand(h, k, ix, iy, None, thr)
            if thr == -np.inf:  # every child, in the same order
                for u, v in ((ka, kb), (xa, xb), (ya, yb), (sa, sb)):
                    assert np.array_equal(u, v), h
            else:  # the kernel may leave out children the caller prunes anyway
                ma, mb = sa > thr, sb > thr
                for u, v in ((ka, kb), (xa, xb), (ya, yb), (sa, sb)):
                    assert np.array_equal(u[ma], v[mb]), h
    for keep in (1.0, 0.9, 0.75):
        best_a, exact_a = a.run(levels=7, lower=-1.0, cap=10**9, keep=keep)
        best_b, exact_b = b.run(levels=7, lower=-1.0, cap=10**9, keep=keep)
        assert exact_a and exact_b and best_a == best_b
        if keep == 1.0:  # no leaves collected
            assert a.leaves == b.leaves == []
            continue
        la, lb = ([np.concatenate(x) for x in zip(*z.leaves, strict=True)] for z in (a, b))
        assert len(la[0]) >= 2 and all(np.array_equal(u, v) for u, v in zip(la, lb, strict=True))


@pytest.mark.twin("order_desc")
def test_counting_sort_is_numpys_stable_descending_argsort(rng):
    from navkit.localization import _kernels

    # the last case: a narrow range of high sums (a pruned batch: the bins span its range only)
    for n, N, lo, hi in ((1, 37, 0, 3145), (600, 37, 0, 3145), (20_000, 150, 0, 12750), (5000, 150, 33000, 34500)):  # fmt: skip
        sums = rng.integers(lo, hi, n)
        sums[: n // 3] = sums[0]  # many ties: their original order must be kept
        bound = sums / (255.0 * N)
        got = _kernels.order_desc(bound, 255.0 * N)
        assert np.array_equal(got, np.argsort(-bound, kind="stable"))
    assert len(_kernels.order_desc(np.zeros(0), 10.0)) == 0
    assert len(_kernels.order_desc(np.array([0.5, -0.1]), 10.0)) == 0  # negative: NumPy sorts


def test_p95_is_numpys_percentile(rng):
    # match_scan's reach (the heading step): the same value as np.percentile(x, 95), bit for bit
    for n in (1, 2, 3, 20, 21, 101, 700):
        for x in (
            rng.uniform(0, 30, n),
            np.round(rng.uniform(0, 30, n), 1),  # ties
            np.linalg.norm(rng.normal(0, 8, (n, 2)), axis=1),
            np.full(n, 7.25),
        ):
            assert M._p95(x) == float(np.percentile(x, 95))
