"""The compiled path kernels (navkit.path._kernels) against their NumPy twins, bit for bit.

Why bit for bit, on any CPU: every kernel and its twin do the same IEEE-754 operations on the
same numbers in the same order, and use only operations the standard requires to be correctly
rounded (``+ - * /`` and ``sqrt``), so each intermediate has exactly one possible result
whatever the vector width, instruction set or thread count. Nothing on either side depends on
the CPU: no libm or SIMD-library functions (``hypot``, ``pow``, ``sin``, ``exp``: their last
bit is the library's), no BLAS products or solves (their summation order depends on the
library, the CPU and the threads), no pairwise ``np.sum`` (the twins sum from 0 in point order
with ``np.cumsum`` or in-place adds, as the kernels' loops do), and Numba compiles without
``fastmath``, so LLVM neither reassociates nor fuses ``a * b + c`` into an FMA. The online
approximator and the loop-free chain, compiled or not, therefore store the same path: the same
segment coefficients, loop cuts, accepted points, arc lengths and deviations - compared with
``np.array_equal`` below, on synthetic loops, random trajectories of every variant and every
recorded trajectory in the shared data.
"""

from __future__ import annotations

import numpy as np
import pytest

from navkit.path import ApproximatorSettings, OnlineApproximator
from navkit.path.fitting import VARIANTS


def _run(xy: np.ndarray, settings: ApproximatorSettings, compiled: bool) -> OnlineApproximator:
    a = OnlineApproximator(settings)
    a.compiled = a._chain.compiled = compiled
    for p in xy:
        a.update(p)
    return a


def _assert_same(xy: np.ndarray, eps: float, **kw: object) -> int:
    """The recorder on kernels and on twins: every stored number identical; returns the cuts."""
    settings = ApproximatorSettings(tolerance=eps, **kw)  # type: ignore[arg-type]
    a, b = _run(xy, settings, True), _run(xy, settings, False)
    ca, cb = a._chain.cuts, b._chain.cuts
    assert len(ca) == len(cb)
    for x, y in zip(ca, cb, strict=True):
        assert (x.s_start, x.s_end) == (y.s_start, y.s_end)
        assert np.array_equal(x.point, y.point)
        for u, v in zip(x.segments, y.segments, strict=True):
            assert np.array_equal(u, v)
    n = a._chain.n_seg
    assert n == b._chain.n_seg
    for name in ("_ax", "_ay", "_len", "_s0"):
        assert np.array_equal(getattr(a._chain, name)[:n], getattr(b._chain, name)[:n])
    assert len(a._raw) == len(b._raw)
    for x, y in zip(a._raw, b._raw, strict=True):
        assert np.array_equal(x[0], y[0]) and np.array_equal(x[1], y[1]) and x[2] == y[2]
    ra, rb = a.finish(), b.finish()
    for name in ("points", "point_s", "deviation"):
        assert np.array_equal(getattr(ra, name), getattr(rb, name)), name
    assert (ra.n_cheap, ra.n_refit_fallbacks) == (rb.n_cheap, rb.n_refit_fallbacks)
    for name in ("s0", "length", "ax", "ay"):
        assert np.array_equal(getattr(ra.spline, name), getattr(rb.spline, name))
    # the loop-free chains have no crossing left, by either search
    assert a._chain.find_crossings(0) == [] and b._chain.find_crossings(0) == []
    return len(ca)


@pytest.mark.twin("within", "natural_fit_endpoints")
@pytest.mark.twin("append_search", "cut_search", "update_leaves", "find_crossings")
def test_spirals_and_figure_eights(rng):
    """Synthetic tracks that close loops at shallow and steep angles, with noise."""
    t = np.linspace(0, 6 * np.pi, 1500)
    tracks = [
        np.c_[np.cos(t) * (5 + 0.2 * t), np.sin(t) * (5 + 0.2 * t)],  # widening spiral: none
        np.c_[10 * np.sin(t), 5 * np.sin(2 * t)],  # figure eight driven three times
    ]
    tracks[1] = tracks[1] + rng.normal(0, 0.01, tracks[1].shape)
    loops = [_assert_same(xy, 0.05) for xy in tracks]
    assert sum(loops) > 0


