"""Plane and line fitting, distances and intersections.

Conventions
-----------
Planes are ``n . x = rho`` with ``n`` a unit normal and ``rho >= 0`` the distance of the plane from
the origin (paper 2's ``X cos a + Y cos b + Z cos g = rho``). For a plane through the origin
(``rho == 0``) the normal is chosen with its first non-zero component positive, so the
representation is unique. 2D lines use the same form ``n . p = rho`` in the plane.

Fits are total least squares (the smallest singular vector of the centred points), optionally
weighted. ``rms`` is the root-mean-square orthogonal residual.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import DegenerateGeometryError, InputError
from navkit.geometry._validate import as_points
from navkit.geometry.linalg import cross3

__all__ = [
    "Line2D",
    "Plane",
    "canonical_plane",
    "fit_line_2d",
    "fit_plane",
    "intersect_lines_2d",
    "intersect_planes",
    "line_from_points_2d",
    "plane_from_points",
]


@dataclass(frozen=True)
class Plane:
    """A plane ``normal . x = rho`` (``rho >= 0``) with fit statistics.

    Attributes
    ----------
    normal : (3,) array
        Unit normal.
    rho : float
        Distance from the origin, metres, ``>= 0``.
    centroid : (3,) array
        Mean of the fitted points (a point on the plane).
    rms : float
        RMS orthogonal residual of the fit, metres (0 for an exact plane).
    count : int
        Number of points fitted.
    """

    normal: NDArray[np.float64]
    rho: float
    centroid: NDArray[np.float64]
    rms: float = 0.0
    count: int = 0

    def distance(self, points: ArrayLike) -> NDArray[np.float64]:
        """Signed distances ``n . x - rho`` of points ``(N, 3)``."""
        return as_points(points, 3) @ self.normal - self.rho

    def project(self, points: ArrayLike) -> NDArray[np.float64]:
        """Orthogonal projections of points ``(N, 3)`` onto the plane."""
        P = as_points(points, 3)
        return P - np.outer(P @ self.normal - self.rho, self.normal)

    def basis(self) -> NDArray[np.float64]:
        """``(2, 3)`` orthonormal in-plane axes ``(u, v)`` with ``u x v = normal``.

        ``u`` is the direction of the world x axis (or y, when x is nearly normal) projected onto
        the plane, so the in-plane frame is reproducible for the same plane.
        """
        n = self.normal
        ref = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        u = ref - (ref @ n) * n
        u /= np.linalg.norm(u)
        return np.stack([u, cross3(n, u)])


@dataclass(frozen=True)
class Line2D:
    """A 2D line ``normal . p = rho`` (``rho >= 0``) with fit statistics.

    ``direction`` is ``normal`` turned by +90 degrees; ``centroid`` is the mean of the points.
    """

    normal: NDArray[np.float64]
    rho: float
    centroid: NDArray[np.float64]
    rms: float = 0.0
    count: int = 0

    @property
    def direction(self) -> NDArray[np.float64]:
        return np.array([-self.normal[1], self.normal[0]])

    @property
    def angle(self) -> float:
        """Angle of the direction from +x, radians, in ``[-pi/2, pi/2)`` (a line has no sense)."""
        d = self.direction
        a = float(np.arctan2(d[1], d[0]))
        return (a + np.pi / 2) % np.pi - np.pi / 2

    def distance(self, points: ArrayLike) -> NDArray[np.float64]:
        """Signed distances of points ``(N, 2)``."""
        return as_points(points, 2) @ self.normal - self.rho

    def project(self, points: ArrayLike) -> NDArray[np.float64]:
        """Abscissae of the points' projections along ``direction``, measured from ``centroid``."""
        return (as_points(points, 2) - self.centroid) @ self.direction


def canonical_plane(normal: ArrayLike, rho: float) -> tuple[NDArray[np.float64], float]:
    """Normalise ``(normal, rho)`` to a unit normal and ``rho >= 0`` (see module conventions)."""
    n = np.asarray(normal, dtype=np.float64)
    if n.shape != (3,):
        raise DegenerateGeometryError(f"plane normal must have 3 components, got shape {n.shape}")
    # The norm as three products and two sums, left to right: IEEE-exact operations, so every CPU
    # and the vectorised form (``planes.extract._canonical_planes``) give the same bits; a BLAS
    # dot product (``numpy.linalg.norm``) may fuse multiply-adds on some CPUs and not on others.
    n0, n1, n2 = float(n[0]), float(n[1]), float(n[2])
    norm = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    if not math.isfinite(norm) or norm == 0:
        raise DegenerateGeometryError("plane normal has zero length")
    return _orient(n / norm, float(rho) / float(norm))


_ZERO_RHO = 1e-12
"""Distances below this (metres) count as zero: the plane/line passes through the origin."""


def _orient(n: NDArray[np.float64], rho: float) -> tuple[NDArray[np.float64], float]:
    """Flip ``(n, rho)`` so that ``rho >= 0``; through the origin, the first non-zero ``n_i > 0``."""
    if abs(rho) <= _ZERO_RHO:
        rho = 0.0
        if n[np.flatnonzero(np.abs(n) > 1e-12)[0]] < 0:
            n = -n
    elif rho < 0:
        n, rho = -n, -rho
    return n, rho


