"""Result types of plane extraction: one :class:`PlaneSegment` per planar object.

In-plane coordinates
--------------------
Every segment carries a 2D frame in its plane: origin ``plane.rho * plane.normal`` (the foot of
the perpendicular from the sensor origin) and axes ``plane.basis()`` (``u x v = normal``). Outline
polygons are ``(M, 2)`` arrays in metres in that frame.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from navkit.geometry import Plane, polygon_area

__all__ = ["ExtractionResult", "PlaneSegment", "outline_from_points", "plane_frame"]

log = logging.getLogger(__name__)


def plane_frame(plane: Plane) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Origin ``(3,)`` and axes ``(2, 3)`` of the plane's own 2D frame (see module docstring)."""
    return plane.rho * plane.normal, plane.basis()


def outline_from_points(uv: NDArray[np.float64], cell: float) -> tuple[NDArray[np.float64], float]:
    """Outline polygon and area of planar points given in plane coordinates.

    The points are rasterised at ``cell`` metres, the raster is closed (3 x 3) to bridge sampling
    gaps, and the largest outer contour is simplified to within one cell (Douglas-Peucker).

    Parameters
    ----------
    uv : (N, 2) array
        In-plane coordinates, metres.
    cell : float
        Raster cell size, metres.

    Returns
    -------
    outline : (M, 2) array
        Counter-clockwise polygon, metres (empty ``(0, 2)`` if fewer than 3 points).
    area : float
        Area covered by the rasterised points (all components), m^2.
    """
    # per-coordinate contiguous rows: reductions over axis 0 of an (N, 2) array are slow
    uT = np.ascontiguousarray(np.asarray(uv, dtype=np.float64).T)
    fin = np.isfinite(uT[0]) & np.isfinite(uT[1])
    if not fin.all():
        uT = uT[:, fin]
    if uT.shape[1] < 3:
        return np.zeros((0, 2)), 0.0
    lo = np.array([uT[0].min(), uT[1].min()]) - cell
    ii = ((uT[0] - lo[0]) * (1.0 / cell)).astype(np.int64)  # >= 0: floor == truncation
    jj = ((uT[1] - lo[1]) * (1.0 / cell)).astype(np.int64)
    shape = np.array([ii.max(), jj.max()]) + 2
    if shape[0] * shape[1] > 4_000_000:  # keep the raster bounded for huge, sparse planes
        scale = np.sqrt(shape[0] * shape[1] / 4_000_000)
        return outline_from_points(uT.T, cell * scale)
    grid = np.zeros((int(shape[1]), int(shape[0])), np.uint8)
    grid[jj, ii] = 1
    grid = np.asarray(cv2.morphologyEx(grid, cv2.MORPH_CLOSE, np.ones((3, 3), np.uint8)), np.uint8)
    area = float(grid.sum()) * cell * cell
    contours, _ = cv2.findContours(grid, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    if not contours:
        return np.zeros((0, 2)), area
    c = max(contours, key=cv2.contourArea)
    c = cv2.approxPolyDP(c, 1.0, True).reshape(-1, 2).astype(np.float64)
    poly = (c + 0.5) * cell + lo
    if len(poly) >= 3 and polygon_area(poly) > 0:
        from navkit.geometry import ensure_ccw

        poly = ensure_ccw(poly)
    return poly, area


@dataclass(frozen=True)
class PlaneSegment:
    """One planar object found in a range image or a cloud.

    Attributes
    ----------
    plane : Plane
        ``normal . x = rho`` in the sensor frame (``rho >= 0``), its TLS fit over the inliers
        (``plane.rms`` = RMS orthogonal residual, metres; ``plane.count`` = inliers).
    inliers : (K,) int array
        Indices of the inlier points into the flattened input (``row * width + col`` for an
        organised input).
    outline : (M, 2) array
        Outline polygon in the plane's 2D frame (:func:`plane_frame`), metres, counter-clockwise.
    area : float
        Area covered by the inliers, m^2.
    """

    plane: Plane
    inliers: NDArray[np.int64]
    outline: NDArray[np.float64]
    area: float

    @property
    def normal(self) -> NDArray[np.float64]:
        return self.plane.normal

    @property
    def rho(self) -> float:
        return self.plane.rho

    @property
    def rms(self) -> float:
        return self.plane.rms

    def outline_3d(self) -> NDArray[np.float64]:
        """The outline polygon as ``(M, 3)`` points in the sensor frame."""
        origin, axes = plane_frame(self.plane)
        return origin + self.outline @ axes


@dataclass(frozen=True)
class ExtractionResult:
    """Planes of one input.

    Attributes
    ----------
    segments : tuple of PlaneSegment
        Sorted by decreasing inlier count.
    labels : array of int
        Segment index per input point (``(H, W)`` for an organised input, ``(N,)`` otherwise),
        ``-1`` where no plane.
    """

    segments: tuple[PlaneSegment, ...]
    labels: NDArray[np.int64]

    def __len__(self) -> int:
        return len(self.segments)

    @property
    def planes(self) -> list[Plane]:
        return [s.plane for s in self.segments]
