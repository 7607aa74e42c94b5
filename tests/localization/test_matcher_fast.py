"""The matcher's fast paths against reference implementations in the test: the per-map padded
pyramid, the optimistic first pass of the branch-and-bound, the peak analysis by
branch-and-bound, and the bicubic sub-cell field."""

from __future__ import annotations

import numpy as np
import pytest

from navkit import jit
from navkit.localization import MatcherSettings, match_scan
from navkit.localization.field import LikelihoodField
from navkit.localization.matcher import _thin, analyse_peak, score_poses
from navkit.localization.search import _Search
from tests.localization.helpers import LSHAPE, RECT, sample_walls, scan_points


@pytest.fixture(scope="module")
def lfield():
    return LikelihoodField.from_points(sample_walls(LSHAPE, 0.01), 0.05, 0.1)


def _all(search: _Search, level: int = 0):
    """Every candidate of a search and its brute-force score at ``level``."""
    K, IX, IY = np.meshgrid(
        np.arange(len(search.thetas)), np.arange(search.n), np.arange(search.n), indexing="ij"
    )
    k, ix, iy = K.ravel(), IX.ravel(), IY.ravel()
    return k, ix, iy, search.scores(level, k, ix, iy)


@pytest.mark.parametrize("corner", [(0.3, 0.4), (9.8, 7.7), (-1.9, 3.0)])
def test_padded_pyramid_scores_equal_the_region_pyramid(lfield, rng, corner):
    """A tracking-sized window (<= 64 cells) reads the per-map padded pyramid; one reaching past
    the map's edges must score every candidate exactly as the per-search region pyramid does
    (the reference), at every level, and its branch-and-bound must return the brute-force
    optimum."""
    pose = np.array([1.5, 1.5, 0.4])
    pts = _thin(scan_points(LSHAPE, pose, n=181, noise=0.01, rng=rng), 0.1)
    thetas = 0.4 + np.linspace(-0.05, 0.05, 5)
    base, n = np.array(corner), 41  # 2 m windows at, and beyond, the map's corners
    padded = _Search(lfield, pts, thetas, base, n)
    region = _Search(lfield, pts, thetas, base, n, cache=[])  # the region path (reference)
    assert padded.flat.shape[1] != region.flat.shape[1]  # really two different layouts
    for level in range(len(lfield.pyramid)):
        assert np.array_equal(_all(padded, level)[3], _all(region, level)[3])
    best, exact = padded.run(levels=7, lower=-1.0, cap=10**9)
    assert exact and best[0] == pytest.approx(_all(region)[3].max(), abs=1e-12)
    # and the scores are the public nearest-cell scores (uint8 rounding: <= 1/255 per point)
    k, ix, iy, sc = _all(padded)
    j = np.argsort(sc)[-5:]
    poses = np.stack([base[0] + ix[j] * 0.05, base[1] + iy[j] * 0.05, thetas[k[j]]], axis=1)
    assert np.allclose(score_poses(lfield, pts, poses), sc[j], atol=1 / 255 + 1e-6)


@pytest.mark.parametrize("optimism", [0.0, 0.001, 0.03, 0.5])
@pytest.mark.parametrize("keep", [1.0, 0.9])
def test_optimistic_first_pass_is_exact(rng, optimism, keep):
    """Whatever the first pass assumes (an optimum just under the top bound, far under it, or
    above the true one so that the second pass or the fallback must run), the search returns
    the brute-force optimum and, with ``keep < 1``, every leaf within ``keep`` of it."""
    fld = LikelihoodField.from_points(sample_walls(RECT, 0.01), 0.05, 0.1)
    pose = np.array([2.0, 2.5, 0.4])
    good = scan_points(RECT, pose, n=181, noise=0.005, rng=rng)
    junk = rng.uniform(-3.0, 3.0, (60, 2))  # points that fit no wall: a low optimum
    for pts in (_thin(good, 0.1), _thin(np.vstack([good[::4], junk]), 0.1)):
        search = _Search(
            fld, pts, np.array([0.38, 0.4, 0.42, 0.4 + np.pi]), np.array([1.5, 1.5]), 101
        )
        search.optimism = optimism
        best, exact = search.run(levels=7, lower=-1.0, cap=10**9, keep=keep)
        k, ix, iy, brute = _all(search)
        assert exact and best[0] == pytest.approx(brute.max(), abs=1e-12)
        if keep < 1:
            _ls, lk, lx, ly = (np.concatenate(a) for a in zip(*search.leaves, strict=True))
            found = set(zip(lk.tolist(), lx.tolist(), ly.tolist(), strict=True))
            want = np.flatnonzero(brute > keep * brute.max())
            assert {(int(k[j]), int(ix[j]), int(iy[j])) for j in want} <= found