def _tls(
    points: NDArray[np.float64], weights: ArrayLike | None
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Weighted centroid, singular values and right singular vectors of the centred points."""
    if weights is None:
        w = np.ones(len(points))
    else:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (len(points),) or np.any(w < 0) or not np.any(w > 0):
            raise InputError(
                "weights must be non-negative, one per point, not all zero",
                field="weights",
                expected=f"({len(points)},) array",
            )
    finite = np.all(np.isfinite(points), axis=1) & (w > 0)
    P, w = points[finite], w[finite]
    if len(P) == 0:
        raise DegenerateGeometryError("no finite points to fit")
    c = (w[:, None] * P).sum(0) / w.sum()
    _, s, Vt = np.linalg.svd(np.sqrt(w)[:, None] * (P - c), full_matrices=False)
    return c, s / np.sqrt(w.sum()), Vt


def fit_plane(points: ArrayLike, weights: ArrayLike | None = None) -> Plane:
    """Total-least-squares plane through points ``(N, 3)``, ``N >= 3`` (NaN rows ignored).

    Raises
    ------
    DegenerateGeometryError
        If the points are (nearly) collinear, so no unique plane exists.
    """
    P = as_points(points, 3, min_count=3)
    c, s, Vt = _tls(P, weights)
    if s.shape[0] < 3 or s[1] <= 1e-9 * max(s[0], 1e-300):
        raise DegenerateGeometryError("points are collinear: no unique plane")
    n, rho = canonical_plane(Vt[2], float(Vt[2] @ c))
    return Plane(
        normal=n, rho=rho, centroid=c, rms=float(s[2]), count=int(np.isfinite(P).all(1).sum())
    )


def plane_from_points(p0: ArrayLike, p1: ArrayLike, p2: ArrayLike) -> Plane:
    """The plane through three points."""
    return fit_plane(np.stack([np.asarray(p, dtype=np.float64) for p in (p0, p1, p2)]))


def fit_line_2d(points: ArrayLike, weights: ArrayLike | None = None) -> Line2D:
    """Total-least-squares line through points ``(N, 2)``, ``N >= 2`` (works for vertical lines,
    unlike ``y = k x + b`` of paper 3)."""
    P = as_points(points, 2, min_count=2)
    c, s, Vt = _tls(P, weights)
    if s[0] <= 1e-12:
        raise DegenerateGeometryError("all points coincide: no unique line")
    n, rho = _canonical_line(Vt[-1], float(Vt[-1] @ c))
    return Line2D(
        normal=n,
        rho=rho,
        centroid=c,
        rms=float(s[-1]) if len(s) > 1 else 0.0,
        count=int(np.isfinite(P).all(1).sum()),
    )


def line_from_points_2d(p0: ArrayLike, p1: ArrayLike) -> Line2D:
    """The line through two distinct points."""
    return fit_line_2d(np.stack([np.asarray(p0, float), np.asarray(p1, float)]))


def _canonical_line(normal: NDArray[np.float64], rho: float) -> tuple[NDArray[np.float64], float]:
    norm = float(np.linalg.norm(normal))
    return _orient(normal / norm, rho / norm)


def intersect_lines_2d(a: Line2D, b: Line2D, min_angle: float = 1e-6) -> NDArray[np.float64]:
    """Intersection point ``(2,)`` of two lines; raises if they are parallel within ``min_angle`` rad."""
    A = np.stack([a.normal, b.normal])
    if abs(np.linalg.det(A)) < np.sin(min_angle):
        raise DegenerateGeometryError("lines are parallel: no unique intersection")
    return np.linalg.solve(A, np.array([a.rho, b.rho]))


def intersect_planes(
    *planes: Plane, min_angle: float = 1e-6
) -> NDArray[np.float64] | tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Intersection of two planes (a line: ``(point (3,), unit direction (3,))``, the point nearest
    the origin) or of three planes (a point ``(3,)``).

    Raises
    ------
    DegenerateGeometryError
        If the normals are (nearly) parallel / coplanar, so the intersection is not unique.
    """
    if len(planes) == 3:
        N = np.stack([p.normal for p in planes])
        if abs(np.linalg.det(N)) < np.sin(min_angle):
            raise DegenerateGeometryError("plane normals are coplanar: no unique point")
        return np.linalg.solve(N, np.array([p.rho for p in planes]))
    if len(planes) == 2:
        a, b = planes
        d = np.cross(a.normal, b.normal)
        s = np.linalg.norm(d)
        if s < np.sin(min_angle):
            raise DegenerateGeometryError("planes are parallel: no intersection line")
        d /= s
        # The point on both planes nearest the origin: minimum-norm solution of the 2x3 system.
        N = np.stack([a.normal, b.normal])
        point = np.linalg.lstsq(N, np.array([a.rho, b.rho]), rcond=None)[0]
        return point, d
    raise InputError(f"got {len(planes)} planes", field="planes", expected="2 or 3 planes")
