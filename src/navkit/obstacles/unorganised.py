"""Paper 1's rules on clouds without a scan structure: a 2.5-D triangulation instead of the grid.

Merged maps, airborne and drone lidar, solid-state lidars with non-repetitive patterns and fused
depth clouds have no rings, so the paper's mesh over the ``(alpha_i, beta_j)`` grid (stage 2)
cannot be built. This module builds the mesh the data allow and runs the paper's stages 3-8 on it:

1. **Recognise the input** (:func:`recognise_cloud`): a cloud whose rings can be recovered goes to
   the scan path (:func:`~navkit.obstacles.grids.cloud_to_grid`); a cloud without them to this one.
2. **The mesh**: a Delaunay triangulation in x-y (``scipy.spatial.Delaunay``) over the cloud
   thinned to its lowest point per cell, the cell being the data's median nearest-neighbour
   spacing (:func:`point_spacing`). Large clouds run in overlapping square tiles
   (:attr:`UnorganisedSettings.tile_m`): the triangulation and every per-triangle array are
   bounded by one tile.
3. **A ground surface estimate** (:func:`ground_surface`). A scan sees the ground around the
   sensor from above it; the paper's zones and its rule P5 use the line of sight to tell the top
   of an obstacle from the ground behind it. A 2.5-D cloud has no line of sight to the sensor, and
   an airborne cloud has roofs larger than the distance between two jumps. The ground is
   estimated from the data: the lowest point per cell (a minimum surface), a progressive opening
   with growing disc windows marks the cells that rise above their surroundings faster than the
   terrain slope allows (objects narrower than the window), and a TIN through the lowest point
   of each remaining cell is the ground surface; components of that TIN bounded by height jumps
   that all step down out of them (a roof wider than the widest window, a tree) are removed by
   the paper's jump rule.
4. **The rules on the mesh** (:func:`classify_triangles`, stages 3-5): per triangle the normal
   (stage 3), its tilt, the height-jump code and the vertices' height over the ground estimate
   (stage 4); the classes (stage 5) with the line of sight taken as the vertical (the view of a
   2.5-D surface): a triangle across a jump has a horizontal ray, so zones I/II never hold and a
   jump triangle is a side shadow (-3); ``P1`` (tilt over ``c1``) or ``P5`` (all three vertices
   above the ground band: the top of an obstacle) make an obstacle (-2); the rest is ground (0);
   triangles with an edge longer than the gap limit (a hole in the data) are unreliable (-1).
5. **Stages 6-8 as in the paper**: connected obstacle triangles form one obstacle, shadow
   triangles go to the obstacle they touch, boundary vertices are those with both obstacle and
   other triangles around them, and the bounding shapes A1-A6 (and A7 over obstacle plus shadow)
   come from :mod:`navkit.geometry.shapes`, every obstacle's vertex sets at once (compiled hulls
   and shapes as on the scan path, or the NumPy twin: the same shapes).

Per-point labels (for scoring against a reference): a point is ground (0) when its height over the
ground surface is within the ground band, else obstacle (-2). The thresholds are in the data's
units, derived from its spacing and its measured height noise (:class:`UnorganisedSettings`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import Delaunay, QhullError, cKDTree

from navkit.errors import InputError
from navkit.geometry.shape_types import Circle, Ellipse, Rectangle
from navkit.obstacles.detector import Obstacle, obstacle_records
from navkit.obstacles.rules import GROUND, OBSTACLE, SIDE_SHADOW, UNRELIABLE
from navkit.obstacles.unorganised_ground import (
    GroundSurface,
    ground_surface,
    height_noise,
    lowest_per_cell,
    point_spacing,
)
from navkit.obstacles.unorganised_settings import UnorganisedSettings

__all__ = [
    "CloudKind",
    "FilterScores",
    "GroundSurface",
    "UnorganisedDetection",
    "UnorganisedSettings",
    "classify_triangles",
    "detect_unorganised",
    "filter_scores",
    "ground_surface",
    "height_noise",
    "lowest_per_cell",
    "point_spacing",
    "recognise_cloud",
    "reference_ground",
]


# ----------------------------------------------------------------------------------------------
# input recognition


@dataclass(frozen=True)
class CloudKind:
    """Which path a cloud takes, and why.

    Attributes
    ----------
    path : str
        ``"scan"`` (rings recoverable: the paper's scan mesh) or ``"unorganised"``.
    reason : str
        One sentence for the run summary.
    """

    path: str
    reason: str


def _finite_points(points: ArrayLike, source: str) -> NDArray[np.float64]:
    try:
        P = np.asarray(points)
    except (TypeError, ValueError) as exc:  # pragma: no cover - numpy rarely refuses
        raise InputError(
            f"is not numeric: {exc}", source=source, field="points", expected="(N, 3) floats"
        ) from exc
    if P.dtype.kind not in "fiu" or P.ndim != 2 or P.shape[1] < 3:
        raise InputError(
            f"has shape {P.shape} and dtype {P.dtype}",
            source=source,
            field="points",
            expected="an (N, >=3) float array",
        )
    Q = np.asarray(P[:, :3], dtype=np.float64)
    ok = np.isfinite(Q).all(axis=1) & (Q != 0).any(axis=1)
    return Q[ok]


def recognise_cloud(points: ArrayLike, *, source: str = "points") -> CloudKind:
    """Decide whether a point-by-point cloud is a scan (rings recoverable) or unorganised.

    A scan is stored in the sensor's frame: the sensor (the origin) lies among its points, and
    either the storage order sweeps the azimuth ring after ring, or the elevation angles seen
    from the origin fall into separate beams (a few to 512 clusters holding nearly every point).
    A cloud with neither is unorganised when it spans an area (a 2.5-D surface can be
    triangulated in x-y); one that does neither is refused.

    Raises
    ------
    InputError
        Fewer than 3 valid points, or points that do not span an area in x-y (all on one
        vertical line or one vertical plane): neither path can mesh them.
    """
    from navkit.obstacles.grids import _rings_by_elevation, _rings_by_order

    Q = _finite_points(points, source)
    if len(Q) < 3:
        raise InputError(
            f"has {len(Q)} valid points",
            source=source,
            field="points",
            expected="at least 3 points that are not NaN or (0, 0, 0)",
        )
    lo, hi = Q[:, :2].min(axis=0), Q[:, :2].max(axis=0)
    span = hi - lo
    origin_inside = bool(np.all(lo <= 0.0) and np.all(hi >= 0.0))
    if origin_inside:
        az = np.arctan2(Q[:, 1], Q[:, 0])
        if _rings_by_order(az) is not None:
            return CloudKind("scan", "the storage order sweeps the azimuth ring after ring")
        rh = np.hypot(Q[:, 0], Q[:, 1])
        with np.errstate(invalid="ignore", divide="ignore"):
            el = np.arctan2(Q[:, 2], rh)
            ring = _rings_by_elevation(el, None)
        kept = ring >= 0
        n_rings = int(ring[kept].max()) + 1 if kept.any() else 0
        if 2 <= n_rings <= 512 and kept.mean() >= 0.9 and len(Q) >= 64 * n_rings:
            # beams: each ring thin in elevation beside the gaps between rings
            r, e = ring[kept], el[kept]
            cnt = np.maximum(np.bincount(r, minlength=n_rings), 1)
            mean = np.bincount(r, weights=e, minlength=n_rings) / cnt
            spread = np.sqrt(np.bincount(r, weights=(e - mean[r]) ** 2, minlength=n_rings) / cnt)
            gap = float(np.median(np.diff(np.sort(mean))))
            beams = float(np.median(spread)) < 0.25 * gap
        else:
            beams = False
        if beams:
            return CloudKind(
                "scan", f"the elevation angles from the sensor fall into {n_rings} beams"
            )
    # 2.5-D: the points must span an area in x-y (the triangulation needs it)
    xy = Q[:, :2] - Q[:, :2].mean(axis=0)
    sv = np.linalg.svd(xy[:: max(1, len(xy) // 100_000)], compute_uv=False)
    extent = float(max(span.max(), np.ptp(Q[:, 2]), 1e-12))
    if sv.size < 2 or sv[1] <= 1e-9 * extent * math.sqrt(len(xy)):
        raise InputError(
            "the points do not span an area in x-y (a vertical line or plane): they are not a "
            "scan with recoverable rings and cannot be triangulated as a 2.5-D surface",
            source=source,
            field="points",
            expected="a lidar scan in its sensor frame, or a cloud covering an area seen from "
            "above (an airborne, merged or accumulated cloud, z up)",
        )
    why = (
        "no ring structure: the sensor's origin is not among the points"
        if not origin_inside
        else "no ring structure: neither the storage order nor the elevation angles give beams"
    )
    return CloudKind("unorganised", why)


# ----------------------------------------------------------------------------------------------
# spacing, noise, thinning


def classify_triangles(
    vxy: NDArray[np.float64],
    vz: NDArray[np.float64],
    simplices: NDArray[np.int64],
    height: NDArray[np.float64],
    band: NDArray[np.float64],
    settings: UnorganisedSettings,
    spacing: float,
) -> tuple[NDArray[np.int8], NDArray[np.float64], NDArray[np.bool_], dict[str, NDArray[np.bool_]]]:
    """Stages 3-5 on a 2.5-D mesh: normals, H_s and the classes.

    Parameters
    ----------
    vxy, vz : mesh vertices.
    simplices : (T, 3) vertex indices of the triangles.
    height : (V,) vertex height over the ground surface.
    band : (V,) the ground band at each vertex (slope-grown).

    Rules (the line of sight is the vertical; see the module docstring):

    - P1: the normal is tilted from the vertical by more than ``c1``.
    - P2 / P3: never (the horizontal projection of a vertical ray is zero: zone III).
    - P4: no height jump: the triangle's vertical extent is at most
      ``band + tan(c0) * horizontal extent``.
    - P5: all three vertices are above the ground band (the top of an obstacle reached across
      its steep faces; on a scan the chain along the ray carries this).

    Productions in the paper's order: ``~(P2 | P3) & ~P4 -> -3`` (side shadow),
    ``P1 | P5 -> -2`` with P1 counted only off the ground (at least one vertex above the band:
    a hillside steeper than ``c1`` whose vertices lie on the ground surface is ground),
    else ``0``; triangles with an edge longer than ``gap_spacings * spacing`` ``-1``.

    Returns ``labels (T,) int8``, ``normals (T, 3)``, ``jump (T,) bool`` and the rules.
    """
    P = np.column_stack([vxy, vz])[simplices]  # (T, 3, 3)
    n = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = n / norm
    n *= np.where(n[:, 2:3] < 0, -1.0, 1.0)  # normals into the upper half-space
    exy = P[:, [1, 2, 0], :2] - P[:, :, :2]
    edge = np.linalg.norm(exy, axis=2)
    reliable = (edge.max(axis=1) <= settings.gap_spacings * spacing) & (norm[:, 0] > 0)
    zext = P[:, :, 2].max(axis=1) - P[:, :, 2].min(axis=1)
    bnd = band[simplices].min(axis=1)
    jump = zext > bnd + math.tan(math.radians(settings.c0_deg)) * edge.max(axis=1)
    above = height[simplices] > band[simplices]
    with np.errstate(invalid="ignore"):
        p1 = n[:, 2] < math.cos(settings.c1_rad)
    p5 = above.all(axis=1)
    p4 = ~jump
    side = reliable & jump
    obstacle = reliable & ~side & ((p1 & above.any(axis=1)) | p5)
    labels = np.full(len(simplices), UNRELIABLE, dtype=np.int8)
    labels[reliable] = GROUND
    labels[obstacle] = OBSTACLE
    labels[side] = SIDE_SHADOW
    none = np.zeros(len(simplices), dtype=bool)
    return labels, n, jump, {"P1": p1, "P2": none, "P3": none, "P4": p4, "P5": p5}


# ----------------------------------------------------------------------------------------------
# stages 6-8


def _triangle_components(
    neighbors: NDArray[np.int64], mask: NDArray[np.bool_]
) -> tuple[NDArray[np.int32], int]:
    """Connected components (1-based, 0 = not in ``mask``) of the masked triangles, adjacency
    across shared edges."""
    T = len(mask)
    a = np.repeat(np.arange(T), 3)
    b = neighbors.reshape(-1)
    ok = (b >= 0) & mask[a] & mask[np.maximum(b, 0)]
    g = coo_matrix((np.ones(int(ok.sum())), (a[ok], b[ok])), shape=(T, T))
    _, lab = connected_components(g, directed=False)
    sel = np.flatnonzero(mask)
    comp = np.zeros(T, dtype=np.int32)
    if sel.size == 0:
        return comp, 0
    _, inv = np.unique(lab[sel], return_inverse=True)
    comp[sel] = inv.astype(np.int32) + 1
    return comp, int(inv.max()) + 1


def _assign_shadows(
    neighbors: NDArray[np.int64], comp: NDArray[np.int32], shadow: NDArray[np.bool_]
) -> NDArray[np.int32]:
    """Stage 6: each shadow triangle goes to the obstacle it touches (across an edge, through
    other shadow triangles; the smallest id when it touches several)."""
    out = comp.copy()
    big = np.iinfo(np.int32).max
    todo = np.flatnonzero(shadow & (out == 0))  # the rounds work on the pending triangles only
    for _ in range(64):
        if todo.size == 0:
            break
        nbr = neighbors[todo]
        nb = np.where(nbr >= 0, out[np.maximum(nbr, 0)], 0)
        nb = np.where(nb > 0, nb, big).min(axis=1)
        take = nb < big
        if not take.any():
            break
        out[todo[take]] = nb[take]
        todo = todo[~take]
    return out


@dataclass(frozen=True)
class UnorganisedDetection:
    """Everything the unorganised path produces for one cloud.

    Attributes
    ----------
    point_labels : (N,) int8
        Per input point: 0 ground, -2 obstacle (above the ground band, or a low outlier),
        -1 for NaN / (0, 0, 0) points.
    point_obstacle : (N,) int32
        Obstacle id of each point (0 = none): the id of its nearest mesh vertex when the point
        is not ground (the id of its record in ``obstacles``; without ``build_map``, ids unique
        over the tiles and no records).
    ground_z : (N,) float
        Height of the ground surface under each point (NaN for invalid points).
    obstacles : tuple of Obstacle
        Stage 8 records (coordinates in the input's frame).
    counts : dict
        Triangles per class over all tiles.
    spacing_m, noise_m, band_m : float
        The measured point spacing, height noise and the ground band used (first tile's noise
        and band when there are several; per-tile values in ``tiles``).
    tiles : list of dict
        Per tile: its square, points, spacing, noise, band, mesh size.
    timings : dict
        Wall-clock seconds per stage.
    sensor_origin : None
        No sensor position is known for an unorganised cloud.
    """

    point_labels: NDArray[np.int8]
    point_obstacle: NDArray[np.int32]
    ground_z: NDArray[np.float64]
    obstacles: tuple[Obstacle, ...]
    counts: dict[str, int]
    spacing_m: float
    noise_m: float
    band_m: float
    tiles: list[dict[str, Any]] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    sensor_origin: None = None

    @property
    def ground(self) -> NDArray[np.bool_]:
        """Per-point ground flag."""
        return self.point_labels == GROUND


def _tile_origins(lo: NDArray[np.float64], hi: NDArray[np.float64], tile: float) -> list[Any]:
    nx = max(1, math.ceil((hi[0] - lo[0]) / tile))
    ny = max(1, math.ceil((hi[1] - lo[1]) / tile))
    # equal tiles covering the extent (no thin last tile)
    tx, ty = (hi[0] - lo[0]) / nx, (hi[1] - lo[1]) / ny
    return [(lo[0] + a * tx, lo[1] + b * ty, tx, ty) for a in range(nx) for b in range(ny)]


def detect_unorganised(
    points: ArrayLike,
    settings: UnorganisedSettings | None = None,
    *,
    source: str = "points",
    ground_only: bool = False,
) -> UnorganisedDetection:
    """Paper 1's stages 3-8 on a cloud without rings (see the module docstring).

    Parameters
    ----------
    points : (N, >=3) float
        x, y, z with z up (extra columns ignored). NaN and ``(0, 0, 0)`` points are no-returns.
    settings : UnorganisedSettings, optional
    ground_only : bool
        Stop after the per-point ground / non-ground labels (the job of a ground filter such as
        SMRF or CSF): no mesh, no obstacles; ``point_obstacle`` is all 0 and ``counts`` all 0.

    Raises
    ------
    InputError
        Fewer than 3 valid points or points that do not span an area in x-y.
    """
    settings = settings or UnorganisedSettings()
    clock: dict[str, float] = {}
    t0 = time.perf_counter()
    try:
        P = np.asarray(points)
    except (TypeError, ValueError) as exc:  # pragma: no cover
        raise InputError(f"is not numeric: {exc}", source=source, field="points") from exc
    if P.dtype.kind not in "fiu" or P.ndim != 2 or P.shape[1] < 3:
        raise InputError(
            f"has shape {P.shape} and dtype {P.dtype}",
            source=source,
            field="points",
            expected="an (N, >=3) float array",
        )
    Q = np.asarray(P[:, :3], dtype=np.float64)
    valid = np.isfinite(Q).all(axis=1) & (Q != 0).any(axis=1)
    idx = np.flatnonzero(valid)
    if idx.size < 3:
        raise InputError(
            f"has {idx.size} valid points",
            source=source,
            field="points",
            expected="at least 3 points that are not NaN or (0, 0, 0)",
        )
    offset = Q[idx, :2].min(axis=0)  # local coordinates: UTM values lose precision in products
    xy_all = Q[idx, :2] - offset
    z_all = Q[idx, 2]
    n = len(Q)
    labels = np.full(n, UNRELIABLE, dtype=np.int8)
    obstacle_id = np.zeros(n, dtype=np.int32)
    ground_z = np.full(n, np.nan)
    counts = {"ground": 0, "unreliable": 0, "obstacle": 0, "side_shadow": 0, "shadow_behind": 0}
    obstacles: list[Obstacle] = []
    tiles_info: list[dict[str, Any]] = []
    id_base = 0
    lo, hi = xy_all.min(axis=0), xy_all.max(axis=0)
    clock["prepare"] = time.perf_counter() - t0
    for tx0, ty0, tw, th in _tile_origins(lo, hi, settings.tile_m):
        ov = settings.overlap_m
        in_work = (
            (xy_all[:, 0] >= tx0 - ov)
            & (xy_all[:, 0] <= tx0 + tw + ov)
            & (xy_all[:, 1] >= ty0 - ov)
            & (xy_all[:, 1] <= ty0 + th + ov)
        )
        in_core = (
            (xy_all[:, 0] >= tx0)
            & (xy_all[:, 0] <= tx0 + tw)
            & (xy_all[:, 1] >= ty0)
            & (xy_all[:, 1] <= ty0 + th)
        )
        work = np.flatnonzero(in_work)
        core = in_core[work]
        if not core.any():
            continue
        res = _detect_tile(xy_all[work], z_all[work], settings, source, clock, ground_only, offset)
        rows = idx[work[core]]
        # a point on a shared tile edge is written by the last tile: the same rule everywhere
        labels[rows] = res["labels"][core]
        ground_z[rows] = res["ground_z"][core]
        base = len(obstacles)
        ids = res["point_obstacle"][core]
        # an obstacle belongs to the tile whose own square holds its outline's centre
        centres = res["centres"]
        inside = (
            (centres[:, 0] >= tx0)
            & (centres[:, 0] <= tx0 + tw)
            & (centres[:, 1] >= ty0)
            & (centres[:, 1] <= ty0 + th)
        )
        keep_obs = [ob for ob, ok in zip(res["obstacles"], inside.tolist(), strict=True) if ok]
        if settings.build_map:
            remap = np.zeros(len(res["obstacles"]) + 1, dtype=np.int32)
            for k, ob in enumerate(keep_obs):
                remap[ob.id] = base + k + 1
            obstacle_id[rows] = remap[ids]
        else:  # no records: the tile's own obstacle ids, made unique over the tiles
            obstacle_id[rows] = np.where(ids > 0, ids + id_base, 0)
            id_base += int(res["point_obstacle"].max(initial=0))
        for k, ob in enumerate(keep_obs):
            # the tile's records are new and not shared yet: renumbered in place
            ob.__dict__["id"] = base + k + 1
            obstacles.append(ob)
        for key, v in res["counts"].items():
            counts[key] += v
        tiles_info.append(
            {
                "square_m": [float(tx0 + offset[0]), float(ty0 + offset[1]), tw, th],
                "n_points": int(core.sum()),
                "n_work_points": int(work.size),
                **res["info"],
            }
        )
    first = tiles_info[0] if tiles_info else {"spacing_m": np.nan, "noise_m": np.nan, "band_m": 0}
    clock["total"] = time.perf_counter() - t0
    return UnorganisedDetection(
        labels,
        obstacle_id,
        ground_z,
        tuple(obstacles),
        counts,
        float(first["spacing_m"]),
        float(first["noise_m"]),
        float(first["band_m"]),
        tiles_info,
        clock,
    )


_SHIFT_FIELDS: dict[type, tuple[tuple[str, ...], tuple[str, ...]]] = {
    Rectangle: (("xmin", "xmax"), ("ymin", "ymax")),
    Circle: (("x",), ("y",)),
    Ellipse: (("x",), ("y",)),
}
"""The coordinate fields of the shipped shapes (:mod:`navkit.geometry.shape_types`)."""


def _shift_shape(shape: Any, dx: float, dy: float) -> Any:
    """A bounding shape moved by ``(dx, dy)`` (rectangles by their bounds, circles and ellipses
    by their centre; other registered shapes are returned as they are)."""
    known = _SHIFT_FIELDS.get(type(shape))
    if known is not None:
        # the shipped records (no ``__post_init__``): a copy of the fields with the coordinates
        # moved, without the frozen dataclass's ``__init__`` (as ``geometry.shapes._ellipses``)
        out = object.__new__(type(shape))
        d = out.__dict__
        d.update(shape.__dict__)
        for name in known[0]:
            d[name] += dx
        for name in known[1]:
            d[name] += dy
        return out
    names = {f.name for f in fields(shape)} if hasattr(shape, "__dataclass_fields__") else set()
    if {"xmin", "xmax", "ymin", "ymax"} <= names:
        return replace(
            shape,
            xmin=shape.xmin + dx,
            xmax=shape.xmax + dx,
            ymin=shape.ymin + dy,
            ymax=shape.ymax + dy,
        )
    if {"x", "y"} <= names:
        return replace(shape, x=shape.x + dx, y=shape.y + dy)
    return shape


def _tick(clock: dict[str, float], key: str, t: float) -> float:
    now = time.perf_counter()
    clock[key] = clock.get(key, 0.0) + now - t
    return now


def _detect_tile(
    xy: NDArray[np.float64],
    z: NDArray[np.float64],
    settings: UnorganisedSettings,
    source: str,
    clock: dict[str, float],
    ground_only: bool = False,
    offset: NDArray[np.float64] | None = None,
) -> dict[str, Any]:
    """Stages 2-8 on one tile's points (local x-y, ``offset`` from the input's frame); only
    the ground labels with ``ground_only``. The obstacle records are in the input's frame,
    ``centres`` the local centres of their outlines."""
    t = time.perf_counter()
    spacing = point_spacing(xy)
    if not math.isfinite(spacing) or spacing <= 0:
        raise InputError(
            "every point of a tile has the same x-y (no spacing to triangulate)",
            source=source,
            field="points",
            expected="points spread over an area",
        )
    surf = ground_surface(xy, z, settings, spacing)
    t = _tick(clock, "ground", t)
    zg, slope = surf.at(xy)
    h = z - zg
    band = surf.band_m + settings.slope_scale_m * slope
    ground = (h <= band) & (h >= -settings.low_factor * band)
    labels = np.where(ground, GROUND, OBSTACLE).astype(np.int8)
    t = _tick(clock, "labels", t)
    info = {
        "spacing_m": spacing,
        "noise_m": surf.noise_m,
        "band_m": surf.band_m,
        "n_ground_vertices": len(surf.z),
    }
    counts = {"ground": 0, "unreliable": 0, "obstacle": 0, "side_shadow": 0, "shadow_behind": 0}
    point_obstacle = np.zeros(len(z), dtype=np.int32)
    obstacles: list[Obstacle] = []
    centres = np.empty((0, 2))
    no_mesh = {  # the result when no mesh is made (ground only, or no triangulation)
        "labels": labels,
        "ground_z": zg,
        "point_obstacle": point_obstacle,
        "obstacles": obstacles,
        "centres": centres,
        "counts": counts,
        "info": info,
    }
    if ground_only:
        return no_mesh
    # stage 2: the mesh over the thinned cloud (lowest point per spacing cell)
    v = (
        surf.lowest  # the ground estimate's cells are the thinning cells
        if settings.thin_spacings == settings.grid_spacings
        else lowest_per_cell(xy, z, settings.thin_spacings * spacing)
    )
    info["n_mesh_vertices"] = int(v.size)
    try:
        mesh = Delaunay(xy[v])
    except QhullError:
        info["n_triangles"] = 0
        return no_mesh
    t = _tick(clock, "mesh", t)
    simp = mesh.simplices.astype(np.int64)
    tri_labels, _, _, _ = classify_triangles(xy[v], z[v], simp, h[v], band[v], settings, spacing)
    t = _tick(clock, "classes", t)
    for k, name in ((0, "ground"), (-1, "unreliable"), (-2, "obstacle"), (-3, "side_shadow")):
        counts[name] = int(np.count_nonzero(tri_labels == k))
    info["n_triangles"] = len(simp)
    # stage 6: separate obstacles; small or low zones are not reported
    nbr = mesh.neighbors.astype(np.int64)
    comp, nc = _triangle_components(nbr, tri_labels == OBSTACLE)
    if nc:
        ntri = np.bincount(comp, minlength=nc + 1)
        top = np.full(nc + 1, -np.inf)
        hv = h[v][simp].max(axis=1)
        np.maximum.at(top, comp, hv)
        ok = (ntri >= settings.min_obstacle_triangles) & (top >= settings.min_obstacle_height_m)
        ok[0] = False
        lut = np.zeros(nc + 1, dtype=np.int32)
        lut[ok] = np.arange(1, int(ok.sum()) + 1, dtype=np.int32)
        comp = lut[comp]
        nc = int(ok.sum())
    owner = _assign_shadows(nbr, comp, tri_labels == SIDE_SHADOW)
    t = _tick(clock, "split", t)
    # stage 7: boundary vertices (some, not all, of their triangles belong to the obstacle)
    nv = len(v)
    flat_v = simp.reshape(-1)
    flat_c = np.repeat(comp, 3)
    n_inc = np.bincount(flat_v, minlength=nv)
    # vertex -> obstacle id: the largest id among its obstacle triangles
    vid = np.zeros(nv, dtype=np.int32)
    np.maximum.at(vid, flat_v, flat_c)
    n_obs_inc = np.bincount(flat_v, weights=(flat_c > 0).astype(float), minlength=nv)
    boundary = (n_obs_inc > 0) & (n_obs_inc < n_inc)
    t = _tick(clock, "boundary", t)
    # per-point obstacle ids: a non-ground point takes its nearest vertex's id
    if nc:
        _, nn = cKDTree(xy[v]).query(xy[~ground])
        point_obstacle[~ground] = vid[nn]
    if settings.build_map and nc:
        obstacles, centres = _stage_8(
            xy, z, v, simp, comp, owner, vid, boundary, nc, settings, offset
        )
    _tick(clock, "shapes", t)
    return {**no_mesh, "obstacles": obstacles, "centres": centres}


def _csr_offsets(counts: NDArray[np.int64]) -> NDArray[np.int64]:
    off = np.zeros(len(counts) + 1, dtype=np.int64)
    np.cumsum(counts, out=off[1:])
    return off


def _stage_8(
    xy: NDArray[np.float64],
    z: NDArray[np.float64],
    v: NDArray[np.int64],
    simp: NDArray[np.int64],
    comp: NDArray[np.int32],
    owner: NDArray[np.int32],
    vid: NDArray[np.int32],
    boundary: NDArray[np.bool_],
    nc: int,
    settings: UnorganisedSettings,
    offset: NDArray[np.float64] | None = None,
) -> tuple[list[Obstacle], NDArray[np.float64]]:
    """Stage 8: an :class:`~navkit.obstacles.Obstacle` per obstacle, shapes on its boundary
    vertices (A1-A6, ...) and A7 over obstacle plus shadow vertices, and the centre of each
    outline (the mean of its hull's vertices, local). The hulls and shapes are computed in the
    local x-y (UTM values lose precision in the shapes' products) and the records moved by
    ``offset`` into the input's frame.

    The vertex sets of all obstacles are built at once in a CSR layout (rows of obstacle ``k``
    in vertex order): its vertices (``vid == k``), their boundary vertices (all its vertices
    when none is on the boundary), and its vertices with those of its shadow triangles. With
    the compiled kernels the hulls and shapes of every obstacle come from a few kernel calls
    (:func:`navkit.geometry.shapes.hulls_csr`, :func:`~navkit.geometry.shapes.shapes_csr`, as
    the scan path's stage 8); else from :func:`~navkit.geometry.shapes.compute_shapes` on the
    hulls (the twin: the same shapes bit for bit).
    """
    from navkit.geometry.shapes import compute_shapes, hull_points, hulls_csr, shapes_csr
    from navkit.jit import kernels_enabled

    vxy, vz = xy[v], z[v]
    nv = len(v)
    # each obstacle's vertices, in vertex order
    vsel = np.flatnonzero(vid > 0)
    mem = vsel[np.argsort(vid[vsel], kind="stable")]
    mem_id = vid[mem].astype(np.int64)
    n_points = np.bincount(mem_id, minlength=nc + 1)[1:]
    m_off = _csr_offsets(n_points)
    z_min = np.full(nc, np.nan)
    z_max = np.full(nc, np.nan)
    if mem.size:
        full = n_points > 0
        z_min[full] = np.minimum.reduceat(vz[mem], m_off[:-1][full])
        z_max[full] = np.maximum.reduceat(vz[mem], m_off[:-1][full])
    # boundary vertices (all the obstacle's vertices when none is on its boundary)
    on_b = boundary[mem]
    n_b = np.bincount(mem_id[on_b], minlength=nc + 1)[1:]
    take = on_b | (n_b == 0)[mem_id - 1]
    b_ids = mem_id[take]
    b_xy = np.ascontiguousarray(vxy[mem[take]])
    b_off = _csr_offsets(np.bincount(b_ids, minlength=nc + 1)[1:])
    # obstacle + shadow vertices (A7's input), unique, in vertex order
    shadow_tri = (owner > 0) & (comp == 0)
    s_ids = np.repeat(owner[shadow_tri].astype(np.int64), 3)
    key = np.unique(np.concatenate([mem_id * nv + mem, s_ids * nv + simp[shadow_tri].reshape(-1)]))
    g_ids = key // nv
    g_xy = np.ascontiguousarray(vxy[key % nv])
    g_off = _csr_offsets(np.bincount(g_ids, minlength=nc + 1)[1:])
    P = vxy[simp[shadow_tri]]
    area = 0.5 * np.abs(
        (P[:, 1, 0] - P[:, 0, 0]) * (P[:, 2, 1] - P[:, 0, 1])
        - (P[:, 2, 0] - P[:, 0, 0]) * (P[:, 1, 1] - P[:, 0, 1])
    )
    shadow_area = np.bincount(owner[shadow_tri], weights=area, minlength=nc + 1)[1:]
    ntri = np.bincount(comp, minlength=nc + 1)[1:]
    none: list[dict[str, Any]] = [{} for _ in range(nc)]
    if kernels_enabled():
        H, hoff, chain = hulls_csr(b_xy, b_off)
        shapes = shapes_csr(H, hoff, settings.shapes) if settings.shapes else none
        guaranteed = none
        if settings.guaranteed_shapes:
            # the boundary's hull is inside the hull of obstacle + shadows: a cheap first filter
            G, goff, _ = hulls_csr(g_xy, g_off, inner=(H, hoff, chain))
            guaranteed = shapes_csr(G, goff, settings.guaranteed_shapes)
        ho = hoff.tolist()
        hulls = [H[ho[k] : ho[k + 1]] for k in range(nc)]
    else:
        bo_ = b_off.tolist()
        hulls = [hull_points(b_xy[bo_[k] : bo_[k + 1]]) for k in range(nc)]
        shapes = compute_shapes(hulls, settings.shapes, are_hulls=True) if settings.shapes else none
        go_ = g_off.tolist()
        guaranteed = (
            compute_shapes(
                [g_xy[go_[k] : go_[k + 1]] for k in range(nc)], settings.guaranteed_shapes
            )
            if settings.guaranteed_shapes
            else none
        )
    centres = np.array([h.mean(axis=0) for h in hulls]).reshape(-1, 2)
    off = np.zeros(2) if offset is None else np.asarray(offset, dtype=np.float64)
    dx, dy = float(off[0]), float(off[1])
    b_in, g_in = b_xy + off, g_xy + off
    bo, go = b_off.tolist(), g_off.tolist()
    out = obstacle_records(
        ntri.tolist(),
        n_points.tolist(),
        z_min.tolist(),
        z_max.tolist(),
        [b_in[bo[k] : bo[k + 1]] for k in range(nc)],
        [h + off for h in hulls],
        [g_in[go[k] : go[k + 1]] for k in range(nc)],
        shadow_area.tolist(),
        [{name: _shift_shape(sh, dx, dy) for name, sh in shapes[k].items()} for k in range(nc)],
        [{name: _shift_shape(sh, dx, dy) for name, sh in guaranteed[k].items()} for k in range(nc)],
    )
    return out, centres


# ----------------------------------------------------------------------------------------------
# scoring against a per-point ground reference (the ISPRS filter-test measures)


@dataclass(frozen=True)
class FilterScores:
    """The ISPRS "Comparison of Filters" measures (Sithole & Vosselman 2004), in %.

    Attributes
    ----------
    total, type_i, type_ii : float
        Total error (points misclassified / all), type I (ground rejected / ground) and type II
        (objects accepted as ground / objects).
    kappa : float
        Cohen's kappa of the two-class confusion matrix, %.
    n_points : int
    """

    total: float
    type_i: float
    type_ii: float
    kappa: float
    n_points: int


def filter_scores(predicted_ground: ArrayLike, true_ground: ArrayLike) -> FilterScores:
    """Total, type I, type II errors and kappa of a per-point ground / non-ground labelling.

    Raises
    ------
    InputError
        If the two arrays differ in length or are empty.
    """
    p = np.asarray(predicted_ground, dtype=bool).reshape(-1)
    g = np.asarray(true_ground, dtype=bool).reshape(-1)
    if p.shape != g.shape or p.size == 0:
        raise InputError(
            f"has {g.size} reference labels for {p.size} predictions",
            field="true_ground",
            expected="one reference label per point, at least one point",
        )
    n = p.size
    a = float(np.count_nonzero(g & p))
    b = float(np.count_nonzero(g & ~p))
    c = float(np.count_nonzero(~g & p))
    d = float(np.count_nonzero(~g & ~p))
    po = (a + d) / n
    pe = ((a + b) * (a + c) + (c + d) * (b + d)) / (n * n)
    kappa = (po - pe) / (1.0 - pe) if pe < 1.0 else float("nan")
    return FilterScores(
        100.0 * (b + c) / n,
        100.0 * b / (a + b) if a + b else float("nan"),
        100.0 * c / (c + d) if c + d else float("nan"),
        100.0 * kappa,
        n,
    )


def reference_ground(
    points: ArrayLike, ground_points: ArrayLike, *, tolerance: float = 1e-3
) -> NDArray[np.bool_]:
    """Per-point reference labels from a second cloud holding only the ground points (the PCL
    copy of the ISPRS samples: ``sampXX-utm.pcd`` and ``sampXX-utm-ground.pcd``): a point is
    ground when the ground cloud has a point within ``tolerance`` of it in x, y and z."""
    P = np.asarray(points, dtype=np.float64)[:, :3]
    G = np.asarray(ground_points, dtype=np.float64)[:, :3]
    if len(G) == 0:
        return np.zeros(len(P), dtype=bool)
    off = P.min(axis=0)
    d, _ = cKDTree(G - off).query(P - off, p=np.inf)
    return np.asarray(d <= tolerance)
