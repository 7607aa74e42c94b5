"""Region growing of the organised plane extraction (:mod:`navkit.planes.extract`, steps 2-4
and 5's border candidates): planar patches, their graph and connected components, pruning and
merging of regions, and the patches on the regions' borders. Each function runs the compiled
kernel (:mod:`navkit.planes._kernels`) or its NumPy twin, the same bits either way."""

from __future__ import annotations

import logging
from collections.abc import Callable

import cv2
import numpy as np
from numpy.typing import NDArray

from navkit.planes.moments import (
    ExtractionSettings,
    _dot3,
    _kernels,
    _planes_from_rows,
    _rank1_normals,
    _RegionPlanes,
    _sum_rows,
)

log = logging.getLogger(__name__)

# ------------------------------------------------------------------------------ region growing


def _grow_regions(
    M: NDArray[np.float64], hc: int, wc: int, s: ExtractionSettings, compiled: bool = False
) -> tuple[int, NDArray[np.int64], int, _RegionPlanes | None]:
    """Steps 2-4: planar patches, region growing, pruning, merging.

    Returns the number of regions, the region of each patch ``(G,)`` (``-1`` = none), the
    number of planar patches and the regions' planes ``(normals, rho)``
    (``_planes_from_rows(_sum_rows(comp, n, M))``) when they are known - the NumPy path has them
    when the merge joined no regions (computed for the merge test), the compiled path always
    (:func:`navkit.planes._kernels.prune_merge`: steps 3-4 in one call) - else ``None``.
    """
    c = int(s.cell)
    G = hc * wc
    cos_t = np.cos(np.radians(s.angle_deg))
    if compiled:  # the planar test, the edge tests and the components as compiled loops
        kern = _kernels()
        normal, d, rms, mean, rank1 = kern.plane_rows(M)
        # a repeated smallest eigenvalue: LAPACK's vector as the NumPy path, but only for the
        # patches that can pass the planar test - the edges and the pruning use no other
        # patch's plane (the ~100 empty patches and the 1- or 2-pixel ones need none)
        rank1 &= M[:, 0] >= s.min_fill * c * c
        if rank1.any():
            _rank1_normals(M, rank1, normal, d)
        bound, planar, eh, ev = kern.patch_graph(
            normal,
            d,
            mean,
            np.ascontiguousarray(M[:, 0]),
            rms,
            hc,
            wc,
            s.min_fill * c * c,
            s.rms_base,
            s.rms_quadratic,
            float(cos_t),
            s.distance_factor,
        )

        status, n, comp, rn, rd = kern.prune_merge(
            M, normal, mean, bound, planar, eh, ev, hc, wc, int(s.min_cells), float(cos_t),
            s.distance_factor, s.rms_base, s.rms_quadratic,
        )  # fmt: skip
        if status == 0:
            return int(n), comp, int(planar.sum()), ((rn, rd) if n else None)

        # a region's smallest eigenvalue is repeated (a degenerate grid): step by step, LAPACK's
        # vector for that region as in the NumPy path
        def union_find(keep: NDArray[np.bool_]) -> tuple[int, NDArray[np.int64]]:
            n, comp = kern.cell_components(keep.reshape(hc, wc), eh, ev, int(s.min_cells))
            return int(n), comp

        return _prune_merge(M, normal, mean, bound, planar, union_find, s, cos_t, compiled)
    normal, d, rms, mean = _planes_from_rows(M)
    bound = s.noise(_dot3(mean, mean))
    planar = (M[:, 0] >= s.min_fill * c * c) & (rms < bound)
    ids = np.arange(G).reshape(hc, wc)
    pa = np.concatenate([ids[:, :-1].ravel(), ids[:-1, :].ravel()])
    pb = np.concatenate([ids[:, 1:].ravel(), ids[1:, :].ravel()])
    # edge tests that do not depend on the kept set: normals agree, centroids on each other's plane
    tol = s.distance_factor * np.maximum(bound[pa], bound[pb])
    edge_ok = (
        (_dot3(normal[pa], normal[pb]) > cos_t)
        & (np.abs(_dot3(normal[pa], mean[pb]) - d[pa]) < tol)
        & (np.abs(_dot3(normal[pb], mean[pa]) - d[pb]) < tol)
    )

    # the cell graph as an image: patches at even (row, col), the edge between two neighbours
    # at the odd position between them; its 4-connected components are the graph's components
    eh = edge_ok[: hc * (wc - 1)].reshape(hc, wc - 1)
    ev = edge_ok[hc * (wc - 1) :].reshape(hc - 1, wc)
    graph = np.zeros((2 * hc - 1, 2 * wc - 1), np.uint8)

    def regions(keep: NDArray[np.bool_]) -> tuple[int, NDArray[np.int64]]:
        k2 = keep.reshape(hc, wc)
        graph[0::2, 0::2] = k2
        graph[0::2, 1::2] = eh & k2[:, :-1] & k2[:, 1:]
        graph[1::2, 0::2] = ev & k2[:-1, :] & k2[1:, :]
        n_comp, lab = cv2.connectedComponents(graph, connectivity=4, ltype=cv2.CV_32S)
        comp = lab[0::2, 0::2].ravel().astype(np.int64) - 1  # background 0 -> -1
        sizes = np.bincount(comp[comp >= 0], minlength=n_comp - 1)
        big = sizes >= s.min_cells
        remap = -np.ones(n_comp, np.int64)  # index 0 = no component
        remap[1:][big] = np.arange(int(big.sum()))
        return int(big.sum()), remap[comp + 1]

    return _prune_merge(M, normal, mean, bound, planar, regions, s, cos_t)


