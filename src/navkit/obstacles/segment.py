"""Stages 6-7 of paper 1: separate obstacles, shadows to their obstacle, boundary vertices."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from navkit.obstacles.rules import GROUND, OBSTACLE, SHADOW_BEHIND, SIDE_SHADOW, UNRELIABLE

__all__ = [
    "MESH_STRUCTURE",
    "assign_shadows",
    "boundary_vertices",
    "label_components",
    "vertex_incidence",
    "vertex_labels",
]

MESH_STRUCTURE = np.array([[0, 0, 1], [1, 1, 1], [1, 0, 0]], dtype=bool)
"""Neighbourhood of a triangle in the interleaved ``(R, 2C)`` layout: offsets ``(0, +-1)`` and
``(+-1, -+1)`` cover the three edge neighbours of every triangle (plus one vertex neighbour)."""

_OFFSETS = ((0, 1), (0, -1), (1, -1), (-1, 1))


def _pairs(
    a: NDArray[Any],
    b: NDArray[Any],
    wrap: bool,
    where: NDArray[np.bool_] | None = None,
    *,
    seam_only: bool = False,
) -> tuple[NDArray[Any], NDArray[Any]]:
    """Values of ``a`` and ``b`` at every pair of mesh-adjacent triangles (``a`` first).

    ``where`` (same shape as ``a``) keeps only the pairs whose first triangle is selected (done per
    offset, so the full pair list is never built); ``seam_only`` returns only the pairs across
    the azimuth seam (those that ``ndimage.label`` on the array cannot see).
    """
    out_a, out_b = [], []
    for di, dj in _OFFSETS:
        rs_a = slice(max(0, -di), a.shape[0] - max(0, di))
        rs_b = slice(max(0, di), a.shape[0] - max(0, -di))
        cs_a = slice(max(0, -dj), a.shape[1] - max(0, dj))
        cs_b = slice(max(0, dj), a.shape[1] - max(0, -dj))
        if not seam_only:
            if where is None:
                out_a.append(a[rs_a, cs_a].ravel())
                out_b.append(b[rs_b, cs_b].ravel())
            else:
                w = where[rs_a, cs_a]
                out_a.append(a[rs_a, cs_a][w])
                out_b.append(b[rs_b, cs_b][w])
        if wrap and di != 0:
            ra, rb = (-1, 0) if di == 1 else (0, -1)
            if where is None:
                out_a.append(a[ra, cs_a])
                out_b.append(b[rb, cs_b])
            else:
                w = where[ra, cs_a]
                out_a.append(a[ra, cs_a][w])
                out_b.append(b[rb, cs_b][w])
    if not out_a:
        return np.empty(0, dtype=a.dtype), np.empty(0, dtype=b.dtype)
    return np.concatenate(out_a), np.concatenate(out_b)


def label_components(mask: NDArray[np.bool_], wrap: bool) -> tuple[NDArray[np.int32], int]:
    """Connected components of ``mask (R, 2C)`` on the mesh (stage 6): labels 1..n, 0 elsewhere."""
    lab, n = ndimage.label(mask, structure=MESH_STRUCTURE)
    lab = lab.astype(np.int32)
    if wrap and n > 1 and mask.shape[0] > 1:
        a, b = _pairs(lab, lab, True, seam_only=True)  # inside the array: ndimage.label
        keep = (a > 0) & (b > 0) & (a != b)
        if keep.any():
            g = coo_matrix((np.ones(int(keep.sum())), (a[keep], b[keep])), shape=(n + 1, n + 1))
            _, comp = connected_components(g, directed=False)
            # renumber so that label 0 stays 0 and the others are consecutive from 1
            _, new = np.unique(comp[1:], return_inverse=True)
            lut = np.concatenate([[0], new + 1]).astype(np.int32)
            lab = lut[lab]
            n = int(lut.max())
    return lab, n


def assign_shadows(
    labels: NDArray[np.int8], obstacle_id: NDArray[np.int32], wrap: bool
) -> NDArray[np.int32]:
    """Owner obstacle id ``(R, 2C)`` of every shadow triangle (0 = none found; stage 6).

    Shadow triangles (``-3``, ``-4``) are grouped into connected shadow zones; each zone goes to
    the obstacle it shares the most triangle adjacencies with **[reading: the paper says only
    that every shadow belongs to its obstacle; a shadow zone touches the obstacle that casts it]**.
    """
    shadow = (labels == SIDE_SHADOW) | (labels == SHADOW_BEHIND)
    owner = np.zeros(labels.shape, dtype=np.int32)
    if not shadow.any() or obstacle_id.max() == 0:
        return owner
    sl, ns = label_components(shadow, wrap)
    a, b = _pairs(sl, obstacle_id, wrap, sl > 0)
    keep = b > 0
    if not keep.any():
        return owner
    nobs = int(obstacle_id.max()) + 1
    keys, counts = np.unique(a[keep].astype(np.int64) * nobs + b[keep], return_counts=True)
    zone, obs = keys // nobs, keys % nobs
    order = np.lexsort((counts, zone))  # by zone, then count ascending: the last per zone wins
    zone, obs = zone[order], obs[order]
    last = np.r_[zone[1:] != zone[:-1], True]
    lut = np.zeros(ns + 1, dtype=np.int32)
    lut[zone[last]] = obs[last]
    owner[shadow] = lut[sl[shadow]]
    return owner


def _incident_slices(
    values: NDArray[Any], n_az: int, n_el: int, wrap: bool, fill: int
) -> list[NDArray[Any]]:
    """The six ``(n_az, n_el)`` views "value of the k-th triangle around each vertex".

    Vertex ``(p, q)`` belongs to ``T_a(p, q)``, ``T_a(p, q-1)``, ``T_a(p-1, q)``, ``T_b(p-1, q)``,
    ``T_b(p, q-1)`` and ``T_b(p-1, q-1)`` (``T_a`` = even, ``T_b`` = odd interleaved columns);
    missing triangles (grid border) read ``fill``.
    """
    ta, tb = values[:, 0::2], values[:, 1::2]
    R, C = ta.shape

    # pad by one on every side (wrap: the rows continue cyclically) so every neighbour is a slice
    def padded(t: NDArray[Any]) -> NDArray[Any]:
        out = np.full((n_az + 2, C + 2), fill, dtype=values.dtype)
        out[1 : R + 1, 1 : C + 1] = t
        if wrap:
            out[0, 1 : C + 1] = t[-1]
        return out

    pa, pb = padded(ta), padded(tb)
    # vertex (p, q) -> padded index (p + 1 + di, q + 1 + dj)
    return [
        t[1 + di : 1 + di + n_az, 1 + dj : 1 + dj + n_el]
        for t, di, dj in (
            (pa, 0, 0),
            (pa, 0, -1),
            (pa, -1, 0),
            (pb, -1, 0),
            (pb, 0, -1),
            (pb, -1, -1),
        )
    ]


def vertex_incidence(
    values: NDArray[Any], n_az: int, n_el: int, wrap: bool, fill: int
) -> NDArray[Any]:
    """The values of the (up to) six triangles around every vertex: ``(n_az, n_el, 6)``.

    See :func:`_incident_slices` for which triangles; missing ones (grid border) get ``fill``.
    """
    return np.stack(_incident_slices(values, n_az, n_el, wrap, fill), axis=-1)


_FLAG = {GROUND: 1, SHADOW_BEHIND: 2, SIDE_SHADOW: 4, OBSTACLE: 8}


def vertex_labels(
    tri_labels: NDArray[np.int8], valid: NDArray[np.bool_], wrap: bool
) -> NDArray[np.int8]:
    """One class per grid vertex from its triangles (for per-point output).

    Priority: obstacle if any incident triangle is an obstacle, else ground if any is ground, else
    shadow behind, else side shadow, else unreliable; vertices without a return are unreliable.
    """
    lut = np.zeros(256, dtype=np.uint8)
    for cls, bit in _FLAG.items():
        lut[cls & 0xFF] = bit
    flags = lut[tri_labels.view(np.uint8)]
    acc = np.zeros(valid.shape, dtype=np.uint8)
    for sl in _incident_slices(flags, valid.shape[0], valid.shape[1], wrap, 0):
        acc |= sl
    out = np.full(valid.shape, UNRELIABLE, dtype=np.int8)
    for cls in (SIDE_SHADOW, SHADOW_BEHIND, GROUND, OBSTACLE):  # increasing priority
        out[(acc & _FLAG[cls]) > 0] = cls
    out[~valid] = UNRELIABLE
    return out


def main_ground_vertices(
    tri_labels: NDArray[np.int8], n_az: int, n_el: int, wrap: bool, min_share: float = 0.1
) -> NDArray[np.bool_]:
    """Vertices of the main ground zones: ground components (on the mesh) holding at least
    ``min_share`` of the largest one's triangles - the ground reachable around the robot."""
    lab, n = label_components(tri_labels == GROUND, wrap)
    if n == 0:
        return np.zeros((n_az, n_el), dtype=bool)
    size = np.bincount(lab.ravel(), minlength=n + 1)
    size[0] = 0
    main = size >= min_share * size.max()
    flags = main[lab].astype(np.uint8)
    acc = np.zeros((n_az, n_el), dtype=np.uint8)
    for sl in _incident_slices(flags, n_az, n_el, wrap, 0):
        acc |= sl
    return acc > 0


