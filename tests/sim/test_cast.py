"""Ray casting against closed-form answers (derived independently in each test)."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.errors import ConfigError, InputError
from navkit.sim import Box, Cylinder, Ground, Hemisphere, Prism, Scene, Sphere, Wall

TOL = 1e-9  # analytic intersections in float64 on a ~10 m scene: rounding is ~1e-14, 1e-9 is slack


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_flat_ground_range_is_height_over_sine(rng):
    h = 1.7
    el = rng.uniform(-np.pi / 2 + 0.01, -0.01, 500)
    az = rng.uniform(-np.pi, np.pi, 500)
    D = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)
    hits = Scene([Ground(height=0.3)]).cast([1.0, 2.0, h + 0.3], D)
    np.testing.assert_allclose(hits.distance, h / -np.sin(el), rtol=0, atol=TOL * 100)
    np.testing.assert_allclose(hits.point[:, 2], 0.3, atol=TOL)
    np.testing.assert_allclose(hits.normal, np.tile([0, 0, 1.0], (500, 1)), atol=TOL)
    assert np.all(hits.index == 0)
    # rays going up never hit the ground
    assert np.all(np.isnan(Scene([Ground()]).cast([0, 0, 1.0], -D).distance))


def test_sphere_range_matches_geometric_construction(rng):
    c, r = np.array([4.0, -1.0, 2.0]), 1.3
    Or = rng.uniform(-3, 0, (400, 3))
    target = c + rng.uniform(-1.6, 1.6, (400, 3))  # some rays miss
    D = _unit(target - Or)
    hits = Scene([Sphere(c, r)]).cast(Or, D)
    # closest approach construction: tca = (c-Or).D, d^2 = |c-Or|^2 - tca^2, t = tca - sqrt(r^2-d^2)
    oc = c - Or
    tca = np.sum(oc * D, axis=1)
    d2 = np.sum(oc * oc, axis=1) - tca**2
    hit = d2 <= r * r
    expected = np.where(hit, tca - np.sqrt(np.where(hit, r * r - d2, 0)), np.nan)
    assert hit.sum() > 50 and (~hit).sum() > 50
    np.testing.assert_array_equal(np.isfinite(hits.distance), hit)
    np.testing.assert_allclose(hits.distance[hit], expected[hit], atol=TOL)
    np.testing.assert_allclose(np.linalg.norm(hits.point[hit] - c, axis=1), r, atol=TOL)
    # outward normal at the first hit faces the ray
    np.testing.assert_allclose(hits.normal[hit], (hits.point[hit] - c) / r, atol=TOL)


def _slab(Or, D, lo, hi):
    """Kay-Kajiya slab test, the textbook reference."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (lo - Or) / D, (hi - Or) / D
    tn = np.nanmax(np.minimum(t1, t2), axis=1)
    tf = np.nanmin(np.maximum(t1, t2), axis=1)
    return np.where((tn <= tf) & (tn > 0), tn, np.nan)


def test_box_matches_slab_test_axis_aligned_and_yawed(rng):
    center, size = np.array([3.0, 1.0, 0.5]), np.array([2.0, 1.0, 1.0])
    Or = rng.uniform(-2, 0, (500, 3)) + np.array([0, 0, 1.0])
    D = _unit(center + rng.uniform(-1.5, 1.5, (500, 3)) - Or)
    hits = Scene([Box(center, size)]).cast(Or, D)
    ref = _slab(Or, D, center - size / 2, center + size / 2)
    assert np.isfinite(ref).sum() > 100 and np.isnan(ref).sum() > 50
    np.testing.assert_array_equal(np.isfinite(hits.distance), np.isfinite(ref))
    ok = np.isfinite(ref)
    np.testing.assert_allclose(hits.distance[ok], ref[ok], atol=TOL)
    # yawed by 30 deg: rotate the rays into the box frame and use the slab test there
    yaw = np.radians(30)
    Rz = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
    hits = Scene([Box(center, size, yaw=yaw)]).cast(Or, D)
    ref = _slab((Or - center) @ Rz, D @ Rz, -size / 2, size / 2)
    ok = np.isfinite(ref)
    np.testing.assert_array_equal(np.isfinite(hits.distance), ok)
    np.testing.assert_allclose(hits.distance[ok], ref[ok], atol=TOL)
    # the normal is the face normal: one of the box's rotated axes, facing the ray
    axes = np.concatenate([Rz.T, -Rz.T])
    dots = hits.normal[ok] @ axes.T
    np.testing.assert_allclose(dots.max(axis=1), 1.0, atol=TOL)
    assert np.all(np.sum(hits.normal[ok] * D[ok], axis=1) < 0)