def _peak_reference(fld, pts, pose, s):
    """The peak analysis by exhaustive scoring of the whole window (the former implementation)."""
    r = fld.resolution
    n = int(np.ceil(s.ambiguity_window / r))
    step = r / max(np.percentile(np.linalg.norm(pts, axis=1), 95), r)
    search = _Search(fld, pts, pose[2] + np.array([-step, 0.0, step]), pose[:2] - n * r, 2 * n + 1)
    IX, IY = np.meshgrid(np.arange(2 * n + 1), np.arange(2 * n + 1), indexing="ij")
    ix, iy = IX.ravel(), IY.ravel()
    best = np.max([search.scores(0, np.full(len(ix), k), ix, iy) for k in range(3)], axis=0)
    near = best >= (1.0 - s.peak_tolerance) * best.max()
    T = np.stack([(ix[near] - n) * r, (iy[near] - n) * r], axis=1)
    w = best[near]
    mu = (w[:, None] * T).sum(0) / w.sum()
    C = ((w[:, None] * (T - mu)).T @ (T - mu)) / w.sum()
    major, minor = np.linalg.eigh(C)[1][:, 1], np.linalg.eigh(C)[1][:, 0]
    return float(np.ptp(T @ major)) + r, float(np.ptp(T @ minor)) + r, C, float(best.max())


@pytest.mark.parametrize(
    "walls, pose",
    [
        (LSHAPE, (2.0, 3.0, 0.7)),  # a corner: a compact peak
        (np.array([[[-20.0, 2.0], [20.0, 2.0]]]), (0.0, 0.0, 0.0)),  # a wall: a long ridge
    ],
)
def test_peak_analysis_by_branch_and_bound_equals_exhaustive_scoring(rng, walls, pose):
    fld = LikelihoodField.from_points(sample_walls(walls, 0.01), 0.05, 0.1)
    pose = np.array(pose)
    pts = _thin(scan_points(walls, pose, n=181, noise=0.01, rng=rng), 0.1)
    s = MatcherSettings()
    guess = pose + np.array([0.02, -0.03, 0.01])
    _, extent, minor, cov, top = analyse_peak(fld, pts, guess, s)
    r_extent, r_minor, r_cov, r_top = _peak_reference(fld, pts, guess, s)
    assert top == pytest.approx(r_top, abs=1e-12)
    assert extent == pytest.approx(r_extent, abs=1e-9)
    assert minor == pytest.approx(r_minor, abs=1e-9)
    assert np.allclose(cov, r_cov, atol=1e-12)


def test_bicubic_field_matches_the_exact_gaussian_of_the_distance(rng):
    """Sub-cell values for the refinement: the Catmull-Rom spline through the cell centres
    against the exact ``exp(-d^2 / 2 sigma^2)`` of a straight wall (d known analytically)."""
    sigma, h = 0.1, 0.05
    wall = np.array([[[-5.0, 0.013], [5.0, 0.013]]])  # off the cell grid on purpose
    fld = LikelihoodField.from_points(sample_walls(wall, 0.002), h, sigma)
    P = np.stack([rng.uniform(-3, 3, 5000), rng.uniform(-0.35, 0.35, 5000)], axis=1)
    truth = np.exp(-0.5 * ((P[:, 1] - 0.013) / sigma) ** 2)
    # Bilinear interpolation errs by up to h^2 / 8 max|f''| = 0.0025 / 8 * (1 / sigma^2) = 0.031
    # (kinks at the cells: it pins the refined pose to cell centres); Catmull-Rom is third order
    # (error ~ h^3 |f'''|, |f'''| <= 1.38 / sigma^3, with a small constant): allow a third of
    # the bilinear bound. The wall samples are 2 mm apart: <= 1 mm of distance error, < 1e-3.
    assert np.max(np.abs(fld.interpolate_cubic(P) - truth)) < 0.01
    # it interpolates: at the cell centres it returns the stored values
    H, W = fld.shape
    jj, ii = rng.integers(2, H - 2, 50), rng.integers(2, W - 2, 50)
    centres = fld.origin + (np.stack([ii, jj], axis=1) + 0.5) * h
    assert np.allclose(fld.interpolate_cubic(centres), fld.values[jj, ii], atol=1e-6)
    # and it is zero far outside the grid
    assert np.all(fld.interpolate_cubic(np.array([[1e3, 0.0], [-1e3, -1e3]])) == 0.0)


