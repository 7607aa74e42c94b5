"""The classified mesh as a 2D occupancy grid (obstacles occupied, shadows unknown, ground free)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from navkit.errors import ConfigError
from navkit.geometry._validate import check_grid_size
from navkit.obstacles.rules import GROUND, OBSTACLE, SHADOW_BEHIND, SIDE_SHADOW

__all__ = ["OccupancyMap", "occupancy_grid"]

FREE, UNKNOWN, OCCUPIED = 0, -1, 100


@dataclass(frozen=True)
class OccupancyMap:
    """An occupancy grid in the nav_msgs layout (row 0 = lowest y).

    Attributes
    ----------
    occupancy : (H, W) int8
        -1 unknown, 0 free, 100 occupied.
    resolution : float
        Cell size, metres.
    origin_xy : (2,) float
        Body-frame position of the corner of cell (0, 0), metres.
    """

    occupancy: NDArray[np.int8]
    resolution: float
    origin_xy: NDArray[np.float64]


def occupancy_grid(
    detection: object, resolution: float = 0.1, extent_m: float | None = None
) -> OccupancyMap:
    """Rasterise the classified mesh of a detection into an occupancy grid.

    Every map cell centre is located in the scan grid by its polar coordinates about the sensor:
    its azimuth picks the mesh row, its horizontal range (searched in the row's range made
    monotone) the mesh cell, whose most cautious triangle gives the class - a vectorised lookup,
    no loop over triangles. Obstacle triangles -> occupied (100); shadow triangles (side and behind) -> unknown (-1, what
    the sensor could not see); ground -> free (0); cells no reliable triangle covers -> unknown.
    A cell touched by several classes takes the most cautious one (occupied > unknown > free).

    Parameters
    ----------
    detection : ObstacleDetection
    resolution : float
        Cell size, metres.
    extent_m : float, optional
        Half-width of the square map around the sensor; by default it covers every reliable
        triangle.
    """
    if not (resolution > 0 and math.isfinite(resolution)):
        raise ConfigError(f"= {resolution!r}", field="resolution", expected="metres > 0")
    P = detection.points  # type: ignore[attr-defined]
    lab = detection.triangle_labels  # type: ignore[attr-defined]
    wrap = bool(detection.wrap)  # type: ignore[attr-defined]
    s = detection.sensor_origin  # type: ignore[attr-defined]
    n_az, n_el = P.shape[:2]
    with np.errstate(invalid="ignore"):
        rh = np.hypot(P[..., 0] - s[0], P[..., 1] - s[1])
    if extent_m is None:
        extent_m = float(np.nanmax(rh)) + resolution if np.isfinite(rh).any() else 10.0
    if not (extent_m > 0 and math.isfinite(extent_m)):
        raise ConfigError(f"= {extent_m!r}", field="extent_m", expected="metres > 0")
    check_grid_size((2 * extent_m / resolution,) * 2, setting="resolution / extent_m")
    n = math.ceil(2 * extent_m / resolution)
    origin = np.array([s[0] - extent_m, s[1] - extent_m])
    # rank per mesh cell: the most cautious of its two triangles
    rank_of = np.zeros(256, dtype=np.int8)
    (
        rank_of[GROUND & 0xFF],
        rank_of[SIDE_SHADOW & 0xFF],
        rank_of[SHADOW_BEHIND & 0xFF],
        rank_of[OBSTACLE & 0xFF],
    ) = 1, 2, 2, 3
    tr = rank_of[lab.view(np.uint8)]
    cell_rank = np.maximum(tr[:, 0::2], tr[:, 1::2])  # (R, C)
    R = cell_rank.shape[0]
    # row azimuths (rising) from the points; horizontal range made monotone along each row
    with np.errstate(invalid="ignore"):
        az = np.arctan2(P[..., 1] - s[1], P[..., 0] - s[0])
    row_az = np.full(n_az, np.nan)
    has = np.isfinite(az).any(axis=1)
    if has.any():
        first = np.argmax(np.isfinite(az), axis=1)
        row_az[has] = az[np.flatnonzero(has), first[has]]
    row_az = np.interp(np.arange(n_az), np.flatnonzero(has), row_az[has]) if has.any() else row_az
    row_az = np.unwrap(row_az)
    mono = np.fmax.accumulate(np.nan_to_num(rh, nan=-1.0), axis=1)
    # cell centres in polar form about the sensor
    cx = origin[0] + (np.arange(n) + 0.5) * resolution
    cy = origin[1] + (np.arange(n) + 0.5) * resolution
    X, Y = np.meshgrid(cx, cy)
    a = np.arctan2(Y - s[1], X - s[0]).ravel()
    r = np.hypot(X - s[0], Y - s[1]).ravel()
    # azimuth row: between row i and i + 1 (mod n_az when the grid wraps)
    a0 = row_az[0]
    a_rel = (a - a0) % (2 * np.pi) if wrap else a - a0
    span = row_az - a0
    i = np.searchsorted(span, a_rel, side="right") - 1
    if wrap:
        i = np.where(
            i >= n_az - 1, n_az - 1, i
        )  # the seam cell row n_az - 1 joins the last and first rows
        ok = i >= 0
    else:
        ok = (i >= 0) & (i < n_az - 1)
    i = np.clip(i, 0, R - 1)
    # elevation column along that row: one global searchsorted on rows offset by a large constant
    big = float(np.nanmax(mono)) + 2 * extent_m + 10.0
    keys = (mono[:R] + big * np.arange(R)[:, None]).ravel()
    j = np.searchsorted(keys, r + big * i, side="right") - 1 - i * n_el
    ok &= (j >= 0) & (j < n_el - 1)
    ok &= r <= mono[i, -1]
    j = np.clip(j, 0, n_el - 2)
    rank = np.where(ok, cell_rank[i, j], 0)
    out = np.array([UNKNOWN, FREE, UNKNOWN, OCCUPIED], dtype=np.int8)[rank]
    return OccupancyMap(out.reshape(n, n), float(resolution), origin)