@pytest.mark.twin("find_crossings", "update_leaves")
def test_all_crossings_of_a_chain_match():
    """find_crossings over a whole chain without loop removal, every crossing listed."""
    t = np.linspace(0, 4 * np.pi, 2000)
    xy = np.c_[10 * np.sin(t), 5 * np.sin(2 * t) + 0.05 * t]
    out = []
    for compiled in (True, False):
        a = OnlineApproximator(ApproximatorSettings(tolerance=0.02, remove_loops=False))
        a._chain.compiled = compiled
        for p in xy:
            a.update(p)
        out.append(a._chain.find_crossings(0))
    assert len(out[0]) >= 3
    assert len(out[0]) == len(out[1])
    for x, y in zip(out[0], out[1], strict=True):
        assert (x.s_a, x.s_b) == (y.s_a, y.s_b)
        assert np.array_equal(x.point, y.point)


@pytest.mark.parametrize(
    "relative",
    [
        "trajectories/KITTI_00_gt.txt",
        "trajectories/KITTI_00_ORB.txt",
        "trajectories/KITTI_00_SPTAM.txt",
        "trajectories/fr2_desk_groundtruth.txt",
        "trajectories/freiburg1_xyz-groundtruth.txt",
        "odometry/mrclam-dataset7/Robot1_Odometry.dat",
    ],
)
@pytest.mark.twin("within", "natural_fit_endpoints")
@pytest.mark.twin("append_search", "cut_search", "update_leaves", "find_crossings")
def test_recorded_trajectories(data_path, relative):
    from navkit.io.trajectory import load_planar_track

    _, xy, _, _ = load_planar_track(data_path(relative))
    xy = xy[:15000]  # MRCLAM: the first 150 s (its loops are in them)
    assert _assert_same(xy, 0.05) >= 1


@pytest.mark.twin("within")
def test_within_is_the_numpy_test(rng):
    """``_kernels.within`` (the exact deviation test of a point, stopping at the first miss)
    gives ``OnlineApproximator._within``'s verdict: residuals at the points' own parameters,
    then the distance to the curve of the points beyond the limit."""
    from navkit.path import _kernels as K
    from navkit.path.fitting import fit_points

    for trial in range(300):
        n = int(rng.integers(3, 200))
        t = np.linspace(0, rng.uniform(0.5, 3) * np.pi, n)
        xy = np.c_[np.cos(t), np.sin(t)] * rng.uniform(1, 20) + rng.normal(0, 0.02, (n, 2))
        a = OnlineApproximator(ApproximatorSettings(tolerance=0.05, geometric_test=trial % 2 == 0))
        a._buf = xy + rng.normal(0, 1, 2)
        a._tau = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
        fit = fit_points("endpoints", a._tau, a._buf - a._buf[0])
        for limit in (0.01, 0.03, 0.05, 0.2):
            a._eps_fit = limit
            expected = a._within(fit, n - 1, float(a._tau[n - 1]))
            got = K.within(fit.coef, a._tau, a._buf, n, limit, trial % 2 == 0)
            assert got == expected


@pytest.mark.twin("gauss_legendre_length", "project", "power_sums", "fit_endpoints")
def test_freeze_kernels_match_numpy(rng):
    """The freeze's passes - power sums, Gauss-Legendre arc lengths, Newton projection - give
    their NumPy twins' bits, on random cubics and noisy points (1 to 2000 of them, parameters
    outside [0, 1] included), and ``fit_endpoints`` gives ``fitting._fit_endpoints``' bits."""
    from navkit.path import _kernels as K
    from navkit.path.fitting import CubicFit, _fit_endpoints, power_sums, project
    from navkit.path.spline import _GL_W, _GL_X, gauss_legendre_length

    for trial in range(60):
        n = int(rng.integers(1, 2000)) if trial else 1
        coef = rng.normal(0, 5, (2, 4)) * 10.0 ** rng.uniform(-3, 3)
        u = np.sort(rng.random(n))
        s = K.gauss_legendre_length(coef[0], coef[1], u, _GL_X, _GL_W)
        assert np.array_equal(s, gauss_legendre_length(coef[0], coef[1], u))
        d = np.c_[np.polyval(coef[0, ::-1], u), np.polyval(coef[1, ::-1], u)]
        d += rng.normal(0, 0.05, d.shape)
        u0 = np.clip(u + rng.normal(0, 0.02, n), -0.1, 1.1)
        uk, dk = K.project(coef, u0, d, 3)
        un, dn = project(CubicFit(coef=coef, T=1.0, ssr=0.0), u0, d)
        assert np.array_equal(uk, un) and np.array_equal(dk, dn)
        Sk, Dk, Qk = K.power_sums(u, d)
        Sn, Dn, Qn = power_sums(u, d)
        assert np.array_equal(Sk, Sn) and np.array_equal(Dk, Dn) and Qk == Qn
        if n >= 4:
            ok, c, ssr = K.fit_endpoints(Sn, Dn, Qn, float(d[-1, 0]), float(d[-1, 1]))
            ref = _fit_endpoints(
                Sn.tolist(), Dn.tolist(), Qn, 1.0, float(d[-1, 0]), float(d[-1, 1])
            )
            assert ok and np.array_equal(c, ref.coef) and ssr == ref.ssr