def test_a_search_out_of_budget_returns_a_real_leaf_flagged_inexact(lfield, rng):
    """``max_candidates`` cut: the answer is a leaf that was scored (its score is its true
    score), flagged ``exact=False`` - never None, never a bound passed off as a score."""
    pose = np.array([2.0, 3.0, 0.7])
    pts = _thin(scan_points(LSHAPE, pose, n=181, noise=0.01, rng=rng), 0.1)
    search = _Search(lfield, pts, 0.7 + np.linspace(-0.2, 0.2, 21), pose[:2] - 1.5, 61)
    best, exact = search.run(levels=7, lower=-1.0, cap=16, keep=0.9)
    assert best is not None and not exact
    sc = search.scores(0, np.array([best[1]]), np.array([best[2]]), np.array([best[3]]))[0]
    assert best[0] == pytest.approx(sc, abs=1e-12)


@pytest.mark.parametrize("keep", [1.0, 0.9])
def test_rotation_group_bounds_are_upper_bounds_and_the_search_stays_exact(rng, keep):
    """Nodes covering several rotations (the global search's top levels) are bounded by the
    pyramid window dilated by the rotation sweep. Every such bound must be >= the best leaf
    below it (all leaves scored by brute force: the ``uint8`` values are the same, so the
    comparison is exact, no tolerance), and the branch-and-bound over them must return the
    brute-force optimum and, with ``keep < 1``, every leaf within ``keep`` of it."""
    fld = LikelihoodField.from_points(sample_walls(LSHAPE, 0.01), 0.05, 0.1)
    pose = np.array([2.5, 2.0, 0.7])
    # a long reach (the far walls at up to ~8 m): dilations of several cells per group
    pts = _thin(scan_points(LSHAPE, pose, n=361, noise=0.005, rng=rng), 0.1)
    K = 96  # headings over the whole turn, uniform (as in the global search)
    thetas = -np.pi + np.arange(K) * (2 * np.pi / K)
    n = 64
    search = _Search(fld, pts, thetas, np.array([0.9, 0.4]), n, cache=[], levels=7, rot_groups=3)
    assert max(search.a) > 0  # rotation groups really in use
    k, ix, iy, leaf = _all(search)
    S = leaf.reshape(K, n, n)
    for h in range(1, 7):
        g, b = 2 ** search.a[h], 2**h
        nk, nb = -(-K // g), -(-n // b)
        pooled = np.full((nk * g, nb * b, nb * b), -1.0)
        pooled[:K, :n, :n] = S
        want = pooled.reshape(nk, g, nb, b, nb, b).max(axis=(1, 3, 5))  # best leaf per node
        GK, GX, GY = np.meshgrid(
            np.arange(nk) * g, np.arange(nb) * b, np.arange(nb) * b, indexing="ij"
        )
        bound = search.scores(h, GK.ravel(), GX.ravel(), GY.ravel())
        assert np.all(bound >= want.ravel())
    best, exact = search.run(levels=7, lower=-1.0, cap=10**9, keep=keep)
    assert exact and best[0] == leaf.max()
    assert S[best[1], best[2], best[3]] == best[0]
    if keep < 1:
        _ls, lk, lx, ly = (np.concatenate(a) for a in zip(*search.leaves, strict=True))
        found = set(zip(lk.tolist(), lx.tolist(), ly.tolist(), strict=True))
        want_set = np.flatnonzero(leaf > keep * leaf.max())
        assert {(int(k[j]), int(ix[j]), int(iy[j])) for j in want_set} <= found


def _twin_map() -> tuple[LikelihoodField, np.ndarray]:
    """A map holding the same asymmetric wall pattern twice, 4 m (64 cells) apart along x, and
    the pattern's points. Everything is binary-exact (resolution 1/16 m, points on a 1/64 m
    grid, the shift a whole number of cells, and of coarse cells of 4), so the two copies'
    field values - and every score of a pose and of the pose shifted by 4 m - are identical:
    two equally good poses."""
    step = 1 / 64
    a = np.arange(0.0, 2.0 + step / 2, step)
    b = np.arange(0.0, 1.25 + step / 2, step)
    c = np.arange(0.0, 0.5 + step / 2, step)
    pattern = np.concatenate(
        [np.c_[a, 0 * a], np.c_[0 * b, b], np.c_[0 * c + 2.0, c], np.c_[a[:48], 0 * a[:48] + 1.25]]
    )
    shift = np.array([4.0, 0.0])
    fld = LikelihoodField.from_points(np.vstack([pattern, pattern + shift]), 0.0625, 0.1)
    return fld, pattern


def _lowest_best(k, ix, iy, score):  # type: ignore[no-untyped-def]
    """The documented answer: of the leaves with the best score, the lowest ``(k, ix, iy)``."""
    top = np.flatnonzero(score == score.max())
    j = top[np.lexsort((iy[top], ix[top], k[top]))[0]]
    return int(k[j]), int(ix[j]), int(iy[j]), len(top)


@pytest.mark.twin("depth_first", "expand_sums")
@pytest.mark.parametrize("compiled", [True, False])
def test_equal_best_scores_resolve_to_the_lowest_rotation_and_translation(compiled):
    """Two poses score the same (the twin map): the search returns the leaf with the lowest
    ``(k, ix, iy)`` of those with the best score (brute force), whatever order it visits them in
    - the compiled kernels and the NumPy oracle alike, whether the optimistic first pass finds
    the optimum or falls short of it."""
    fld, pattern = _twin_map()
    th = 0.3
    R = np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]])
    pts = _thin((pattern - [1.0, 0.6]) @ R.T, 0.1)  # the pattern seen from (1.0, 0.6, 0.3)
    K = 96
    thetas = -np.pi + np.arange(K) * (2 * np.pi / K)
    with jit.use("eager" if compiled else "numpy"):
        k = ix = iy = leaf = want = None
        for optimism in (0.03, 0.0, 0.3):  # a first pass that finds the optimum / falls short
            search = _Search(
                fld, pts, thetas, np.array([-0.5, -0.25]), 112, cache=[], levels=7, rot_groups=3
            )
            if leaf is None:  # brute force, once
                k, ix, iy, leaf = _all(search)
                want = _lowest_best(k, ix, iy, leaf)
                assert want[3] >= 2  # a tie, at least the two copies
                assert ix[leaf == leaf.max()].max() - want[1] >= 64  # ... one of them 4 m away
            search.optimism = optimism
            best, exact = search.run(levels=7, lower=-1.0, cap=10**9, keep=0.9)
            assert exact and best[0] == leaf.max()
            assert best[1:] == want[:3]


