"""The vectorised fast paths of the detector against slow, obvious reference implementations.

Each optimisation of the per-frame pipeline replaced a simple computation by a faster one that
must give the same answer (exactly, or to rounding where stated): these tests pin that down.
"""

from __future__ import annotations

import warnings
from collections import Counter

import numpy as np
import pytest

from navkit.geometry.shapes import (
    ellipse_a5,
    ellipses_a6_batch,
    hull_points,
    mvee_batch,
)
from navkit.obstacles.detector import detect_obstacles_grid
from navkit.obstacles.grids import cloud_to_grid
from navkit.obstacles.mesh import _nanmedian_rows
from navkit.obstacles.segment import MESH_STRUCTURE, _pairs, label_components


def _random_sets(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """Hulls of random clouds with very different sizes (3 to ~40 hull vertices)."""
    out = []
    for _ in range(n):
        k = int(rng.integers(3, 400))
        P = rng.normal(size=(k, 2)) * rng.uniform(0.05, 3.0, size=2) + rng.uniform(-20, 20, 2)
        if rng.random() < 0.3:  # points on a circle: many hull vertices
            t = rng.uniform(0, 2 * np.pi, k)
            P = np.c_[np.cos(t), 0.4 * np.sin(t)] * rng.uniform(0.5, 3)
        out.append(hull_points(P))
    return out


def test_nanmedian_rows_equals_numpy(rng):
    for _ in range(100):
        a = rng.normal(size=(int(rng.integers(1, 30)), int(rng.integers(1, 8)))).astype(np.float32)
        a[rng.random(a.shape) < 0.4] = np.nan
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns
            ref = np.nanmedian(a, axis=0)
        np.testing.assert_array_equal(_nanmedian_rows(a), ref)


@pytest.mark.parametrize("wrap", [False, True])
def test_pairs_filtered_and_seam_only_equal_the_full_list(wrap, rng):
    a = rng.integers(0, 4, size=(7, 10))
    b = rng.integers(0, 100, size=(7, 10))
    full_a, full_b = _pairs(a, b, wrap)
    where = a > 1
    fa, fb = _pairs(a, b, wrap, where)
    keep = full_a > 1
    np.testing.assert_array_equal(fa, full_a[keep])
    np.testing.assert_array_equal(fb, full_b[keep])
    # the full list = the pairs inside the array + the pairs across the seam (as multisets)
    sa, sb = _pairs(a, b, wrap, seam_only=True)
    na, nb = _pairs(a, b, False)
    expected_seam = 2 * (a.shape[1] - 1) if wrap else 0  # offsets (1, -1) and (-1, 1)
    assert len(sa) == expected_seam
    assert Counter(zip(full_a.tolist(), full_b.tolist(), strict=True)) == Counter(
        zip(na.tolist(), nb.tolist(), strict=True)
    ) + Counter(zip(sa.tolist(), sb.tolist(), strict=True))


def test_label_components_across_the_seam_matches_a_graph_reference(rng):
    """Components with the seam closed against connected components of the explicit graph."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    R, C = 12, 16
    for _ in range(5):
        mask = rng.random((R, C)) < 0.45
        lab, n = label_components(mask, wrap=True)
        # reference: one edge per pair of masked cells at an offset of MESH_STRUCTURE, rows cyclic
        idx = np.arange(R * C).reshape(R, C)
        src, dst = [], []
        for di, dj in zip(*np.nonzero(MESH_STRUCTURE), strict=True):
            di, dj = int(di) - 1, int(dj) - 1
            j0, j1 = max(0, -dj), C - max(0, dj)
            a_ = idx[:, j0:j1]
            b_ = np.roll(idx, -di, axis=0)[:, j0 + dj : j1 + dj]
            ok = mask.ravel()[a_] & mask.ravel()[b_]
            src.append(a_[ok])
            dst.append(b_[ok])
        s_, d_ = np.concatenate(src), np.concatenate(dst)
        g = coo_matrix((np.ones(len(s_)), (s_, d_)), shape=(R * C, R * C))
        _, comp = connected_components(g, directed=False)
        cells = np.flatnonzero(mask.ravel())
        ref = comp[cells]
        fast = lab.ravel()[cells]
        assert np.all(fast > 0) and np.all(lab.ravel()[~mask.ravel()] == 0)
        # the same partition: a bijection between the two labellings
        pairs = set(zip(fast.tolist(), ref.tolist(), strict=True))
        assert len(pairs) == n == len(set(ref.tolist()))


def test_a6_batched_by_size_equals_one_set_at_a_time(rng):
    hulls = _random_sets(rng, 25)
    starts = [ellipse_a5(h) for h in hulls]
    batch = ellipses_a6_batch(hulls, starts)
    for h, s, e in zip(hulls, starts, batch, strict=True):
        alone = ellipses_a6_batch([h], [s])[0]
        assert e.params() == alone.params()  # each set's search is independent: bit-identical


def test_mvee_batched_equals_one_set_at_a_time(rng):
    hulls = _random_sets(rng, 20)
    batch = mvee_batch(hulls)
    for h, e in zip(hulls, batch, strict=True):
        alone = mvee_batch([h])[0]
        # the same iterations on the same numbers; only the moment sums may round differently
        assert e.area == pytest.approx(alone.area, rel=1e-9)
        assert e.contains(h, 1e-9).all()


def test_cloud_to_grid_keeps_the_nearest_point_of_each_cell(rng):
    """Several points per cell (a noisy cloud, shuffled): each cell holds its nearest point."""
    n_beams, n_cols = 8, 360
    az = np.repeat(np.linspace(-np.pi, np.pi, n_cols, endpoint=False), n_beams)
    el = np.tile(np.radians(np.linspace(-15, 2, n_beams)), n_cols)
    rng_m = rng.uniform(5, 30, size=az.size)
    P = np.c_[np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)] * rng_m[:, None]
    # up to four extra returns per cell, a little off in angle and at other ranges
    extra = rng.integers(0, az.size, size=3 * az.size)
    jitter = rng.normal(scale=1e-4, size=(extra.size, 2))
    r2 = rng.uniform(2, 40, size=extra.size)
    a2, e2 = az[extra] + jitter[:, 0], el[extra] + jitter[:, 1]
    Q = np.c_[np.cos(e2) * np.cos(a2), np.cos(e2) * np.sin(a2), np.sin(e2)] * r2[:, None]
    cloud = np.concatenate([P, Q])[rng.permutation(az.size + extra.size)]
    grid = cloud_to_grid(cloud, ring_method="elevation", n_rings=n_beams)
    cell = grid.cell_of_point
    rng_all = np.linalg.norm(cloud, axis=1)
    best = np.full(grid.points.shape[0] * grid.points.shape[1], np.inf)
    np.minimum.at(best, cell, rng_all)  # slow reference: the minimum range per cell
    got = np.linalg.norm(grid.points.reshape(-1, 3), axis=1)
    hit = np.isfinite(best)
    np.testing.assert_allclose(got[hit], best[hit], rtol=0, atol=1e-12)
    assert np.all(np.isnan(got[~hit]))


def test_cpu_and_wall_timings_cover_every_stage():
    az = np.radians(np.arange(-60, 61))
    el = np.radians(np.arange(-30, 1))
    d = 1.5 / np.sin(-np.minimum(el, -1e-3))
    P = np.stack(
        [
            np.outer(np.cos(az), d * np.cos(el)),
            np.outer(np.sin(az), d * np.cos(el)),
            np.tile(1.5 + d * np.sin(el), (az.size, 1)),
        ],
        axis=-1,
    )
    det = detect_obstacles_grid(P, (0.0, 0.0, 1.5))
    assert set(det.timings) == set(det.cpu_timings)
    assert all(v >= 0 for v in det.cpu_timings.values())
    assert len(det.obstacles) == 0  # level ground


def test_compiled_hulls_match_qhull(rng):
    """The map stage's compiled hulls (monotone chain, one kernel call for all sets) against
    Qhull's (``hull_points``): the same vertices in the same order (counter-clockwise from the
    lexicographically smallest vertex), on Gaussian clouds, points densely on an ellipse (many
    nearly collinear hull neighbours), duplicated points and degenerate sets (Qhull's dilated
    hull). Each hull is strictly convex, made of input rows, and contains every input point."""
    from navkit.geometry.shapes import _offsets, hulls_csr

    sets = []
    for _ in range(60):
        k = int(rng.integers(3, 2000))
        P = rng.normal(size=(k, 2)) * rng.uniform(0.05, 5.0, size=2) + rng.uniform(-80, 80, 2)
        if rng.random() < 0.3:  # many hull vertices, nearly collinear neighbours
            t = rng.uniform(0, 2 * np.pi, k)
            P = np.c_[np.cos(t), 0.4 * np.sin(t)] * rng.uniform(0.5, 3) + rng.uniform(-80, 80, 2)
        if rng.random() < 0.3:  # duplicated points, as boundary vertices shared by triangles
            P = np.concatenate([P, P[: k // 2]])
        sets.append(P)
    degenerate = [
        np.array([[1.0, 2.0]]),
        np.array([[1.0, 2.0], [3.0, 4.0]]),
        np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]]),  # collinear
        np.array([[5.0, 5.0], [5.0, 5.0], [5.0, 5.0]]),  # one point, repeated
        np.array([[0.0, 0.0], [2.0, 0.0], [1.0, 0.0], [1.0, 1.0], [np.nan, 3.0]]),  # NaN row
    ]
    every = sets + degenerate
    xy, off = np.concatenate(every), _offsets([len(p) for p in every])
    H, hoff, chain = hulls_csr(xy, off)
    # the same hulls when the points inside the hull of a subset are dropped first (the map
    # stage's A7 sets: obstacle + shadows, filtered by the boundary's hull)
    subsets = [P[: max(1, len(P) // 3)] for P in every]
    inner = hulls_csr(np.concatenate(subsets), _offsets([len(p) for p in subsets]))
    H2, hoff2, _ = hulls_csr(xy, off, inner=inner)
    np.testing.assert_array_equal(H2, H)
    np.testing.assert_array_equal(hoff2, hoff)
    assert chain[: len(sets)].all() and not chain[len(sets) :].any()
    for s, P in enumerate(every):
        h = H[hoff[s] : hoff[s + 1]]
        np.testing.assert_array_equal(h, hull_points(P))
        if s >= len(sets):
            continue
        e = np.roll(h, -1, axis=0) - h
        assert (e[:, 0] * np.roll(e[:, 1], -1) - e[:, 1] * np.roll(e[:, 0], -1) > 0).all()
        assert {tuple(r) for r in h} <= {tuple(r) for r in P}
        cross = e[None, :, 0] * (P[:, None, 1] - h[None, :, 1]) - e[None, :, 1] * (
            P[:, None, 0] - h[None, :, 0]
        )
        assert (cross >= -1e-9).all()
        assert tuple(h[0]) == min(map(tuple, P))  # the lexicographically smallest point
