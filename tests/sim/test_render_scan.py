"""render_scan: geometry of the grid, body frame, truth labels, noise statistics."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.geometry import se3_apply, se3_from_rt
from navkit.sim import Box, Ground, Hemisphere, Scene, SpinningLidar, TiltingScanner, render_scan
from navkit.sim.scanners import RangeNoise


def _pose(x, y, z, yaw=0.0, pitch=0.0):
    cz, sz, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1.0]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    return se3_from_rt(Rz @ Ry, [x, y, z])


@pytest.fixture
def yard():
    return Scene(
        [
            Ground(name="ground"),
            Box((6.0, 0.0, 0.5), (1.0, 2.0, 1.0), name="crate"),
            Hemisphere((0.0, 5.0, 0.0), 0.8, name="rock"),
        ]
    )


def test_scanner_grids():
    t = TiltingScanner()
    assert t.azimuth.shape == (181,) and t.elevation.shape == (31,)
    np.testing.assert_allclose(np.degrees(t.elevation[[0, -1]]), [-30, 0])
    s = SpinningLidar(n_beams=16, n_columns=360)
    assert s.azimuth.shape == (360,) and s.elevation.shape == (16,)
    np.testing.assert_allclose(np.diff(s.azimuth), 2 * np.pi / 360)
    np.testing.assert_allclose(np.degrees(s.elevation[[0, -1]]), [-24.8, 2.0])


def test_scan_points_map_to_true_world_points(yard):
    T = _pose(1.0, -0.5, 1.2, yaw=0.4, pitch=0.1)  # tilted mount: body frame stays level
    sim = render_scan(yard, SpinningLidar(n_beams=32, n_columns=360), T)
    scan = sim.scan
    # body frame: level, on the ground under the sensor, yawed like the sensor
    np.testing.assert_allclose(sim.T_world_body[:3, 3], [1.0, -0.5, 0.0], atol=1e-12)
    np.testing.assert_allclose(sim.T_world_body[2, :3], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(scan.sensor_height, 1.2, atol=1e-12)
    pw = se3_apply(sim.T_world_body, scan.points("body").reshape(-1, 3)).reshape(
        sim.points_world.shape
    )
    valid = scan.valid
    assert valid.sum() > 5000
    np.testing.assert_allclose(pw[valid], sim.points_world[valid], atol=1e-9)
    np.testing.assert_array_equal(valid, sim.hit_index >= 0)


def test_ground_truth_labels(yard):
    sim = render_scan(
        yard, TiltingScanner(azimuth_step_deg=0.5, elevation_step_deg=0.5), _pose(0.0, 0.0, 1.0)
    )
    pts = sim.points_world
    # ground hits lie at z = 0, every other hit above it
    np.testing.assert_allclose(pts[sim.is_ground][:, 2], 0.0, atol=1e-9)
    assert np.all(pts[(sim.hit_index >= 0) & ~sim.is_ground][:, 2] > 1e-9)
    # the crate is seen straight ahead (azimuth 0) between the ground returns
    crate = yard.index_of("crate")
    ahead = np.argmin(np.abs(sim.scan.azimuth))
    assert np.any(sim.hit_index[ahead] == crate)
    np.testing.assert_allclose(pts[sim.hit_index == crate][:, 0].min(), 5.5, atol=1e-9)
    # the rock at +90 deg azimuth: all its points on the dome of radius 0.8
    rock_pts = pts[sim.hit_index == yard.index_of("rock")]
    assert len(rock_pts) > 10
    np.testing.assert_allclose(np.linalg.norm(rock_pts - [0, 5, 0], axis=1), 0.8, atol=1e-9)


def test_range_noise_statistics_and_dropouts(yard, rng):
    noise = RangeNoise(relative_sigma=0.01, absolute_sigma=0.0, dropout=0.1)
    sim = render_scan(
        yard, SpinningLidar(n_beams=32, n_columns=720), _pose(0, 0, 1.5), noise=noise, rng=rng
    )
    hit = sim.hit_index >= 0
    kept = sim.scan.valid
    n = hit.sum()
    # dropout ~ Binomial(n, 0.1): 5 standard deviations of the fraction
    frac = 1 - kept.sum() / n
    assert abs(frac - 0.1) < 5 * np.sqrt(0.1 * 0.9 / n)
    rel = (sim.scan.ranges[kept] - sim.true_ranges[kept]) / sim.true_ranges[kept]
    m = rel.size
    # relative errors ~ N(0, 0.01): mean within 5 sigma/sqrt(m); std within 5 sigma/sqrt(2m)
    assert abs(rel.mean()) < 5 * 0.01 / np.sqrt(m)
    assert abs(rel.std() - 0.01) < 5 * 0.01 / np.sqrt(2 * m)
    # same seed, same scan
    again = render_scan(
        yard,
        SpinningLidar(n_beams=32, n_columns=720),
        _pose(0, 0, 1.5),
        noise=noise,
        rng=np.random.default_rng(12345),
    )
    np.testing.assert_array_equal(again.scan.ranges, sim.scan.ranges)


def test_max_range_and_hills():
    scene = Scene([Ground(hill_amplitude=0.25, hill_wavelength=12.0)])
    sim = render_scan(
        scene, SpinningLidar(n_beams=16, n_columns=256), _pose(2.0, 3.0, 1.8), max_range=20.0
    )
    r = sim.scan.ranges
    assert np.nanmax(r) < 20.0
    # body origin sits on the hilly ground under the sensor
    g = scene.ground
    np.testing.assert_allclose(sim.T_world_body[2, 3], g.height_at(2.0, 3.0), atol=1e-12)
    p = sim.points_world[sim.scan.valid]
    np.testing.assert_allclose(p[:, 2], g.height_at(p[:, 0], p[:, 1]), atol=1e-10)
    assert sim.is_ground[sim.scan.valid].all()
