"""Compiled (Numba) kernels of paper 1's stage 1: the scan grid from a cloud
(:func:`navkit.obstacles.grids.cloud_to_grid`) and the body-frame points of a grid; and the
obstacle map's per-scan cell counting (:meth:`navkit.obstacles.ObstacleMapper.update`).

Each kernel computes exactly what its NumPy twin computes (``TWINS`` below), in the same
floating-point types and the same order of operations, so that classes, ids and masks are identical
and floats agree to the last bit (tested in ``tests/obstacles/test_kernels.py``). Rules kept for
that:

- float32 arithmetic stays float32: constants that NumPy 2 treats as *weak* Python scalars
  (``jump_height_m`` in ``z_max - z_min > jump_height_m + ...`` on float32 arrays) are passed in
  as ``np.float32``; square roots of float32 values are rounded back to float32;
- NaN propagates through minima and maxima as in ``np.minimum`` / ``np.maximum``;
- transcendental functions (``arctan2``, ``cos``) stay in NumPy (its SIMD ``arctan2`` differs
  from libm's by an ulp on ~7 % of inputs), the kernels take their results - except the scan
  grid's per-point azimuth, which both paths compute with one fixed arithmetic
  (:func:`navkit.geometry.angles.atan2` and its kernel ``atan2_kernel``, the same bits).

The kernels run on one thread: the targets are CPU time per frame (``parallel=True`` would add
threads, not remove work). ``cache=True`` keeps the compiled code on disk (``NUMBA_CACHE_DIR`` or
``__pycache__``); :mod:`navkit.jit` chooses between the kernels and the twins
(``navkit.jit.use``); see ``docs/kernels.md``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from navkit.obstacles._kernels_common import _median, _median_banded
from navkit.obstacles.rules import OBSTACLE

__all__ = [
    "body_points_kernel",
    "cloud_prep_kernel",
    "cloud_valid_kernel",
    "grid_cells_kernel",
    "grid_fill_kernel",
    "grid_order_fill_kernel",
    "map_cells_kernel",
    "phase_fractions_kernel",
    "phase_sin_cos_kernel",
    "points_kernel",
    "rings_by_order_kernel",
    "rings_order_kernel",
]

TWINS = {
    "body_points_kernel": "navkit.obstacles.mounting.Mounting.to_body",
    "cloud_prep_kernel": "navkit.obstacles.grids.cloud_to_grid",
    "cloud_valid_kernel": "navkit.obstacles.grids.cloud_to_grid",
    "grid_cells_kernel": "navkit.obstacles.grids.cloud_to_grid",
    "grid_fill_kernel": "navkit.obstacles.grids.cloud_to_grid",
    "grid_order_fill_kernel": "navkit.obstacles.grids.cloud_to_grid",
    "map_cells_kernel": "navkit.obstacles.mapper.count_scan_cells",
    "phase_fractions_kernel": "navkit.obstacles.grids.cloud_to_grid",
    "phase_sin_cos_kernel": "navkit.obstacles.grids.cloud_to_grid",
    "points_kernel": "navkit.obstacles.detector.detect_obstacles_grid",
    "rings_by_order_kernel": "navkit.obstacles.grids._rings_by_order",
    "rings_order_kernel": "navkit.obstacles.grids._rings_by_order",
}
"""Each public kernel -> its NumPy twin (the NumPy path of that function)."""


# ------------------------------------------------------------------------------------------
# stage 1 input: the cloud-to-grid fill (twin: the end of grids.cloud_to_grid)


@njit(cache=True, error_model="numpy")
def grid_fill_kernel(Q, rh, cell, n_cells):  # type: ignore[no-untyped-def]
    """The nearest point of each cell: ``(n_cells, 3)`` rows of ``Q (N, 3)`` (NaN rows if empty).

    The range is ``sqrt(rh^2 + z^2)`` as in the twin; among points at exactly the same range the
    last one in input order wins, which is where the twin's overwrite rounds converge.
    """
    win = np.full(n_cells, -1, np.int64)
    r = np.empty(len(cell), np.float64)
    for p in range(len(cell)):
        z = Q[p, 2]
        r[p] = math.sqrt(rh[p] * rh[p] + z * z)
        c = cell[p]
        w = win[c]
        if w < 0 or r[p] <= r[w]:
            win[c] = p
    out = np.empty((n_cells, 3), np.float64)
    for c in range(n_cells):
        w = win[c]
        if w < 0:
            out[c, 0] = np.nan
            out[c, 1] = np.nan
            out[c, 2] = np.nan
        else:
            out[c, 0] = Q[w, 0]
            out[c, 1] = Q[w, 1]
            out[c, 2] = Q[w, 2]
    return out


# ------------------------------------------------------------------------------------------
# stage 1 input, fast path: rings from the storage order, columns, cells and the fill in three
# kernels writing into caller-provided arrays (twin: grids.cloud_to_grid, ring_method "order")


@njit(cache=True, error_model="numpy")
def cloud_valid_kernel(P, far, qx, qy, qz, idx):  # type: ignore[no-untyped-def]
    """The valid points of ``P (N, >=3)`` (finite, not ``(0, 0, 0)``, every coordinate below
    ``far`` in magnitude - the twin NaNs the others) as float64 columns ``qx, qy, qz`` and
    their input index ``idx``. Returns how many.

    No horizontal range here: the twin's ``np.hypot`` (libm's, a function call per point, ~0.4
    ms per KITTI frame) enters only comparisons - the ring ranking and the nearest point per
    cell - which the later kernels decide with ``sqrt(x^2 + y^2)`` whenever the answer is
    certain and with ``math.hypot`` (= ``np.hypot``) when it is not."""
    n = P.shape[0]
    m = 0
    for p in range(n):
        x = np.float64(P[p, 0])
        y = np.float64(P[p, 1])
        z = np.float64(P[p, 2])
        ok = abs(x) < far and abs(y) < far and abs(z) < far  # False for NaN
        ok = ok and (x != 0 or y != 0 or z != 0)
        if ok:
            um = np.uint64(m)  # >= 0: no negative-index fix-up
            qx[um] = x
            qy[um] = y
            qz[um] = z
            idx[um] = p
            m += 1
    return m


@njit(cache=True, error_model="numpy")
def rings_order_kernel(az, qx, qy, qz, d, ad, work, ring, sums, abs_sums, counts):  # type: ignore[no-untyped-def]
    """``grids._rings_by_order`` on ``az (n,)``: ``(found, azimuth step, number of rings, lowest
    raw ring)``, the raw ring of every point in ``ring`` (subtract the lowest one for the ring
    index) and, per ring ``r - lowest``, the count of points and the sum, in point order, of
    ``z / max(sqrt(x^2 + y^2), 1e-9)`` and of its magnitude (the twin's ``bincount`` weights
    with ``sqrt`` for ``hypot``, summed in any order: only their ranking is used, which
    :func:`grid_order_fill_kernel` checks against their error bound) in ``counts``, ``sums``
    and ``abs_sums`` (at least 512 long). ``d, ad, work`` are float64 work arrays of ``n``."""
    n = len(az)
    two_pi = 2 * np.pi
    if n < 100:
        return False, 0.0, 0, 0
    pos = 0
    for k in range(n - 1):  # one pass: the wrapped steps, their magnitudes, how many are > 0
        v = az[k + 1] - az[k]
        v = v - two_pi if v >= np.pi else v
        v = v + two_pi if v < -np.pi else v
        d[k] = v
        ad[k] = abs(v)
        pos += 1 if v > 0 else 0
    step = _median_banded(ad[: n - 1], work)
    if not step > 0:
        return False, 0.0, 0, 0
    direction = 1.0 if 2 * pos > n - 1 else -1.0
    fwd = 0
    lim = -0.5 * step
    for k in range(n - 1):
        fwd += 1 if direction * d[k] > lim else 0
    if step > two_pi / 64 or fwd / (n - 1) < 0.9:
        return False, 0.0, 0, 0
    # the unwrapped azimuth: the twin's cumsum, a serial chain of additions (nothing else in
    # this loop, so that the rest vectorises)
    u = work
    acc = 0.0
    u[0] = acc
    for k in range(1, n):
        acc += d[k - 1]
        u[k] = acc
    half = 0.5 * step
    lo = 0
    hi = 0
    for k in range(n):  # vectorised: division, floor, min / max
        r = np.int64(math.floor((direction * u[k] + half) / two_pi))
        ring[k] = r
        lo = min(lo, r)
        hi = max(hi, r)
    n_r = hi - lo + 1
    if n_r < 2 or n_r > 512:
        return False, 0.0, 0, 0
    t = ad
    for k in range(n):  # vectorised
        x = qx[k]
        y = qy[k]
        t[k] = qz[k] / max(math.sqrt(x * x + y * y), 1e-9)
    for r in range(n_r):
        sums[r] = 0.0
        abs_sums[r] = 0.0
        counts[r] = 0
    # per-ring sums over runs of points of one ring (a ring is mostly one run in storage
    # order), four running sums each: these sums only have to be within their error bound,
    # which holds for any order of the additions
    k = 0
    while k < n:
        r = ring[k]
        e = k + 1
        while e < n and ring[e] == r:
            e += 1
        s0 = s1 = s2 = s3 = 0.0
        a0 = a1 = a2 = a3 = 0.0
        q = k
        while q + 4 <= e:
            s0 += t[q]
            s1 += t[q + 1]
            s2 += t[q + 2]
            s3 += t[q + 3]
            a0 += abs(t[q])
            a1 += abs(t[q + 1])
            a2 += abs(t[q + 2])
            a3 += abs(t[q + 3])
            q += 4
        while q < e:
            s0 += t[q]
            a0 += abs(t[q])
            q += 1
        ur = np.uint64(r - lo)
        sums[ur] += (s0 + s1) + (s2 + s3)
        abs_sums[ur] += (a0 + a1) + (a2 + a3)
        counts[ur] += e - k
        k = e
    return True, step, n_r, lo


@njit(cache=True, error_model="numpy")
def _cells_pass(az, ring, lo, lut, phase, n_columns, n_el, qx, qy, qz, idx, r2w, cell_of_point):  # type: ignore[no-untyped-def]
    """The column ``i`` of every point (the twin's ``floor((az + pi) / (2 pi) n_columns - phase
    + 0.5) % n_columns``), its cell ``i n_el + j`` into ``cell_of_point`` (at ``idx``, -1 for
    the other entries), its ring-major cell ``j n_columns + i`` over ``ring`` and ``x^2 + y^2 +
    z^2`` into ``r2w``.

    Two passes: the arithmetic (vectorised), with the columns parked in ``cell_of_point[:n]``,
    then the ring lookup and the cells, backwards: ``idx[k] >= k``, so a cell written at
    ``idx[k]`` never overwrites a parked column still to be read. The modulo as two selects:
    ``az`` in ``[-pi, pi]`` (``arctan2``) and ``phase`` in ``[-1/2, 1/2]`` (``arctan2 / 2 pi``)
    put ``floor(...)`` in ``[0, n_columns + 1]``, where subtracting ``n_columns`` once from
    values ``>= n_columns`` is the modulo (``n_columns >= 3``); the select for negative values
    only guards the reasoning."""
    n = len(az)
    scale = 2 * np.pi
    for k in range(n):  # vectorised: division, floor, selects, squares
        x = (az[k] + np.pi) / scale * n_columns
        i = math.floor(x - phase + 0.5)
        i = i - n_columns if i >= n_columns else i
        i = i + n_columns if i < 0 else i
        cell_of_point[k] = i
        px = qx[k]
        py = qy[k]
        pz = qz[k]
        r2w[k] = px * px + py * py + pz * pz
    for k in range(n - 1, -1, -1):
        uk = np.uint64(k)
        i = cell_of_point[uk]
        j = lut[np.uint64(ring[uk] - lo)]
        cell_of_point[np.uint64(idx[uk])] = i * n_el + j
        ring[uk] = j * n_columns + i
    if n < len(cell_of_point):  # the points that are not valid: -1 (between the valid ones)
        prev = -1
        for k in range(n):
            for p in range(prev + 1, idx[k]):
                cell_of_point[p] = -1
            prev = idx[k]
        for p in range(prev + 1, len(cell_of_point)):
            cell_of_point[p] = -1


@njit(cache=True, error_model="numpy")
def grid_order_fill_kernel(  # type: ignore[no-untyped-def]
    qx, qy, qz, az, idx, ring, lo, lut, n_el, n_columns, phase, win, best, r2w, grid, cell_of_point
):
    """The column of every point, its cell, the nearest point per cell into ``grid (n_columns
    n_el, 3)`` (NaN rows if empty; among points at the same range the last one wins, as in the
    twin) and ``cell_of_point (N,)`` (-1 for the points that are not valid). ``lut`` maps a
    ring ``ring - lo`` to its elevation index (``grids._ring_lut``: the rings ranked by rising
    mean ``z / r_h``). ``win`` (int32 when the points fit: less to clear and read than int64,
    ~0.08 ms per KITTI frame) and ``best`` (float64) are work arrays of the cells, ``r2w`` a
    float64 work array of the points; ``ring`` is overwritten (with each point's ring-major
    cell).

    Bit for bit the twin's decisions without its ``hypot`` per point: the nearest point per
    cell compares squared ranges ``x^2 + y^2 + z^2`` and falls back to the twin's range
    ``sqrt(hypot(x, y)^2 + z^2)`` when two are within a relative ``1e-12`` of each other or
    tiny (written out here, not as a helper: each helper is one more function to compile on
    the first call)."""
    n = len(az)
    n_cells = n_columns * n_el
    for c in range(n_cells):
        win[c] = -1
    lo_f = 1.0 - 1e-12
    hi_f = 1.0 + 1e-12
    tiny = 1e-280
    # columns, cells and squared ranges first, in a loop without the scatter's branches
    # (~0.35 ms of KITTI's ~1 ms here, scalar: the lookup keeps it from vectorising); the
    # ring-major cell of each point replaces its ring
    _cells_pass(az, ring, lo, lut, phase, n_columns, n_el, qx, qy, qz, idx, r2w, cell_of_point)
    # unsigned indices (all >= 0 by construction): no negative-index fix-up per access
    for k in range(n):
        c = np.uint64(ring[k])
        r2 = r2w[k]
        w = win[c]
        if w < 0:
            take = True
        else:
            b2 = best[c]
            if r2 < lo_f * b2 and r2 > tiny:
                take = True
            elif r2 > hi_f * b2 and b2 > tiny:
                take = False
            else:  # too close to tell (or tiny): the twin's ranges
                uw = np.uint64(w)
                hk = math.hypot(qx[k], qy[k])
                hw = math.hypot(qx[uw], qy[uw])
                zk = qz[k]
                zw = qz[uw]
                take = math.sqrt(hk * hk + zk * zk) <= math.sqrt(hw * hw + zw * zw)
        if take:
            win[c] = k
            best[c] = r2
    ncol = np.uint64(n_columns)
    g = grid.reshape(-1)
    nel = np.uint64(n_el)
    three = np.uint64(3)
    for i in range(n_columns):
        for j in range(n_el):
            w = win[np.uint64(j) * ncol + np.uint64(i)]
            c = three * (np.uint64(i) * nel + np.uint64(j))
            if w < 0:
                g[c] = np.nan
                g[c + np.uint64(1)] = np.nan
                g[c + np.uint64(2)] = np.nan
            else:
                uw = np.uint64(w)
                g[c] = qx[uw]
                g[c + np.uint64(1)] = qy[uw]
                g[c + np.uint64(2)] = qz[uw]
    return n_el


# ------------------------------------------------------------------------------------------
# stage 1 input, general path: validity, rings from the storage order, cells (twin:
# grids.cloud_to_grid; the fill is grid_fill_kernel)


@njit(cache=True, error_model="numpy")
def rings_by_order_kernel(az):  # type: ignore[no-untyped-def]
    """``grids._rings_by_order``: ``(ok, ring per point, azimuth step)``; ``ok`` False when the
    storage order is not a sweep."""
    n = len(az)
    two_pi = 2 * np.pi
    empty = np.zeros(0, np.int64)
    if n < 100:
        return False, empty, 0.0
    d = np.empty(n - 1)
    ad = np.empty(n - 1)
    pos = 0
    for k in range(n - 1):
        v = az[k + 1] - az[k]
        if v >= np.pi:
            v -= two_pi
        elif v < -np.pi:
            v += two_pi
        d[k] = v
        ad[k] = abs(v)
        if v > 0:
            pos += 1
    step = _median(ad)
    if not step > 0:
        return False, empty, 0.0
    direction = 1.0 if 2 * pos > n - 1 else -1.0
    fwd = 0
    for k in range(n - 1):
        if direction * d[k] > -0.5 * step:
            fwd += 1
    if step > two_pi / 64 or fwd / (n - 1) < 0.9:
        return False, empty, 0.0
    ring = np.empty(n, np.int64)
    acc = 0.0
    half = 0.5 * step
    lo = np.iinfo(np.int64).max
    hi = np.iinfo(np.int64).min
    for k in range(n):
        if k > 0:
            acc += d[k - 1]
        r = math.floor((direction * acc + half) / two_pi)
        ring[k] = r
        lo = min(lo, r)
        hi = max(hi, r)
    if hi - lo + 1 < 2 or hi - lo + 1 > 512:
        return False, empty, 0.0
    for k in range(n):
        ring[k] -= lo
    return True, ring, step


@njit(cache=True, error_model="numpy")
def grid_cells_kernel(Q, rh, az, ring, n_columns, phase):  # type: ignore[no-untyped-def]
    """The rest of ``grids.cloud_to_grid`` after the rings: rings ranked by rising mean
    elevation, azimuth columns, flat cell per point. Returns ``(cell, n_el)``."""
    n = len(ring)
    n_r = 0
    for k in range(n):
        n_r = max(n_r, ring[k] + 1)
    counts = np.zeros(n_r, np.int64)
    sums = np.zeros(n_r, np.float64)
    for k in range(n):
        counts[ring[k]] += 1
        sums[ring[k]] += Q[k, 2] / max(rh[k], 1e-9)
    key = np.empty(n_r)
    n_el = 0
    for r in range(n_r):
        if counts[r] > 0:
            key[r] = sums[r] / max(counts[r], 1)
            n_el += 1
        else:
            key[r] = np.inf
    rank = np.argsort(key, kind="mergesort")
    lut = np.empty(n_r, np.int64)
    for r in range(n_r):
        lut[rank[r]] = r
    cell = np.empty(n, np.int64)
    scale = 2 * np.pi
    for k in range(n):
        x = (az[k] + np.pi) / scale * n_columns
        i = math.floor(x - phase + 0.5) % n_columns
        cell[k] = i * n_el + lut[ring[k]]
    return cell, n_el


@njit(cache=True)
def cloud_prep_kernel(P):  # type: ignore[no-untyped-def]
    """The start of ``grids.cloud_to_grid``: the valid points (finite, not ``(0, 0, 0)``) of
    ``P (N, >=3)`` as float64 rows ``Q (M, 3)``, their input indices and horizontal ranges."""
    n = P.shape[0]
    keep = np.empty(n, np.int64)
    m = 0
    for p in range(n):
        x = np.float64(P[p, 0])
        y = np.float64(P[p, 1])
        z = np.float64(P[p, 2])
        if math.isfinite(x) and math.isfinite(y) and math.isfinite(z):
            if x != 0 or y != 0 or z != 0:
                keep[m] = p
                m += 1
    Q = np.empty((m, 3), np.float64)
    rh = np.empty(m, np.float64)
    for k in range(m):
        p = keep[k]
        Q[k, 0] = np.float64(P[p, 0])
        Q[k, 1] = np.float64(P[p, 1])
        Q[k, 2] = np.float64(P[p, 2])
        rh[k] = math.hypot(Q[k, 0], Q[k, 1])
    return Q, keep[:m].copy(), rh


# ------------------------------------------------------------------------------------------
# stage 1 on an organised grid: validity codes and body-frame points (twin: the NumPy stage 1
# of detector.detect_obstacles_grid and Mounting.to_body)


@njit(cache=True, error_model="numpy")
def points_kernel(P, out, valid, limit):  # type: ignore[no-untyped-def]
    """Stage 1's validity codes C_d: ``valid`` = all three coordinates finite, and the points
    with NaN rows where not valid (``detector.detect_obstacles_grid``), written into ``out
    (n_az, n_el, 3) float64`` and ``valid (n_az, n_el) bool``. Returns ``(number of valid
    points, number of valid points with a coordinate beyond limit in magnitude)``: the caller
    refuses the input when the second is not 0 (the bound that keeps the later stages' grid
    indices in range, ``geometry._validate.MAX_COORDINATE_M``); the pass reads every point
    anyway, so the check costs nothing here."""
    n_az, n_el = P.shape[0], P.shape[1]
    inf = np.inf
    count = 0
    far = 0
    for i in range(n_az):
        for j in range(n_el):  # branch-free (selects): the loop vectorises
            x, y, z = P[i, j, 0], P[i, j, 1], P[i, j, 2]
            ok = (abs(x) < inf) & (abs(y) < inf) & (abs(z) < inf)  # finite; NaN fails
            valid[i, j] = ok
            count += 1 if ok else 0
            far += 1 if (ok & ((abs(x) > limit) | (abs(y) > limit) | (abs(z) > limit))) else 0
            out[i, j, 0] = x if ok else np.nan
            out[i, j, 1] = y if ok else np.nan
            out[i, j, 2] = z if ok else np.nan
    return count, far


@njit(cache=True)
def phase_fractions_kernel(az, step, n_columns, out):  # type: ignore[no-untyped-def]
    """``2 pi ((az[::step] + pi) / (2 pi) n_columns % 1)`` into ``out`` (the subsample whose
    circular mean gives the columns' phase in ``grids.cloud_to_grid``; the same values as the
    twin's NumPy expression: ``%`` of a positive value is exact). Returns how many."""
    m = 0
    two_pi = 2 * np.pi
    for k in range(0, len(az), step):
        xs = (az[k] + np.pi) / two_pi * n_columns
        out[m] = two_pi * (xs % 1.0)
        m += 1
    return m


@njit(cache=True, error_model="numpy")
def phase_sin_cos_kernel(az, step, n_columns, s, c):  # type: ignore[no-untyped-def]
    """``sin`` and ``cos`` of ``2 pi ((az[::step] + pi) / (2 pi) n_columns % 1)`` into ``s`` and
    ``c`` (the subsample whose circular mean gives the columns' phase in
    ``grids.cloud_to_grid``; their means are NumPy's, as in the twin). ``math.sin`` /
    ``math.cos`` are libm's, which NumPy's float64 ``sin`` / ``cos`` call (``grids`` checks
    that once per process and keeps NumPy's otherwise). Returns how many."""
    m = 0
    two_pi = 2 * np.pi
    for k in range(0, len(az), step):
        xs = (az[k] + np.pi) / two_pi * n_columns
        f = two_pi * (xs % 1.0)
        s[m] = math.sin(f)
        c[m] = math.cos(f)
        m += 1
    return m


@njit(cache=True, error_model="numpy")
def body_points_kernel(S, R, h, out, valid, limit):  # type: ignore[no-untyped-def]
    """Stage 1 from sensor-frame points: ``Mounting.to_body`` (``S @ R.T``, then ``z += h``)
    and :func:`points_kernel` in one pass, into ``out (n_az, n_el, 3) float64`` and ``valid
    (n_az, n_el) bool``. Returns ``(number of valid points, number of valid body points with a
    coordinate beyond limit in magnitude)``, as :func:`points_kernel`.

    Only for a rotation ``R`` whose rows each hold one entry +-1 and two +-0 (the identity of a
    level mounting, axis swaps): every product is then exact and the sum of one value and two
    signed zeros does not depend on the order of the terms, so the result is the matmul's bit
    for bit, whatever order or fused multiply-adds BLAS uses (the sums start from +0 as BLAS's
    accumulators do; `tests/obstacles/test_kernels.py` checks signed zeros). Other rotations go
    through NumPy.
    """
    n = S.shape[0] * S.shape[1]
    s = S.reshape(n * 3)
    o = out.reshape(n * 3)
    v = valid.reshape(n)
    r00, r01, r02 = R[0, 0], R[0, 1], R[0, 2]
    r10, r11, r12 = R[1, 0], R[1, 1], R[1, 2]
    r20, r21, r22 = R[2, 0], R[2, 1], R[2, 2]
    inf = np.inf
    count = 0
    far = 0
    # branch-free (finite = |v| < inf, NaN fails; selects, not ifs): the loop vectorises, ~3x
    # faster than with branches
    for p in range(n):
        sx, sy, sz = s[3 * p], s[3 * p + 1], s[3 * p + 2]
        # sums started from +0, as BLAS's accumulators: an all-zero row gives +0 (a plain
        # sum of three -0 products would give -0)
        x = ((0.0 + sx * r00) + sy * r01) + sz * r02
        y = ((0.0 + sx * r10) + sy * r11) + sz * r12
        z = (((0.0 + sx * r20) + sy * r21) + sz * r22) + h
        ok = (abs(x) < inf) & (abs(y) < inf) & (abs(z) < inf)
        v[p] = ok
        count += 1 if ok else 0
        far += 1 if (ok & ((abs(x) > limit) | (abs(y) > limit) | (abs(z) > limit))) else 0
        o[3 * p] = x if ok else np.nan
        o[3 * p + 1] = y if ok else np.nan
        o[3 * p + 2] = z if ok else np.nan
    return count, far


# ------------------------------------------------------------------------------------------
# the obstacle map: one scan's cells counted (twin: mapper.count_scan_cells)


@njit(cache=True)
def map_cells_kernel(P, valid, vlab, vobs, S, o, max_r2, H, W, hits, seen, mark, box):  # type: ignore[no-untyped-def]
    """``mapper.count_scan_cells`` in one pass over the points: each counted point's cell from
    the twin's operations in its order (``((x S0 + y S1) + z S2) + o``; a cell index ``c`` is in
    the grid when ``0 <= c < W``, where ``floor(c)`` is ``int(c)``), counted at once; ``mark``
    (zero on entry and on return: 1 seen, 2 seen and obstacle) counts a cell once per scan in
    ``seen`` and in ``hits``; ``box`` (row min, row max, column min, column max) grows to hold
    every cell seen. Returns the obstacle cells (ascending) and the number of distinct cells
    seen."""
    n = P.shape[0]
    obst = np.empty(n, np.int64)
    cells = np.empty(n, np.int64)
    n_obst = 0
    n_seen = 0
    s00, s01, s02 = S[0, 0], S[0, 1], S[0, 2]
    s10, s11, s12 = S[1, 0], S[1, 1], S[1, 2]
    o0, o1 = o[0], o[1]
    fw, fh = float(W), float(H)
    r0, r1, c0, c1 = box[0], box[1], box[2], box[3]
    for i in range(n):
        if not valid[i]:
            continue
        x, y, z = P[i, 0], P[i, 1], P[i, 2]
        if not (x * x + y * y <= max_r2):
            continue
        c = ((x * s00 + y * s01) + z * s02) + o0
        r = ((x * s10 + y * s11) + z * s12) + o1
        if not (c >= 0.0 and r >= 0.0 and c < fw and r < fh):  # NaN fails
            continue
        ir, ic = int(r), int(c)
        f = ir * W + ic
        m = mark[f]
        if m == 0:
            seen[f] += 1
            cells[n_seen] = f
            n_seen += 1
            m = 1
            r0, r1, c0, c1 = min(r0, ir), max(r1, ir), min(c0, ic), max(c1, ic)
        if m == 1 and vlab[i] == OBSTACLE and vobs[i] > 0:
            hits[f] += 1
            obst[n_obst] = f
            n_obst += 1
            m = 2
        mark[f] = m
    for k in range(n_seen):
        mark[cells[k]] = 0
    box[0], box[1], box[2], box[3] = r0, r1, c0, c1
    return np.sort(obst[:n_obst]), n_seen
