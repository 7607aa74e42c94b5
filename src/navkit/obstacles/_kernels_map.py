"""Compiled (Numba) kernels of stages 6-8 that share passes or batch all obstacles at once.

Twins (the NumPy references, ``TWINS`` below) live in :mod:`navkit.obstacles.detector`,
:mod:`navkit.obstacles.segment` and :mod:`navkit.obstacles.ground`; see ``docs/kernels.md`` ("Obstacles"). The shape kernels of
stage 8 are in :mod:`navkit.geometry._kernels`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from navkit.obstacles._kernels_common import (
    _OFF_I,
    _OFF_J,
    _find,
    _kth,
    _max_nan,
    _min_nan,
    _renumber_by_min,
    _union,
)

__all__ = [
    "ground_cells_kernel",
    "map_groups_kernel",
    "refine_kernel",
    "split_kernel",
    "vertex_kernel",
]

TWINS = {
    "ground_cells_kernel": "navkit.obstacles.ground.ground_height_map",
    "map_groups_kernel": "navkit.obstacles.detector._build_obstacles",
    "refine_kernel": "navkit.obstacles.ground.refine_by_ground_height",
    "split_kernel": "navkit.obstacles.detector._split",
    "vertex_kernel": "navkit.obstacles.detector._vertices",
}
"""Each public kernel -> its NumPy twin."""


# ------------------------------------------------------------------------------------------
# per-vertex windows: the six triangles around vertex (p, q) are three neighbours in triangle
# row p (columns 2q - 2 .. 2q) and three in row p - 1 (columns 2q - 1 .. 2q + 1)
# (``segment._incident_slices``); a missing triangle counts as 0 (no obstacle, no class): a
# missing row is a row of zeros, and only the first and last vertex of a row lose triangles.


@njit(cache=True, inline="always")
def _window_ids(vid, bnd, p, rowp, rowm, n_el):  # type: ignore[no-untyped-def]
    """Vertex row ``p`` of ``segment.boundary_vertices`` from triangle rows ``p`` and ``p - 1``
    (zeros where missing): the largest incident obstacle id and the boundary flag. The two end
    vertices (fewer triangles) are peeled off, so that the interior loop has no branch and
    vectorises (AVX2: ~3x faster than one loop with the end tests inside)."""
    for q in range(1, n_el - 1):  # interior: the six triangles are there
        a0, a1, a2 = rowp[2 * q - 2], rowp[2 * q - 1], rowp[2 * q]
        b0, b1, b2 = rowm[2 * q - 1], rowm[2 * q], rowm[2 * q + 1]
        hi = max(max(max(a0, a1), max(a2, b0)), max(b1, b2))
        lo = min(min(min(a0, a1), min(a2, b0)), min(b1, b2))
        vid[p, q] = hi
        bnd[p, q] = (hi > 0) & (lo != hi)
    # the ends (``n_el >= 2``, ``C = n_el - 1``): a missing triangle counts as 0
    _put_window(vid, bnd, p, 0, 0, 0, rowp[0], 0, rowm[0], rowm[1])
    q = n_el - 1
    _put_window(vid, bnd, p, q, rowp[2 * q - 2], rowp[2 * q - 1], 0, rowm[2 * q - 1], 0, 0)


@njit(cache=True, inline="always")
def _put_window(vid, bnd, p, q, a0, a1, a2, b0, b1, b2):  # type: ignore[no-untyped-def]
    """Vertex ``(p, q)``'s largest incident obstacle id and boundary flag from its six
    triangles' ids."""
    hi = max(max(max(a0, a1), max(a2, b0)), max(b1, b2))
    lo = min(min(min(a0, a1), min(a2, b0)), min(b1, b2))
    vid[p, q] = hi
    bnd[p, q] = (hi > 0) & (lo != hi)


@njit(cache=True)
def _boundary_ids(obs_lab, n_az, n_el, wrap):  # type: ignore[no-untyped-def]
    """``segment.boundary_vertices``, row by row: obstacle
    id per vertex (the largest incident) and boundary."""
    R, W = obs_lab.shape
    vid = np.empty((n_az, n_el), np.int32)
    bnd = np.empty((n_az, n_el), np.bool_)
    zero = np.zeros(W, obs_lab.dtype)
    for p in range(n_az):
        rowp = obs_lab[p] if p < R else zero
        rm = p - 1 if p >= 1 else (R - 1 if wrap else -1)
        rowm = obs_lab[rm] if rm >= 0 else zero
        _window_ids(vid, bnd, p, rowp, rowm, n_el)
    return vid, bnd


@njit(cache=True)
def _merge_close_rows(obs_lab, n, P, wrap, distance_m, gap):  # type: ignore[no-untyped-def]
    """``segment.merge_close_components`` (a union-find on the
    obstacle ids; the components do not depend on the order of the unions) with the boundary
    vertices from :func:`_boundary_ids`. ``obs_lab`` (C-contiguous) is relabelled in place."""
    lut, m, merged = _merge_lut(obs_lab, n, P, wrap, distance_m, gap)
    if not merged:
        return obs_lab, n
    flat = obs_lab.ravel()
    for f in range(len(flat)):  # in place: the caller's array is the kernel's own
        flat[f] = lut[flat[f]]
    return obs_lab, m


