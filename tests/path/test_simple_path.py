"""The stored path is simple: no crossing left at any scale down to eps / 100 (property tests).

Random planar trajectories are built from loops of many sizes: spirals (a circle whose radius
drifts, so the loop's end crosses its start at an angle ~ sqrt(2 |drift|), down to a degree),
hairpins (out, a U-turn, back across the way out at a shallow angle) and random wandering,
sampled every few millimetres to centimetres with noise. Checked on the stored spline sampled
every eps / 100: it is simple (shapely), every input point outside the removed loops is within
eps of it, and its ends are the trajectory's ends.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from navkit.path import ApproximatorSettings, OnlineApproximator, approximate
from navkit.path.loops import LoopCut, kept_intervals

shapely = pytest.importorskip("shapely")

_DS = 1e-3  # integration step of the curvature profiles, metres


def _spiral(radius: float, drift: float, sign: float) -> np.ndarray:
    """Curvature of a loop whose radius grows by ``drift * radius`` per turn; it turns until
    well past the crossing of its end with its start (at ~ 2 pi + sqrt(2 |drift|))."""
    turn = 2.0 * np.pi + 4.0 * math.sqrt(2.0 * abs(drift))
    phi = np.arange(0.0, turn, _DS / radius)  # ~ one step of arc length each (drift < 0.2)
    return sign / (radius * (1.0 + drift * phi / (2.0 * np.pi)))


def _hairpin(
    radius: float, angle: float, sign: float, beyond: float = 0.3, most: float = 3.0
) -> np.ndarray:
    """A U-turn of ``pi + angle`` and the way back, ``beyond`` metres past where it crosses
    the way out (which the caller makes at least as long) at ``angle``, at most ``most``."""
    arc = np.full(int((np.pi + angle) * radius / _DS), sign / radius)
    back = min(2.0 * radius / math.sin(angle) + beyond, most)
    return np.concatenate([arc, np.zeros(int(back / _DS))])


def _wander(seed: int, length: float) -> np.ndarray:
    """Random curvature (a heading random walk with a drift): loops at any angle."""
    rng = np.random.default_rng(seed)
    n = int(length / _DS)
    kappa = np.repeat(rng.normal(rng.uniform(-4.0, 4.0), 3.0, n // 50 + 1), 50)[:n]
    return kappa


_loop = st.one_of(
    st.tuples(
        st.just("spiral"),
        st.floats(0.05, 2.0),  # radius
        st.floats(-4.0, -0.7).map(lambda e: 10.0**e),  # radius drift per turn, log-uniform
        st.sampled_from([-1.0, 1.0]),  # outwards / inwards
        st.sampled_from([-1.0, 1.0]),  # left / right
    ),
    st.tuples(
        st.just("hairpin"),
        st.floats(0.03, 0.5),  # radius
        st.floats(-2.0, -0.3).map(lambda e: 10.0**e),  # crossing angle (rad), log-uniform
        st.just(1.0),
        st.sampled_from([-1.0, 1.0]),
    ),
    st.tuples(
        st.just("wander"),
        st.integers(0, 2**16),
        st.floats(1.0, 6.0),
        st.just(1.0),
        st.just(1.0),
    ),
)


@st.composite
def trajectories(draw) -> tuple[np.ndarray, float]:
    """``(points (N, 2), eps)``: straight stretches and loops, sampled with noise."""
    loops = draw(st.lists(_loop, min_size=1, max_size=3))
    eps = draw(st.sampled_from([0.01, 0.05, 0.1]))
    step = draw(st.sampled_from([0.004, 0.01, 0.03]))
    noise = eps * draw(st.sampled_from([0.0, 0.05, 0.2]))
    seed = draw(st.integers(0, 2**16))
    parts = [np.zeros(int(draw(st.floats(0.3, 1.0)) / _DS))]
    for kind, a, b, c, sign in loops:
        if kind == "spiral":
            parts.append(_spiral(a, c * b, sign))
        elif kind == "hairpin":
            pin = _hairpin(a, b, sign)
            parts[-1] = np.zeros(max(len(parts[-1]), len(pin) - int(np.pi * a / _DS)))
            parts.append(pin)
        else:
            parts.append(_wander(int(a), b))
        parts.append(np.zeros(int(draw(st.floats(0.2, 1.0)) / _DS)))
    kappa = np.concatenate(parts)
    heading = np.cumsum(kappa) * _DS
    xy = np.cumsum(_DS * np.c_[np.cos(heading), np.sin(heading)], axis=0)
    rng = np.random.default_rng(seed)
    every = max(1, round(step / _DS))
    idx = np.unique(np.r_[np.arange(0, len(xy), every), len(xy) - 1])
    pts = xy[idx] + noise * rng.standard_normal((len(idx), 2))
    return pts, eps


def _simple(spline, eps: float) -> bool:
    """The spline sampled every eps / 100 (and at every knot) has no self-intersection."""
    if spline.n_segments == 0:
        return True
    _, xy = spline.sample(eps / 100.0)
    return bool(shapely.LineString(xy).is_simple)


@settings(max_examples=150)
@given(trajectories())
def test_stored_path_is_simple_and_keeps_the_rest(track):
    P, eps = track
    result = approximate(P, ApproximatorSettings(tolerance=eps), timed=False)
    path = result.spline
    assert _simple(path, eps)
    # every input point outside the removed loops is on the stored path within eps: at its own
    # parameter (the recorder's guarantee carried through the cuts) ...
    s = result.stored_arclength(result.point_s)
    kept = np.isfinite(s)
    assert kept.any()
    d_own = np.linalg.norm(result.points[kept] - path.position(s[kept]), axis=1)
    assert d_own.max() <= eps * (1.0 + 1e-9)
    # ... and by a nearest-point search that knows nothing of the bookkeeping (it can only
    # over-estimate the distance, by rounding)
    _, d_near = path.nearest(result.points[kept])
    assert d_near.max() <= eps * (1.0 + 1e-9)
    # the ends: the endpoints variant fixes both ends of every segment on data points
    np.testing.assert_allclose(path.position(0.0), P[0], atol=1e-9)
    np.testing.assert_allclose(path.position(path.total_length), P[-1], atol=1e-9)


@settings(max_examples=30)
@given(trajectories())
def test_path_so_far_is_simple_after_every_add(track):
    P, eps = track
    rec = OnlineApproximator(ApproximatorSettings(tolerance=eps))
    seen = (0, 0.0)
    for p in P:
        rec.update(p)
        path = rec.spline  # the frozen, loop-free part; it changes only when a segment freezes
        now = (path.n_segments, path.total_length)
        if now != seen:
            assert _simple(path, eps), f"after point {rec.n_input}"
            seen = now


def _shallow_loop_track() -> np.ndarray:
    """A drone-like track: 1 m/s sampled at 100 Hz with 1 mm noise, a 1.5 m straight run, a
    loop of radius 1 m whose end crosses its start at ~2 deg (a radius drift of 0.06 % per
    turn), a 1.5 m straight run. Cut where the box search put the crossing, its junction left
    a 0.5 mm loop in the stored path."""
    kappa = np.concatenate([np.zeros(1500), _spiral(1.0, 6e-4, 1.0), np.zeros(1500)])
    heading = np.cumsum(kappa) * _DS
    xy = np.cumsum(_DS * np.c_[np.cos(heading), np.sin(heading)], axis=0)[::10]
    return xy + 1e-3 * np.random.default_rng(2).standard_normal(xy.shape)


def test_shallow_junction_is_exact():
    """The loop is cut where its branches cross, solved on the cubics: the head of the path
    ends and the tail starts on the same point (a gap of rounding size, not the box search's
    precision / sin(angle))."""
    P = _shallow_loop_track()
    eps = 0.05
    result = approximate(P, ApproximatorSettings(tolerance=eps), timed=False)
    path = result.spline
    assert len(result.loops) == 1
    # the loop is the circle: 2 pi R = 6.28 m, to the tolerance and the noise
    assert result.loops[0].length == pytest.approx(2.0 * np.pi, abs=0.1)
    assert _simple(path, eps)
    ends = np.stack(
        [
            [
                np.polyval(path.ax[k][::-1], path.length[k]),
                np.polyval(path.ay[k][::-1], path.length[k]),
            ]
            for k in range(path.n_segments - 1)
        ]
    )
    assert np.linalg.norm(ends - path.knots[1:-1], axis=1).max() < 1e-12


def test_record_shallow_loops_path_json_is_simple(cli, tmp_path):
    """``navkit path record`` on a TUM trajectory whose loops end at a shallow angle writes a
    path.json that is simple when sampled every eps / 100."""
    from navkit.io.pathjson import read_path_json

    P = _shallow_loop_track()
    f = tmp_path / "shallow.tum"
    t = np.arange(len(P)) * 0.01
    rows = np.c_[t, P, np.zeros(len(P)), np.zeros((len(P), 3)), np.ones(len(P))]
    np.savetxt(f, rows, fmt="%.6f")
    out = tmp_path / "rec"
    r = cli("path", "record", f, "--tolerance", "0.05", "--plane", "xy", "--out", out)
    assert r.exit_code == 0, r.output
    path = read_path_json(out / "path.json")
    assert _simple(path, 0.05)


def test_kept_intervals_replay_the_cuts():
    """Cut [1, 2] of a 10 m path, then [0.5, 3] of what is left (= [0.5, 4] before the first
    cut): the kept parts are [0, 0.5] and [4, 10]."""
    empty = (np.zeros(0), np.zeros((0, 4)), np.zeros((0, 4)))
    cuts = [
        LoopCut(s_start=1.0, s_end=2.0, point=np.zeros(2), segments=empty),
        LoopCut(s_start=0.5, s_end=3.0, point=np.zeros(2), segments=empty),
    ]
    np.testing.assert_allclose(kept_intervals(cuts, 10.0), [[0.0, 0.5], [4.0, 10.0]])
