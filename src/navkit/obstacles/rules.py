"""Stage 5 of paper 1: production rules P1-P5 and the five triangle classes."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from navkit.jit import kernels_enabled
from navkit.obstacles.mesh import (
    MeshCharacteristics,
    build_mesh,
    robust_cell_normals,
    robust_strides_compiled,
    smooth_normals,
    triangle_indices,
)
from navkit.obstacles.settings import ObstacleSettings

__all__ = [
    "GROUND",
    "OBSTACLE",
    "SHADOW_BEHIND",
    "SIDE_SHADOW",
    "UNRELIABLE",
    "classify",
    "mesh_and_classes",
    "zone_cosine",
]

GROUND = 0
"""m_t = 0: the underlying (traversable) surface."""
UNRELIABLE = -1
"""m_t = -1: a vertex without a valid measurement (C_d)."""
OBSTACLE = -2
"""m_t = -2: obstacle."""
SIDE_SHADOW = -3
"""m_t = -3: side shadow (zone III across a height jump)."""
SHADOW_BEHIND = -4
"""m_t = -4: shadow behind the obstacle (zone II across a height jump)."""

_HUGE = 1.0e6
_SEG = 1.0e7


def zone_cosine(normal: NDArray[Any], ray: NDArray[Any]) -> NDArray[np.float64]:
    """Cosine between the horizontal projections of normal and line of sight (in D'x'y').

    Positive: co-directed (zone II, behind); negative: opposed (zone I, front); near 0 or a
    vertical normal: zone III (sides).
    """
    nh, rh = normal[..., :2], ray[..., :2]
    num = np.einsum("...i,...i->...", nh, rh)
    den = np.linalg.norm(nh, axis=-1) * np.linalg.norm(rh, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 1e-9, num / np.where(den > 0, den, 1.0), 0.0)


def classify(
    mesh: MeshCharacteristics,
    settings: ObstacleSettings,
    *,
    wrap: bool,
    robust_cells: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.int8], dict[str, NDArray[np.bool_]]]:
    """Labels ``m_t (R, 2C) int8`` from the production rules (paper 1, stage 5).

    Rules, per reliable triangle:

    - P1: the (robust, see :func:`smooth_normals`) normal is tilted from the vertical by more than
      ``c1``; a triangle with a height jump uses its own normal.
    - P2 / P3: the horizontal projection of the normal is co-directed (``cos > c2``, zone II) /
      opposed (``cos < -c2``, zone I) to the line of sight's.
    - P4: no height jump (see :class:`MeshCharacteristics`).
    - P5: the previous triangle along the rising ray (axis 1) is an obstacle - evaluated as "an
      earlier P1 triangle in the same run of non-shadow, reliable triangles", and only while the
      triangle is ``chain_min_height_m`` above the lowest P1 triangle of that run.

    Productions in this order **[reading: the printed formula is damaged; the order follows the
    paper's explanation]**: ``P2 & ~P4 -> -4``; ``~(P2 | P3) & ~P4 -> -3`` (a side shadow lies
    across a jump); ``P1 | P5 -> -2``; otherwise ``0``; unreliable triangles ``-1``.

    Returns
    -------
    labels : (R, 2C) int8
    rules : dict of (R, 2C) bool
        ``P1 .. P5`` as evaluated (for inspection and tests).

    NumPy only: with the compiled kernels the detector evaluates the rules inside the stage 2-5
    kernel (:func:`mesh_and_classes`), the same labels.
    """
    ok = mesh.valid
    jump = mesh.jump
    # zones matter only across a jump: evaluate them there only
    # (flat indices and ``take``: the jumps are a few % of the triangles, boolean masks over the
    # (R, 2C, 3) arrays cost more than the gather)
    cosz = np.zeros(ok.shape)
    j = np.flatnonzero(jump)
    first = mesh.triangles.reshape(-1).take(3 * j)  # (a take on a strided view copies it)
    cosz.ravel()[j] = zone_cosine(
        mesh.normal.reshape(-1, 3).take(j, axis=0),
        mesh.vertex_ray.reshape(-1, 3).take(first, axis=0),
    )
    p2 = jump & (cosz > settings.c2)
    p3 = jump & (cosz < -settings.c2)
    p4 = ok & ~jump
    shadow_behind = ok & p2 & ~p4
    side_shadow = ok & ~p2 & ~p3 & ~p4
    shadow = shadow_behind | side_shadow

    if settings.normal_support > 0:
        nrm = mesh.normal
        if robust_cells is not None:
            # the cell's robust normal for both of its triangles; the own normal where it has none
            rc = np.repeat(robust_cells, 2, axis=1)
            nrm = np.where(np.isfinite(rc[..., 2:3]), rc, nrm)
        nz = smooth_normals(nrm, ok & ~jump, settings.normal_support, wrap)[..., 2]
    elif robust_cells is not None:
        # only the vertical component matters for P1: the same choice on z alone
        rcz = np.repeat(robust_cells[..., 2], 2, axis=1)
        nz = np.where(np.isfinite(rcz), rcz, mesh.normal[..., 2])
    else:
        nz = mesh.normal[..., 2]
    nz = np.where(jump, mesh.normal[..., 2], nz)
    with np.errstate(invalid="ignore"):
        p1 = ok & ~shadow & (nz < math.cos(settings.c1_rad))

    # P5 as a run-length chain along axis 1, vectorised with a segmented running minimum:
    # runs are broken by shadows and unreliable triangles; the key subtracts a per-run offset so
    # that np.minimum.accumulate restarts at each break.
    breaker = ~ok | shadow
    seg = np.cumsum(breaker, axis=1, dtype=np.int32).astype(np.float64)  # exact small integers
    val = np.where(p1, mesh.z_min, _HUGE)
    val = np.where(breaker, _HUGE, val)
    base = np.minimum.accumulate(val - seg * _SEG, axis=1) + seg * _SEG
    with np.errstate(invalid="ignore"):
        p5 = ~breaker & (base < _HUGE / 2) & (mesh.z_min - base >= settings.chain_min_height_m)
    obstacle = ok & ~shadow & (p1 | p5)

    labels = np.full(ok.shape, UNRELIABLE, dtype=np.int8)
    labels[ok] = GROUND
    labels[obstacle] = OBSTACLE
    labels[side_shadow] = SIDE_SHADOW
    labels[shadow_behind] = SHADOW_BEHIND
    return labels, {"P1": p1, "P2": p2, "P3": p3, "P4": p4, "P5": p5}


def mesh_and_classes(
    points: NDArray[np.float64],
    valid: NDArray[np.bool_],
    sensor_origin: NDArray[np.float64],
    settings: ObstacleSettings,
    *,
    wrap: bool,
    rules: bool = False,
) -> tuple[MeshCharacteristics, NDArray[np.int8], dict[str, NDArray[np.bool_]]]:
    """Stages 2-5: the mesh with H_s and C_d (:func:`~navkit.obstacles.mesh.build_mesh`), the
    robust normals (:func:`~navkit.obstacles.mesh.robust_cell_normals`, when
    ``settings.normal_support_m > 0``) and the classes (:func:`classify`).

    With the compiled kernels (:mod:`navkit.jit`; and ``normal_support = 0``) the three run as
    one pass over the grid (:func:`navkit.obstacles._kernels_mesh.stages_2_5_kernel`): each
    cell's two triangles get their normal, jump test, robust normal and class at once, and the
    robust vertex normals are computed one row ahead of the cells that use them. The results are
    those of the three functions one after the other (the NumPy twin), bit for bit. With
    ``normal_support > 0`` (a box filter over the normals, SciPy's) the twin runs.

    Parameters
    ----------
    points : (n_az, n_el, 3) float
        Body-frame points (NaN where invalid), as stage 1 leaves them.
    valid : (n_az, n_el) bool
        Validity codes C_d.
    sensor_origin : (3,) float
        Sensor position in the body frame.
    settings : ObstacleSettings
    wrap : bool
        The mesh closes across the azimuth seam.
    rules : bool
        Also return the rules P1-P5 (the compiled pass writes them only when asked).

    Returns
    -------
    mesh : MeshCharacteristics
    labels : (R, 2C) int8
        Classes m_t.
    rules : dict of (R, 2C) bool
        ``P1 .. P5`` (empty unless ``rules``).
    """
    return _mesh_and_classes(
        points,
        valid,
        sensor_origin,
        settings,
        wrap=wrap,
        rules=rules,
        full_mesh=True,
        compiled=kernels_enabled(),
    )


def _mesh_and_classes(
    points: NDArray[np.float64],
    valid: NDArray[np.bool_],
    sensor_origin: NDArray[np.float64],
    settings: ObstacleSettings,
    *,
    wrap: bool,
    rules: bool,
    full_mesh: bool,
    compiled: bool,
) -> tuple[MeshCharacteristics, NDArray[np.int8], dict[str, NDArray[np.bool_]]]:
    """:func:`mesh_and_classes` (``compiled``: the kernel, as the caller decided from
    :func:`navkit.jit.kernels_enabled`); with ``full_mesh=False`` (the detector's path) the compiled pass
    leaves out the mesh fields no later stage reads - ``valid``, ``vertex_ray`` and
    ``range_mean`` are then empty arrays - which saves ~2.75 MB of writes per KITTI grid (and the
    zeroing of their fresh pages). Every other field, the classes and the rules are the same."""
    jump_kw = {
        "jump_height_m": settings.jump_height_m,
        "jump_range_fraction": settings.jump_range_fraction,
        "jump_range_ratio": settings.jump_range_ratio,
    }
    steep_cos = math.cos(settings.c1_rad)
    if not compiled or settings.normal_support > 0:
        mesh = build_mesh(
            points,
            valid,
            sensor_origin,
            wrap=wrap,
            steep_cos=steep_cos,
            **jump_kw,
        )
        robust = None
        if settings.normal_support_m > 0:
            robust = robust_cell_normals(
                points,
                valid,
                sensor_origin,
                support_m=settings.normal_support_m,
                wrap=wrap,
                jump_height_m=settings.jump_height_m,
                jump_range_fraction=settings.jump_range_fraction,
                jump_range_ratio=settings.jump_range_ratio,
            )
        labels, found = classify(mesh, settings, wrap=wrap, robust_cells=robust)
        return mesh, labels, found if rules else {}
    from navkit.obstacles import _kernels_mesh
    from navkit.obstacles._buffers import arena, cached_work

    n_az, n_el = valid.shape
    origin = np.asarray(sensor_origin, dtype=np.float64).reshape(3)
    use_robust = settings.normal_support_m > 0
    max_stride = 32  # robust_cell_normals' default
    if use_robust:
        k_scale, m_col = robust_strides_compiled(
            points, valid, origin, settings.normal_support_m, max_stride
        )
    else:
        k_scale, m_col = np.float32(1.0), np.ones(n_el, dtype=np.intp)
    use_ratio = bool(np.isfinite(settings.jump_range_ratio))
    ratio = settings.jump_range_ratio if use_ratio else 0.0
    R = n_az if wrap else n_az - 1
    C2 = 2 * (n_el - 1)
    nv = n_az * n_el
    P2 = 2 * R * n_el
    L = max(nv + n_el + 1, P2)
    nr = P2 if rules else 0
    work = cached_work(
        ("stages 2-5", n_az, n_el, bool(wrap), bool(rules)),
        lambda: arena(
            [
                ((14, L), np.float32),
                ((3, L), np.bool_),
                ((P2,), np.int8),
                ((5, nr), np.bool_),
                ((nv,), np.float64),
                ((nv,), np.int64),
            ]
        ),
    )
    rr, rc = (R, C2) if rules else (0, 0)
    mr, mc, ma = (R, C2, n_az) if full_mesh else (0, 0, 0)
    outs = arena(
        [
            ((mr, mc), np.bool_),
            ((R, C2, 3), np.float32),
            ((ma, n_el, 3), np.float32),
            ((mr, mc), np.float32),
            ((R, C2), np.float32),
            ((R, C2), np.float32),
            ((R, C2), np.bool_),
            ((R, C2), np.int8),
            ((5, rr, rc), np.bool_),
        ]
    )
    _kernels_mesh.stages_2_5_kernel(
        np.ascontiguousarray(points, dtype=np.float64),
        np.ascontiguousarray(valid, dtype=np.bool_),
        origin,
        bool(wrap),
        np.float32(settings.jump_height_m),
        np.float32(settings.jump_range_fraction),
        np.float32(ratio),
        use_ratio,
        np.float32(steep_cos),
        True,
        use_robust,
        k_scale,
        m_col,
        max_stride,
        float(settings.jump_height_m),
        float(settings.jump_range_fraction),
        float(ratio),
        float(settings.c2),
        np.float32(math.cos(settings.c1_rad)),
        float(settings.chain_min_height_m),
        bool(rules),
        bool(full_mesh),
        *work,
        *outs,
    )
    ok, normal, vray, rng, z_min, z_max, jump, labels, found_rules = outs
    tri = triangle_indices(n_az, n_el, wrap)
    mesh = MeshCharacteristics(tri, ok, normal, vray, rng, z_min, z_max, jump)
    found = dict(zip(("P1", "P2", "P3", "P4", "P5"), found_rules, strict=True)) if rules else {}
    return mesh, labels, found