@pytest.mark.twin("monotone_breaks")
def test_monotone_breaks_kernel_is_the_python_one(rng):
    """``_kernels.monotone_breaks`` gives ``loops.monotone_breaks`` bit for bit, degenerate
    cubics (lines, parabolas, double roots, roots at the ends) included."""
    from navkit.path import _kernels as K
    from navkit.path.loops import monotone_breaks

    cases = [rng.normal(size=(2, 4)) for _ in range(300)]
    cases += [
        np.array([[0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]]),  # a line along x
        np.array([[0.0, 1.0, -0.5, 0.0], [0.0, 0.0, 1.0, 0.0]]),  # x turns at u = 1
        np.array([[0.0, 3.0, -3.0, 1.0], [1.0, 0.0, 0.0, 0.0]]),  # double root of x' at u = 1
        np.array([[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]),  # roots at u = 0
    ]
    for c in cases:
        for length in (0.5, 1.0, 3.0):
            expected = monotone_breaks(c[0], c[1], length)
            got = K.monotone_breaks(c[0].copy(), c[1].copy(), length)
            assert np.array_equal(got, expected)


@pytest.mark.twin("append_search", "cut_search", "update_leaves")
def test_compiled_chain_is_the_numpy_chain():
    """``LoopFreeChain.append`` as one kernel call per step (push + search, cut + search) leaves
    the NumPy chain's state: the same segments, monotone pieces, leaf boxes and root box, the
    same cuts (crossings bit for bit) with the same pre-cut segments."""
    from navkit.path.loops import LoopFreeChain

    t = np.linspace(0, 6 * np.pi, 900)
    xy = np.c_[10 * np.sin(t), 5 * np.sin(2 * t) + 0.02 * t]  # a figure eight, three times
    ref = OnlineApproximator(ApproximatorSettings(tolerance=0.05, remove_loops=False))
    ref.compiled = ref._chain.compiled = False
    for p in xy:
        ref.update(p)
    raw = ref.finish().raw_spline
    chains = []
    for compiled in (True, False):
        chain = LoopFreeChain()
        chain.compiled = compiled
        for k in range(raw.n_segments):
            chain.append(raw.ax[k], raw.ay[k], raw.length[k])
        chains.append(chain)
    a, b = chains
    assert len(a.cuts) == len(b.cuts) >= 2
    for x, y in zip(a.cuts, b.cuts, strict=True):
        assert (x.s_start, x.s_end) == (y.s_start, y.s_end)
        assert np.array_equal(x.point, y.point)
        for u, v in zip(x.segments, y.segments, strict=True):
            assert np.array_equal(u, v)
    assert (a.n_seg, a.n_piece) == (b.n_seg, b.n_piece)
    n, m = a.n_seg, a.n_piece
    for name in ("_ax", "_ay", "_len", "_s0"):
        assert np.array_equal(getattr(a, name)[:n], getattr(b, name)[:n])
    assert np.array_equal(a._seg_first_piece[: n + 1], b._seg_first_piece[: n + 1])
    for name in ("_pseg", "_pu0", "_pu1"):
        assert np.array_equal(getattr(a, name)[:m], getattr(b, name)[:m])
    for box in ("_lo", "_hi"):
        x, y = getattr(a, box), getattr(b, box)
        assert np.array_equal(x[a._cap : a._cap + m], y[b._cap : b._cap + m])
        assert np.array_equal(x[1], y[1])  # the root: the whole chain


def _figure_eight_segments(tolerance: float):  # type: ignore[no-untyped-def]
    """The raw segments of a figure eight driven three times (the NumPy recorder, no loop
    removal): a chain whose pieces overlap their older ones at every crossing."""
    t = np.linspace(0, 6 * np.pi, 900)
    xy = np.c_[10 * np.sin(t), 5 * np.sin(2 * t) + 0.02 * t]
    ref = OnlineApproximator(ApproximatorSettings(tolerance=tolerance, remove_loops=False))
    ref.compiled = ref._chain.compiled = False
    for p in xy:
        ref.update(p)
    return ref.finish().raw_spline


@pytest.mark.twin("push_segment", "update_leaves")
def test_push_segment_is_the_numpy_push():
    """``_kernels.push_segment`` (a segment, its monotone pieces, their leaves and ancestors)
    leaves ``LoopFreeChain._push_segment``'s state, segment after segment: the same starts,
    pieces and boxes bit for bit, the tree grown as the NumPy chain grows it."""
    from navkit.path import _kernels as K
    from navkit.path.loops import LoopFreeChain

    raw = _figure_eight_segments(0.003)  # 67 pieces: the tree grows past its 64 leaves
    a, b = LoopFreeChain(), LoopFreeChain()
    a.compiled, b.compiled = True, False
    for k in range(raw.n_segments):
        ax, ay, length = raw.ax[k].copy(), raw.ay[k].copy(), float(raw.length[k])
        a._reserve(5)  # room for the segment and its (at most 5) pieces, as append does
        a.n_piece = K.push_segment(
            a._ax, a._ay, a._len, a._s0, a._seg_first_piece, a._pseg, a._pu0, a._pu1,
            a._lo, a._hi, a._cap, a.n_seg, a.n_piece, ax, ay, length,
        )  # fmt: skip
        a.n_seg += 1
        b._push_segment(ax, ay, length)
        assert (a.n_seg, a.n_piece) == (b.n_seg, b.n_piece)
    n, m = a.n_seg, a.n_piece
    assert m > n  # segments with several monotone pieces
    for name in ("_ax", "_ay", "_len", "_s0"):
        assert np.array_equal(getattr(a, name)[:n], getattr(b, name)[:n]), name
    assert np.array_equal(a._seg_first_piece[: n + 1], b._seg_first_piece[: n + 1])
    for name in ("_pseg", "_pu0", "_pu1"):
        assert np.array_equal(getattr(a, name)[:m], getattr(b, name)[:m]), name
    assert a._cap == b._cap == 128
    assert np.array_equal(a._lo, b._lo) and np.array_equal(a._hi, b._hi)


@pytest.mark.twin("candidate_pairs")
def test_candidate_pairs_kernel_is_the_numpy_descent():
    """``_kernels.candidate_pairs`` (depth-first descent of the box tree) gives
    ``LoopFreeChain._candidate_pairs``' (older, newer) piece pairs in the same order, from
    every first piece of a chain with crossings (none from beyond its last piece)."""
    from navkit.path import _kernels as K
    from navkit.path.loops import LoopFreeChain

    raw = _figure_eight_segments(0.05)
    chain = LoopFreeChain()
    chain.compiled = False
    for k in range(raw.n_segments):
        chain.append(raw.ax[k], raw.ay[k], raw.length[k], remove_loops=False)
    total = 0
    for first in range(chain.n_piece + 1):
        want_a, want_b = chain._candidate_pairs(first)
        got_a, got_b = K.candidate_pairs(chain._lo, chain._hi, chain._cap, first, chain.n_piece)
        assert np.array_equal(got_a, want_a) and np.array_equal(got_b, want_b), first
        total += len(want_a)
    assert total > chain.n_piece  # neighbours and the crossings' overlapping boxes


@pytest.mark.twin("natural_fit_endpoints")
def test_natural_fit_kernel_matches_numpy(rng):
    """``_kernels.natural_fit_endpoints`` (the freeze's fit over t, arc lengths, refit and
    projection in one call, in a reused workspace) against the NumPy steps of
    ``OnlineApproximator._natural_fit`` and, when a point is beyond eps, ``_scaled_t_fit``."""
    from navkit.path import _kernels as K
    from navkit.path.spline import _GL_W, _GL_X

    W = np.full((K.W_ROWS, 2100), np.nan)  # reused: stale numbers from the last trial must not leak
    speed = np.full(5 * 2100, np.nan)
    for trial in range(20):
        n = int(rng.integers(4, 2000))
        t = np.linspace(0, rng.uniform(0.3, 2.0), n)
        xy = np.c_[np.cos(t), np.sin(t)] * rng.uniform(1, 30) + rng.normal(0, 0.01, (n, 2))
        a = OnlineApproximator(ApproximatorSettings(tolerance=0.05))
        a.compiled = False
        a._buf = np.vstack([xy, np.zeros((3, 2))])  # rows beyond n are not read
        a._tau = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T)), 0, 0, 0]
        fit, s, dev = a._natural_fit("endpoints", a._buf[0].copy(), n)
        eps = (0.005, 1.0)[trial % 2]  # with a point beyond eps the fallback is computed too
        ok, far, _, _, c_t, T_s, _, c_s = K.natural_fit_endpoints(
            a._buf, a._tau, n, _GL_X, _GL_W, eps, W, speed
        )
        assert ok and far == bool(dev.max() > eps)
        assert T_s == fit.T and np.array_equal(c_s, fit.coef)
        assert np.array_equal(W[K.W_UP, :n] * T_s, s)
        assert np.array_equal(W[K.W_DIST, :n], dev)
        if far:
            fit_f, s_f, dev_f = a._scaled_t_fit("endpoints", a._buf[0].copy(), n)
            assert np.array_equal(c_t, fit_f.coef) and W[K.W_S, n - 1] == fit_f.T
            assert np.array_equal(W[K.W_UP2, :n] * W[K.W_S, n - 1], s_f)
            assert np.array_equal(W[K.W_DIST2, :n], dev_f)