@njit(cache=True)
def _merge_lut(obs_lab, n, P, wrap, distance_m, gap):  # type: ignore[no-untyped-def]
    """The merging of :func:`_merge_close_rows` without the relabelling: ``(lut (n + 1,),
    number of merged ids, whether any two merged)``; a boundary vertex's point is read only
    when another obstacle's vertex is in its window. A row of vertices is skipped when the
    rows of its windows hold one obstacle id at most (no other id to merge with: about half
    the rows of a SemanticKITTI frame)."""
    n_az, n_el = P.shape[0], P.shape[1]
    vid, bnd = _boundary_ids(obs_lab, n_az, n_el, wrap)
    # per row of vertices: the smallest and largest obstacle id in it (0, 0: none)
    rlo = np.zeros(n_az, np.int32)
    rhi = np.zeros(n_az, np.int32)
    big = np.int32(2147483647)  # the largest int32
    for r in range(n_az):
        lo = big
        hi = np.int32(0)
        for c in range(n_el):
            v = vid[r, c]
            hi = max(hi, v)
            lo = min(lo, v if v > 0 else big)
        rlo[r] = lo if hi > 0 else 0
        rhi[r] = hi
    parent = np.arange(n + 1).astype(np.int64)
    merged = False
    # flat views and unsigned indices (every index >= 0): no negative-index fix-up per access
    vf = vid.ravel()
    bf = bnd.ravel()
    pf = np.ascontiguousarray(P).reshape(-1)
    uel = np.uint64(n_el)
    three = np.uint64(3)
    for si in range(n_az):
        lo = big
        hi = np.int32(0)
        for di in range(0, gap + 1):
            ti = si + di
            if ti >= n_az:
                if not wrap:
                    continue
                ti = ti % n_az
            if rhi[ti] > 0:
                lo = min(lo, rlo[ti])
                hi = max(hi, rhi[ti])
        if hi == 0 or lo == hi:  # one id at most in the window rows: nothing to merge
            continue
        srow = np.uint64(si) * uel
        for sj in range(n_el):
            us = srow + np.uint64(sj)
            if not bf[us]:
                continue
            va = vf[us]
            loaded = False
            px = py = pz = 0.0
            for di in range(0, gap + 1):
                ti = si + di
                if ti >= n_az:
                    if not wrap:
                        continue
                    ti = ti % n_az
                j0 = sj + 1 if di == 0 else max(sj - gap, 0)
                j1 = min(sj + gap + 1, n_el)
                trow = np.uint64(ti) * uel
                # branch-free first look: another obstacle's vertex in this row of the window?
                other = False
                for tj in range(j0, j1):
                    vb = vf[trow + np.uint64(tj)]
                    other |= (vb > 0) & (vb != va)
                if not other:
                    continue
                if not loaded:
                    q = three * us
                    px, py, pz = pf[q], pf[q + np.uint64(1)], pf[q + np.uint64(2)]
                    loaded = True
                for tj in range(j0, j1):
                    ut = trow + np.uint64(tj)
                    vb = vf[ut]
                    if vb <= 0 or vb == va:
                        continue
                    q = three * ut
                    dx = px - pf[q]
                    dy = py - pf[q + np.uint64(1)]
                    dz = pz - pf[q + np.uint64(2)]
                    if math.sqrt(dx * dx + dy * dy + dz * dz) < distance_m:
                        _union(parent, va, vb)
                        merged = True
    if not merged:
        return np.arange(n + 1).astype(np.int32), n, False
    lut, m = _renumber_by_min(parent, n)
    return lut, m, True


# ------------------------------------------------------------------------------------------
# stage 6: one union-find for the obstacle, shadow and ground components

_GROUND, _OBSTACLE, _SHADOW = 0, 1, 2
_MAIN = 17  # stage 7's code of a main-ground triangle: ground (1) | main (16)


@njit(cache=True)
def _class_union_find(labels, wrap, cls, parent):  # type: ignore[no-untyped-def]
    """The mesh components of the ground, obstacle and shadow triangles in one union-find
    (``segment.MESH_STRUCTURE``, rows cyclic with ``wrap``; a union only joins triangles of one
    class, so the components are those of three separate passes). Returns the class per
    triangle (flat, -1: none) and the parent array (every root is its set's smallest member, and
    ``parent[f] <= f`` everywhere), written into ``cls (R * C,) int8`` and ``parent (R * C,)
    int32``.

    One raster scan: a triangle is a new singleton when reached, so it takes its left
    neighbour's root (kept from the previous step) and joins the upper-right and seam
    neighbours' sets by a find each."""
    R, C = labels.shape
    seam = wrap and R > 1
    # the component class of classes -4 .. 0 (shadow, shadow, obstacle, none, ground) by the
    # class's byte (-4 .. -1 are 252 .. 255; any other class: none), and unsigned flat indices
    # (``f - C + 1`` etc. are >= 0 where read): no range test and no negative-index fix-up per
    # access
    ctab = np.full(256, -1, np.int8)
    ctab[252], ctab[253], ctab[254], ctab[0] = _SHADOW, _SHADOW, _OBSTACLE, _GROUND
    lf = labels.ravel()
    uC = np.uint64(C)
    one = np.uint64(1)
    for i in range(R):
        prev = -1
        cur = np.int32(0)
        row = np.uint64(i) * uC
        for j in range(C):
            uf = row + np.uint64(j)
            f = np.int32(uf)
            c = ctab[np.uint8(lf[uf])]
            cls[uf] = c
            if c < 0:
                parent[uf] = f
                prev = -1
                continue
            root = f
            if prev == c:
                root = cur
            # the upper-right neighbour; already in this set when the left neighbour joined the
            # upper one (f - C) and both upper triangles are of this class (no find)
            if (
                i > 0
                and j + 1 < C
                and cls[uf - uC + one] == c
                and not (prev == c and cls[uf - uC] == c)
            ):
                rb = _find(parent, f - C + 1)
                if rb < root:
                    if root != f:
                        parent[root] = rb
                    root = rb
                elif root < rb:
                    parent[rb] = root
            if seam and i == R - 1 and j > 0 and cls[j - 1] == c:
                rb = _find(parent, j - 1)
                if rb < root:
                    if root != f:
                        parent[root] = rb
                    root = rb
                elif root < rb:
                    parent[rb] = root
            parent[uf] = root
            prev = c
            cur = root
    return cls, parent


