"""Per-point refinement by height above the local ground (beyond the paper, optional).

Paper 1 labels triangles; a point's class follows from its triangles. Points at the ground's
level next to an obstacle (the foot of a curb, the ground under a car's bumper, isolated returns
between missing ones) then inherit "obstacle" or "unreliable", and points high on a wall seen at
a grazing angle can inherit "ground". A robot's planner, and the per-point ground benchmarks,
want the height above the ground instead. This step estimates the ground height on a coarse
horizontal grid from the points of the main ground zones (the ground connected on the mesh to
the ground around the robot; a low quantile per cell, holes filled from the nearest cell) and
re-labels per point: within ``band_m`` of the local ground -> ground; labelled ground but more
than ``above_m`` above it -> obstacle (an elevated flat surface the rules call ground because
no steep face led to it along the ray). Triangle classes, obstacles and shapes are not
changed.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from navkit.geometry._validate import check_grid_size
from navkit.obstacles.rules import GROUND, OBSTACLE

__all__ = ["fill_missing_cells", "ground_height_map", "refine_by_ground_height"]


def ground_height_map(
    points: NDArray[np.floating[Any]],
    is_ground: NDArray[np.bool_],
    cell_m: float = 2.0,
    quantile: float = 0.25,
    envelope: int = 0,
) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Ground height per horizontal cell: the ``quantile`` of the ground points' z in each cell.

    Returns ``(heights (nx, ny) indexed [x, y], origin_xy (2,), cell_m)``; cells without ground points take the
    value of the nearest cell that has some (Euclidean distance transform).
    """
    # one coordinate at a time: reductions along the short axis of (N, 3) rows are slow
    sel = np.flatnonzero(is_ground)
    gx, gy, z = (points[sel, k] for k in range(3))
    fin = np.isfinite(gx + gy + z)  # the sum is finite only when all three are
    if not fin.all():
        gx, gy, z = gx[fin], gy[fin], z[fin]
    if len(z) == 0:
        return np.zeros((1, 1)), np.zeros(2), cell_m
    lo = np.array([gx.min(), gy.min()])
    # the grid's size before any index is computed: huge extents are refused, not allocated
    check_grid_size(
        (
            math.floor((gx.max() - lo[0]) / cell_m) + 1.0,
            math.floor((gy.max() - lo[1]) / cell_m) + 1.0,
        ),
        setting="ground_cell_m",
        source="ground height map",
    )
    ix = np.floor((gx - lo[0]) / cell_m).astype(np.int64)
    iy = np.floor((gy - lo[1]) / cell_m).astype(np.int64)
    nx, ny = int(ix.max()) + 1, int(iy.max()) + 1
    cell = ix * ny + iy  # flat index of the (x, y) cell
    zr = float(z.max() - z.min()) + 1.0
    order = np.argsort(cell + (z - z.min()) / (1.01 * zr))  # by cell, then by height
    cs = cell[order]
    counts = np.bincount(cs, minlength=nx * ny)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    has = counts > 0
    pick = starts[has] + np.floor(quantile * (counts[has] - 1)).astype(np.int64)
    heights = np.full(nx * ny, np.nan)
    heights[np.flatnonzero(has)] = z[order[pick]]
    grid = fill_missing_cells(heights.reshape(nx, ny))  # [x index, y index]
    if envelope > 0:
        # a lower envelope over neighbouring cells: an elevated flat surface that the rules
        # call ground (a terrace, a low wall's top) does not lift the ground estimate
        grid = ndimage.minimum_filter(grid, size=2 * envelope + 1, mode="nearest")
    return grid, lo, cell_m


def fill_missing_cells(grid: NDArray[np.float64]) -> NDArray[np.float64]:
    """Cells without a height (NaN) take the value of the nearest cell that has one (Euclidean
    distance transform)."""
    missing = ~np.isfinite(grid)
    if missing.any():
        _, (ix, iy) = ndimage.distance_transform_edt(missing, return_indices=True)
        grid = grid[ix, iy]
    return grid


def refine_by_ground_height(
    points: NDArray[np.floating[Any]],
    labels: NDArray[np.int8],
    valid: NDArray[np.bool_],
    *,
    band_m: float,
    above_m: float,
    cell_m: float = 2.0,
    envelope: int = 0,
    reference: NDArray[np.bool_] | None = None,
) -> NDArray[np.int8]:
    """Per-vertex classes re-labelled by height above the local ground (see the module doc).

    Parameters
    ----------
    points : (n_az, n_el, 3) body-frame points
    labels : (n_az, n_el) int8 classes of the vertices
    valid : (n_az, n_el) bool
    band_m : points within this height of the local ground become ground
    above_m : ground points higher than this above the lower envelope of the local ground (the
        minimum over ``2 envelope + 1`` cells) become obstacle
    reference : (n_az, n_el) bool, optional
        The points that define the ground height (default: every ground point). The detector
        passes the ground connected on the mesh to the main ground zones, so that an elevated
        flat surface the rules call ground (a terrace, a low wall's top, cut off from the ground
        around the robot by its steep sides) does not define the ground height.
    """
    ref = (labels == GROUND) if reference is None else reference
    grid, lo, cell = ground_height_map(points.reshape(-1, 3), ref.reshape(-1), cell_m)
    P = points.reshape(-1, 3)
    ok = np.flatnonzero(valid.reshape(-1))
    px, py, pz = (P[ok, k] for k in range(3))
    # clipped as floats, then converted: a far point's cell index may not fit an integer
    ix = np.clip(np.floor((px - lo[0]) / cell), 0, grid.shape[0] - 1).astype(np.int64)
    iy = np.clip(np.floor((py - lo[1]) / cell), 0, grid.shape[1] - 1).astype(np.int64)
    flat = ix * grid.shape[1] + iy
    h = pz - grid.ravel()[flat]
    low = (
        ndimage.minimum_filter(grid, size=2 * envelope + 1, mode="nearest")
        if envelope > 0
        else grid
    )
    h_low = h if envelope <= 0 else pz - low.ravel()[flat]
    out = labels.reshape(-1).copy()
    sub = out[ok]
    sub[np.abs(h) <= band_m] = GROUND
    sub[(sub == GROUND) & (h_low > above_m)] = OBSTACLE
    out[ok] = sub
    return out.reshape(labels.shape)