def _random_track(rng: np.random.Generator, n: int) -> np.ndarray:
    """A vehicle-like random track: speed and turn rate as smoothed random walks (loops, tight
    turns, straights, stops), position noise, a few repeated points and NaN rows."""
    turn = np.cumsum(rng.normal(0, 0.02, n))
    turn = np.convolve(turn - turn.mean(), np.ones(25) / 25, mode="same") * rng.uniform(0.5, 3)
    speed = np.abs(np.convolve(rng.normal(1, 0.6, n), np.ones(15) / 15, mode="same"))
    speed[rng.random(n) < 0.02] = 0.0  # repeats
    heading = np.cumsum(turn)
    xy = np.cumsum(np.c_[np.cos(heading), np.sin(heading)] * speed[:, None] * 0.1, axis=0)
    xy += rng.normal(0, 0.005, xy.shape) * (rng.random((n, 1)) < 0.5)
    xy[rng.random(n) < 0.005] = np.nan
    return xy * 10.0 ** rng.uniform(-1, 1)


@pytest.mark.twin(
    "within", "natural_fit_endpoints", "power_sums", "gauss_legendre_length", "project"
)
@pytest.mark.twin("append_search", "cut_search", "update_leaves", "find_crossings")
@pytest.mark.parametrize("variant", VARIANTS)
def test_random_trajectories_every_variant(variant):
    """Random tracks (loops at every angle, noise, repeats, NaN rows), every fitting variant,
    with and without the geometric test, tolerances from 1 mm to 0.5 m: the kernels' path is
    the twins' path, bit for bit."""
    rng = np.random.default_rng(VARIANTS.index(variant))
    cuts = 0
    for trial in range(6):
        xy = _random_track(rng, int(rng.integers(300, 2500)))
        eps = float(10.0 ** rng.uniform(-3, np.log10(0.5)))
        cuts += _assert_same(xy, eps, variant=variant, geometric_test=trial % 2 == 0)
    assert cuts >= 1  # the loop search and the cuts were exercised
