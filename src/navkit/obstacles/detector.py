"""Paper 1's eight stages composed: scan grid in, classes, obstacles and their 2D map out."""

from __future__ import annotations

import functools
import logging
import math
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError
from navkit.geometry._validate import (
    MAX_COORDINATE_M,
    check_coordinates,
    check_grid_size,
    max_grid_cells,
)
from navkit.geometry.shapes import compute_shapes, hull_points, hulls_csr, shapes_csr
from navkit.jit import kernels_enabled
from navkit.obstacles.grids import ScanGrid
from navkit.obstacles.ground import refine_by_ground_height
from navkit.obstacles.mesh import MeshCharacteristics
from navkit.obstacles.mounting import Mounting
from navkit.obstacles.rules import GROUND, OBSTACLE, _mesh_and_classes
from navkit.obstacles.segment import (
    assign_shadows,
    boundary_vertices,
    label_components,
    main_ground_vertices,
    merge_close_components,
    vertex_labels,
)
from navkit.obstacles.settings import ObstacleSettings
from navkit.sensors import RangeScan

__all__ = [
    "Obstacle",
    "ObstacleDetection",
    "detect_obstacles",
    "detect_obstacles_grid",
    "detect_obstacles_in_grid",
    "unsort_vertex_array",
]

log = logging.getLogger(__name__)

MAIN_GROUND_SHARE = 0.1
"""Main ground zones: ground components with at least this share of the largest one's triangles
(``segment.main_ground_vertices``' default; the compiled stage 6 finds them)."""

STAGES = ("points", "mesh", "classes", "split", "boundaries", "map")
"""Stage names used as keys of :attr:`ObstacleDetection.timings` (stages 3-4 are in "mesh"; with
the compiled kernels stages 2-5 run as one kernel, charged to "mesh", and "classes" is ~0)."""


