"""Wall maps to grids: wall segments sampled as points, and the occupancy raster of a map
(walls, free space swept by the beams, the outline) that the likelihood field is built on."""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError
from navkit.geometry._validate import as_points, check_grid_size
from navkit.localization.walls import (
    WallSegment,
)

log = logging.getLogger(__name__)


def sample_segments(walls: Sequence[WallSegment], spacing: float) -> NDArray[np.float64]:
    """Points ``(K, 2)`` every ``spacing`` metres along the walls (both ends included)."""
    if not walls:
        return np.zeros((0, 2))
    S = np.array([w.start for w in walls])
    E = np.array([w.end for w in walls])
    n = np.maximum(2, np.ceil(np.linalg.norm(E - S, axis=1) / spacing).astype(int) + 1)
    owner = np.repeat(np.arange(len(walls)), n)
    first = np.cumsum(n) - n
    t = (np.arange(n.sum()) - first[owner]) / (n[owner] - 1)
    return S[owner] + t[:, None] * (E - S)[owner]


def rasterize(
    walls: Sequence[WallSegment],
    resolution: float,
    *,
    free_polygon: ArrayLike | None = None,
    rays: tuple[ArrayLike, ArrayLike] | None = None,
    occupied_points: ArrayLike | None = None,
    margin: float = 1.0,
) -> tuple[NDArray[np.int8], NDArray[np.float64]]:
    """Occupancy grid of a wall map.

    Parameters
    ----------
    walls : list of WallSegment
        Occupied cells (sampled at half a cell).
    resolution : float
        Cell size, metres.
    free_polygon : (K, 2) array, optional
        Cells whose centres are inside are free (the room outline).
    rays : ((R, 2) origins, (R, 2) ends), optional
        Cells crossed by these rays (sensor beams) are free.
    occupied_points : (P, 2) array, optional
        Further occupied places (laser end points: clutter that is not a straight wall).
    margin : float
        Metres of border around the walls.

    Returns
    -------
    grid : (H, W) int8
        -1 unknown, 0 free, 100 occupied; row 0 at ``origin[1]`` (min y).
    origin : (2,) array
        World ``(x, y)`` of the lower-left corner of cell ``[0, 0]``.
    """
    if not (np.isfinite(resolution) and resolution > 0):
        raise InputError(f"is {resolution}", field="resolution", expected="positive metres")
    occ = sample_segments(walls, resolution / 2)
    if occupied_points is not None:
        extra = as_points(occupied_points, 2, "occupied_points")
        occ = np.concatenate([occ, extra[np.all(np.isfinite(extra), axis=1)]])
    occ = occ[np.all(np.isfinite(occ), axis=1)]
    extent = [occ] if len(occ) else []
    if rays is not None:
        o, e = as_points(rays[0], 2, "ray origins"), as_points(rays[1], 2, "ray ends")
        if len(o) != len(e):
            raise InputError(
                f"{len(o)} origins for {len(e)} ends", field="rays", expected="one origin per end"
            )
        ok = np.all(np.isfinite(o), axis=1) & np.all(np.isfinite(e), axis=1)
        o, e = o[ok], e[ok]  # beams without a return carry no free space
        extent += [o, e]
    if free_polygon is not None:
        poly = as_points(free_polygon, 2, "free_polygon")
        if not np.isfinite(poly).all():
            raise InputError("has NaN or inf corners", field="free_polygon", expected="finite")
        extent.append(poly)
    extent = [x for x in extent if len(x)]
    if not extent:
        log.warning("rasterize: no wall, no valid beam and no outline: the grid is empty")
        return np.full((1, 1), -1, dtype=np.int8), np.zeros(2)
    if not (np.isfinite(margin) and margin >= 0):
        raise InputError(f"is {margin}", field="margin", expected="metres >= 0")
    allp = np.concatenate(extent)
    lo = np.floor((allp.min(axis=0) - margin) / resolution) * resolution
    hi = allp.max(axis=0) + margin
    size = np.ceil((hi - lo) / resolution) + 1
    check_grid_size((size[1], size[0]), setting="resolution")
    W, H = size.astype(int).tolist()
    grid = np.full((H, W), -1, dtype=np.int8)

    def cells(p: NDArray[np.float64]) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        ij = np.floor((p - lo) / resolution).astype(np.intp)
        ij[:, 0] = np.clip(ij[:, 0], 0, W - 1)
        ij[:, 1] = np.clip(ij[:, 1], 0, H - 1)
        return ij[:, 1], ij[:, 0]

    if free_polygon is not None:
        from navkit.geometry.polygons import points_in_polygon

        yy, xx = np.mgrid[0:H, 0:W]
        centres = np.stack([xx.ravel() + 0.5, yy.ravel() + 0.5], axis=1) * resolution + lo
        inside = points_in_polygon(centres, as_points(free_polygon, 2)).reshape(H, W)
        grid[inside] = 0
    if rays is not None:
        length = np.linalg.norm(e - o, axis=1)
        n = np.maximum(1, np.ceil(length / (resolution / 2)).astype(int))
        chunk = 2_000_000
        start = 0
        cum = np.cumsum(n)
        while start < len(n):
            stop = int(np.searchsorted(cum, (cum[start - 1] if start else 0) + chunk, side="right"))
            stop = max(stop, start + 1)
            nn = n[start:stop]
            owner = np.repeat(np.arange(start, stop), nn)
            first = np.cumsum(nn) - nn
            t = (np.arange(nn.sum()) - first[owner - start]) / nn[owner - start]  # [0, 1)
            r, c = cells(o[owner] + t[:, None] * (e - o)[owner])
            grid[r, c] = 0
            start = stop
    if len(occ):
        r, c = cells(occ)
        grid[r, c] = 100
    return grid, lo


# --------------------------------------------------------------------------- building
