"""Association: the same planes found after a motion, new and vanished planes left out."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from navkit.geometry import se3_from_rt
from navkit.geometry.fitting import Plane, canonical_plane
from navkit.planes import PlaneSegment
from navkit.planes.associate import AssociationSettings, associate


def segment(n, rho, half=2.0):
    n, rho = canonical_plane(n, rho)
    plane = Plane(n, rho, n * rho, count=5000)
    square = np.array([[-half, -half], [half, -half], [half, half], [-half, half]])
    return PlaneSegment(plane, np.arange(10), square, (2 * half) ** 2)


def directions(rng, k):
    """k unit normals pairwise at least 25 deg apart (as distinct walls / floors are)."""
    out = []
    while len(out) < k:
        v = rng.normal(size=3)
        v /= np.linalg.norm(v)
        if all(abs(v @ w) < np.cos(np.radians(25)) for w in out):
            out.append(v)
    return out


@settings(max_examples=40, deadline=None)
@given(
    st.integers(0, 10_000),
    st.integers(2, 5),
    st.integers(0, 2),
    st.integers(0, 2),
    st.floats(0, 0.08),
    st.floats(0, 0.1),
)
def test_matches_survive_motion_new_and_vanished_planes(seed, k, n_new, n_gone, angle, shift):
    rng = np.random.default_rng(seed)
    dirs = directions(rng, k + n_new + n_gone)
    rhos = rng.uniform(0.8, 4.0, size=len(dirs))
    R = Rotation.from_rotvec(rng.normal(size=3) / np.sqrt(3) * angle).as_matrix()
    t = rng.normal(size=3) / np.sqrt(3) * shift
    # frame 1: shared planes + vanishing ones; frame 2: shared ones (moved) + new ones, shuffled
    shared = range(k)
    f1 = [segment(dirs[i], rhos[i]) for i in [*shared, *range(k + n_new, k + n_new + n_gone)]]
    f2_items = [(i, segment(R.T @ dirs[i], rhos[i] - dirs[i] @ t)) for i in shared]
    f2_items += [(None, segment(dirs[i], rhos[i])) for i in range(k, k + n_new)]
    order = rng.permutation(len(f2_items))
    f2 = [f2_items[o][1] for o in order]
    truth = {(i, int(np.flatnonzero(order == i)[0])) for i in shared}
    # motions up to 4.6 deg and 10 cm stay inside the default gates (12 deg, 25 cm)
    got = set(associate(f1, f2))
    assert got == truth


def test_prior_motion_makes_large_motions_associable():
    rng = np.random.default_rng(3)
    dirs = directions(rng, 3)
    R = Rotation.from_rotvec([0, 0.6, 0]).as_matrix()  # 34 deg: outside the gate without a prior
    t = np.array([0.5, 0.0, 0.8])
    f1 = [segment(d, 2.0 + i) for i, d in enumerate(dirs)]
    f2 = [segment(R.T @ d, 2.0 + i - d @ t) for i, d in enumerate(dirs)][::-1]
    assert associate(f1, f2) != [(0, 2), (1, 1), (2, 0)]
    assert associate(f1, f2, se3_from_rt(R, t)) == [(0, 2), (1, 1), (2, 0)]


def test_inconsistent_match_is_dropped():
    """A plane whose normal moved differently from the others is not kept."""
    dirs = [
        np.array([1.0, 0, 0]),
        np.array([0, 1.0, 0]),
        np.array([0, 0, 1.0]),
        np.ones(3) / np.sqrt(3),
    ]
    f1 = [segment(d, 2.0) for d in dirs]
    odd = Rotation.from_rotvec([0.15, 0, 0]).apply(dirs[1])  # 8.6 deg: inside the gate
    f2 = [segment(dirs[0], 2.0), segment(odd, 2.0), segment(dirs[2], 2.0), segment(dirs[3], 2.0)]
    got = associate(f1, f2, settings=AssociationSettings(consistency_deg=3.0))
    # three of four matches agree on one rotation (the identity); the odd one is dropped
    assert got == [(0, 0), (2, 2), (3, 3)]


def test_no_overlap_no_match():
    a = segment(np.array([0, 0, 1.0]), 2.0, half=0.5)
    from dataclasses import replace

    from navkit.planes.segments import plane_frame

    o, axes = plane_frame(a.plane)
    moved = replace(a.plane, centroid=o + np.array([10.0, 10.0]) @ axes)
    b = PlaneSegment(moved, a.inliers, a.outline + 10.0, a.area)  # same plane, 14 m away
    assert associate([a], [b]) == []
    assert associate([a], [a]) == [(0, 0)]


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000))
def test_global_association_handles_large_motions(seed):
    """No prior: 40-90 deg turns and metres of translation, six planes in distinct directions."""
    from navkit.planes.associate import associate_global

    rng = np.random.default_rng(seed)
    dirs = directions(rng, 6)
    rhos = rng.uniform(1.0, 5.0, size=6)
    axis = rng.normal(size=3)
    R = Rotation.from_rotvec(axis / np.linalg.norm(axis) * rng.uniform(0.7, 1.6)).as_matrix()
    t = rng.normal(size=3)
    f1 = [segment(d, r) for d, r in zip(dirs, rhos, strict=True)]
    f2 = [segment(R.T @ d, r - d @ t) for d, r in zip(dirs, rhos, strict=True)]
    # segment() canonicalises rho >= 0: a plane the sensor crossed flips its normal; keep the
    # test to planes seen from the same side (as walls of a room are)
    if any(r - d @ t <= 0.2 for d, r in zip(dirs, rhos, strict=True)):
        return
    order = rng.permutation(6)
    pairs, T = associate_global(f1, [f2[o] for o in order])
    assert T is not None
    assert np.allclose(T[:3, :3], R, atol=1e-6) and np.allclose(T[:3, 3], t, atol=1e-6)
    assert sorted(pairs) == sorted((int(order[j]), j) for j in range(6))


def test_a_tread_matched_to_its_neighbour_is_dropped():
    """Stairs: treads 20 cm apart fall inside the 25 cm distance gate. Frame 2 has lost tread
    1.2 m and sees a new one at 1.4 m: the gates pair 1.2 with 1.4 (same normal, 20 cm), but that
    match disagrees with the translation of all the others (eq. 2) and is dropped."""
    R = Rotation.from_rotvec([0.0, 0.02, 0.0]).as_matrix()
    t = np.array([0.01, 0.0, -0.02])
    wall = (np.array([0.0, 0.0, 1.0]), 2.5)
    treads = [(np.array([0.0, 1.0, 0.0]), r) for r in (0.6, 0.8, 1.0, 1.2)]
    f1 = [segment(n, r) for n, r in [wall, *treads]]

    def seen_from_2(n, r):  # frame 2 sees N2 = R^T N1, rho2 = rho1 - N1 . t (eqs. 1, 2)
        return segment(R.T @ n, r - n @ t)

    f2 = [seen_from_2(n, r) for n, r in [wall, *treads[:3]]]
    f2.append(seen_from_2(np.array([0.0, 1.0, 0.0]), 1.4))  # a new tread, 20 cm beyond
    pairs = associate(f1, f2)
    assert pairs == [(0, 0), (1, 1), (2, 2), (3, 3)]
    # without the translation check the wrong match is kept
    assert (4, 4) in associate(f1, f2, settings=AssociationSettings(consistency_m=0.0))
