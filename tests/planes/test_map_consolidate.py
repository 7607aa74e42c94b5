"""``PlaneMap.consolidate``: map planes that are one surface (seen first in parts) become one;
separate surfaces - coplanar but apart, or overlapping but tilted - stay apart."""

from __future__ import annotations

import numpy as np

from navkit.geometry.fitting import Plane
from navkit.planes.plane_map import MapPlane, PlaneMap, _refit


def _patch(pid: int, x0: float, x1: float, tilt_deg: float, obs: list[int], rng) -> MapPlane:
    """Points of the plane ``z = 1`` over ``x0 <= x <= x1``, ``0 <= y <= 2``, tilted by
    ``tilt_deg`` about the patch's centre line along y, with 3 mm of noise."""
    n = 3000
    P = np.column_stack([rng.uniform(x0, x1, n), rng.uniform(0.0, 2.0, n), np.zeros(n)])
    a = np.radians(tilt_deg)
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    c = np.array([(x0 + x1) / 2, 0.0, 0.0])
    P = (P - c) @ R.T + c + np.array([0.0, 0.0, 1.0]) + rng.normal(0, 0.003, (n, 3))
    mp = MapPlane(pid, Plane(np.array([0, 0, 1.0]), 1.0, P.mean(0)), P, np.zeros((0, 2)), 0.0,
                  list(obs), tex_ref=np.zeros(3), tex_axes=np.eye(3)[:2])  # fmt: skip
    _refit(mp)
    return mp


def test_parts_of_one_surface_become_one_plane_and_others_stay():
    rng = np.random.default_rng(0)
    left = _patch(0, 0.0, 1.5, 0.0, [0, 1, 2], rng)
    right = _patch(1, 1.3, 3.0, 0.5, [3, 4], rng)  # the same floor, overlapping, 0.5 deg off
    far = _patch(2, 5.0, 6.0, 0.0, [1, 5], rng)  # coplanar, 2 m away: another surface
    ramp = _patch(3, 0.5, 2.5, 20.0, [2, 6], rng)  # crosses the floor at 20 deg
    m = PlaneMap([left, right, far, ramp], nu=0.02, next_id=4)
    joined = m.consolidate(angle_deg=8.0, distance_m=0.08, margin_m=0.2, max_points=5000)
    assert joined == 1
    assert [p.id for p in m.planes] == [0, 2, 3]
    floor = m.planes[0]
    assert floor.observations == [0, 1, 2, 3, 4]
    assert len(floor.points) == 5000
    # refitted to both parts: the floor spans x 0-3 m, its normal within the 0.5 deg between
    # the parts
    span = floor.points[:, 0].max() - floor.points[:, 0].min()
    assert span > 2.9
    assert np.degrees(np.arccos(abs(floor.plane.normal[2]))) < 0.5
    assert m.consolidate(angle_deg=8.0, distance_m=0.08, margin_m=0.2, max_points=5000) == 0
