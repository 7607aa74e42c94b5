"""The visual-odometry error model: exact without noise, biased as configured, random as configured."""

import numpy as np
import pytest

from navkit.errors import InputError
from navkit.sensors import VisualOdometryNoise


def square_path(step=0.05, side=2.0):
    n = int(side / step)
    pts, heading = [(0.0, 0.0, 0.0)], 0.0
    for _ in range(4):
        for _ in range(n):
            x, y, _ = pts[-1]
            pts.append((x + step * np.cos(heading), y + step * np.sin(heading), heading))
        heading += np.pi / 2
        x, y, _ = pts[-1]
        pts.append((x, y, heading))
    return np.array(pts)


def test_zero_noise_reproduces_truth(rng):
    truth = square_path()
    vo = VisualOdometryNoise(scale_sigma=0.0, heading_sigma=0.0)
    out = vo.corrupt(truth, rng)
    np.testing.assert_allclose(out[:, :2], truth[:, :2], atol=1e-9)


def test_scale_bias_scales_a_straight_line(rng):
    truth = np.c_[np.linspace(0, 10, 101), np.zeros(101), np.zeros(101)]
    out = VisualOdometryNoise(scale_bias=0.05, scale_sigma=0.0, heading_sigma=0.0).corrupt(
        truth, rng
    )
    assert out[-1, 0] == pytest.approx(10.5)


def test_heading_noise_statistics(rng):
    """Per-step heading noise sigma over n steps gives a final heading spread of sigma * sqrt(n)."""
    truth = np.c_[np.linspace(0, 10, 101), np.zeros(101), np.zeros(101)]
    sigma = np.radians(0.5)
    vo = VisualOdometryNoise(scale_sigma=0.0, heading_sigma=sigma)
    final = np.array([vo.corrupt(truth, rng)[-1, 2] for _ in range(400)])
    expected = sigma * np.sqrt(100)
    # the sample std of 400 normals is within ~ +-3.5 * expected / sqrt(2 * 400)
    assert abs(final.std() - expected) < 3.5 * expected / np.sqrt(800)


def test_bad_input():
    with pytest.raises(InputError, match="poses_xytheta"):
        VisualOdometryNoise().corrupt(np.zeros((5, 2)))
    with pytest.raises(InputError, match="rate_hz"):
        VisualOdometryNoise(rate_hz=0.0)


def test_increment_sigma_matches_the_simulated_vo():
    """The model's increment uncertainty over 10 steps of 6 cm equals the root mean square
    error of 4000 increments of :meth:`corrupt` (the mission's VO: 2 % long, 5 % scale noise,
    0.6 deg/m drift, 0.3 deg per step) within 10 % (the Monte-Carlo RMS itself is known to
    about 1 %; the sideways term's straight-path approximation is the rest)."""
    from navkit.geometry import se2_from_xytheta, se2_inverse, se2_to_xytheta

    m = VisualOdometryNoise(10.0, 0.02, 0.05, np.radians(0.6), np.radians(0.3))
    n, d = 10, 0.6
    P = np.column_stack([np.linspace(0, d, n + 1), np.zeros(n + 1), np.zeros(n + 1)])
    rng = np.random.default_rng(0)
    et, eh = [], []
    for _ in range(4000):
        V = m.corrupt(P, rng)
        inc = se2_to_xytheta(se2_inverse(se2_from_xytheta(*V[0])) @ se2_from_xytheta(*V[-1]))
        et.append(np.hypot(inc[0] - d, inc[1]))
        eh.append(inc[2])
    sig_t, sig_h = m.increment_sigma(d, n)
    assert abs(sig_t / np.sqrt(np.mean(np.square(et))) - 1) < 0.1
    assert abs(sig_h / np.sqrt(np.mean(np.square(eh))) - 1) < 0.1
