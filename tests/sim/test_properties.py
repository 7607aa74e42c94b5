"""Property tests: for random solids and rays, the first hit is on the surface and nothing
of the solid lies on the ray before it (checked against the solid's inside test)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from navkit.sim import Box, Cylinder, Prism, Scene, Sphere

coord = st.floats(-3.0, 3.0, allow_nan=False)
extent = st.floats(0.2, 2.0, allow_nan=False)
angle = st.floats(-np.pi, np.pi, allow_nan=False)


def _inside(prim, P):
    """Inside test (strict, with a margin) written directly from each primitive's definition."""
    if isinstance(prim, Sphere):
        return np.linalg.norm(P - prim.center, axis=-1) < prim.radius - 1e-7
    if isinstance(prim, Cylinder):
        d = P - prim.center
        return (
            (np.hypot(d[..., 0], d[..., 1]) < prim.radius - 1e-7)
            & (d[..., 2] > 1e-7)
            & (d[..., 2] < prim.height - 1e-7)
        )
    c, s = np.cos(prim.yaw), np.sin(prim.yaw)
    local = (P - prim.center) @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    h = 0.5 * np.asarray(prim.size)
    inside_box = np.all(np.abs(local) < h - 1e-7, axis=-1)
    if isinstance(prim, Box):
        return inside_box
    # prism: below the slope z = x hz / hx (local), margin scaled by the slope normal
    return inside_box & (local[..., 2] - local[..., 0] * h[2] / h[0] < -1e-7)


solids = st.one_of(
    st.builds(lambda x, y, z, r: Sphere((x, y, z), r), coord, coord, coord, extent),
    st.builds(lambda x, y, z, r, h: Cylinder((x, y, z), r, h), coord, coord, coord, extent, extent),
    st.builds(
        lambda x, y, z, a, b, c, yaw: Box((x, y, z), (a, b, c), yaw),
        coord,
        coord,
        coord,
        extent,
        extent,
        extent,
        angle,
    ),
    st.builds(
        lambda x, y, z, a, b, c, yaw: Prism((x, y, z), (a, b, c), yaw),
        coord,
        coord,
        coord,
        extent,
        extent,
        extent,
        angle,
    ),
)


@settings(max_examples=60, deadline=None)
@given(solid=solids, seed=st.integers(0, 2**32 - 1))
def test_first_hit_is_on_the_surface_and_unobstructed(solid, seed):
    rng = np.random.default_rng(seed)
    origin = rng.uniform(-8, 8, 3)
    origin[2] = rng.uniform(4.0, 8.0)  # above every solid: outside
    target = np.asarray(solid._bound()[0]) + rng.uniform(-1.5, 1.5, (200, 3))
    D = target - origin
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    hits = Scene([solid]).cast(origin, D)
    h = hits.hit
    if not h.any():
        return
    P = hits.point[h]
    # just beyond the hit (along the ray) is inside or on the solid's boundary, just before is
    # outside: the hit is on the surface and is the first one
    eps = 1e-6
    before = P - eps * D[h]
    assert not _inside(solid, before).any()
    # samples along the way are outside too
    f = np.linspace(0.0, 1.0, 50, endpoint=False)[None, :, None]
    Q = origin + f * (hits.distance[h][:, None, None] * D[h][:, None, :])
    assert not _inside(solid, Q).any()
    # normals are unit and face the ray
    np.testing.assert_allclose(np.linalg.norm(hits.normal[h], axis=1), 1.0, atol=1e-12)
    assert np.all(np.sum(hits.normal[h] * D[h], axis=1) <= 1e-12)
    # a miss never passes through the inside
    miss = ~h
    if miss.any():
        Qm = origin + np.linspace(0, 30, 400)[None, :, None] * D[miss][:, None, :]
        assert not _inside(solid, Qm).any()