def boundary_vertices(
    obstacle_id: NDArray[np.int32], n_az: int, n_el: int, wrap: bool
) -> tuple[NDArray[Any], NDArray[np.bool_]]:
    """Stage 7: the obstacle id of every vertex and the boundary mask ``(n_az, n_el)``.

    A boundary vertex is one where only part of the triangles containing it belong to the
    obstacle (a vertex on the grid's edge counts as boundary: the triangles beyond are unknown).
    """
    sl = _incident_slices(obstacle_id.astype(np.int32), n_az, n_el, wrap, 0)
    vmax = sl[0].copy()
    vmin = sl[0].copy()
    for t in sl[1:]:
        np.maximum(vmax, t, out=vmax)
        np.minimum(vmin, t, out=vmin)
    boundary = (vmax > 0) & (vmin != vmax)
    return vmax, boundary


def merge_close_components(
    obstacle_id: NDArray[np.int32],
    n: int,
    points: NDArray[np.floating],
    wrap: bool,
    distance_m: float,
    gap_cells: int,
) -> tuple[NDArray[np.int32], int]:
    """Merge obstacle components whose vertices come within ``distance_m`` (3D) across a gap of at
    most ``gap_cells`` grid cells (stage 6).

    **[reading: the paper splits obstacle zones by mesh connectivity; on real scans one object is
    often cut into several zones by a missing return (a car window) or a small jump inside it; a
    robot cannot pass between parts closer than ``distance_m`` anyway]**. Vectorised over vertex
    pairs at each grid offset, then a union-find by ``scipy.sparse.csgraph``.
    """
    if n < 2 or gap_cells < 1 or distance_m <= 0:
        return obstacle_id, n
    n_az, n_el = points.shape[:2]
    vid, boundary = boundary_vertices(obstacle_id, n_az, n_el, wrap)
    vflat = vid.ravel()
    # one contiguous array per coordinate: gathers of single values, no (K, 3) row reductions
    X, Y, Z = (np.ascontiguousarray(points[..., k]).ravel() for k in range(3))
    # a gap to another obstacle starts at a boundary vertex: only those are sources
    src = np.flatnonzero(boundary.ravel())
    si, sj = np.divmod(src, n_el)
    a_all, b_all = [], []
    for di in range(0, gap_cells + 1):
        for dj in range(-gap_cells, gap_cells + 1):
            if (di, dj) <= (0, 0):
                continue
            ti, tj = si + di, sj + dj
            ok = (tj >= 0) & (tj < n_el)
            if wrap:
                # 0 <= di: one subtraction wraps unless the gap spans the whole grid
                ti = np.where(ti >= n_az, ti - n_az, ti) if gap_cells < n_az else ti % n_az
            else:
                ok &= ti < n_az
            s_ok = src[ok]
            t = ti[ok] * n_el + tj[ok]
            va, vb = vflat[s_ok], vflat[t]
            cand = (vb > 0) & (va != vb)
            if not cand.any():
                continue
            sc, tc = s_ok[cand], t[cand]
            dx, dy, dz = X[sc] - X[tc], Y[sc] - Y[tc], Z[sc] - Z[tc]
            d = np.sqrt(dx * dx + dy * dy + dz * dz)
            close = d < distance_m
            a_all.append(va[cand][close])
            b_all.append(vb[cand][close])
    if not a_all or sum(len(a) for a in a_all) == 0:
        return obstacle_id, n
    a, b = np.concatenate(a_all), np.concatenate(b_all)
    g = coo_matrix((np.ones(len(a)), (a, b)), shape=(n + 1, n + 1))
    _, comp = connected_components(g, directed=False)
    _, new = np.unique(comp[1:], return_inverse=True)
    lut = np.concatenate([[0], new + 1]).astype(np.int32)
    return lut[obstacle_id], int(lut.max())