@pytest.mark.twin("rotated_cells", "flat_table", "gather_sums", "expand_sums", "depth_first")
def test_global_fix_on_two_equally_good_poses_is_the_documented_one():
    """A global fix on the twin map: both backends return the copy with the lower coarse
    ``(k, ix, iy)`` - the lower x here (the same heading) - and report the other as the second
    peak (its coarse leaf ties with the winner's)."""
    fld, pattern = _twin_map()
    th = 0.3
    R = np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]])
    pts = (pattern - [1.0, 0.6]) @ R.T
    s = MatcherSettings(global_resolution=0.25)
    fixes = []
    for implementation in ("eager", "numpy"):
        with jit.use(implementation):
            fixes.append(match_scan(fld, pts, None, s))
    a, b = fixes
    assert np.array_equal(a.pose, b.pose) and a.score == b.score
    assert np.allclose(a.pose, [1.0, 0.6, th], atol=0.05)
    assert a.ambiguity.reason == b.ambiguity.reason == "second peak"
    # the runner-up is the other copy's coarse leaf: the winner's, 16 coarse cells (4 m) on
    assert np.array_equal(a.ambiguity.second_pose, b.ambiguity.second_pose)
    assert a.ambiguity.second_score == b.ambiguity.second_score
    assert np.allclose(a.ambiguity.second_pose[:2] - [4.0, 0.0], a.pose[:2], atol=0.25)
