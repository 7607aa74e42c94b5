"""RangeScan: paper 1's stage-1 formulas, validation, mounting."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from navkit.errors import InputError
from navkit.sensors import RangeScan


def test_points_follow_paper_formula():
    az = np.radians([-30.0, 0.0, 45.0])
    el = np.radians([-20.0, -5.0, 10.0])
    d = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]])
    scan = RangeScan(d, az, el, sensor_height=1.7)
    p = scan.points()
    a, b = np.meshgrid(az, el, indexing="ij")
    np.testing.assert_allclose(p[..., 0], d * np.cos(b) * np.cos(a))
    np.testing.assert_allclose(p[..., 1], d * np.cos(b) * np.sin(a))
    np.testing.assert_allclose(p[..., 2], 1.7 + d * np.sin(b))
    np.testing.assert_allclose(np.linalg.norm(scan.points("sensor"), axis=-1), d)


def test_missing_returns_are_nan_not_errors():
    d = np.array([[1.0, np.nan, 0.0, -1.0, 50.0, np.inf]])
    scan = RangeScan(d, [0.0], np.radians(np.linspace(-10, 0, 6)), max_range=40.0)
    np.testing.assert_array_equal(scan.valid, [[True, False, False, False, False, False]])
    assert np.isnan(scan.points()[0, 1:]).all()


def test_tilted_mount_rotates_rays():
    R = Rotation.from_euler("y", 10, degrees=True).as_matrix()  # pitched down by 10 deg
    scan = RangeScan(np.array([[5.0]]), [0.0], [0.0], sensor_height=2.0, R_body_sensor=R)
    p = scan.points()[0, 0]
    np.testing.assert_allclose(
        p, [5 * np.cos(np.radians(10)), 0, 2 - 5 * np.sin(np.radians(10))], atol=1e-12
    )
    np.testing.assert_allclose(scan.T_body_sensor[:3, 3], [0, 0, 2.0])


@pytest.mark.parametrize(
    ("ranges", "az", "el", "field"),
    [
        (np.zeros((2, 3)), np.zeros(3), np.zeros(3), "ranges"),
        (np.zeros(3), np.zeros(3), np.zeros(1), "ranges"),
        (np.zeros((0, 0)), np.zeros(0), np.zeros(0), "ranges"),
        (np.zeros((1, 1)), [np.nan], [0.0], "azimuth/elevation"),
        (np.zeros((1, 1)), [0.0], [2.0], "elevation"),
        ([["a"]], [0.0], [0.0], "ranges"),
    ],
)
def test_bad_input_names_the_field(ranges, az, el, field):
    with pytest.raises(InputError, match=f"field '{field}'"):
        RangeScan(ranges, az, el)
