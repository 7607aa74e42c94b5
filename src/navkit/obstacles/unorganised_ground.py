"""The ground under an unorganised cloud (:mod:`navkit.obstacles.unorganised`): the data's point
spacing and height noise, the lowest point per cell, and the ground surface - a progressive
opening, then triangulated irregular networks cut at height jumps - that the rules' heights are
measured from."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import Delaunay, QhullError, cKDTree

from navkit.errors import InputError
from navkit.obstacles.unorganised_settings import UnorganisedSettings


def point_spacing(xy: NDArray[np.float64], *, sample: int = 20_000) -> float:
    """Median horizontal nearest-neighbour distance (the data's point spacing), on at most
    ``sample`` query points (the median of a few thousand is stable to a few %)."""
    if len(xy) < 2:
        return float("nan")
    tree = cKDTree(xy)
    q = xy[:: max(1, len(xy) // sample)]
    d, _ = tree.query(q, k=2)
    pos = d[:, 1][d[:, 1] > 0]
    return float(np.median(pos)) if pos.size else float("nan")


def lowest_per_cell(
    xy: NDArray[np.float64],
    z: NDArray[np.float64],
    cell: float,
    subset: NDArray[np.int64] | None = None,
) -> NDArray[np.int64]:
    """Indices (into ``xy``) of the lowest point of each ``cell`` x ``cell`` square (among
    ``subset`` when given), sorted."""
    idx = np.arange(len(xy)) if subset is None else np.asarray(subset, dtype=np.int64)
    if idx.size == 0:
        return idx
    ij = np.floor((xy[idx] - xy[idx].min(axis=0)) / cell).astype(np.int64)
    key = ij[:, 0] * (int(ij[:, 1].max()) + 1) + ij[:, 1]
    o = np.lexsort((z[idx], key))
    first = np.ones(len(o), dtype=bool)
    first[1:] = key[o][1:] != key[o][:-1]
    return np.sort(idx[o[first]])


def _min_grid(
    xy: NDArray[np.float64], z: NDArray[np.float64], cell: float
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """The minimum surface: lowest z per cell, empty cells filled from the nearest full cell."""
    ij = np.floor((xy - xy.min(axis=0)) / cell).astype(np.int64)
    shape = (int(ij[:, 0].max()) + 1, int(ij[:, 1].max()) + 1)
    Z = np.full(shape[0] * shape[1], np.inf)
    np.minimum.at(Z, ij[:, 0] * shape[1] + ij[:, 1], z)
    Z = Z.reshape(shape)
    empty = ~np.isfinite(Z)
    if empty.any():
        _, ind = ndimage.distance_transform_edt(empty, return_indices=True)
        Z = Z[tuple(ind)]
    return Z, empty


def height_noise(Z: NDArray[np.float64]) -> float:
    """Height noise of a minimum surface: the robust spread (1.4826 x MAD) of each cell's
    second difference to its 3 x 3 neighbourhood's median, over the cells whose neighbourhood
    is smooth (the lower half of the local ranges: ground, not walls). For independent noise
    of deviation sigma on a plane this is about ``1.1 sigma``."""
    med = ndimage.median_filter(Z, size=3, mode="nearest")
    rng = ndimage.maximum_filter(Z, size=3) - ndimage.minimum_filter(Z, size=3)
    smooth = rng <= np.median(rng)
    r = (Z - med)[smooth]
    if r.size < 10:
        return 0.0
    return float(1.4826 * np.median(np.abs(r - np.median(r))))


# ----------------------------------------------------------------------------------------------
# the ground surface


@dataclass(frozen=True)
class GroundSurface:
    """A TIN through ground points: the ground estimate.

    Attributes
    ----------
    xy, z : arrays
        The TIN's vertices.
    tri : scipy.spatial.Delaunay or _Thinned
        Their Delaunay triangulation in x-y (``points``, ``simplices``, ``neighbors``): SciPy's,
        or the first jump pass's with the removed vertices taken out (:func:`_thinned`).
    band_m : float
        The ground band (m) the surface was built with.
    noise_m : float
        The measured height noise (m).
    lowest : (K,) int
        Index (into the points the surface was built from) of the lowest point of each cell of
        the minimum surface, sorted (:func:`lowest_per_cell`).
    """

    xy: NDArray[np.float64]
    z: NDArray[np.float64]
    tri: Any
    band_m: float
    noise_m: float
    lowest: NDArray[np.int64] = field(default_factory=lambda: np.empty(0, dtype=np.int64))

    def at(self, q: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Height and slope (rise over run) of the surface at ``q (M, 2)``; outside the hull
        the nearest vertex's height and slope 0."""
        return _tin_at(self.xy, self.z, self.tri, q)


TIE_BARYCENTRIC = 1e-9
"""A query whose barycentric coordinate in its triangle is within this of 0 lies on that
triangle's edge (two of them: on a vertex); far above the rounding of the coordinates
(~1e-13 for a tile's local coordinates) and far below any real offset from an edge."""


def _tin_at(
    vxy: NDArray[np.float64], vz: NDArray[np.float64], tri: Any, q: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Height and slope of the TIN at ``q``: each triangle's plane ``z = z0 + g . (p - p0)``
    (its gradient ``g`` from its two edges), evaluated in the triangle holding the query.

    The TIN is continuous, so a query on an edge or a vertex has one height whichever triangle
    holds it, but each triangle its own slope (the band's slope term). There the gentlest of
    the triangles meeting at the query is used: on a vertex the height is the vertex's own
    measured height, not an interpolation over a slope, and on an edge the interpolation runs
    along the edge. (Every ground vertex is a query, and so is every other return at its x-y.)
    """
    s = _find_simplex(tri, q)
    s0 = np.maximum(s, 0)
    V = np.asarray(tri.simplices, dtype=np.int64)
    A, Zv = vxy[V], vz[V]
    e1, e2 = A[:, 1] - A[:, 0], A[:, 2] - A[:, 0]
    d1, d2 = Zv[:, 1] - Zv[:, 0], Zv[:, 2] - Zv[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    det = np.where(det == 0.0, np.inf, det)  # a flat sliver: slope 0, its first vertex's height
    gx = (d1 * e2[:, 1] - d2 * e1[:, 1]) / det
    gy = (e1[:, 0] * d2 - e2[:, 0] * d1) / det
    tslope = np.hypot(gx, gy)
    p0 = A[s0, 0]
    zq = Zv[s0, 0] + gx[s0] * (q[:, 0] - p0[:, 0]) + gy[s0] * (q[:, 1] - p0[:, 1])
    slope = tslope[s0]
    # queries on an edge (the gentler of its two triangles) or a vertex (the gentlest around it)
    b = _barycentric(A[s0], q)
    on = (np.abs(b) <= TIE_BARYCENTRIC) & (s >= 0)[:, None]
    nb = tri.neighbors[s0]
    for i in range(3):
        m = on[:, i] & (nb[:, i] >= 0)
        slope[m] = np.minimum(slope[m], tslope[nb[m, i]])
    vert = np.count_nonzero(on, axis=1) >= 2
    if vert.any():
        gentlest = np.full(len(vxy), np.inf)
        np.minimum.at(gentlest, V.reshape(-1), np.repeat(tslope, 3))
        vi = V[s0[vert], np.argmax(b[vert], axis=1)]
        slope[vert] = gentlest[vi]
        zq[vert] = vz[vi]
    out = s < 0
    if out.any():
        _, nn = cKDTree(vxy).query(q[out])
        zq[out] = vz[nn]
        slope[out] = 0.0
    return zq, slope


def _framed(
    vxy: NDArray[np.float64],
    vz: NDArray[np.float64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    step: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The TIN vertices plus a frame around ``[lo, hi]`` (a vertex every ``step`` along the
    rectangle one step outside it), each at the height of its nearest vertex: every query in
    the rectangle is then inside the triangulation (SciPy's point location falls back to a
    search over every triangle for a query outside the hull)."""
    a, b = lo - step, hi + step
    nx = max(1, math.ceil((b[0] - a[0]) / step))
    ny = max(1, math.ceil((b[1] - a[1]) / step))
    xs = np.linspace(a[0], b[0], nx + 1)
    ys = np.linspace(a[1], b[1], ny + 1)[1:-1]
    frame = np.concatenate(
        [
            np.column_stack([xs, np.full_like(xs, a[1])]),
            np.column_stack([xs, np.full_like(xs, b[1])]),
            np.column_stack([np.full_like(ys, a[0]), ys]),
            np.column_stack([np.full_like(ys, b[0]), ys]),
        ]
    )
    _, nn = cKDTree(vxy).query(frame)
    return np.concatenate([vxy, frame]), np.concatenate([vz, vz[nn]])


WALK_STEPS = 256
"""Steps after which a point's walk is given up for a search of every triangle (a walk from
the nearest vertex takes a step or two; only rounding on near-degenerate triangles makes one
circle)."""


def _find_simplex(tri: Any, q: NDArray[np.float64]) -> NDArray[np.int64]:
    """The triangle of ``tri`` (``points``, ``simplices``, ``neighbors`` as SciPy's Delaunay)
    holding each query (within rounding; -1 outside), by a visibility walk in NumPy, all
    queries at once: each starts in a triangle of its nearest vertex and steps across the
    edge its most negative barycentric coordinate faces until a triangle holds it (a walk
    that terminates on a Delaunay triangulation; from the nearest vertex it is a step or
    two). SciPy's own ``find_simplex`` computes a LAPACK factorisation per triangle first,
    slow with a multi-threaded BLAS, and walks from the previous query, slow on a cloud in
    random order."""
    P = np.asarray(tri.points, dtype=np.float64)
    S = np.asarray(tri.simplices, dtype=np.int64)
    N = np.asarray(tri.neighbors, dtype=np.int64)
    out = np.full(len(q), -1, dtype=np.int64)
    if len(q) == 0 or len(S) == 0:
        return out
    start = np.full(len(P), -1, dtype=np.int64)
    start[S.reshape(-1)] = np.repeat(np.arange(len(S)), 3)
    used = np.flatnonzero(start >= 0)
    _, nn = cKDTree(P[used]).query(q)
    cur = start[used[nn]]
    todo = np.arange(len(q))
    for _ in range(WALK_STEPS):
        b = _barycentric(P[S[cur]], q[todo])
        low = np.argmin(np.where(np.isnan(b), -np.inf, b), axis=1)
        held = b[np.arange(len(todo)), low] >= -TIE_BARYCENTRIC
        out[todo[held]] = cur[held]
        nxt = N[cur[~held], low[~held]]
        todo, cur = todo[~held][nxt >= 0], nxt[nxt >= 0]
        if todo.size == 0:
            return out
    # walks that did not end (rounding on near-degenerate triangles): every triangle tried
    A = P[S]
    for k in todo.tolist():
        b = _barycentric(A, np.broadcast_to(q[k], (len(S), 2)))
        hit = np.flatnonzero((b >= -TIE_BARYCENTRIC).all(axis=1))
        out[k] = hit[0] if hit.size else -1
    return out


def _tin_edges(tri: Any) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Every edge of a triangulation in both directions (``i -> j`` and ``j -> i``)."""
    if isinstance(tri, Delaunay):
        ip, ix = tri.vertex_neighbor_vertices
        return np.repeat(np.arange(len(ip) - 1), np.diff(ip)), ix.astype(np.int64)
    # each edge once: from the triangle with the larger index, or from its only triangle
    S, nb = tri.simplices, tri.neighbors
    once = (nb < np.arange(len(S))[:, None]).reshape(-1)
    a = S[:, [1, 2, 0]].reshape(-1)[once]
    b = S[:, [2, 0, 1]].reshape(-1)[once]
    return np.concatenate([a, b]), np.concatenate([b, a])


def _neighbours(S: NDArray[np.int64], n: int) -> NDArray[np.int64]:
    """``(T, 3)`` the triangle across the edge opposite each vertex (-1 on the hull), as
    :attr:`scipy.spatial.Delaunay.neighbors`."""
    T = len(S)
    u, w = S[:, [1, 2, 0]].reshape(-1), S[:, [2, 0, 1]].reshape(-1)
    key = np.minimum(u, w) * n + np.maximum(u, w)
    order = np.argsort(key, kind="stable")
    k = key[order]
    pair = np.flatnonzero(k[1:] == k[:-1])
    nb = np.full(3 * T, -1, dtype=np.int64)
    a, b = order[pair], order[pair + 1]
    nb[a], nb[b] = b // 3, a // 3
    return nb.reshape(T, 3)


def _areas(P: NDArray[np.float64]) -> NDArray[np.float64]:
    return 0.5 * np.abs(
        (P[:, 1, 0] - P[:, 0, 0]) * (P[:, 2, 1] - P[:, 0, 1])
        - (P[:, 2, 0] - P[:, 0, 0]) * (P[:, 1, 1] - P[:, 0, 1])
    )


@dataclass(frozen=True)
class _Thinned:
    """A Delaunay triangulation with vertices taken out (:func:`_thinned`): ``simplices``
    index ``points``, ``neighbors`` as SciPy's (the triangle across the edge opposite each
    vertex, -1 on the hull)."""

    points: NDArray[np.float64]
    simplices: NDArray[np.int64]
    neighbors: NDArray[np.int64]


def _barycentric(A: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(M, 3)`` barycentric coordinates of ``q (M, 2)`` in the triangles ``A (M, 3, 2)``."""
    e1, e2, d = A[:, 1] - A[:, 0], A[:, 2] - A[:, 0], q - A[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    det = np.where(det == 0.0, np.nan, det)  # a flat sliver holds nothing
    u = (d[:, 0] * e2[:, 1] - d[:, 1] * e2[:, 0]) / det
    v = (e1[:, 0] * d[:, 1] - e1[:, 1] * d[:, 0]) / det
    return np.column_stack([1.0 - u - v, u, v])


def _thinned(base: Any, removed: NDArray[np.bool_]) -> _Thinned | None:
    """The Delaunay triangulation ``base`` without the vertices ``removed``: the triangles
    around them (the cavity) replaced by the Delaunay triangles of the cavity's other vertices
    that lie inside it.

    Taking vertices out of a Delaunay triangulation leaves every triangle not incident to them
    Delaunay, and the triangles of the points left that cover the cavity have circles empty of
    them, so they are triangles of the cavity's own vertices: the same triangulation as a new
    one of the points left (up to the choice among co-circular points), at the cost of the
    cavity. None when the cavity holds more than a quarter of the vertices (a new
    triangulation is then as cheap) or its new triangles do not cover it exactly (co-circular
    or collinear rims).
    """
    S = np.asarray(base.simplices, dtype=np.int64)
    P = base.points
    hit: NDArray[np.bool_] = np.asarray(removed[S].any(axis=1), dtype=bool)
    rim = np.unique(S[hit])
    rim = rim[~removed[rim]]
    if len(rim) < 3 or len(rim) > len(P) // 4:
        return None
    try:
        sub = Delaunay(P[rim])
    except QhullError:
        return None
    sub_s = rim[sub.simplices.astype(np.int64)]
    loc = _find_simplex(base, P[sub_s].mean(axis=1))
    inside = (loc >= 0) & hit[np.maximum(loc, 0)]
    cav_area = float(_areas(P[S[hit]]).sum())
    if abs(float(_areas(P[sub_s[inside]]).sum()) - cav_area) > 1e-9 * cav_area:
        return None
    simplices = np.concatenate([S[~hit], sub_s[inside]])
    return _Thinned(P, simplices, _neighbours(simplices, len(P)))


def _jump_components(
    xy: NDArray[np.float64],
    z: NDArray[np.float64],
    tan0: float,
    band: float,
    frame: tuple[NDArray[np.float64], NDArray[np.float64], float],
    *,
    rounds: int = 4,
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.float64], Any]:
    """Rules P1/P4 on a ground TIN: drop the vertices of components that stand on jumps.

    Edges rising faster than ``band + tan0 * length`` are height jumps; the TIN cut at its jumps
    falls into components. A component whose jump edges all step down out of it (at least 90 %
    of them) is an obstacle top (a roof, a tree crown); a component of at most 3 vertices whose
    jumps all step up is a low outlier. The largest component is the terrain and stays.

    The TIN holds the vertices with their frame (:func:`_framed` around
    ``frame = (lo, hi, step)``, the frame's heights from the nearest vertex kept) and only the
    edges between vertices are judged, so the last pass's TIN is the ground surface's. A
    pass's removals are taken out of the first pass's triangulation (:func:`_thinned`: only
    the cavities are triangulated again) unless they are too many. Returns the kept vertex
    indices, the surface's vertices (kept, then frame) with their heights, and its
    triangulation.
    """
    lo, hi, step = frame
    ids = np.arange(len(xy))  # the base's vertices (then its frame)
    gxy, gz = _framed(xy, z, lo, hi, step)
    base = Delaunay(gxy)
    tri: Any = base
    alive = np.ones(len(gxy), dtype=bool)
    for _ in range(rounds):
        n = len(ids)
        i, j = _tin_edges(tri)
        inner = (i < n) & (j < n)
        i, j = i[inner], j[inner]
        d = np.hypot(*(gxy[i] - gxy[j]).T)
        dz = gz[i] - gz[j]
        cut = np.abs(dz) > band + tan0 * d
        smooth = ~cut
        graph = coo_matrix((np.ones(int(smooth.sum())), (i[smooth], j[smooth])), shape=(n, n))
        nc, lab = connected_components(graph, directed=False)
        li, lj = lab[i], lab[j]
        c = cut & (li != lj)
        down = np.bincount(li[c], weights=(dz[c] > 0).astype(float), minlength=nc)
        total = np.bincount(li[c], minlength=nc)
        size = np.bincount(lab[alive[:n]], minlength=nc)  # removed vertices stand alone
        top = (total > 0) & (down >= 0.9 * total)
        pit = (total > 0) & (down <= 0.1 * total) & (size <= 3)
        bad = top | pit
        bad[int(size.argmax())] = False
        drop = bad[lab] & alive[:n]
        if not drop.any():
            break
        alive[:n] &= ~drop
        kept = ids[alive[:n]]
        _, nn = cKDTree(xy[kept]).query(gxy[n:])  # the frame's heights: nearest vertex kept
        gz = np.concatenate([gz[:n], z[kept[nn]]])
        thin = _thinned(base, ~alive)
        if thin is not None:
            tri = thin
            continue
        sel = np.flatnonzero(alive)  # a new triangulation of the vertices kept
        ids, gxy, gz = kept, gxy[sel], gz[sel]
        base = tri = Delaunay(gxy)
        alive = np.ones(len(gxy), dtype=bool)
    keep = ids[alive[: len(ids)]]
    if isinstance(tri, _Thinned):  # the vertices kept, then the frame, as after a new one
        sel = np.flatnonzero(alive)
        remap = np.full(len(gxy), -1, dtype=np.int64)
        remap[sel] = np.arange(len(sel))
        gxy, gz = gxy[sel], gz[sel]
        tri = replace(tri, points=gxy, simplices=remap[tri.simplices])
    return keep, gxy, gz, tri


def _lowest_cells(
    xy: NDArray[np.float64], z: NDArray[np.float64], cell: float, shape: tuple[int, int]
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The lowest point of each full cell of the minimum surface: its index and its cell's flat
    index (row-major in ``shape``)."""
    li = lowest_per_cell(xy, z, cell)
    ij = np.floor((xy[li] - xy.min(axis=0)) / cell).astype(np.int64)
    return li, ij[:, 0] * shape[1] + ij[:, 1]


OPENING_ROWS_BUDGET = 1 << 25
"""Most float32 cells the row-wise opening (:func:`_openings_by_rows`) holds at once (128 MB);
a larger grid is opened disc by disc."""


def _disc(w: int) -> NDArray[np.uint8]:
    import cv2

    return np.asarray(cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * w + 1, 2 * w + 1)))


def _disc_rows(w: int) -> list[int] | None:
    """Half-widths of the rows of OpenCV's elliptic element of radius ``w`` (row ``dy + w``),
    or None if a row is not one run centred on the middle column."""
    half = []
    for row in _disc(w):
        on = np.flatnonzero(row)
        h = (len(on) - 1) // 2
        if len(on) == 0 or len(on) != 2 * h + 1 or on[0] != w - h:
            return None
        half.append(h)
    return half


def _openings_by_discs(surface: NDArray[np.float32], radii: range) -> list[NDArray[Any]]:
    """The opening of ``surface`` by each disc (OpenCV's elliptic element, replicated border)."""
    import cv2

    out = []
    for w in radii:
        k = _disc(w)
        eroded = cv2.erode(surface, k, borderType=cv2.BORDER_REPLICATE)
        out.append(cv2.dilate(eroded, k, borderType=cv2.BORDER_REPLICATE))
    return out


def _openings_by_rows(surface: NDArray[np.float32], radii: range) -> list[NDArray[Any]] | None:
    """:func:`_openings_by_discs`, the same values: a disc is a stack of centred row segments,
    so its erosion is the minimum over its rows of the row erosions shifted by the row's
    offset (dilation likewise). The row erosions of ``surface`` (one per half-width) serve
    every disc; each disc then costs one minimum per row instead of one per element, and
    minima and maxima of float32 values are exact, so any order gives the same bits. None when
    the grid is too large to hold the row erosions (:data:`OPENING_ROWS_BUDGET`) or a disc is
    not such a stack."""
    import cv2

    W = max(radii, default=0)
    H, C = surface.shape
    rows = [_disc_rows(w) for w in radii]
    if (
        W == 0
        or any(r is None for r in rows)
        or (W + 1) * (H + 2 * W) * (C + 2 * W) > OPENING_ROWS_BUDGET
    ):
        return None
    rep = cv2.BORDER_REPLICATE
    pad = cv2.copyMakeBorder(surface, W, W, W, W, rep)
    seg = [np.ones((1, 2 * h + 1), np.uint8) for h in range(W + 1)]
    eroded_rows = [pad] + [cv2.erode(pad, seg[h], borderType=rep) for h in range(1, W + 1)]
    out = []
    for w, half in zip(radii, rows, strict=True):
        assert half is not None
        acc = eroded_rows[half[w]][W : W + H, W : W + C].copy()
        for dy in range(1, w + 1):
            for r in (w + dy, w - dy):
                cv2.min(acc, eroded_rows[half[r]][W + r - w : W + r - w + H, W : W + C], dst=acc)
        q = cv2.copyMakeBorder(acc, w, w, w, w, rep)
        dil = {h: cv2.dilate(q, seg[h], borderType=rep) if h else q for h in set(half)}
        res = dil[half[w]][w : w + H, w : w + C].copy()
        for dy in range(1, w + 1):
            for r in (w + dy, w - dy):
                cv2.max(res, dil[half[r]][r : r + H, w : w + C], dst=res)
        out.append(res)
    return out


def opening_objects(
    Z: NDArray[np.float64], cell: float, settings: UnorganisedSettings
) -> NDArray[np.bool_]:
    """The progressive opening of a minimum surface (SMRF's test, Pingel et al. 2013): discs
    of radius 1, 2, ... cells up to ``max_object_m``; a cell whose opened height drops by more
    than ``opening_slope * radius * cell`` from the previous disc's is an object cell. The
    windows are discs (OpenCV's elliptic structuring element), so the slope a window tolerates
    is the same in every direction: a square window reaches ``sqrt(2)`` times as far along its
    diagonals and cuts crests and ridges of the terrain that a disc keeps. The openings are
    computed row by row (:func:`_openings_by_rows`; the same values as disc by disc)."""
    surface = (Z - float(Z.min())).astype(np.float32)  # over the lowest cell: mm-exact in float32
    radii = range(1, max(1, math.ceil(settings.max_object_m / cell)) + 1)
    openings = _openings_by_rows(surface, radii)
    if openings is None:
        openings = _openings_by_discs(surface, radii)
    last: NDArray[Any] = surface
    obj = np.zeros(Z.shape, dtype=bool)
    for w, opened in zip(radii, openings, strict=True):
        obj |= (last - opened) > settings.opening_slope * w * cell
        last = opened
    return obj


def ground_surface(
    xy: NDArray[np.float64],
    z: NDArray[np.float64],
    settings: UnorganisedSettings,
    spacing: float,
) -> GroundSurface:
    """The ground estimate of one tile (see the module docstring, step 3).

    1. The minimum surface on cells of ``grid_spacings * spacing``; its noise gives the band.
    2. The progressive opening with disc windows (:func:`opening_objects`) marks object cells.
    3. The lowest point of each remaining cell (at its own x-y, not the cell's centre: on a
       slope the centre would shift the surface by up to half a cell times the slope) is a
       ground vertex.
    4. The paper's jump rule on the TIN of those vertices (:func:`_jump_components`): the
       components bounded by jumps that all step down out of them (a roof wider than the widest
       window, a crown) are removed. The TIN of the rest is the ground surface returned.
    """
    cell = settings.grid_spacings * spacing
    Z, _ = _min_grid(xy, z, cell)
    noise = height_noise(Z)
    band = max(settings.band_min_m, settings.band_noise * noise)
    obj = opening_objects(Z, cell, settings)
    li, flat = _lowest_cells(xy, z, cell, Z.shape)
    ok = ~obj.reshape(-1)[flat]
    if np.count_nonzero(ok) < 3:
        ok[:] = True
    v = li[ok]
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    step = 10.0 * cell
    tan0 = math.tan(math.radians(settings.c0_deg))
    try:
        _, gxy, gz, tri = _jump_components(xy[v], z[v], tan0, band, (lo, hi, step))
    except QhullError as exc:
        raise InputError(
            f"the ground points are degenerate in x-y ({exc.__class__.__name__})",
            field="points",
            expected="ground points spanning an area",
        ) from None
    return GroundSurface(gxy, gz, tri, band, noise, li)


# ----------------------------------------------------------------------------------------------
# stages 3-5 on the mesh
