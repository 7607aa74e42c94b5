"""Polygon helpers against closed forms and a brute-force point-in-polygon reference."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from navkit.errors import DegenerateGeometryError
from navkit.geometry.polygons import (
    convex_hull_2d,
    ensure_ccw,
    points_in_polygon,
    polygon_area,
    polygon_centroid,
    polygon_perimeter,
    signed_area,
)

square = np.array([[0, 0], [2, 0], [2, 1], [0, 1.0]])


def test_rectangle_closed_forms():
    assert polygon_area(square) == pytest.approx(2.0)
    assert signed_area(square) > 0 and signed_area(square[::-1]) < 0
    assert polygon_perimeter(square) == pytest.approx(6.0)
    np.testing.assert_allclose(polygon_centroid(square), [1.0, 0.5])
    np.testing.assert_allclose(ensure_ccw(square[::-1]), square[::-1][::-1])


@given(st.integers(3, 60), st.floats(0.1, 10))
def test_regular_polygon_area(n, r):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    P = r * np.c_[np.cos(t), np.sin(t)]
    assert polygon_area(P) == pytest.approx(0.5 * n * r * r * np.sin(2 * np.pi / n), rel=1e-9)


def test_points_in_polygon_matches_ray_crossing(rng):
    # an L-shaped (non-convex) polygon
    L = np.array([[0, 0], [3, 0], [3, 1], [1, 1], [1, 3], [0, 3.0]])
    pts = rng.uniform(-0.5, 3.5, size=(2000, 2))
    inside = (
        (pts[:, 0] > 0)
        & (pts[:, 1] > 0)
        & (((pts[:, 0] < 3) & (pts[:, 1] < 1)) | ((pts[:, 0] < 1) & (pts[:, 1] < 3)))
    )
    np.testing.assert_array_equal(points_in_polygon(pts, L), inside)


def test_hull_contains_all_points_and_is_ccw(rng):
    pts = rng.normal(size=(300, 2))
    hull = convex_hull_2d(pts)
    assert signed_area(hull) > 0
    assert points_in_polygon(pts, hull, tolerance=1e-9).all()
    with pytest.raises(DegenerateGeometryError):
        convex_hull_2d(np.c_[np.arange(5.0), np.arange(5.0)])
