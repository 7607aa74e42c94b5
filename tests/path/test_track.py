"""Trajectory preparation: cleaning, ground plane, odometry integration."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from navkit.errors import ConfigError
from navkit.path.track import clean_track, ground_plane, integrate_odometry, to_plane


def test_integrate_odometry_matches_the_simulated_unicycle(rng):
    from navkit.sim import simulate_unicycle

    n = 500
    dt = 0.01
    v = rng.uniform(0.0, 0.5, n)
    w = rng.uniform(-1.0, 1.0, n)
    t = np.arange(n + 1) * dt
    sim = simulate_unicycle(v, w, dt, start=(1.0, 2.0, 0.3))
    ours = integrate_odometry(t, np.r_[v, 0.0], np.r_[w, 0.0], start=(1.0, 2.0, 0.3))
    # both integrate constant (v, omega) steps exactly along arcs: equal to rounding
    np.testing.assert_allclose(ours, sim, atol=1e-10)


def test_clean_track_drops_backwards_and_nan(caplog):
    t = np.array([0.0, 1.0, 2.0, 1.5, 3.0, 3.0, 4.0])
    P = np.c_[np.arange(7.0), np.zeros(7)]
    P[6, 1] = np.nan
    with caplog.at_level(logging.WARNING):
        t2, P2 = clean_track(t, P, source="x.txt")
    np.testing.assert_array_equal(t2, [0.0, 1.0, 2.0, 3.0])
    np.testing.assert_array_equal(P2[:, 0], [0.0, 1.0, 2.0, 4.0])
    assert any("backwards" in r.message for r in caplog.records)
    assert any("NaN" in r.message for r in caplog.records)


def test_ground_plane_fit_recovers_a_tilted_plane(rng):
    # points on a plane tilted 20 deg about x: in-plane distances must be preserved
    xy = rng.uniform(-10, 10, (200, 2))
    c, s = np.cos(np.radians(20)), np.sin(np.radians(20))
    P = np.c_[xy[:, 0], c * xy[:, 1], s * xy[:, 1]] + [5.0, 1.0, -2.0]
    gp = ground_plane(P)
    q = to_plane(P, gp)
    d_in = np.hypot(*(q[1:] - q[:-1]).T)
    d_true = np.hypot(*(xy[1:] - xy[:-1]).T)
    np.testing.assert_allclose(d_in, d_true, atol=1e-9)
    assert gp.rms < 1e-9


def test_coordinate_planes_take_coordinates_as_they_are():
    P = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    np.testing.assert_array_equal(to_plane(P, ground_plane(P, "xz")), [[1.0, 3.0], [4.0, 6.0]])
    np.testing.assert_array_equal(to_plane(P, ground_plane(P, "yz")), [[2.0, 3.0], [5.0, 6.0]])
    with pytest.raises(ConfigError, match="plane"):
        ground_plane(P, "xw")


@pytest.mark.realdata
def test_kitti_ground_plane_is_the_camera_xz_plane(data_path):
    from navkit.io.trajectory import read_trajectory

    traj = read_trajectory(data_path("trajectories/KITTI_00_gt.txt"))
    gp = ground_plane(traj.positions)
    normal = np.cross(gp.axes[0], gp.axes[1])
    # KITTI camera frames: y points down, the road is (nearly) the x-z plane; the 3.7 km drive
    # climbs a few metres, so the fitted normal is within a few degrees of y
    assert abs(normal[1]) > np.cos(np.radians(3))
    assert normal[1] < 0  # seen from above (camera y points down): turns keep their sense
    # in-plane path length equals the 3D length to 0.1 % (height changes are small)
    q = to_plane(traj.positions, gp)
    L2 = np.hypot(*np.diff(q, axis=0).T).sum()
    assert L2 == pytest.approx(traj.path_length, rel=1e-3)