@njit(cache=True)
def _neighbours(i, j, R, C, wrap, out):  # type: ignore[no-untyped-def]
    """The (up to 4) mesh neighbours of triangle ``(i, j)`` (``segment.MESH_STRUCTURE``) as flat
    indices in ``out``; returns their number."""
    m = 0
    for o in range(4):
        ti, tj = i + _OFF_I[o], j + _OFF_J[o]
        if tj < 0 or tj >= C:
            continue
        if ti < 0 or ti >= R:
            if not (wrap and R > 1):
                continue
            ti = ti % R
        out[m] = ti * C + tj
        m += 1
    return m


@njit(cache=True)
def split_kernel(  # type: ignore[no-untyped-def]
    labels,
    zmin,
    zmax,
    P,
    wrap,
    min_triangles,
    min_height32,
    half,
    distance_m,
    gap,
    main_share,
    work_i8,
    work_i32,
):
    """Stage 6 (twin: ``detector._split``): obstacle components, the size / height /
    noise-patch filters, merging of close components and the shadows' owners, with the ground
    components of stage 7 from the same union-find. ``labels`` is changed in place (dropped
    components back to ground). ``work_i8 (R * C,) int8`` and ``work_i32 (7, R * C) int32``
    are work arrays (any content; kept between calls by the caller).

    Returns ``obs_lab, n, tri_obstacle, tcode, shadows, ntri``: ``tri_obstacle`` the obstacle
    id of
    obstacle triangles and the owner of shadow triangles (the twin's ``owner`` is
    ``tri_obstacle`` on the shadow triangles, 0 elsewhere); ``tcode (R, 2C) int8`` each
    triangle's class flag for stage 7 (1 ground, 2 shadow behind, 4 side shadow, 8 obstacle,
    0 unreliable) with ``_MAIN`` (= 1 | 16) for a ground triangle of a main ground zone (a
    ground component after the drop with at least ``main_share`` of the largest one's
    triangles; ``segment.main_ground_vertices``); ``shadows`` the flat indices of the shadow
    triangles (raster order; their owners, possibly 0, in ``tri_obstacle``) and ``ntri (n,)``
    the triangles of each obstacle (stage 8's inputs: no pass over the grid there).

    Every root of the union-find is its set's smallest member and ``parent[f] <= f``, so one
    raster pass ``parent[f] = parent[parent[f]]`` points every triangle at its root (no
    ``find``), a set is numbered when its root is reached (the first member in raster order)
    and per-set arrays indexed by the root need no clearing.
    """
    R, C = labels.shape
    cls = work_i8
    parent = work_i32[0]
    new = work_i32[1]  # per root: the component's number (written at the root first)
    sl = work_i32[2]  # per shadow triangle: its shadow zone
    shf = work_i32[3]  # the shadow triangles in raster order
    obf = work_i32[4]  # the obstacle triangles in raster order
    ground_size = work_i32[5]  # per ground root: the component's size
    groots = work_i32[6]  # the roots of the ground sets (some joined later by the drops)
    _class_union_find(labels, wrap, cls, parent)
    # obstacle and shadow components numbered by first appearance in raster order; every
    # triangle pointed at its root on the way
    lab = np.empty((R, C), np.int32)
    labf = lab.ravel()
    n = 0
    ns = 0
    nsh = 0
    nt = 0
    ng = 0
    # unsigned indices (every index here is >= 0): no negative-index fix-up per access
    for f in range(R * C):
        uf = np.uint64(f)
        r = parent[np.uint64(parent[uf])]
        ur = np.uint64(r)
        parent[uf] = r
        c = cls[uf]
        if c <= 0:
            labf[uf] = 0
            if c == _GROUND:  # the ground sets' sizes, at their roots (reached first)
                if r == f:
                    ground_size[uf] = 1
                    groots[ng] = f
                    ng += 1
                else:
                    ground_size[ur] += 1
            continue
        if r == f:
            if c == _OBSTACLE:
                n += 1
                new[uf] = n
            else:
                ns += 1
                new[uf] = ns
        if c == _OBSTACLE:
            labf[uf] = new[ur]
            obf[nt] = f
            nt += 1
        else:
            labf[uf] = 0
            sl[uf] = new[ur]
            shf[nsh] = f
            nsh += 1
    dropped_any = False
    ntri = np.zeros(1, np.int64)  # per final obstacle id: its triangles
    if n:
        size = np.zeros(n + 1, np.int64)
        hi = np.full(n + 1, -np.inf, np.float32)
        lo = np.full(n + 1, np.inf, np.float32)
        sm = np.zeros(n + 1, np.float64)
        h = np.float32(0.5)
        # obstacle triangles (raster order) grouped by label: a counting sort
        for k in range(nt):
            size[labf[obf[k]]] += 1
        start = np.zeros(n + 2, np.int64)
        for a in range(1, n + 1):
            start[a + 1] = start[a] + size[a]
        fill = start.copy()
        zs = np.empty(nt, np.float64)  # their mid heights by label
        # those with a ground neighbour (the lift's pairs): row, column, label and which of
        # the four offsets (``_OFF_I``, ``_OFF_J``; rows cyclic with ``wrap``) is ground
        bi_ = np.empty(nt, np.int32)
        bj_ = np.empty(nt, np.int32)
        ba_ = np.empty(nt, np.int32)
        bm_ = np.empty(nt, np.int8)
        nbd = 0
        i = 0
        ca = 0  # the label of the current run
        chi, clo, csm, cfill = hi[0], lo[0], sm[0], fill[0]
        # flat views and unsigned indices (all >= 0 where read): no negative-index fix-up
        lbf = labels.ravel()
        zxf = zmax.ravel()
        znf = zmin.ravel()
        uC = np.uint64(C)
        for k in range(nt):
            f = obf[k]
            while f >= (i + 1) * C:  # raster order: the row without a division
                i += 1
            j = f - i * C
            uf = np.uint64(f)
            a = labf[uf]
            # the ground neighbours (offsets (0, +-1), (+-1, -+1), rows cyclic with wrap)
            up = i - 1 if i > 0 else (R - 1 if wrap else -1)
            dn = i + 1 if i + 1 < R else (0 if wrap else -1)
            mk = 0
            if j + 1 < C:
                mk |= 1 if lbf[uf + np.uint64(1)] == 0 else 0
                mk |= 8 if (up >= 0 and lbf[np.uint64(up) * uC + np.uint64(j + 1)] == 0) else 0
            if j > 0:
                mk |= 2 if lbf[uf - np.uint64(1)] == 0 else 0
                mk |= 4 if (dn >= 0 and lbf[np.uint64(dn) * uC + np.uint64(j - 1)] == 0) else 0
            if mk:
                bi_[nbd] = i
                bj_[nbd] = j
                ba_[nbd] = a
                bm_[nbd] = mk
                nbd += 1
            if a != ca:  # a run of one label: its sums in registers, the same order
                if ca:
                    hi[ca], lo[ca], sm[ca], fill[ca] = chi, clo, csm, cfill
                ca = a
                chi, clo, csm, cfill = hi[a], lo[a], sm[a], fill[a]
            zx = zxf[uf]
            zn = znf[uf]
            chi = _max_nan(chi, zx)
            clo = _min_nan(clo, zn)
            zm = np.float64(h * (zx + zn))
            csm += zm
            zs[np.uint64(cfill)] = zm
            cfill += 1
        if ca:
            hi[ca], lo[ca], sm[ca], fill[ca] = chi, clo, csm, cfill
        # lift over the adjacent ground, the sums in the twin's pair order (per offset: the
        # pairs inside the array in raster order, then the ones across the seam)
        cnt_g = np.zeros(n + 1, np.int64)
        sum_g = np.zeros(n + 1, np.float64)
        bi_ = bi_[:nbd]
        first_last = np.searchsorted(bi_, R - 1)  # where row R - 1 starts
        first_one = np.searchsorted(bi_, 1)  # where row 0 ends
        for o in range(4):
            di, dj = _OFF_I[o], _OFF_J[o]
            for seam in range(2 if (wrap and di != 0) else 1):
                k0, k1 = 0, nbd
                if seam == 1:  # only row R - 1 (di = 1) or row 0 (di = -1) crosses
                    k0, k1 = (first_last, nbd) if di == 1 else (0, first_one)
                bit = 1 << o
                for k in range(k0, k1):
                    if not (bm_[k] & bit):  # that neighbour is not ground (or not there)
                        continue
                    ti = bi_[k] + di
                    crosses = ti < 0 or ti >= R
                    if crosses != (seam == 1):
                        continue
                    if crosses:
                        ti = ti % R
                    q = np.uint64(ti) * uC + np.uint64(bj_[k] + dj)
                    a = np.uint64(ba_[k])
                    cnt_g[a] += 1
                    sum_g[a] += np.float64(h * (zxf[q] + znf[q]))
        lut = np.zeros(n + 1, np.int32)
        m2 = 0
        for a in range(1, n + 1):
            if not (size[a] >= min_triangles and (hi[a] - lo[a]) >= min_height32):
                continue
            lift = sm[a] / max(size[a], 1) - sum_g[a] / cnt_g[a] if cnt_g[a] > 0 else np.inf
            if lift < half:
                # a patch of noise on the ground: little spread (10th to 90th percentile of
                # the mid heights) and no lift; computed only where it decides
                k = size[a] - 1
                k90, k10 = math.floor(0.9 * k), math.floor(0.1 * k)
                seg = zs[start[a] : start[a + 1]]
                v90 = _kth(seg, k90)  # leaves the k90 + 1 smallest in front
                if v90 - _kth(seg[: k90 + 1], k10) < half:
                    continue
            m2 += 1
            lut[a] = m2
        for k in range(nt):
            f = obf[k]
            uf = np.uint64(f)
            a = np.uint64(labf[uf])
            if lut[a] == 0:
                labels[f // C, f % C] = 0  # (``lbf`` is a copy if ``labels`` is strided)
                cls[uf] = _GROUND
                dropped_any = True
                r = parent[uf]  # the component's root, its first triangle in raster order
                if r == f:
                    ground_size[uf] = 1
                    groots[ng] = f
                    ng += 1
                else:
                    ground_size[np.uint64(r)] += 1
            labf[uf] = lut[a]
        if dropped_any:  # the dropped triangles join the ground around them
            nb = np.empty(4, np.int64)
            for k in range(nt):
                f = obf[k]
                if cls[f] != _GROUND:
                    continue
                i = f // C
                for q in range(_neighbours(i, f - i * C, R, C, wrap, nb)):
                    if cls[nb[q]] == _GROUND:
                        # ``_union`` (the smaller root stays the root) with the sizes
                        ra = _find(parent, f)
                        rb = _find(parent, nb[q])
                        if rb < ra:
                            ra, rb = rb, ra
                        if ra < rb:
                            parent[rb] = ra
                            ground_size[ra] += ground_size[rb]
        n = m2
        mlut = np.arange(n + 1).astype(np.int32)
        if n >= 2 and gap >= 1 and distance_m > 0:
            mlut, n, merged = _merge_lut(lab, n, P, wrap, distance_m, gap)
            if merged:  # the obstacle triangles only (every other id is 0)
                for k in range(nt):
                    f = obf[k]
                    labf[f] = mlut[labf[f]]
        ntri = np.zeros(n + 1, np.int64)
        for a in range(1, len(lut)):
            if lut[a] > 0:
                ntri[mlut[lut[a]]] += size[a]
    # ground components: the main ground zones (>= main_share of the largest one's triangles)
    # and each triangle's code for stage 7 (class flag, main ground)
    big = 0
    for k in range(ng):
        g = groots[k]
        if parent[g] == g:
            big = max(big, ground_size[g])
    thr = main_share * big
    ithr = math.ceil(thr)  # an integer size s is >= thr exactly when s >= ceil(thr)
    tcode = np.empty((R, C), np.int8)
    tflat = tcode.ravel()
    # the flag of classes -4 .. 0 (shadow behind, side shadow, obstacle, unreliable, ground) by
    # the class's byte (-4 .. -1 are 252 .. 255); any other class 0
    flag = np.zeros(256, np.int8)
    flag[252], flag[253], flag[254], flag[255], flag[0] = 2, 4, 8, 0, 1
    for i in range(R):
        for j in range(C):
            t = labels[i, j]
            f = i * C + j
            # the root, without a branch: parent[f] < f was pointed at its root earlier in
            # this raster pass (the unions keep parent[x] <= x and the roots smallest; a
            # ground set's members are ground triangles; the size read for another class's
            # root is not used)
            uf = np.uint64(f)
            r = parent[np.uint64(parent[uf])]
            parent[uf] = r
            main = (t == 0) & (ground_size[np.uint64(r)] >= ithr)
            tflat[uf] = _MAIN if main else flag[np.uint8(t)]
    tri_obstacle = lab.copy()  # obstacle ids, and the owners of the shadows (below)
    shadows = shf[:nsh].copy()
    if ns == 0 or n == 0:
        return lab, n, tri_obstacle, tcode, shadows, ntri[1:]
    # shadow owners: per shadow zone, the obstacle it shares the most adjacencies with (ties:
    # the larger id, as the twin's stable lexsort)
    nobs = n + 1
    dense = (ns + 1) * nobs <= 1 << 22
    counts = np.zeros((ns + 1) * nobs if dense else 1, np.int64)
    keys = np.empty(0 if dense else 4 * R * C, np.int64)
    k = 0
    nb = np.empty(4, np.int64)
    labf = lab.ravel()
    for t in range(nsh):
        f = shf[t]
        i = f // C
        z = sl[f]
        for q in range(_neighbours(i, f - i * C, R, C, wrap, nb)):
            b = labf[nb[q]]
            if b <= 0:
                continue
            if dense:
                counts[z * nobs + b] += 1
            else:
                keys[k] = np.int64(z) * nobs + b
                k += 1
    best = np.zeros(ns + 1, np.int32)
    if dense:
        for z in range(1, ns + 1):
            bc = 0
            for b in range(1, nobs):
                c = counts[z * nobs + b]
                if c > 0 and c >= bc:
                    bc = c
                    best[z] = b
    elif k:
        # the pairs grouped by zone (a counting sort), then each zone's counts per obstacle in
        # a scratch array cleared after the zone: the largest count, ties to the larger id (as
        # a sort of the keys would give; ``np.sort`` here cost ~1 s of first-call compilation)
        zstart = np.zeros(ns + 2, np.int64)
        for m in range(k):
            zstart[keys[m] // nobs + 1] += 1
        for z in range(1, ns + 2):
            zstart[z] += zstart[z - 1]
        zfill = zstart.copy()
        bz = np.empty(k, np.int64)
        for m in range(k):
            z = keys[m] // nobs
            bz[zfill[z]] = keys[m] % nobs
            zfill[z] += 1
        cnt = np.zeros(nobs, np.int64)
        for z in range(1, ns + 1):
            a0, a1 = zstart[z], zstart[z + 1]
            for t in range(a0, a1):
                cnt[bz[t]] += 1
            bc = 0
            for t in range(a0, a1):
                b = bz[t]
                if cnt[b] > bc or (cnt[b] == bc and b > best[z]):
                    bc = cnt[b]
                    best[z] = b
            for t in range(a0, a1):
                cnt[bz[t]] = 0
    trif = tri_obstacle.ravel()
    for t in range(nsh):
        f = shf[t]
        trif[f] = best[sl[f]]
    return lab, n, tri_obstacle, tcode, shadows, ntri[1:]


# ------------------------------------------------------------------------------------------
# stage 7: one pass over the vertices


@njit(cache=True)
def vertex_kernel(tcode, obs_lab, valid, wrap, ref):  # type: ignore[no-untyped-def]
    """``segment.boundary_vertices`` + ``vertex_labels`` + ``main_ground_vertices`` in one pass
    over the vertices, each reading its six incident triangles once
    (``segment._incident_slices``' order; a missing triangle counts as obstacle id 0, no class,
    not main ground) in stage 6's codes ``tcode`` (:func:`split_kernel`). Returns ``vid,
    boundary, vertex labels, main ground vertices`` and the flat indices of the main ground
    vertices labelled ground (the ground-height reference, raster order; a view of the work
    array ``ref (n_az * n_el,) int64``, any content on entry). Row by row on the
    row windows (:func:`_window_ids`): no branch per triangle, the class from a table of the
    16 flag combinations."""
    n_az, n_el = valid.shape
    R, W = tcode.shape
    vid = np.empty((n_az, n_el), np.int32)
    bnd = np.empty((n_az, n_el), np.bool_)
    vlab = np.empty((n_az, n_el), np.int8)
    main = np.empty((n_az, n_el), np.bool_)
    # the class of a valid vertex from the flags of its triangles: obstacle, ground, shadow
    # behind, side shadow, else unreliable
    table = np.empty(32, np.int8)
    for fl in range(32):
        table[fl] = -2 if fl & 8 else (0 if fl & 1 else (-4 if fl & 2 else (-3 if fl & 4 else -1)))
    zero_i = np.zeros(W, obs_lab.dtype)
    zero_c = np.zeros(W, tcode.dtype)
    C = W // 2
    nref = 0
    for p in range(n_az):
        rm = p - 1 if p >= 1 else (R - 1 if wrap else -1)
        rowp = obs_lab[p] if p < R else zero_i
        rowm = obs_lab[rm] if rm >= 0 else zero_i
        _window_ids(vid, bnd, p, rowp, rowm, n_el)
        cp = tcode[p] if p < R else zero_c
        cm = tcode[rm] if rm >= 0 else zero_c
        # the end vertices (fewer triangles) peeled off, the interior without a branch per
        # vertex (unsigned indices: no negative-index fix-up); still in raster order
        f0 = cp[0] | cm[0] | cm[1]
        q1 = n_el - 1
        base = p * n_el
        nref = _vertex_flags(f0, valid[p, 0], table, main, vlab, p, 0, ref, base, nref)
        for q in range(1, C):
            uq = np.uint64(2 * q)
            flags = (cp[uq - np.uint64(2)] | cp[uq - np.uint64(1)] | cp[uq]) | (
                cm[uq - np.uint64(1)] | cm[uq] | cm[uq + np.uint64(1)]
            )
            nref = _vertex_flags(flags, valid[p, q], table, main, vlab, p, q, ref, base, nref)
        if q1 >= 1:
            f1 = cp[2 * q1 - 2] | cp[2 * q1 - 1] | cm[2 * q1 - 1]
            nref = _vertex_flags(f1, valid[p, q1], table, main, vlab, p, q1, ref, base, nref)
    return vid, bnd, vlab, main, ref[:nref]


@njit(cache=True, inline="always")
def _vertex_flags(flags, ok, table, main, vlab, p, q, ref, base, nref):  # type: ignore[no-untyped-def]
    """Vertex ``(p, q)`` of :func:`vertex_kernel` from the OR of its triangles' codes: main
    ground, class, and its flat index appended to ``ref`` when it is a main-ground vertex
    labelled ground (written always, kept by advancing ``nref``); returns the new ``nref``."""
    is_main = (flags & 16) != 0
    main[p, q] = is_main
    cl = table[np.uint64(flags & 15)] if ok else np.int8(-1)
    vlab[p, q] = cl
    ref[np.uint64(nref)] = base + q
    return nref + (1 if (is_main & (cl == 0)) else 0)


@njit(cache=True, inline="always")
def _kth_select(v, k):  # type: ignore[no-untyped-def]
    """The k-th smallest of ``v`` (0-based; no NaN), reordering ``v``: a quickselect whose
    partitions do not branch on the comparisons (each element is swapped to the front and the
    front advances by the comparison's 0 / 1), with a median-of-3 pivot; a second pass puts the
    values equal to the pivot next (so every step shrinks the range). The same value as
    ``_kernels._kth`` (an order statistic is unique); ~2.6x faster on the ~90-value cells of
    the ground heights, where a branch per comparison is mispredicted about half the time."""
    lo, hi = 0, len(v) - 1
    while lo < hi:
        a, b, c = v[lo], v[(lo + hi) // 2], v[hi]
        pivot = max(min(a, b), min(max(a, b), c))
        i = lo
        for j in range(lo, hi + 1):  # v[lo:i] < pivot
            x = v[j]
            v[j] = v[i]
            v[i] = x
            i += x < pivot
        if k < i:
            hi = i - 1
            continue
        i2 = i
        for j in range(i, hi + 1):  # v[i:i2] == pivot
            x = v[j]
            v[j] = v[i2]
            v[i2] = x
            i2 += x <= pivot
        if k < i2:
            return pivot
        lo = i2
    return v[k]


@njit(cache=True)
def ground_cells_kernel(P, sel, cell_m, quantile, work_f, work_i, max_cells):  # type: ignore[no-untyped-def]
    """``ground.ground_height_map`` before its hole filling, on the reference points ``sel``
    (flat indices in raster order, from :func:`vertex_kernel`): the ``quantile`` of their z
    per horizontal cell ``(nx, ny)`` (NaN: no point), the grid's origin, and whether a cell is
    empty. The arithmetic of ``_kernels.ground_cells_kernel``, without its two passes over
    every vertex to find the reference points. ``work_f (4, >= m) float64`` and ``work_i (2,
    >= m) int64`` are work arrays (any content; kept between calls by the caller).

    Precondition: the points of ``sel`` are finite (valid vertices). Only the kernel knows
    which points are the reference, so it checks the grid's size itself, in floats, before any
    index is formed: when ``nx * ny`` would exceed ``max_cells`` it allocates nothing and
    returns a ``(0, 0)`` grid with ``(nx, ny)`` (as floats) in place of the origin, which the
    caller turns into an error. Every index below is then in ``[0, nx) x [0, ny)``."""
    m = len(sel)
    if m == 0:
        return np.zeros((1, 1)), np.zeros(2), False
    # one gather of the reference points into contiguous arrays (the later passes read those)
    xs = work_f[0, :m]
    ys = work_f[1, :m]
    zz = work_f[2, :m]
    gx_min = np.inf
    gy_min = np.inf
    gx_max = -np.inf
    gy_max = -np.inf
    for k in range(m):
        p = sel[k]
        x, y = P[p, 0], P[p, 1]
        xs[k] = x
        ys[k] = y
        zz[k] = P[p, 2]
        gx_min = min(gx_min, x)
        gy_min = min(gy_min, y)
        gx_max = max(gx_max, x)
        gy_max = max(gy_max, y)
    fnx = np.floor((gx_max - gx_min) / cell_m) + 1.0
    fny = np.floor((gy_max - gy_min) / cell_m) + 1.0
    if not (fnx * fny <= max_cells):  # also refuses a NaN size
        dims = np.empty(2)
        dims[0] = fnx
        dims[1] = fny
        return np.zeros((0, 0)), dims, False
    ix = work_i[0, :m]
    iy = work_i[1, :m]
    nx = 0
    ny = 0
    for k in range(m):
        ix[k] = math.floor((xs[k] - gx_min) / cell_m)
        iy[k] = math.floor((ys[k] - gy_min) / cell_m)
        nx = max(nx, ix[k] + 1)
        ny = max(ny, iy[k] + 1)
    counts = np.zeros(nx * ny + 1, np.int64)
    for k in range(m):
        counts[ix[k] * ny + iy[k] + 1] += 1
    start = np.cumsum(counts)
    fill = start.copy()
    zs = work_f[3, :m]
    for k in range(m):
        c = ix[k] * ny + iy[k]
        zs[fill[c]] = zz[k]
        fill[c] += 1
    heights = np.full((nx, ny), np.nan)
    missing = False
    for c in range(nx * ny):
        a, b = start[c], start[c + 1]
        if b > a:
            heights[c // ny, c % ny] = _kth_select(zs[a:b], math.floor(quantile * (b - a - 1)))
        else:
            missing = True
    origin = np.empty(2)
    origin[0] = gx_min
    origin[1] = gy_min
    return heights, origin, missing


# ------------------------------------------------------------------------------------------
# stage 7: refinement by height above the ground


@njit(cache=True)
def refine_kernel(P, vlab, valid, grid, origin, cell_m, band_m, above_m):  # type: ignore[no-untyped-def]
    """``ground.refine_by_ground_height`` (``envelope = 0``) per valid vertex.

    Any finite coordinates: the cell index is clamped to the grid as a float, before it becomes
    an integer (a far point's ``(x - origin) / cell_m`` may not fit one), so every read of
    ``grid`` is in range."""
    n = P.shape[0]
    out = vlab.copy()
    nx, ny = grid.shape
    for p in range(n):
        if not valid[p]:
            continue
        fx = min(max(np.floor((P[p, 0] - origin[0]) / cell_m), 0.0), nx - 1.0)
        fy = min(max(np.floor((P[p, 1] - origin[1]) / cell_m), 0.0), ny - 1.0)
        h = P[p, 2] - grid[int(fx), int(fy)]
        lab = out[p]
        if abs(h) <= band_m:
            lab = 0
        if lab == 0 and h > above_m:
            lab = -2
        out[p] = lab
    return out


# ------------------------------------------------------------------------------------------
# stage 8 input: per-obstacle vertex sets (twin: detector._build_obstacles' groupings)


@njit(cache=True, error_model="numpy")
def map_groups_kernel(flat, tri, tri_obstacle, shadows, ntri, vid, boundary, n):  # type: ignore[no-untyped-def]
    """Stage 8's per-obstacle sets in CSR layouts (offsets ``(n + 1,)``) for obstacles 1..n:
    boundary vertices ``(x, y)`` (``b_off``, ``b_xy``) and A7's input, the obstacle's
    vertices' ``(x, y)`` followed by its shadow vertices' (``g_off``, ``g_xy``: the twin's
    ``np.concatenate([vertices, shadows])``), with the number of vertices, their lowest and
    highest ``z`` (``np.minimum`` / ``np.maximum``: a NaN wins), the shadow areas and the
    triangle counts, in the twin's orders (vertices in raster order; a shadow set's vertices
    sorted by index, each once; areas summed in raster order).

    One pass over the shadow triangles ``shadows`` (raster order, owners in
    ``tri_obstacle``) and two over the vertices; the vertices' coordinates go straight to
    their place in ``g_xy`` (no per-obstacle vertex array and no second copy for A7: those
    were ~1.6 MB of memory traffic per frame). The triangle counts ``ntri (n,)`` are stage
    6's (:func:`split_kernel`)."""
    # the shadow triangles with an owner (raster order): counts per owner, areas, vertices
    C2 = tri_obstacle.shape[1]
    area = np.zeros(n + 1)
    t_cnt = np.zeros(n + 1, np.int64)
    sh_own = np.empty(len(shadows), np.int64)
    sh_v = np.empty((len(shadows), 3), np.int64)
    ns = 0
    ownf = tri_obstacle.ravel()
    for k in range(len(shadows)):
        f = shadows[k]
        a = ownf[f]
        if a <= 0:
            continue
        r, c = f // C2, f % C2
        i0, i1, i2 = tri[r, c, 0], tri[r, c, 1], tri[r, c, 2]
        t_cnt[a] += 1
        sh_own[ns] = a
        sh_v[ns, 0], sh_v[ns, 1], sh_v[ns, 2] = i0, i1, i2
        ns += 1
        v0x, v0y = flat[i0, 0], flat[i0, 1]
        area[a] += 0.5 * abs(
            (flat[i1, 0] - v0x) * (flat[i2, 1] - v0y) - (flat[i2, 0] - v0x) * (flat[i1, 1] - v0y)
        )
    t_off = np.zeros(n + 2, np.int64)
    for a in range(1, n + 1):
        t_off[a + 1] = t_off[a] + 3 * t_cnt[a]
    fill = t_off.copy()
    verts = np.empty(3 * ns, np.int64)
    for k in range(ns):
        a = sh_own[k]
        p = fill[a]
        verts[p] = sh_v[k, 0]
        verts[p + 1] = sh_v[k, 1]
        verts[p + 2] = sh_v[k, 2]
        fill[a] = p + 3
    s_cnt = np.zeros(n + 1, np.int64)
    m = 0
    for a in range(1, n + 1):  # each owner's vertices sorted (in place), each once
        seg = verts[t_off[a] : t_off[a + 1]]
        seg.sort()
        m0 = m
        for k in range(len(seg)):
            if k == 0 or seg[k] != seg[k - 1]:
                verts[m] = seg[k]
                m += 1
        s_cnt[a] = m - m0
    # the vertices: counts per obstacle, then the coordinates in place
    vf = vid.ravel()
    bf = boundary.ravel()
    nv = len(vf)
    v_cnt = np.zeros(n + 1, np.int64)
    b_off = np.zeros(n + 1, np.int64)
    for k in range(nv):
        a = vf[k]
        if a > 0:
            v_cnt[a] += 1
            if bf[k]:
                b_off[a] += 1
    g_off = np.zeros(n + 1, np.int64)
    for a in range(1, n + 1):  # counts -> offsets: id a's rows are off[a - 1]:off[a]
        g_off[a] = g_off[a - 1] + v_cnt[a] + s_cnt[a]
        b_off[a] += b_off[a - 1]
    g_xy = np.empty((g_off[n], 2))
    b_xy = np.empty((b_off[n], 2))
    z_min = np.full(n, np.inf)
    z_max = np.full(n, -np.inf)
    gfill = g_off.copy()
    bfill = b_off.copy()
    for k in range(nv):
        a = vf[k]
        if a > 0:
            x, y, z = flat[k, 0], flat[k, 1], flat[k, 2]
            p = gfill[a - 1]
            g_xy[p, 0] = x
            g_xy[p, 1] = y
            gfill[a - 1] = p + 1
            if z < z_min[a - 1] or z != z:  # np.minimum: a NaN stays
                if z_min[a - 1] == z_min[a - 1]:
                    z_min[a - 1] = z
            if z > z_max[a - 1] or z != z:
                if z_max[a - 1] == z_max[a - 1]:
                    z_max[a - 1] = z
            if bf[k]:
                q = bfill[a - 1]
                b_xy[q, 0] = x
                b_xy[q, 1] = y
                bfill[a - 1] = q + 1
    # each obstacle's shadow vertices after its own
    q = 0
    for a in range(1, n + 1):
        p = gfill[a - 1]
        for k in range(q, q + s_cnt[a]):
            w = verts[k]
            g_xy[p, 0] = flat[w, 0]
            g_xy[p, 1] = flat[w, 1]
            p += 1
        q += s_cnt[a]
    return b_off, b_xy, g_off, g_xy, v_cnt[1:], z_min, z_max, area[1:], ntri
