"""Polygon helpers on ``(N, 2)`` vertex arrays (closed implicitly: the last vertex joins the first)."""

from __future__ import annotations

import numpy as np
from matplotlib.path import Path
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import ConvexHull, QhullError

from navkit.errors import DegenerateGeometryError
from navkit.geometry._validate import as_points

__all__ = [
    "convex_hull_2d",
    "ensure_ccw",
    "points_in_polygon",
    "polygon_area",
    "polygon_centroid",
    "polygon_perimeter",
    "signed_area",
]


def signed_area(polygon: ArrayLike) -> float:
    """Shoelace area, positive for counter-clockwise vertex order (m^2)."""
    P = as_points(polygon, 2)
    x, y = P[:, 0], P[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def polygon_area(polygon: ArrayLike) -> float:
    """Area of a simple polygon (m^2)."""
    return abs(signed_area(polygon))


def polygon_perimeter(polygon: ArrayLike) -> float:
    """Length of the closed boundary (m)."""
    P = as_points(polygon, 2)
    return float(np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1).sum())


def polygon_centroid(polygon: ArrayLike) -> NDArray[np.float64]:
    """Area centroid ``(2,)`` of a simple polygon (vertex mean for a degenerate one)."""
    P = as_points(polygon, 2, min_count=1)
    x, y = P[:, 0], P[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    A = cross.sum() / 2.0
    if abs(A) < 1e-15:
        return P.mean(axis=0)
    return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * A)


def ensure_ccw(polygon: ArrayLike) -> NDArray[np.float64]:
    """The polygon with counter-clockwise vertex order."""
    P = as_points(polygon, 2)
    return P[::-1].copy() if signed_area(P) < 0 else P.copy()


def points_in_polygon(
    points: ArrayLike, polygon: ArrayLike, tolerance: float = 0.0
) -> NDArray[np.bool_]:
    """Which points ``(N, 2)`` lie inside (or within ``tolerance`` m of) a simple polygon."""
    P = as_points(points, 2)
    poly = ensure_ccw(as_points(polygon, 2, min_count=3))
    # matplotlib's radius grows a CCW path outwards when positive.
    return Path(poly).contains_points(P, radius=float(tolerance))


def convex_hull_2d(points: ArrayLike) -> NDArray[np.float64]:
    """Counter-clockwise convex hull vertices ``(M, 2)`` of points ``(N, 2)``.

    Raises
    ------
    DegenerateGeometryError
        If fewer than three non-collinear points are given.
    """
    P = as_points(points, 2)
    P = P[np.all(np.isfinite(P), axis=1)]
    if len(P) < 3:
        raise DegenerateGeometryError(f"a hull needs 3 non-collinear points, got {len(P)}")
    try:
        hull = ConvexHull(P)
    except QhullError as exc:
        raise DegenerateGeometryError("points are collinear: the hull has no area") from exc
    return P[hull.vertices]  # SciPy returns 2-D hull vertices counter-clockwise
