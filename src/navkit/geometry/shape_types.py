"""The bounding shapes' records (paper 1, stage 8): :class:`Rectangle`, :class:`Circle`,
:class:`Ellipse` and the :class:`Shape` protocol they share; the functions that compute them are
in :mod:`navkit.geometry.shapes`."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.geometry._validate import as_points

__all__ = ["Circle", "Ellipse", "Rectangle", "Shape"]


class Shape(Protocol):
    """What every bounding shape offers."""

    @property
    def area(self) -> float: ...

    def contains(self, points: ArrayLike, tol: float = 1e-9) -> NDArray[np.bool_]: ...

    def outline(self, n: int = 64) -> NDArray[np.float64]: ...

    def params(self) -> dict[str, Any]: ...


@dataclass(frozen=True)
class Rectangle:
    """Axis-aligned rectangle ``[xmin, xmax] x [ymin, ymax]`` (m); the paper's A1."""

    xmin: float
    xmax: float
    ymin: float
    ymax: float
    kind: str = "rectangle"

    @property
    def area(self) -> float:
        """``D_x * D_y`` (m^2)."""
        return (self.xmax - self.xmin) * (self.ymax - self.ymin)

    def contains(self, points: ArrayLike, tol: float = 1e-9) -> NDArray[np.bool_]:
        """``(N,)`` mask of points ``(N, 2)`` inside (within ``tol`` m)."""
        P = as_points(points, 2)
        return (
            (P[:, 0] >= self.xmin - tol)
            & (P[:, 0] <= self.xmax + tol)
            & (P[:, 1] >= self.ymin - tol)
            & (P[:, 1] <= self.ymax + tol)
        )

    def outline(self, n: int = 4) -> NDArray[np.float64]:
        """The four corners ``(4, 2)``, counter-clockwise."""
        return np.array(
            [
                [self.xmin, self.ymin],
                [self.xmax, self.ymin],
                [self.xmax, self.ymax],
                [self.xmin, self.ymax],
            ]
        )

    def params(self) -> dict[str, Any]:
        """``MnX, MxX, MnY, MxY, D_x, D_y`` (m) and the area (m^2)."""
        return {
            "kind": self.kind,
            "MnX": self.xmin,
            "MxX": self.xmax,
            "MnY": self.ymin,
            "MxY": self.ymax,
            "D_x": self.xmax - self.xmin,
            "D_y": self.ymax - self.ymin,
            "area": self.area,
        }


@dataclass(frozen=True)
class Circle:
    """Circle of centre ``(x, y)`` and ``radius`` (m)."""

    x: float
    y: float
    radius: float
    kind: str = "circle"

    @property
    def area(self) -> float:
        """``pi r^2`` (m^2)."""
        return math.pi * self.radius**2

    def contains(self, points: ArrayLike, tol: float = 1e-9) -> NDArray[np.bool_]:
        """``(N,)`` mask of points ``(N, 2)`` inside (within ``tol`` m)."""
        P = as_points(points, 2)
        return np.hypot(P[:, 0] - self.x, P[:, 1] - self.y) <= self.radius + tol

    def outline(self, n: int = 64) -> NDArray[np.float64]:
        """``(n, 2)`` points on the circle, counter-clockwise."""
        t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
        return np.column_stack([self.x + self.radius * np.cos(t), self.y + self.radius * np.sin(t)])

    def params(self) -> dict[str, Any]:
        """Centre, radius (m) and area (m^2)."""
        return {
            "kind": self.kind,
            "x": self.x,
            "y": self.y,
            "radius": self.radius,
            "area": self.area,
        }


@dataclass(frozen=True)
class Ellipse:
    """Ellipse of centre ``(x, y)``, semi-axes ``a >= b >= 0`` (m), major axis at ``angle`` (rad).

    The paper's five numbers are ``x_O, y_O, a, e, angle`` with eccentricity
    ``e = sqrt(1 - b^2 / a^2)``.
    """

    x: float
    y: float
    a: float
    b: float
    angle: float
    kind: str = "ellipse"

    @property
    def area(self) -> float:
        """``pi a b`` (m^2)."""
        return math.pi * self.a * self.b

    @property
    def eccentricity(self) -> float:
        """``e = sqrt(1 - b^2/a^2)``."""
        return math.sqrt(max(0.0, 1.0 - (self.b / self.a) ** 2)) if self.a > 0 else 0.0

    def contains(self, points: ArrayLike, tol: float = 1e-9) -> NDArray[np.bool_]:
        """``(N,)`` mask of points ``(N, 2)`` inside the ellipse grown by ``tol`` m on both axes."""
        P = as_points(points, 2)
        c, s = math.cos(self.angle), math.sin(self.angle)
        dx, dy = P[:, 0] - self.x, P[:, 1] - self.y
        u = c * dx + s * dy
        v = -s * dx + c * dy
        a, b = self.a + tol, self.b + tol
        return (u / a) ** 2 + (v / b) ** 2 <= 1.0 + 1e-12

    def outline(self, n: int = 64) -> NDArray[np.float64]:
        """``(n, 2)`` points on the ellipse, counter-clockwise."""
        t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
        u, v = self.a * np.cos(t), self.b * np.sin(t)
        c, s = math.cos(self.angle), math.sin(self.angle)
        return np.column_stack([self.x + c * u - s * v, self.y + s * u + c * v])

    def params(self) -> dict[str, Any]:
        """Centre, semi-axes (m), eccentricity, major-axis angle (rad) and area (m^2)."""
        return {
            "kind": self.kind,
            "x": self.x,
            "y": self.y,
            "a": self.a,
            "b": self.b,
            "e": self.eccentricity,
            "angle": self.angle,
            "area": self.area,
        }


def _ellipse(x: float, y: float, a: float, b: float, angle: float) -> Ellipse:
    """Normalise so that ``a >= b`` and the angle is in ``(-pi/2, pi/2]``."""
    a, b = abs(a), abs(b)
    if b > a:
        a, b, angle = b, a, angle + math.pi / 2
    angle = (angle + math.pi / 2) % math.pi - math.pi / 2
    return Ellipse(float(x), float(y), float(a), float(b), float(angle))
