"""Result types of plane extraction: one :class:`PlaneSegment` per planar object.

In-plane coordinates
--------------------
Every segment carries a 2D frame in its plane: origin ``plane.rho * plane.normal`` (the foot of
the perpendicular from the sensor origin) and axes ``plane.basis()`` (``u x v = normal``). Outline
polygons are ``(M, 2)`` arrays in metres in that frame.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from navkit.geometry.fitting import Plane

__all__ = ["ExtractionResult", "PlaneSegment", "outline_from_points", "plane_frame"]

log = logging.getLogger(__name__)


def plane_frame(plane: Plane) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Origin ``(3,)`` and axes ``(2, 3)`` of the plane's own 2D frame (see module docstring)."""
    return plane.rho * plane.normal, plane.basis()


def outline_from_points(
    uv: NDArray[np.float64], cell: float, *, quads: NDArray[np.float64] | None = None
) -> tuple[NDArray[np.float64], float]:
    """Outline polygon and area of planar points (and filled quadrilaterals) in plane coordinates.

    The points are rasterised at ``cell`` metres, the quadrilaterals filled, the raster is closed
    (3 x 3) to bridge sampling gaps, and the largest outer contour is simplified to within one
    cell (Douglas-Peucker).

    Parameters
    ----------
    uv : (N, 2) array
        In-plane coordinates, metres.
    cell : float
        Raster cell size, metres.
    quads : (Q, 4, 2) array, optional
        Quadrilaterals (in-plane coordinates, metres, corners in order) covered entirely: the
        organised extraction passes each patch inside a plane as one quadrilateral instead of its
        pixels. Quadrilaterals that tile a region (shared corners) fill it without gaps.

    Returns
    -------
    outline : (M, 2) array
        Counter-clockwise polygon, metres (empty ``(0, 2)`` if fewer than 3 points).
    area : float
        Area covered by the rasterised points and quadrilaterals (all components), m^2.
    """
    # per-coordinate contiguous rows: reductions over axis 0 of an (N, 2) array are slow
    uT = np.ascontiguousarray(np.asarray(uv, dtype=np.float64).reshape(-1, 2).T)
    fin = np.isfinite(uT[0]) & np.isfinite(uT[1])
    if not fin.all():
        uT = uT[:, fin]
    Q = np.zeros((0, 4, 2)) if quads is None else np.asarray(quads, np.float64).reshape(-1, 4, 2)
    if len(Q):
        Q = Q[np.isfinite(Q).all(axis=(1, 2))]
    if uT.shape[1] + 4 * len(Q) < 3:
        return np.zeros((0, 2)), 0.0
    qT = Q.reshape(-1, 2).T
    parts = [a for a in (uT, qT) if a.shape[1]]  # bounding box of points and corners: (2,)
    lo = np.min([a.min(axis=1) for a in parts], axis=0) - cell
    hi = np.max([a.max(axis=1) for a in parts], axis=0)
    # the raster size in floating point first: a far outlier (a wrong motion merged into a map
    # plane) made the int64 cast overflow to a negative size ("negative dimensions")
    extent = (hi - lo) * (1.0 / cell) + 2.0
    if float(extent[0]) * float(extent[1]) > 4_000_000:  # bounded raster for huge planes
        scale = np.sqrt(float(extent[0]) * float(extent[1]) / 4_000_000) * 1.01
        return outline_from_points(uT.T, cell * scale, quads=Q)
    shape = extent.astype(np.int64)
    grid = np.zeros((int(shape[1]), int(shape[0])), np.uint8)
    ii = ((uT[0] - lo[0]) * (1.0 / cell)).astype(np.int64)  # >= 0: floor == truncation
    jj = ((uT[1] - lo[1]) * (1.0 / cell)).astype(np.int64)
    grid[jj, ii] = 1
    if len(Q):
        # raster cell i spans [lo + i cell, lo + (i + 1) cell): its centre is OpenCV's pixel i;
        # corners in 1/16 pixel (shift = 4)
        q = np.rint(((Q - lo) * (1.0 / cell) - 0.5) * 16.0).astype(np.int32)
        cv2.fillPoly(grid, list(q), 1, cv2.LINE_8, 4)
    return outline_of_raster(grid, lo, cell)


_CLOSE_3X3 = np.ones((3, 3), np.uint8)


def _largest_contour(contours: Sequence[NDArray[Any]]) -> NDArray[Any]:
    """``max(contours, key=cv2.contourArea)`` (the first of equal areas) without the areas of
    the contours of fewer than 3 points (isolated raster cells: area 0), most of a plane's."""
    big = [c for c in contours if len(c) >= 3]
    if not big:
        return contours[0]
    c = max(big, key=cv2.contourArea)
    return c if cv2.contourArea(c) > 0 else contours[0]


def outline_of_raster(
    grid: NDArray[np.uint8], lo: NDArray[np.float64], cell: float
) -> tuple[NDArray[np.float64], float]:
    """The last steps of :func:`outline_from_points` on its raster ``grid (rows, cols)`` (1 =
    covered, row = v, column = u; cell ``(i, j)`` spans ``lo + (j, i) cell`` to ``lo + (j + 1,
    i + 1) cell``): 3 x 3 closing, area, the largest outer contour simplified to one cell,
    counter-clockwise. The organised extraction fills the rasters of all planes in one
    compiled pass and calls this per plane (the same outlines)."""
    grid = np.asarray(cv2.morphologyEx(grid, cv2.MORPH_CLOSE, _CLOSE_3X3), np.uint8)
    return outline_of_closed(grid, float(np.count_nonzero(grid)) * cell * cell, lo, cell)


def outline_of_closed(
    grid: NDArray[np.uint8], area: float, lo: NDArray[np.float64], cell: float
) -> tuple[NDArray[np.float64], float]:
    """:func:`outline_of_raster` after its closing: ``grid`` is the closed raster and
    ``area`` its covered area (m^2). The organised extraction closes the rasters of all planes
    in one compiled pass (``navkit.planes._kernels_outline.close_rasters``, the same cells) and
    calls this per plane."""
    contours, _ = cv2.findContours(grid, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    if not contours:
        return np.zeros((0, 2)), area
    c = cv2.approxPolyDP(_largest_contour(contours), 1.0, True)
    # raster (x, y) = (u, v); OpenCV's oriented area is > 0 for a counter-clockwise polygon in
    # (u, v) (checked against navkit.geometry.polygons.signed_area): the others are reversed
    if len(c) >= 3 and cv2.contourArea(c, oriented=True) < 0:
        c = c[::-1]
    poly = (c.reshape(-1, 2).astype(np.float64) + 0.5) * cell + lo
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
