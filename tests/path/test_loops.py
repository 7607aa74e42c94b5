"""Loop search through the bounding-box tree against brute force, and a known answer."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from navkit.path import ApproximatorSettings, approximate
from navkit.path.loops import LoopFreeChain, find_crossings, monotone_breaks, remove_loops
from navkit.path.spline import cubic_eval


def _brute_force_crossings(spline, step: float = 0.005) -> np.ndarray:
    """All crossings of the densely sampled spline by an O(n^2) test of every pair of polyline
    pieces (the search the paper calls too expensive), as rows (s_a, s_b)."""
    s, xy = spline.sample(step)
    p, q = xy[:-1], xy[1:]
    n = len(p)
    out = []
    d = q - p
    for i0 in range(0, n, 256):  # chunks of rows, each vectorised against every later piece
        i = np.arange(i0, min(i0 + 256, n))[:, None]
        j = np.arange(n)[None, :]
        valid = j > i + 1
        r = d[i[:, 0]][:, None, :]
        e = d[None, :, :]
        w = p[None, :, :] - p[i[:, 0]][:, None, :]
        den = r[..., 0] * e[..., 1] - r[..., 1] * e[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (w[..., 0] * e[..., 1] - w[..., 1] * e[..., 0]) / den
            u = (w[..., 0] * r[..., 1] - w[..., 1] * r[..., 0]) / den
        hit = valid & (den != 0) & (t >= 0) & (t <= 1) & (u >= 0) & (u <= 1)
        a, b = np.nonzero(hit)
        ia, jb = i[a, 0], b
        out.append(
            np.c_[s[ia] + t[a, b] * (s[ia + 1] - s[ia]), s[jb] + u[a, b] * (s[jb + 1] - s[jb])]
        )
    return np.concatenate(out) if out else np.zeros((0, 2))


def _loopy_spline(seed: int):
    rng = np.random.default_rng(seed)
    n = 400
    heading = np.cumsum(rng.normal(0.0, 0.25, n)) + np.linspace(0, rng.uniform(4, 10), n)
    P = np.cumsum(0.04 * np.c_[np.cos(heading), np.sin(heading)], axis=0)
    return approximate(
        P, ApproximatorSettings(tolerance=0.02, remove_loops=False), timed=False
    ).spline


@pytest.mark.parametrize("seed", range(8))
def test_tree_search_finds_the_brute_force_crossings(seed):
    spline = _loopy_spline(seed)
    brute = _brute_force_crossings(spline)
    tree = np.array([(c.s_a, c.s_b) for c in find_crossings(spline)]).reshape(-1, 2)
    # compare crossings that make loops longer than 2 cm (the polyline step is 5 mm: its chords
    # are off the curve by <= step^2 kappa / 8 ~ 1e-5 m, so a crossing moves by far less than 1 cm
    # along the path unless the curves are nearly tangent, which these random seeds avoid)
    brute = brute[brute[:, 1] - brute[:, 0] > 0.02]
    tree = tree[tree[:, 1] - tree[:, 0] > 0.02]
    for a, b in brute:
        assert np.min(np.hypot(tree[:, 0] - a, tree[:, 1] - b)) < 0.01, (a, b)
    for a, b in tree:
        assert np.min(np.hypot(brute[:, 0] - a, brute[:, 1] - b)) < 0.01, (a, b)
    # each tree crossing is a real intersection to the requested precision (0.1 mm)
    for c in find_crossings(spline)[:50]:
        assert np.hypot(*(spline.position(c.s_a) - spline.position(c.s_b))) < 3e-4


@pytest.mark.parametrize("seed", range(4))
def test_removal_leaves_no_crossing_and_keeps_the_rest(seed):
    spline = _loopy_spline(seed)
    clean, cuts = remove_loops(spline)
    assert len(_brute_force_crossings(clean)) == 0
    # the loop-free path is part of the original: every point of it lies on the original curve
    _, xy = clean.sample(0.05)
    _, dist = spline.nearest(xy)
    assert dist.max() < 1e-3
    removed = sum(c.length for c in cuts)
    assert clean.total_length == pytest.approx(
        spline.total_length - removed, abs=1e-3 * (1 + len(cuts))
    )


def test_prolate_cycloid_known_loops():
    """x = t - a sin t, y = -a cos t (a = 2) has a loop around each t = 2 pi k; the crossing is at
    t = 2 pi k +- tau with tau = a sin tau, the point (2 pi k, -a cos tau)."""
    a = 2.0
    t = np.linspace(0.0, 4 * np.pi + 2.5, 3500)  # closes the loops at 2 pi and 4 pi
    P = np.c_[t - a * np.sin(t), -a * np.cos(t)]
    result = approximate(P, ApproximatorSettings(tolerance=0.002), timed=False)
    tau = brentq(lambda x: x - a * np.sin(x), 0.5, 3.0)
    speed = lambda x: np.hypot(1 - a * np.cos(x), a * np.sin(x))  # noqa: E731
    loop_len = quad(speed, -tau, tau)[0]
    assert len(result.loops) == 2
    for k, cut in zip((1, 2), result.loops, strict=True):
        np.testing.assert_allclose(cut.point, [2 * np.pi * k, -a * np.cos(tau)], atol=0.005)
        # the spline is within eps = 2 mm of the curve: the loop length agrees to a few eps
        assert cut.length == pytest.approx(loop_len, abs=0.02)
    assert len(_brute_force_crossings(result.spline)) == 0


def test_monotone_pieces_are_monotone(rng):
    for _ in range(50):
        ax, ay = rng.normal(size=4), rng.normal(size=4)
        br = monotone_breaks(ax, ay, 3.0)
        for u0, u1 in itertools.pairwise(br):
            u = np.linspace(u0, u1, 50)
            for c in (ax, ay):
                dv = np.diff(cubic_eval(c, u))
                assert np.all(dv >= -1e-12) or np.all(dv <= 1e-12)


def test_chain_grows_and_truncates_consistently():
    chain = LoopFreeChain()
    for k in range(40):  # a straight zig-zag with no loops: the tree grows past its capacity
        chain.append(
            np.array([float(k), 1.0, 0.0, 0.0]), np.array([0.0, 0.0, 0.1 * (-1) ** k, 0.0]), 1.0
        )
    assert chain.n_seg == 40 and not chain.cuts
    assert chain.total_length == pytest.approx(40.0)


def test_segment_distance_never_overestimates(rng):
    """The chord test prunes a pair only if the chords are farther apart than the curves can
    stray from them, so the segment distance must never exceed the true one (checked against
    dense samples, which over-estimate by at most half a sample step)."""
    from navkit.path.loops import _segment_distance

    n = 1500
    p1, q1, p2, q2 = (rng.normal(size=(n, 2)) for _ in range(4))
    q1[:50] = p1[:50]  # degenerate A
    q2[50:100] = p2[50:100]  # degenerate B
    q2[100:150] = p2[100:150] + (q1[100:150] - p1[100:150])  # parallel
    d = _segment_distance(p1, q1, p2, q2)
    t = np.linspace(0.0, 1.0, 401)
    A = p1[:, None, :] + (q1 - p1)[:, None, :] * t[None, :, None]
    B = p2[:, None, :] + (q2 - p2)[:, None, :] * t[None, :, None]
    # all sample pairs of each segment pair, 50 segment pairs at a time (~130 MB, not 12 GB)
    sampled = np.concatenate(
        [
            np.linalg.norm(A[k : k + 50, :, None, :] - B[k : k + 50, None, :, :], axis=-1).min(
                axis=(1, 2)
            )
            for k in range(0, n, 50)
        ]
    )
    assert np.all(d <= sampled + 1e-12)
    # segment lengths here are ~1.4-4: the 401-sample grid is off by < 0.01
    assert np.all(d >= sampled - 0.01)