def test_cylinder_side_and_cap_ranges():
    cyl = Cylinder((0.0, 0.0, 0.0), radius=0.5, height=2.0)
    scene = Scene([cyl])
    ang = np.linspace(0, 2 * np.pi, 37)[:-1]
    # horizontal rays from a circle of radius 6 aimed at the axis: range 6 - r
    Or = np.stack([6 * np.cos(ang), 6 * np.sin(ang), np.full_like(ang, 1.2)], axis=1)
    hits = scene.cast(Or, -Or * [1, 1, 0])
    np.testing.assert_allclose(hits.distance, 5.5, atol=TOL)
    np.testing.assert_allclose(hits.normal, _unit(Or * [1, 1, 0]), atol=TOL)
    # vertical rays down onto the top cap at radius < r hit at z = 2; at radius > r they miss
    Or = np.array([[0.3, 0.2, 5.0], [0.6, 0.0, 5.0]])
    hits = scene.cast(Or, [[0, 0, -1.0], [0, 0, -1.0]])
    np.testing.assert_allclose(hits.distance[0], 3.0, atol=TOL)
    assert np.isnan(hits.distance[1])
    np.testing.assert_allclose(hits.normal[0], [0, 0, 1], atol=TOL)
    # an oblique ray: side hit point lies on the mantle; quadratic solved by the textbook formula
    Or = np.array([[3.0, 1.0, 3.0]])
    D = _unit(np.array([[-3.0, -0.9, -2.5]]))
    a = D[0, 0] ** 2 + D[0, 1] ** 2
    b = 2 * (Or[0, 0] * D[0, 0] + Or[0, 1] * D[0, 1])
    c = Or[0, 0] ** 2 + Or[0, 1] ** 2 - 0.25
    t = (-b - np.sqrt(b * b - 4 * a * c)) / (2 * a)
    assert 0 <= Or[0, 2] + t * D[0, 2] <= 2
    np.testing.assert_allclose(scene.cast(Or, D).distance[0], t, atol=TOL)


def test_hemisphere_is_only_the_dome():
    scene = Scene([Hemisphere((0.0, 0.0, 0.0), 1.0)])
    # a horizontal ray through z = 0.5 hits the dome at x = -sqrt(1 - 0.25)
    hits = scene.cast([-5.0, 0.0, 0.5], [[1.0, 0.0, 0.0]])
    np.testing.assert_allclose(hits.distance, 5 - np.sqrt(0.75), atol=TOL)
    # a horizontal ray below the centre passes under (the lower half is not a surface)
    assert np.isnan(scene.cast([-5.0, 0.0, -0.5], [[1.0, 0.0, 0.0]]).distance[0])
    # a ray from below going up enters through the open base and hits the dome from inside
    hits = scene.cast([0.2, 0.0, -3.0], [[0.0, 0.0, 1.0]])
    np.testing.assert_allclose(hits.point[0, 2], np.sqrt(1 - 0.04), atol=TOL)
    np.testing.assert_allclose(hits.normal[0], [-0.2, 0, -np.sqrt(0.96)], atol=TOL)  # faces the ray


def test_wall_parametric_hit_and_edges(rng):
    wall = Wall((2.0, -1.0, 0.0), (0.0, 2.0, 0.0), (0.0, 0.0, 3.0))
    scene = Scene([wall])
    y = rng.uniform(-2, 2, 300)
    z = rng.uniform(-1, 4, 300)
    D = _unit(np.stack([np.full(300, 2.0), y, z - 1.0], axis=1))
    hits = scene.cast([0.0, 0.0, 1.0], D)
    t = 2.0 / D[:, 0]
    P = np.array([0, 0, 1.0]) + t[:, None] * D
    inside = (P[:, 1] >= -1) & (P[:, 1] <= 1) & (P[:, 2] >= 0) & (P[:, 2] <= 3)
    np.testing.assert_array_equal(hits.hit, inside)
    np.testing.assert_allclose(hits.distance[inside], t[inside], atol=TOL)
    np.testing.assert_allclose(
        hits.normal[inside], np.tile([-1.0, 0, 0], (inside.sum(), 1)), atol=TOL
    )


