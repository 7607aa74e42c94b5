"""Wall segmentation and TLS fits against known geometry."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from navkit.errors import ConfigError
from navkit.localization.walls import (
    SegmentationSettings,
    merge_two,
    ransac_walls,
    segment_from_points,
    split_and_merge,
)
from tests.localization.helpers import RECT, scan_points


def _angle_diff(a: float, b: float) -> float:
    return abs((a - b + np.pi / 2) % np.pi - np.pi / 2)


def test_split_and_merge_finds_the_walls_of_a_room_scan(rng):
    # a 360-degree scan from inside the 8 x 6 m room, 1 cm range noise
    pts = scan_points(RECT, np.array([3.0, 2.0, 0.3]), n=720, noise=0.01, rng=rng)
    assert len(split_and_merge(pts)) == 5  # the wall behind is cut by the wrap of the scan
    segs = split_and_merge(pts, closed=True)
    assert len(segs) == 4
    # In the sensor frame the walls are turned by -0.3 rad: directions 0 and 90 deg become
    # -0.3 and 1.27 rad. The TLS direction error is sigma / sqrt(sum t^2) ~ 0.01 / sqrt(n L^2/12)
    # ~ 1e-3 rad for >= 50 points over >= 2 m; 5 sigma = 0.3 deg.
    for s in segs:
        err = min(_angle_diff(s.angle, -0.3), _angle_diff(s.angle, np.pi / 2 - 0.3))
        assert np.degrees(err) < 0.3
        assert s.rms < 0.02  # ~ the 1 cm noise (rms of N(0, 0.01) is 0.01)


def test_reported_angle_uncertainty_matches_monte_carlo():
    # 60 points on a 3 m wall with 2 cm noise: the reported sigma_angle should predict the
    # spread of the fitted direction over many noisy draws (within 25 %: the std of a std
    # estimate from 400 draws is ~3.5 %, plus first-order propagation error).
    rng = np.random.default_rng(7)
    x = np.linspace(0, 3, 60)
    angles, sigmas = [], []
    for _ in range(400):
        P = np.stack([x, 1.0 + rng.normal(0, 0.02, x.shape)], axis=1)
        s = segment_from_points(P)
        angles.append(s.angle)
        sigmas.append(s.sigma_angle)
    assert np.std(angles) == pytest.approx(np.mean(sigmas), rel=0.25)


def test_gap_splits_a_wall_at_a_doorway():
    x = np.concatenate([np.linspace(0, 2, 100), np.linspace(3, 5, 100)])  # 1 m doorway
    P = np.stack([x, np.full_like(x, 2.0)], axis=1)
    segs = split_and_merge(P)
    assert len(segs) == 2
    ends = sorted([sorted([s.start[0], s.end[0]]) for s in segs])
    np.testing.assert_allclose(ends, [[0, 2], [3, 5]], atol=1e-9)


def test_ransac_recovers_walls_from_unordered_cloud_with_outliers(rng):
    from tests.localization.helpers import sample_walls

    P = sample_walls(RECT, 0.02) + rng.normal(0, 0.01, (1, 2)) * 0
    P = P + rng.normal(0, 0.01, P.shape)
    outliers = rng.uniform([0, 0], [8, 6], (len(P) // 5, 2))  # 20 % clutter
    cloud = rng.permutation(np.concatenate([P, outliers]))
    segs = ransac_walls(cloud, SegmentationSettings(seed=3))
    long = [s for s in segs if s.length > 3]
    assert len(long) == 4
    for s in long:
        # every long segment lies on a true wall: offset error ~ 0.01/sqrt(n) << 1 cm
        d = np.min([abs(s.distance(np.array([[0.0, 0.0]]))[0] + 0.0) for _ in [0]])
        assert d >= 0
        on_wall = min(
            abs(s.centroid[0]), abs(s.centroid[0] - 8), abs(s.centroid[1]), abs(s.centroid[1] - 6)
        )
        assert on_wall < 0.01
        assert min(_angle_diff(s.angle, 0.0), _angle_diff(s.angle, np.pi / 2)) < np.radians(0.3)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000), st.integers(3, 40), st.integers(3, 40))
def test_merging_statistics_equals_fitting_the_union(seed, n1, n2):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(n1, 2)) * [3, 0.1] + rng.normal(size=2)
    B = rng.normal(size=(n2, 2)) * [3, 0.1] + rng.normal(size=2)
    merged = merge_two(segment_from_points(A), segment_from_points(B))
    union = segment_from_points(np.concatenate([A, B]))
    assert merged.count == union.count
    np.testing.assert_allclose(merged.centroid, union.centroid, atol=1e-9)
    np.testing.assert_allclose(merged.scatter, union.scatter, atol=1e-7)
    assert abs(merged.normal @ union.normal) == pytest.approx(1.0, abs=1e-9)
    assert merged.rms == pytest.approx(union.rms, abs=1e-9)


def test_bad_settings_raise_config_error():
    with pytest.raises(ConfigError, match="split_distance"):
        SegmentationSettings(split_distance=-1)
    with pytest.raises(ConfigError, match="min_points"):
        SegmentationSettings(min_points=1)