def _prune_merge(
    M: NDArray[np.float64],
    normal: NDArray[np.float64],
    mean: NDArray[np.float64],
    bound: NDArray[np.floating],
    planar: NDArray[np.bool_],
    regions: Callable[[NDArray[np.bool_]], tuple[int, NDArray[np.int64]]],
    s: ExtractionSettings,
    cos_t: float,
    compiled: bool = False,
) -> tuple[int, NDArray[np.int64], int, _RegionPlanes | None]:
    """Steps 3-4 of :func:`_grow_regions` from the planar patches: regions (``regions(keep)``:
    the components of the kept patches' graph), pruning, regrouping, merging (``compiled``: the
    coplanar regions' components by union-find, :func:`navkit.planes._kernels.dense_components`,
    the same numbering)."""
    n_planar = int(planar.sum())
    n_reg, comp = regions(planar)
    if n_reg == 0:
        return 0, comp, n_planar, None
    # 4. prune patches that disagree with their region's refit plane, then regroup
    rn, rd, _, _ = _planes_from_rows(_sum_rows(comp, n_reg, M))
    r = np.maximum(comp, 0)
    agree = (_dot3(normal, rn[r]) > cos_t) & (
        np.abs(_dot3(rn[r], mean) - rd[r]) < s.distance_factor * bound
    )
    n_reg, comp = regions(planar & (comp >= 0) & agree)
    if n_reg == 0:
        return 0, comp, n_planar, None
    # merge coplanar regions (e.g. a wall cut in two by an object in front of it)
    rn, rd, _, rmean = _planes_from_rows(_sum_rows(comp, n_reg, M))
    rtol = s.distance_factor * s.noise(_dot3(rmean, rmean))
    same = (_dot3(rn[:, None], rn[None]) > cos_t) & (
        np.abs(_dot3(rn[:, None], rmean[None]) - rd[:, None])
        < np.maximum(rtol[:, None], rtol[None, :])
    )
    same &= same.T
    n_m, merged = _kernels().dense_components(same) if compiled else _dense_components(same)
    comp = np.where(comp >= 0, merged[np.maximum(comp, 0)], -1)
    # no regions joined (each its own component, numbered in order): comp and the planes stand
    return n_m, comp, n_planar, ((rn, rd) if n_m == n_reg else None)


def _dense_components(adj: NDArray[np.bool_]) -> tuple[int, NDArray[np.int64]]:
    """Connected components of a small symmetric adjacency matrix ``(n, n)`` by repeated
    squaring of its reachability matrix (log2(n) products of n x n: microseconds for the few
    dozen regions of a frame). Components are numbered by their first member."""
    n = len(adj)
    R = (adj | np.eye(n, dtype=bool)).astype(np.float32)
    for _ in range(max(1, int(np.ceil(np.log2(max(n, 2)))))):
        R2 = np.minimum(R @ R, 1.0)
        if np.array_equal(R2, R):
            break
        R = R2
    first = np.argmax(R > 0, axis=1)  # smallest member of each node's component
    roots, comp = np.unique(first, return_inverse=True)
    return len(roots), comp.astype(np.int64)


# ------------------------------------------------------------------------------ refinement


def _border_patches(
    cellmap: NDArray[np.int64], full: bool
) -> tuple[NDArray[np.bool_], NDArray[np.int64], NDArray[np.int64]]:
    """Which patches are assigned wholesale, and the candidate regions of the others.

    Returns ``wholesale (hc, wc)`` - region patches whose 8 neighbours are in the same region
    (the image border counts as the same region; none for ``refine="full"``) - the ids of the
    patches to refine pixel by pixel ``(B,)`` and their candidate regions ``(B, m)`` (their own
    and their 8 neighbours', each once, ``-1`` padded), by decreasing number of candidates.
    """
    hc, wc = cellmap.shape
    padded = np.pad(cellmap, 1, mode="edge")
    nb = np.stack(
        [
            padded[1 + di : 1 + di + hc, 1 + dj : 1 + dj + wc]
            for di in (-1, 0, 1)
            for dj in (-1, 0, 1)
        ]
    )  # (9, hc, wc), the patch itself in the middle
    if full:
        interior = np.zeros((hc, wc), bool)
    else:
        interior = (cellmap >= 0) & np.all(nb == cellmap[None], axis=0)
    cand = np.sort(nb.reshape(9, -1).T, axis=1)  # (G, 9)
    cand[:, 1:][cand[:, 1:] == cand[:, :-1]] = -1  # each region once
    cand = -np.sort(-cand, axis=1)  # regions first, -1 last
    n_cand = (cand >= 0).sum(axis=1)
    border = ~interior.ravel() & (n_cand > 0)
    ids = np.flatnonzero(border)
    ids = ids[np.argsort(-n_cand[ids], kind="stable")]
    m = int(n_cand[ids].max()) if len(ids) else 0
    return interior, ids, cand[ids, :m]