def test_prism_slope_angle_and_heights():
    ramp = Prism((0.0, 0.0, 0.5), (2.0, 1.0, 1.0), yaw=np.pi / 2)  # rises towards +y
    scene = Scene([ramp])
    # vertical rays down onto the footprint: top height = (y + 1) / 2 (0 at y=-1, 1 at y=+1)
    ys = np.linspace(-0.9, 0.9, 19)
    Or = np.stack([np.zeros_like(ys), ys, np.full_like(ys, 5.0)], axis=1)
    hits = scene.cast(Or, np.tile([0, 0, -1.0], (19, 1)))
    np.testing.assert_allclose(hits.point[:, 2], (ys + 1) / 2, atol=TOL)
    # normal tilted by atan(h / l) = atan(1/2) from vertical, pointing towards -y (down-slope)
    tilt = np.arccos(hits.normal[:, 2])
    np.testing.assert_allclose(tilt, np.arctan(0.5), atol=TOL)
    assert np.all(hits.normal[:, 1] < 0)
    np.testing.assert_allclose(ramp.slope_angle, np.arctan(0.5))


def test_hills_hit_points_lie_on_the_surface_and_flat_limit_is_exact(rng):
    g = Ground(height=0.2, hill_amplitude=0.4, hill_wavelength=8.0)
    el = rng.uniform(-1.2, -0.02, 2000)
    az = rng.uniform(-np.pi, np.pi, 2000)
    D = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)
    hits = Scene([g]).cast([0.5, 0.3, 2.0], D)
    assert hits.hit.all()
    P = hits.point
    np.testing.assert_allclose(P[:, 2], g.height_at(P[:, 0], P[:, 1]), atol=1e-10)
    # the hit is the first crossing: dense samples before it are all above the surface
    s = np.linspace(0, 1, 400, endpoint=False)[None, :, None] * hits.distance[:, None, None]
    Q = np.array([0.5, 0.3, 2.0]) + s * D[:, None, :]
    # a grazing ray may skip a dip under a crest of at most Ground.max_missed_dip = 1e-6 m
    assert np.all(Q[..., 2] - g.height_at(Q[..., 0], Q[..., 1]) > -1e-6)
    # normal = normalised (-dz/dx, -dz/dy, 1)
    k = 2 * np.pi / 8.0
    gx = 0.4 * k * np.cos(k * P[:, 0]) * np.sin(k * P[:, 1])
    gy = 0.4 * k * np.sin(k * P[:, 0]) * np.cos(k * P[:, 1])
    np.testing.assert_allclose(
        hits.normal, _unit(np.stack([-gx, -gy, np.ones_like(gx)], 1)), atol=1e-9
    )
    flat = Scene([Ground(height=0.2, hill_amplitude=0.0)]).cast([0.5, 0.3, 2.0], D)
    np.testing.assert_allclose(flat.distance, 1.8 / -D[:, 2], atol=TOL)


def test_nearest_hit_wins_and_labels():
    scene = Scene(
        [
            Ground(name="ground"),
            Box((5.0, 0.0, 0.5), (1.0, 1.0, 1.0), name="near"),
            Box((8.0, 0.0, 1.0), (1.0, 1.0, 2.0), name="far"),
            Wall((12.0, -5.0, 0.0), (0.0, 10.0, 0.0), (0.0, 0.0, 4.0), name="wall"),
        ]
    )
    D = _unit(
        np.array([[1.0, 0, 0], [1.0, 0, 0.12], [1.0, 0, 0.25], [1.0, 0, -0.5], [-1.0, 0, 0.5]])
    )
    hits = scene.cast([0.0, 0.0, 0.5], D)
    names = scene.primitive_names(hits.index)
    assert list(names) == ["near", "far", "wall", "ground", ""]
    np.testing.assert_allclose(hits.distance[0], 4.5, atol=TOL)
    np.testing.assert_array_equal(
        scene.is_ground_index(hits.index), [False, False, False, True, False]
    )
    assert np.all(np.sum(hits.normal[hits.hit] * D[hits.hit], axis=1) < 0)
    # max_range turns far hits into misses
    short = scene.cast([0.0, 0.0, 0.5], D, max_range=6.0)
    assert list(scene.primitive_names(short.index)) == ["near", "", "", "ground", ""]