@dataclass(frozen=True)
class Obstacle:
    """One obstacle and its 2D map entry (paper 1, stages 6-8).

    Attributes
    ----------
    id : int
        1-based id (the value in :attr:`ObstacleDetection.triangle_obstacle`).
    n_triangles, n_points : int
        Obstacle triangles and the grid vertices they use.
    z_min, z_max : float
        Lowest and highest obstacle vertex (body frame, m); ``height = z_max - z_min``.
    boundary_xy : (M, 2) float
        Boundary vertices (stage 7) in the body frame's x, y, metres.
    polygon_xy : (K, 2) float
        Counter-clockwise convex hull of the boundary vertices (the outline written to files).
    shadow_xy : (S, 2) float
        Vertices of the obstacle together with its shadows (input of A7).
    shadow_area : float
        Horizontal area of the obstacle's shadow triangles, m^2.
    shapes : dict
        Bounding shapes on the boundary vertices (A1-A6, MEC, MVEE, ...; stage 8).
    guaranteed : dict
        A7: the same kinds of shape over obstacle plus shadows.
    """

    id: int
    n_triangles: int
    n_points: int
    z_min: float
    z_max: float
    boundary_xy: NDArray[np.float64]
    polygon_xy: NDArray[np.float64]
    shadow_xy: NDArray[np.float64]
    shadow_area: float
    shapes: dict[str, Any] = field(default_factory=dict)
    guaranteed: dict[str, Any] = field(default_factory=dict)

    @property
    def height(self) -> float:
        """Vertical extent of the obstacle, metres."""
        return self.z_max - self.z_min

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON description (what ``obstacles.json`` holds for each obstacle)."""
        return obstacle_dict(*self.json_fields())

    def json_fields(self) -> tuple[Any, ...]:
        """What :meth:`to_dict` is made of, unformatted (:func:`obstacle_dict` makes the dict):
        ``navkit run`` hands these to its writer process, which formats ``obstacles.json``."""
        return (
            self.id,
            self.n_points,
            self.n_triangles,
            self.z_min,
            self.z_max,
            self.polygon_xy,
            len(self.boundary_xy),
            self.shadow_area,
            self.shapes,
            self.guaranteed,
        )


def obstacle_dict(
    id: int,
    n_points: int,
    n_triangles: int,
    z_min: float,
    z_max: float,
    polygon_xy: NDArray[np.float64],
    n_boundary_points: int,
    shadow_area: float,
    shapes: dict[str, Any],
    guaranteed: dict[str, Any],
) -> dict[str, Any]:
    """:meth:`Obstacle.to_dict` from :meth:`Obstacle.json_fields`."""
    return {
        "id": id,
        "n_points": n_points,
        "n_triangles": n_triangles,
        "height": z_max - z_min,
        "z_min": z_min,
        "z_max": z_max,
        "boundary_polygon": polygon_xy.tolist(),
        "n_boundary_points": n_boundary_points,
        "shadow_area": shadow_area,
        "shapes": {k: v.params() for k, v in shapes.items()},
        "A7": {k: v.params() for k, v in guaranteed.items()},
    }


@dataclass(frozen=True)
class ObstacleDetection:
    """Everything the eight stages produce for one scan grid.

    Attributes
    ----------
    points : (n_az, n_el, 3) float
        Stage 1 points in the level body frame (NaN where no return).
    valid : (n_az, n_el) bool
        Validity codes C_d.
    sensor_origin : (3,) float
        Sensor position in the body frame.
    wrap : bool
        Whether the mesh closes across the azimuth seam.
    triangles : (R, 2C, 3) int
        Vertex indices of the mesh (see :mod:`navkit.obstacles.mesh`).
    normals : (R, 2C, 3) float
        Unit normals (NaN for unreliable triangles).
    jump : (R, 2C) bool
        Height-jump code of H_s.
    triangle_labels : (R, 2C) int8
        Classes m_t: 0 ground, -1 unreliable, -2 obstacle, -3 side shadow, -4 shadow behind.
    triangle_obstacle : (R, 2C) int32
        Obstacle id of obstacle triangles and of the shadow triangles they own (0 = none).
    vertex_labels : (n_az, n_el) int8
        One class per grid vertex (see :func:`navkit.obstacles.segment.vertex_labels`).
    vertex_obstacle : (n_az, n_el) int32
        Obstacle id per vertex (0 = none).
    boundary : (n_az, n_el) bool
        Boundary vertices (stage 7).
    obstacles : tuple of Obstacle
    timings : dict
        Wall-clock seconds per stage (keys of :data:`STAGES`).
    cpu_timings : dict
        CPU seconds per stage (``time.process_time``: all threads of the process), same keys.
    """

    points: NDArray[np.float64]
    valid: NDArray[np.bool_]
    sensor_origin: NDArray[np.float64]
    wrap: bool
    triangles: NDArray[np.int64]
    normals: NDArray[np.floating[Any]]
    jump: NDArray[np.bool_]
    triangle_labels: NDArray[np.int8]
    triangle_obstacle: NDArray[np.int32]
    vertex_labels: NDArray[np.int8]
    vertex_obstacle: NDArray[np.int32]
    boundary: NDArray[np.bool_]
    obstacles: tuple[Obstacle, ...]
    timings: dict[str, float]
    cpu_timings: dict[str, float] = field(default_factory=dict)

    @property
    def counts(self) -> dict[str, int]:
        """Number of triangles per class name."""
        names = {
            0: "ground",
            -1: "unreliable",
            -2: "obstacle",
            -3: "side_shadow",
            -4: "shadow_behind",
        }
        return {name: int(np.count_nonzero(self.triangle_labels == k)) for k, name in names.items()}


class _Clock:
    """Wall and CPU time per stage: ``lap(name)`` charges the time since the last lap."""

    def __init__(self) -> None:
        self.wall = {s: 0.0 for s in STAGES}
        self.cpu = {s: 0.0 for s in STAGES}
        self._w, self._c = time.perf_counter(), time.process_time()

    def lap(self, stage: str) -> None:
        w, c = time.perf_counter(), time.process_time()
        self.wall[stage] += w - self._w
        self.cpu[stage] += c - self._c
        self._w, self._c = w, c


def _check_grid(points: ArrayLike, source: str) -> NDArray[np.float64]:
    try:
        P = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"is not numeric: {exc}",
            source=source,
            field="points",
            expected="(n_az, n_el, 3) floats",
        ) from exc
    if P.ndim != 3 or P.shape[2] != 3:
        raise InputError(
            f"has shape {P.shape}", source=source, field="points", expected="(n_az, n_el, 3) array"
        )
    if P.shape[0] < 2 or P.shape[1] < 2:
        raise InputError(
            f"has shape {P.shape}",
            source=source,
            field="points",
            expected="a grid of at least 2 x 2 cells",
        )
    return P


def _auto_wrap(azimuth: NDArray[np.float64] | None) -> bool:
    if azimuth is None or len(azimuth) < 3:
        return False
    step = np.median(np.abs(np.diff(azimuth)))
    return bool(np.ptp(azimuth) + 1.5 * step >= 2 * math.pi)


def detect_obstacles_grid(
    points: ArrayLike,
    sensor_origin: ArrayLike = (0.0, 0.0, 0.0),
    settings: ObstacleSettings | None = None,
    *,
    azimuth: ArrayLike | None = None,
    source: str = "points",
) -> ObstacleDetection:
    """Run stages 2-8 on an organised grid of body-frame points.

    Parameters
    ----------
    points : (n_az, n_el, 3) float
        Level body-frame points (z up, origin on the ground under the sensor), azimuth rising
        (counter-clockwise) along axis 0 and elevation rising along axis 1; NaN = no return.
    sensor_origin : (3,) float
        The sensor's position in that frame, normally ``(0, 0, z_D)``.
    settings : ObstacleSettings
    azimuth : (n_az,) float, optional
        Azimuth of each row (rad), only used to decide ``wrap_azimuth=None``.
    source : str
        Name used in error messages.

    Raises
    ------
    InputError
        If the grid has the wrong shape or no valid point at all.
    """
    settings = settings or ObstacleSettings()
    clock = _Clock()
    P = _check_grid(points, source)
    origin = np.asarray(sensor_origin, dtype=np.float64).reshape(3)
    compiled = kernels_enabled()
    if compiled:
        from navkit.obstacles import _kernels_grid
        from navkit.obstacles._buffers import arena

        P_in = P
        P, valid = arena([(P_in.shape, np.float64), (P_in.shape[:2], np.bool_)])
        n_valid, n_far = _kernels_grid.points_kernel(P_in, P, valid, MAX_COORDINATE_M)
        if n_far:
            check_coordinates(P_in, field="points", source=source)
        any_valid = n_valid > 0
    else:
        check_coordinates(P, field="points", source=source)
        valid = np.isfinite(P[..., 0]) & np.isfinite(P[..., 1]) & np.isfinite(P[..., 2])
        any_valid = bool(valid.any())
    if not any_valid:
        raise InputError(
            "has no valid point (all NaN / no return)",
            source=source,
            field="points",
            expected="at least one measured point",
        )
    if not compiled:
        P = np.where(valid[..., None], P, np.nan)
    return _detect_from_stage_1(P, valid, origin, settings, azimuth, clock, compiled)


def _detect_from_stage_1(
    P: NDArray[np.float64],
    valid: NDArray[np.bool_],
    origin: NDArray[np.float64],
    settings: ObstacleSettings,
    azimuth: ArrayLike | None,
    clock: _Clock,
    compiled: bool,
) -> ObstacleDetection:
    """Stages 2-8 of :func:`detect_obstacles_grid` after stage 1 (``P`` with NaN rows where not
    ``valid``, at least one valid point); ``compiled``: the kernels (the frame's one decision,
    :func:`navkit.jit.kernels_enabled`), else the NumPy twins."""
    wrap = (
        settings.wrap_azimuth
        if settings.wrap_azimuth is not None
        else _auto_wrap(None if azimuth is None else np.asarray(azimuth, dtype=np.float64))
    )
    wrap = bool(wrap and P.shape[0] > 2)
    clock.lap("points")

    # stages 2-5: mesh, normals, characteristic parameters H_s, validity codes C_d, production
    # rules P1-P5 -> classes (compiled: one pass over the grid, all charged to "mesh")
    # (the mesh's valid, vertex_ray and range_mean are not computed: nothing below reads them)
    mesh, labels, _rules = _mesh_and_classes(
        P, valid, origin, settings, wrap=wrap, rules=False, full_mesh=False, compiled=compiled
    )
    clock.lap("mesh")
    clock.lap("classes")

    # stage 6: separate obstacles (mesh components), drop tiny / flat ones, give shadows an owner
    if compiled:
        obs_lab, n, tri_obstacle, tcode, shadows, ntri = _compiled_split(
            labels, mesh, P, wrap, settings
        )
    else:
        obs_lab, n, owner = _split(labels, mesh, P, wrap, settings)
        tri_obstacle = np.where(obs_lab > 0, obs_lab, owner).astype(np.int32)
    clock.lap("split")

    # stage 7: boundary vertices, per-vertex classes
    if compiled:
        vid, boundary, vlab = _compiled_vertices(labels, obs_lab, P, valid, wrap, settings, tcode)
    else:
        vid, boundary, vlab = _vertices(labels, obs_lab, P, valid, wrap, settings)
    clock.lap("boundaries")

    # stage 8: the 2D map - bounding shapes of every obstacle
    if not settings.build_map:  # stages 1-7 only: classes, ids and boundaries per point
        obstacles = []
    elif compiled:
        obstacles = _build_compiled(
            P, mesh.triangles, tri_obstacle, shadows, ntri, vid, boundary, n, settings
        )
    else:
        obstacles = _build_obstacles(
            P, mesh.triangles, labels, obs_lab, owner, vid, boundary, n, settings
        )
    clock.lap("map")
    log.debug("obstacle detection: %d obstacles, timings %s", len(obstacles), clock.wall)
    return ObstacleDetection(
        points=P,
        valid=valid,
        sensor_origin=origin,
        wrap=wrap,
        triangles=mesh.triangles,
        normals=mesh.normal,
        jump=mesh.jump,
        triangle_labels=labels,
        triangle_obstacle=tri_obstacle,
        vertex_labels=vlab,
        vertex_obstacle=vid,
        boundary=boundary,
        obstacles=tuple(obstacles),
        timings=clock.wall,
        cpu_timings=clock.cpu,
    )


def _split(
    labels: NDArray[np.int8],
    mesh: MeshCharacteristics,
    P: NDArray[np.float64],
    wrap: bool,
    settings: ObstacleSettings,
) -> tuple[NDArray[np.int32], int, NDArray[np.int32]]:
    """Stage 6 (NumPy reference): obstacle components, filters, merging, shadow owners.
    ``labels`` is changed in place (dropped components back to ground)."""
    obs_lab, n = label_components(labels == OBSTACLE, wrap)
    if n:
        size = np.bincount(obs_lab.ravel(), minlength=n + 1)[1:]
        zmax, zmin = _per_label_extrema(obs_lab, mesh.z_max, mesh.z_min, n)
        zmid = 0.5 * (mesh.z_max + mesh.z_min)
        spread = _per_label_spread(obs_lab, zmid, n)
        lift = _lift_over_adjacent_ground(obs_lab, labels, zmid, n, wrap)
        half = 0.5 * settings.min_obstacle_height_m
        # a patch of noise on the ground: little spread and no lift over the ground around it
        # (an elevated flat fragment - a car's roof cut off by missing returns - is kept)
        noise_patch = (spread < half) & (lift < half)
        keep = (
            (size >= settings.min_obstacle_triangles)
            & (zmax - zmin >= settings.min_obstacle_height_m)
            & ~noise_patch
        )
        lut = np.zeros(n + 1, dtype=np.int32)
        lut[1:][keep] = np.arange(1, int(keep.sum()) + 1)
        dropped = (obs_lab > 0) & (lut[obs_lab] == 0)
        labels[dropped] = 0  # back to ground: too small or too flat to be an obstacle
        obs_lab = lut[obs_lab]
        n = int(keep.sum())
        # zones that passed the filters and nearly touch are one obstacle (after the filters, so
        # that low debris such as curbs cannot bridge separate objects)
        obs_lab, n = merge_close_components(
            obs_lab, n, P, wrap, settings.merge_distance_m, settings.merge_gap_cells
        )
    owner = assign_shadows(labels, obs_lab, wrap)
    return obs_lab, n, owner


def _work_6_7(R: int, C: int, N: int) -> list[NDArray[Any]]:
    """The work arrays of the compiled stages 6 and 7 for ``R x C`` triangles and ``N``
    vertices, kept between calls under one key (``_buffers.cached_work`` keeps four):
    ``int8 (R * C,)``, ``int32 (7, R * C)`` (stage 6), ``float64 (4, N)``, ``int64 (3, N)``
    (stage 7)."""
    from navkit.obstacles._buffers import cached_work

    return cached_work(
        ("split", R, C, N),
        lambda: [
            np.empty(R * C, np.int8),
            np.empty((7, R * C), np.int32),
            np.empty((4, N)),
            np.empty((3, N), np.int64),
        ],
    )


def _compiled_split(
    labels: NDArray[np.int8],
    mesh: MeshCharacteristics,
    P: NDArray[np.float64],
    wrap: bool,
    settings: ObstacleSettings,
) -> tuple[
    NDArray[np.int32],
    int,
    NDArray[np.int32],
    NDArray[np.int8],
    NDArray[np.int32],
    NDArray[np.int64],
]:
    """Stage 6 in one kernel (:func:`navkit.obstacles._kernels_map.split_kernel`), same answers;
    returns the obstacle ids, their number, the triangles' obstacle ids with the shadows'
    owners (the twin's separate ``owner`` array is not built), each triangle's code
    for stage 7 (class, main ground zone: the ground components come from the same union-find
    as the obstacle and shadow components), and for stage 8 the shadow triangles (flat
    indices, raster order) and each obstacle's number of triangles."""
    from navkit.obstacles import _kernels_map

    R, C = labels.shape
    work_i8, work_i32, _, _ = _work_6_7(R, C, P.shape[0] * P.shape[1])
    obs_lab, n, tri_obstacle, tcode, shadows, ntri = _kernels_map.split_kernel(
        labels,
        mesh.z_min.astype(np.float32, copy=False),
        mesh.z_max.astype(np.float32, copy=False),
        np.ascontiguousarray(P),
        bool(wrap),
        int(settings.min_obstacle_triangles),
        np.float32(settings.min_obstacle_height_m),
        0.5 * settings.min_obstacle_height_m,
        float(settings.merge_distance_m),
        int(settings.merge_gap_cells),
        MAIN_GROUND_SHARE,
        work_i8,
        work_i32,
    )
    return obs_lab, int(n), tri_obstacle, tcode, shadows, ntri


def _vertices(
    labels: NDArray[np.int8],
    obs_lab: NDArray[np.int32],
    P: NDArray[np.float64],
    valid: NDArray[np.bool_],
    wrap: bool,
    settings: ObstacleSettings,
) -> tuple[NDArray[np.int32], NDArray[np.bool_], NDArray[np.int8]]:
    """Stage 7 (NumPy reference): obstacle id per vertex, boundary, per-vertex classes."""
    n_az, n_el = valid.shape
    vid, boundary = boundary_vertices(obs_lab, n_az, n_el, wrap)
    vlab = vertex_labels(labels, valid, wrap)
    if settings.ground_refine:  # beyond the paper: per-point height above the local ground
        main = main_ground_vertices(labels, n_az, n_el, wrap, MAIN_GROUND_SHARE)
        vlab = refine_by_ground_height(
            P,
            vlab,
            valid,
            band_m=settings.ground_band_m,
            above_m=settings.ground_above_m,
            cell_m=settings.ground_cell_m,
            reference=main & (vlab == GROUND),
        )
    return vid, boundary, vlab


def _compiled_vertices(
    labels: NDArray[np.int8],
    obs_lab: NDArray[np.int32],
    P: NDArray[np.float64],
    valid: NDArray[np.bool_],
    wrap: bool,
    settings: ObstacleSettings,
    tcode: NDArray[np.int8],
) -> tuple[NDArray[np.int32], NDArray[np.bool_], NDArray[np.int8]]:
    """Stage 7 with the kernels of :mod:`navkit.obstacles._kernels_map` (one pass over the
    vertices, on stage 6's triangle codes ``tcode``, then the ground-height refinement); same
    answers."""
    from navkit.obstacles import _kernels_map
    from navkit.obstacles.ground import fill_missing_cells

    _, _, work_f, work_i = _work_6_7(labels.shape[0], labels.shape[1], valid.size)
    vid, boundary, vlab, _main, ref = _kernels_map.vertex_kernel(
        tcode, obs_lab, valid, bool(wrap), work_i[2]
    )
    if settings.ground_refine:
        flat = P.reshape(-1, 3)
        grid, origin, missing = _kernels_map.ground_cells_kernel(
            flat, ref, float(settings.ground_cell_m), 0.25, work_f, work_i, max_grid_cells()
        )
        if grid.size == 0:  # refused by the kernel: (nx, ny) in place of the origin
            check_grid_size(tuple(origin), setting="ground_cell_m", source="ground height map")
        if missing:
            grid = fill_missing_cells(grid)
        vlab = _kernels_map.refine_kernel(
            flat,
            vlab.reshape(-1),
            valid.reshape(-1),
            grid,
            origin,
            float(settings.ground_cell_m),
            float(settings.ground_band_m),
            float(settings.ground_above_m),
        ).reshape(vlab.shape)
    return vid, boundary, vlab


def _per_label_extrema(
    lab: NDArray[np.int32], hi: NDArray[Any], lo: NDArray[Any], n: int
) -> tuple[NDArray[Any], NDArray[Any]]:
    """Max of ``hi`` and min of ``lo`` over each label 1..n (sort + reduceat over labelled cells)."""
    sel = np.flatnonzero(lab.ravel() > 0)
    ids = lab.ravel()[sel]
    order = np.argsort(ids, kind="stable")
    counts = np.bincount(ids, minlength=n + 1)[1:]
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    return (
        np.maximum.reduceat(hi.ravel()[sel][order], starts),
        np.minimum.reduceat(lo.ravel()[sel][order], starts),
    )


def _per_label_spread(lab: NDArray[np.int32], z: NDArray[Any], n: int) -> NDArray[np.float64]:
    """Robust vertical extent per label 1..n: 90th minus 10th percentile of the triangles' mid
    heights (a patch of range noise on flat ground has a large max - min but a small spread)."""
    sel = np.flatnonzero(lab.ravel() > 0)
    ids = lab.ravel()[sel].astype(np.int64)
    zz = z.ravel()[sel].astype(np.float64)
    lo, hi = float(zz.min()), float(zz.max())
    order = np.argsort(ids + (zz - lo) / (1.01 * (hi - lo) + 1e-9))  # by label, then by height
    counts = np.bincount(ids, minlength=n + 1)[1:]
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    zs = zz[order]
    q10 = zs[starts + np.floor(0.1 * (counts - 1)).astype(np.int64)]
    q90 = zs[starts + np.floor(0.9 * (counts - 1)).astype(np.int64)]
    return q90 - q10


def _lift_over_adjacent_ground(
    lab: NDArray[np.int32], labels: NDArray[np.int8], z: NDArray[Any], n: int, wrap: bool
) -> NDArray[np.float64]:
    """Mean height of each label's triangles minus the mean height of the ground triangles next
    to them (+inf for a label with no ground neighbour)."""
    from navkit.obstacles.segment import _pairs

    z_ground = np.where(labels == GROUND, z, np.nan)  # NaN: not a ground neighbour
    # only the pairs that start on a labelled triangle
    a, zb = _pairs(lab, z_ground, wrap, lab > 0)
    keep = np.isfinite(zb)
    cnt_g = np.bincount(a[keep], minlength=n + 1)[1:]
    sum_g = np.bincount(a[keep], weights=zb[keep].astype(np.float64), minlength=n + 1)[1:]
    sel = np.flatnonzero(lab.ravel())
    ids = lab.ravel()[sel]
    cnt = np.bincount(ids, minlength=n + 1)[1:]
    sm = np.bincount(ids, weights=z.ravel()[sel].astype(np.float64), minlength=n + 1)[1:]
    with np.errstate(invalid="ignore", divide="ignore"):
        lift = sm / np.maximum(cnt, 1) - sum_g / cnt_g
    return np.where(cnt_g > 0, lift, np.inf)


def _group(
    ids: NDArray[np.int64], values: NDArray[np.float64], n: int
) -> list[NDArray[np.float64]]:
    """Split ``values`` rows by ``ids`` (1..n) into a list of n arrays (vectorised sort + split)."""
    order = np.argsort(ids, kind="stable")
    counts = np.bincount(ids, minlength=n + 1)[1:]
    return np.split(values[order], np.cumsum(counts)[:-1])


def _build_obstacles(
    P: NDArray[np.float64],
    tri: NDArray[np.int64],
    labels: NDArray[np.int8],
    obs_lab: NDArray[np.int32],
    owner: NDArray[np.int32],
    vid: NDArray[np.int32],
    boundary: NDArray[np.bool_],
    n: int,
    settings: ObstacleSettings,
) -> list[Obstacle]:
    if n == 0:
        return []
    flat = P.reshape(-1, 3)
    # boundary vertices per obstacle
    bmask = boundary.ravel()
    bxy = _group(vid.ravel()[bmask].astype(np.int64), flat[bmask, :2], n)
    # vertices of each obstacle (stage 7 gives every vertex its obstacle id)
    vflat = vid.ravel()
    vsel = np.flatnonzero(vflat > 0)
    pid = vflat[vsel].astype(np.int64)
    vxyz = _group(pid, flat[vsel], n)  # one sort for the heights and the xy of each obstacle
    nv = len(flat)
    # obstacle + its shadows (A7), and shadow areas
    is_sh = owner > 0
    sh_ids = owner[is_sh]
    skey = np.unique(np.repeat(sh_ids.astype(np.int64), 3) * nv + tri[is_sh].ravel())
    sxy = _group(skey // nv, flat[skey % nv, :2], n) if len(skey) else [np.empty((0, 2))] * n
    V = flat[tri[is_sh]][..., :2]
    area = 0.5 * np.abs(
        (V[:, 1, 0] - V[:, 0, 0]) * (V[:, 2, 1] - V[:, 0, 1])
        - (V[:, 2, 0] - V[:, 0, 0]) * (V[:, 1, 1] - V[:, 0, 1])
    )
    shadow_area = np.bincount(sh_ids, weights=area, minlength=n + 1)[1:]
    ntri = np.bincount(obs_lab.ravel(), minlength=n + 1)[1:]
    return _assemble_obstacles(bxy, vxyz, sxy, shadow_area, ntri, n, settings)


def _build_compiled(
    P: NDArray[np.float64],
    tri: NDArray[np.int64],
    tri_obstacle: NDArray[np.int32],
    shadows: NDArray[np.int32],
    ntri: NDArray[np.int64],
    vid: NDArray[np.int32],
    boundary: NDArray[np.bool_],
    n: int,
    settings: ObstacleSettings,
) -> list[Obstacle]:
    """:func:`_build_obstacles` with the compiled kernels: the groupings in one kernel
    (:func:`navkit.obstacles._kernels_map.map_groups_kernel`, on stage 6's ``tri_obstacle``,
    shadow triangles and triangle counts),
    then :func:`_assemble_compiled`; the same obstacles."""
    if n == 0:
        return []
    from navkit.obstacles import _kernels_map

    b_off, b_xy, g_off, g_xy, n_points, z_min, z_max, shadow_area, ntri = (
        _kernels_map.map_groups_kernel(
            P.reshape(-1, 3), tri, tri_obstacle, shadows, ntri, vid, boundary, n
        )
    )
    return _assemble_compiled(
        b_xy, b_off, g_xy, g_off, n_points, z_min, z_max, shadow_area, ntri, settings
    )


def _assemble_obstacles(
    bxy: list[NDArray[np.float64]],
    vxyz: list[NDArray[np.float64]],
    sxy: list[NDArray[np.float64]],
    shadow_area: NDArray[Any],
    ntri: NDArray[Any],
    n: int,
    settings: ObstacleSettings,
) -> list[Obstacle]:
    """Hulls, shapes and the :class:`Obstacle` records from the per-obstacle vertex sets."""
    vz = [v[:, 2] for v in vxyz]
    vxy = [v[:, :2] for v in vxyz]
    guaranteed_sets = [np.concatenate([o, s]) for o, s in zip(vxy, sxy, strict=True)]
    # the outline written to files, and the shapes' input (counter-clockwise from the
    # lexicographically smallest vertex: A3 and Welzl depend on the start)
    hulls = [hull_points(b) for b in bxy]
    shapes = (
        compute_shapes(hulls, settings.shapes, are_hulls=True)
        if settings.shapes
        else [{} for _ in range(n)]
    )
    guaranteed = (
        compute_shapes(guaranteed_sets, settings.guaranteed_shapes)
        if settings.guaranteed_shapes
        else [{} for _ in range(n)]
    )
    out = []
    for k in range(n):
        out.append(
            Obstacle(
                id=k + 1,
                n_triangles=int(ntri[k]),
                n_points=len(vz[k]),
                z_min=float(vz[k].min()),
                z_max=float(vz[k].max()),
                boundary_xy=bxy[k],
                polygon_xy=hulls[k],
                shadow_xy=guaranteed_sets[k],
                shadow_area=float(shadow_area[k]),
                shapes=shapes[k],
                guaranteed=guaranteed[k],
            )
        )
    return out


def _assemble_compiled(
    b_xy: NDArray[np.float64],
    b_off: NDArray[np.int64],
    g_xy: NDArray[np.float64],
    g_off: NDArray[np.int64],
    n_points: NDArray[np.int64],
    z_min: NDArray[np.float64],
    z_max: NDArray[np.float64],
    shadow_area: NDArray[Any],
    ntri: NDArray[Any],
    settings: ObstacleSettings,
) -> list[Obstacle]:
    """:func:`_assemble_obstacles` on CSR vertex sets (rows ``off[k]:off[k + 1]`` of obstacle
    ``k + 1``: ``b_xy`` its boundary vertices, ``g_xy`` its vertices and then its shadow
    vertices, A7's input) with the per-obstacle vertex counts and heights: the hulls and shapes
    of all obstacles in a few kernel calls (:func:`navkit.geometry.shapes.hulls_csr`,
    :func:`~navkit.geometry.shapes.shapes_csr`), the same obstacles as the twin."""
    n = len(b_off) - 1
    H, hoff, chain = hulls_csr(b_xy, b_off)
    shapes = shapes_csr(H, hoff, settings.shapes)
    if settings.guaranteed_shapes:
        # the boundary's hull is inside the hull of obstacle + shadows: a cheap first filter
        G, goff, _ = hulls_csr(g_xy, g_off, inner=(H, hoff, chain))
        guaranteed = shapes_csr(G, goff, settings.guaranteed_shapes)
    else:
        guaranteed = [{} for _ in range(n)]
    bo, ho, go = b_off.tolist(), hoff.tolist(), g_off.tolist()
    return obstacle_records(
        ntri.tolist(),
        n_points.tolist(),
        z_min.tolist(),
        z_max.tolist(),
        [b_xy[bo[k] : bo[k + 1]] for k in range(n)],
        [H[ho[k] : ho[k + 1]] for k in range(n)],
        [g_xy[go[k] : go[k + 1]] for k in range(n)],
        shadow_area.tolist(),
        shapes,
        guaranteed,
    )


def obstacle_records(
    n_triangles: list[int],
    n_points: list[int],
    z_min: list[float],
    z_max: list[float],
    boundary_xy: list[NDArray[np.float64]],
    polygon_xy: list[NDArray[np.float64]],
    shadow_xy: list[NDArray[np.float64]],
    shadow_area: list[float],
    shapes: list[dict[str, Any]],
    guaranteed: list[dict[str, Any]],
) -> list[Obstacle]:
    """:class:`Obstacle` records ``1 .. n`` from per-obstacle lists, built without the frozen
    dataclass's ``__init__`` (its per-field ``object.__setattr__`` is ~5x the cost of filling
    ``__dict__``; Obstacle has no ``__post_init__``), as the shapes' records
    (``geometry.shapes._ellipses``): the fields stored one by one, no keyword dictionary per
    record. Shared by the scan path and the unorganised path."""
    new = object.__new__
    out = []
    for k in range(len(n_triangles)):
        o = new(Obstacle)
        d = o.__dict__
        d["id"] = k + 1
        d["n_triangles"] = n_triangles[k]
        d["n_points"] = n_points[k]
        d["z_min"] = z_min[k]
        d["z_max"] = z_max[k]
        d["boundary_xy"] = boundary_xy[k]
        d["polygon_xy"] = polygon_xy[k]
        d["shadow_xy"] = shadow_xy[k]
        d["shadow_area"] = shadow_area[k]
        d["shapes"] = shapes[k]
        d["guaranteed"] = guaranteed[k]
        out.append(o)
    return out


def detect_obstacles(
    scan: RangeScan, settings: ObstacleSettings | None = None
) -> ObstacleDetection:
    """The eight stages of paper 1 on a :class:`~navkit.sensors.RangeScan`.

    Stage 1 computes ``x = d cos b cos a, y = d cos b sin a, z = z_D + d sin b`` in the level body
    frame (the scan's ``R_body_sensor`` and ``sensor_height`` give the mounting). The grid must
    have azimuth and elevation rising along its axes; scans with falling angles are flipped.

    Examples
    --------
    >>> import numpy as np
    >>> from navkit.sensors import RangeScan
    >>> az, el = np.radians(np.arange(-90, 91)), np.radians(np.arange(-30, 1))
    >>> d = 1.5 / np.sin(-np.minimum(el, -1e-3))           # level ground, sensor at 1.5 m
    >>> scan = RangeScan(np.tile(d, (az.size, 1)), az, el, sensor_height=1.5, max_range=50)
    >>> result = detect_obstacles(scan)
    >>> len(result.obstacles), result.counts["obstacle"]
    (0, 0)
    """
    if not isinstance(scan, RangeScan):
        raise InputError(
            f"got {type(scan).__name__}", field="scan", expected="a navkit.sensors.RangeScan"
        )
    t0, c0 = time.perf_counter(), time.process_time()
    az, el = scan.azimuth, scan.elevation
    P = scan.points("body")
    ia = np.argsort(az, kind="stable")
    ie = np.argsort(el, kind="stable")
    P = P[ia][:, ie]
    origin = scan.T_body_sensor[:3, 3]
    t_points, c_points = time.perf_counter() - t0, time.process_time() - c0
    res = detect_obstacles_grid(P, origin, settings, azimuth=az[ia], source="scan")
    res.timings["points"] += t_points
    res.cpu_timings["points"] += c_points
    return res


def unsort_vertex_array(scan: RangeScan, values: NDArray[Any]) -> NDArray[Any]:
    """Put a per-vertex array of :func:`detect_obstacles` back into the scan's own grid order."""
    ia = np.argsort(scan.azimuth, kind="stable")
    ie = np.argsort(scan.elevation, kind="stable")
    out = np.empty_like(values)
    out[np.ix_(ia, ie)] = values
    return out


def _with_wrap(settings: ObstacleSettings, wrap: bool) -> ObstacleSettings:
    """``settings`` with ``wrap_azimuth=wrap``, one validated copy per pair: ``replace`` runs
    ``__post_init__``'s checks (~0.25 ms), which a detection per frame need not repeat
    (settings holding an unhashable value are copied each time)."""
    try:
        return _with_wrap_cached(settings, wrap)
    except TypeError:
        return replace(settings, wrap_azimuth=wrap)


@functools.lru_cache(maxsize=32)
def _with_wrap_cached(settings: ObstacleSettings, wrap: bool) -> ObstacleSettings:
    return replace(settings, wrap_azimuth=wrap)


def detect_obstacles_in_grid(
    grid: ScanGrid,
    mounting: Mounting | None = None,
    settings: ObstacleSettings | None = None,
    *,
    source: str = "grid",
) -> ObstacleDetection:
    """Stages 1-8 on a :class:`~navkit.obstacles.grids.ScanGrid` (a recovered lidar grid, an
    organised cloud or a depth image), mounted on the robot as ``mounting`` says.

    With ``settings.wrap_azimuth = None`` the mesh closes across the seam when the grid covers
    360 deg. Per-point labels: ``grid.per_point(result.vertex_labels)``.
    """
    mounting = mounting or Mounting()
    settings = settings or ObstacleSettings()
    t0, c0 = time.perf_counter(), time.process_time()
    clock = _Clock()  # the compiled stage 1 below charges it
    if settings.wrap_azimuth is None:
        settings = _with_wrap(settings, bool(grid.wraps))
    R = mounting.R_body_sensor
    S = grid.points
    if (
        kernels_enabled()
        and S.ndim == 3
        and S.shape[2] == 3
        and min(S.shape[:2]) >= 2
        and np.all((np.abs(R) == 1).sum(axis=1) == 1)
        and np.all((R == 0).sum(axis=1) == 2)
    ):
        # stage 1 in one pass (mounting.to_body + the validity codes, the same bits: R only
        # permutes and flips axes, see _kernels_grid.body_points_kernel)
        from navkit.obstacles import _kernels_grid
        from navkit.obstacles._buffers import arena

        P, valid = arena([(S.shape, np.float64), (S.shape[:2], np.bool_)])
        S64 = np.ascontiguousarray(S, dtype=np.float64)
        n_valid, n_far = _kernels_grid.body_points_kernel(
            S64, R, float(mounting.height_m), P, valid, MAX_COORDINATE_M
        )
        if n_far:  # the body points of a permuting mounting: the sensor's coordinates + height
            check_coordinates(P, field="points", source=source)
        if n_valid:
            clock.lap("points")
            res = _detect_from_stage_1(
                P, valid, mounting.T_body_sensor[:3, 3], settings, None, clock, True
            )
            return res
    P = mounting.to_body(grid.points)
    t_points, c_points = time.perf_counter() - t0, time.process_time() - c0
    res = detect_obstacles_grid(P, mounting.T_body_sensor[:3, 3], settings, source=source)
    res.timings["points"] += t_points
    res.cpu_timings["points"] += c_points
    return res