def test_colors_come_from_textures_and_are_deterministic():
    from navkit.sim import Texture

    wall = Wall(
        (2.0, -5.0, 0.0), (0.0, 10.0, 0.0), (0.0, 0.0, 3.0), texture=Texture("bricks", seed=4)
    )
    y, z = np.meshgrid(np.linspace(-4, 4, 60), np.linspace(0.1, 2.9, 40))
    D = _unit(np.stack([np.full(y.size, 2.0), y.ravel(), z.ravel() - 1.0], axis=1))
    c1 = Scene([wall]).cast([0.0, 0.0, 1.0], D).color
    c2 = Scene([wall]).cast([0.0, 0.0, 1.0], D).color
    np.testing.assert_array_equal(c1, c2)
    assert np.all((c1 >= 0) & (c1 <= 1))
    assert np.unique(np.round(c1, 6), axis=0).shape[0] > 50  # textured, not flat


def test_bad_input_raises_navkit_errors():
    with pytest.raises(ConfigError, match="radius"):
        Sphere((0, 0, 0), -1.0)
    with pytest.raises(ConfigError, match="size"):
        Box((0, 0, 0), (1, 0, 1))
    with pytest.raises(ConfigError, match="parallel"):
        Wall((0, 0, 0), (1, 0, 0), (2, 0, 0))
    with pytest.raises(InputError, match="directions"):
        Scene([Ground()]).cast([0, 0, 1], [[0, 0]])
    with pytest.raises(InputError, match="NaN"):
        Scene([Ground()]).cast([0, 0, 1], [[0, 0, np.nan]])
    with pytest.raises(ConfigError, match="duplicate"):
        Scene([Ground(name="a"), Box((0, 0, 0), (1, 1, 1), name="a")])


def test_box_slab_fast_path_matches_generic_half_space_clipping(rng):
    """Box uses a 3-slab test; the prism's generic Cyrus-Beck clipping must agree with it,
    including rays starting inside the box (they hit the face they leave through)."""
    from navkit.sim.primitives import _convex_intersect

    box = Box((1.0, -2.0, 0.7), (2.0, 1.0, 1.4), yaw=0.8)
    Or = np.concatenate(
        [rng.uniform(-4, 4, (400, 3)), box.center + rng.uniform(-0.4, 0.4, (100, 3))]
    )
    D = _unit(rng.normal(size=(500, 3)))
    D[:20, 2] = 0.0  # rays parallel to the top and bottom slabs
    D[:20] = _unit(D[:20])
    t_fast, f_fast = box._intersect(Or, D)
    R = box._R()
    N, d = box._local_planes()
    t_gen, f_gen = _convex_intersect((Or - np.asarray(box.center)) @ R, D @ R, N, d)
    np.testing.assert_array_equal(np.isfinite(t_fast), np.isfinite(t_gen))
    ok = np.isfinite(t_gen)
    assert ok[400:].all()  # every ray from inside hits
    np.testing.assert_allclose(t_fast[ok], t_gen[ok], atol=TOL)
    np.testing.assert_array_equal(f_fast[ok], f_gen[ok])


def test_cast_on_intersects_only_the_given_primitive():
    scene = Scene(
        [
            Ground(name="ground"),
            Box((5.0, 0.0, 0.5), (1.0, 1.0, 1.0), name="near"),
            Wall((12.0, -5.0, 0.0), (0.0, 10.0, 0.0), (0.0, 0.0, 4.0), name="wall"),
        ]
    )
    D = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    idx = np.array([1, 2, -1, 2])  # near box, wall (behind the box), none, wall (missed)
    hits = scene.cast_on(idx, [0.0, 0.0, 0.5], D)
    np.testing.assert_array_equal(hits.index, [1, 2, -1, -1])
    np.testing.assert_allclose(hits.distance[:2], [4.5, 12.0], atol=TOL)
    full = scene.cast([0.0, 0.0, 0.5], D[:1])
    np.testing.assert_array_equal(hits.color[0], full.color[0])
