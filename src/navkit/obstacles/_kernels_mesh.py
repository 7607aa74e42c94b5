"""Compiled (Numba) kernel of paper 1's stages 2-5 in one pass over the grid: mesh, normals,
height jumps H_s, robust normals, rules P1-P5 and the triangle classes
(:func:`navkit.obstacles.rules.mesh_and_classes`).

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

from navkit._intrinsics import prefetch
from navkit.obstacles._kernels_common import _kth, _median_banded

__all__ = ["robust_strides_kernel", "stages_2_5_kernel"]

TWINS = {
    "robust_strides_kernel": "navkit.obstacles.mesh.robust_strides",
    "stages_2_5_kernel": "navkit.obstacles.rules.mesh_and_classes",
}
"""Each public kernel -> its NumPy twin."""

_NAN32 = np.float32(np.nan)


# ------------------------------------------------------------------------------------------
# stages 2-5 fused: mesh, robust normals, H_s, rules, classes in one pass over the grid
# (twin: rules.mesh_and_classes - mesh.build_mesh, mesh.robust_cell_normals and rules.classify
# one after the other)


@njit(cache=True, error_model="numpy")
def robust_strides_kernel(points, valid, origin, az, support_m, max_stride):  # type: ignore[no-untyped-def]
    """The strides of :func:`~navkit.obstacles.mesh.robust_cell_normals` from the grid.

    ``az (n_az, S) float64`` are NumPy's ``arctan2`` of the sampled columns (``points[:,
    ::step]`` as float32, minus the origin in float64). Returns ``(dalpha, m_col)``: the median
    azimuth step (rad, 1.0 when none) and the elevation stride per column ``(n_el,) intp``,
    computed as the twin computes them (float32 horizontal ranges of every 4th row, their
    per-column medians, ``np.interp`` over the empty columns, the clipped ``rint``).
    """
    n_az, n_el = valid.shape
    two_pi = 2 * np.pi
    S = az.shape[1]
    dal = np.empty(max(n_az - 1, 0) * S)
    m = 0
    for i in range(n_az - 1):
        for s in range(S):
            # NumPy's ``(d + pi) % (2 pi) - pi`` for d + pi in (-2 pi, 4 pi), without fmod: the
            # same result (x - 2 pi is exact there, Sterbenz; x + 2 pi is NumPy's own step)
            x = (az[i + 1, s] - az[i, s]) + np.pi
            if x >= two_pi:
                x = x - two_pi
            elif not x >= 0:  # negative or NaN
                x = x + two_pi
            v = abs(x - np.pi)
            dal[m] = v  # branch-free: always written, kept when finite and > 0
            m += 1 if (math.isfinite(v) and v > 0) else 0
    dalpha = 1.0
    if m > 0:  # np.median: the middle order statistic(s), exactly
        dalpha = _median_banded(dal[:m], np.empty(m))
    ox32 = np.float32(origin[0])
    oy32 = np.float32(origin[1])
    n4 = (n_az + 3) // 4
    # the float32 horizontal ranges of every 4th row, gathered per column (row by row: in
    # memory order)
    cols = np.empty((n_el, n4), np.float32)
    cnts = np.zeros(n_el, np.int64)
    for i in range(0, n_az, 4):
        for j in range(n_el):
            if valid[i, j]:
                # float32 hypot as glibc's hypotf computes it: in double, rounded once
                hx = np.float64(np.float32(points[i, j, 0]) - ox32)
                hy = np.float64(np.float32(points[i, j, 1]) - oy32)
                cols[j, cnts[j]] = np.float32(math.sqrt(hx * hx + hy * hy))
                cnts[j] += 1
    xp = np.empty(n_el, np.float64)
    fp = np.empty(n_el, np.float64)
    n_cols = 0
    for j in range(n_el):
        cnt = cnts[j]
        if cnt == 0:
            continue
        col = cols[j]
        h = (cnt - 1) // 2
        lo = _kth(col[:cnt], h)
        hi = lo
        if cnt % 2 == 0:  # the upper middle: the least of what the selection left after h
            hi = col[h + 1]
            for q in range(h + 2, cnt):
                hi = col[q] if col[q] < hi else hi
        xp[n_cols] = j
        fp[n_cols] = np.float64((lo + hi) / np.float32(2))
        n_cols += 1
    rh_col = np.ones(n_el)
    if n_cols == 1:
        for j in range(n_el):
            rh_col[j] = fp[0]
    elif n_cols > 1:
        # np.interp at the integers 0 .. n_el - 1 (left / right: the end values)
        k = 0
        for j in range(n_el):
            x = np.float64(j)
            if x <= xp[0]:
                rh_col[j] = fp[0]
                continue
            if x >= xp[n_cols - 1]:
                rh_col[j] = fp[n_cols - 1]
                continue
            while xp[k + 1] <= x:
                k += 1
            if xp[k] == x:
                rh_col[j] = fp[k]
            else:
                slope = (fp[k + 1] - fp[k]) / (xp[k + 1] - xp[k])
                rh_col[j] = slope * (x - xp[k]) + fp[k]
    se = np.empty(n_el)
    for j in range(n_el - 1):
        se[j] = abs(rh_col[j + 1] - rh_col[j])
    se[n_el - 1] = se[n_el - 2] if n_el > 1 else 0.0
    m_col = np.empty(n_el, np.intp)
    for j in range(n_el):
        a = se[j]
        b = se[j - 1] if j > 0 else se[n_el - 1]
        f = b if (a != a or b < a) else a  # np.fmin
        if f != f or f < 1e-3:
            f = 1e-3
        v = np.rint(support_m / (2.0 * f))
        m_col[j] = min(max(int(v), 1), max_stride)
    return dalpha, m_col


@njit(cache=True, error_model="numpy")
def _vertex_pass(pf, vf, origin, nv, n_el, X, Y, Z, V, D, vr, want_vr):  # type: ignore[no-untyped-def]
    """Stage 2-5 pass 1: float32 coordinates, validity, range and line of sight per vertex, in
    flat arrays with one extra row (row 0 again: the seam) and one more vertex (padding). The
    lines of sight ``vr`` only with ``want_vr`` (no stage after 5 reads them: the detector
    skips their 1.5 MB of writes per KITTI grid)."""
    o0 = np.float32(origin[0])
    o1 = np.float32(origin[1])
    o2 = np.float32(origin[2])
    # the coordinates from the flat points with unsigned indices, the validity in its own loop:
    # ~45 % faster on a Zen 3 core (AVX2) than one loop over ``pf[f, c]`` and ``vf[f]``
    pflat = pf.reshape(-1)
    three = np.uint64(3)
    for ff in range(nv):
        q = three * np.uint64(ff)
        X[ff] = np.float32(pflat[q])
        Y[ff] = np.float32(pflat[q + np.uint64(1)])
        Z[ff] = np.float32(pflat[q + np.uint64(2)])
    for f in range(nv):
        V[f] = vf[f]
    if want_vr:
        for f in range(nv):
            rx = X[f] - o0
            ry = Y[f] - o1
            rz = Z[f] - o2
            d = np.float32(math.sqrt(rx * rx + ry * ry + rz * rz))
            D[f] = d
            vr[3 * f] = rx / d
            vr[3 * f + 1] = ry / d
            vr[3 * f + 2] = rz / d
    else:
        for f in range(nv):
            rx = X[f] - o0
            ry = Y[f] - o1
            rz = Z[f] - o2
            D[f] = np.float32(math.sqrt(rx * rx + ry * ry + rz * rz))
    for f in range(n_el + 1):
        g = f if f < nv else nv - 1
        X[nv + f] = X[g]
        Y[nv + f] = Y[g]
        Z[nv + f] = Z[g]
        D[nv + f] = D[g]
        V[nv + f] = V[g] if f < n_el else False


@njit(cache=True, error_model="numpy")
def _robust_prep(X, Y, Z, origin, nv, k_scale, max_stride, Df, kst):  # type: ignore[no-untyped-def]
    """Stage 2-5 pass 2a: per vertex, the float64 range ``Df`` and the azimuth stride ``kst``
    of :func:`robust_normals_kernel` (``rint(k_scale / r_h)`` clipped to ``[1, max_stride]``,
    1 for NaN)."""
    for f in range(nv):
        dx = np.float64(X[f]) - origin[0]
        dy = np.float64(Y[f]) - origin[1]
        dz = np.float64(Z[f]) - origin[2]
        Df[f] = math.sqrt(dx * dx + dy * dy + dz * dz)
    ox32 = np.float32(origin[0])
    oy32 = np.float32(origin[1])
    fmax = np.float32(max_stride)
    for f in range(nv):
        hx = np.float64(X[f] - ox32)
        hy = np.float64(Y[f] - oy32)
        rh = np.float32(math.sqrt(hx * hx + hy * hy))
        kf = np.rint(k_scale / rh)
        kf = kf if kf >= 1 else np.float32(1.0)  # NaN -> 1
        kf = kf if kf <= fmax else fmax
        kst[f] = int(kf)


@njit(cache=True, error_model="numpy")
def _robust_rows(  # type: ignore[no-untyped-def]
    i0,
    i1,
    X,
    Y,
    Z,
    Df,
    kst,
    n_az,
    n_el,
    jp_tab,
    jm_tab,
    wrap,
    max_stride,
    jump_h,
    jump_f,
    ratio,
    use_ratio,
    nvx,
    nvy,
    nvz,
):
    """Stage 2-5 pass 2b: the robust vertex normals of rows ``i0 .. i1 - 1`` (the first loop of
    :func:`robust_normals_kernel`) into the flat ``nvx, nvy, nvz``."""
    # unsigned indices: Numba then skips its negative-index fix-up on every gather (~25 %
    # faster on KITTI); every end point is a valid index (>= 0) by construction
    big = n_az > max_stride
    tb = np.empty((6, n_el), np.float32)  # the row's tangents (azimuth, elevation)
    naz = np.uint64(n_az)
    nel = np.uint64(n_el)
    for i in range(i0, i1):
        ii = np.uint64(i)
        base = ii * nel
        # the farthest row the end points of the coming rows can reach, ahead of use: its
        # first touch otherwise stalls on memory (the end points hop between rows, which the
        # hardware prefetcher does not follow; ~40 % of the pass on a Zen 3 core)
        ia = i + max_stride + 2
        ia = ia - n_az if ia >= n_az else ia
        if ia < n_az:
            ba = np.uint64(ia) * nel
            for q in range(ba, ba + nel, np.uint64(16)):
                prefetch(X, q)
                prefetch(Y, q)
                prefetch(Z, q)
            for q in range(ba, ba + nel, np.uint64(8)):
                prefetch(Df, q)
        for jj in range(n_el):
            j = np.uint64(jj)
            f = base + j
            zc = Z[f]
            if zc != zc:  # an empty vertex: every test below fails and the normal is 0 (zero
                # tangents: 0 * (1 / 0) is NaN, not finite)
                for q in range(6):
                    tb[q, j] = np.float32(0.0)
                continue
            k = np.uint64(kst[f])
            if wrap and big:  # 1 <= k <= max_stride < n_az
                ip = ii + k
                im = ii + naz - k
                ip = ip - naz if ip >= naz else ip
                im = im - naz if im >= naz else im
            elif wrap:
                ip = np.uint64((i + kst[f]) % n_az)
                im = np.uint64((i - kst[f]) % n_az)
            else:
                ip = np.uint64(min(i + kst[f], n_az - 1))
                im = np.uint64(max(i - kst[f], 0))
            dc = Df[f]
            lim = jump_h + jump_f * dc
            e0 = ip * nel + j
            e1 = im * nel + j
            e2 = base + np.uint64(jp_tab[jj])
            e3 = base + np.uint64(jm_tab[jj])
            d0 = Df[e0]
            d1 = Df[e1]
            # the end-point tests without short-circuits (no branches; a NaN fails them all,
            # as in the twin)
            t0 = np.float64(abs(Z[e0] - zc)) <= lim
            t1 = np.float64(abs(Z[e1] - zc)) <= lim
            if use_ratio:
                m0 = d0 if d0 < dc else dc
                m1 = d1 if d1 < dc else dc
                t0 = t0 & (abs(d0 - dc) <= ratio * m0)
                t1 = t1 & (abs(d1 - dc) <= ratio * m1)
            t2 = np.float64(abs(Z[e2] - zc)) <= lim
            t3 = np.float64(abs(Z[e3] - zc)) <= lim
            e0 = e0 if t0 else f
            e1 = e1 if t1 else f
            e2 = e2 if t2 else f
            e3 = e3 if t3 else f
            tb[0, j] = X[e0] - X[e1]
            tb[1, j] = Y[e0] - Y[e1]
            tb[2, j] = Z[e0] - Z[e1]
            tb[3, j] = X[e2] - X[e3]
            tb[4, j] = Y[e2] - Y[e3]
            tb[5, j] = Z[e2] - Z[e3]
        # the row's normals from the buffered tangents, in a loop that vectorises: the square
        # root and the division off the gathers' dependency chain (one long chain per vertex
        # left the out-of-order core idle on a Zen 3 core)
        ox = nvx[base : base + nel]
        oy = nvy[base : base + nel]
        oz = nvz[base : base + nel]
        tax_, tay_, taz_, tex_, tey_, tez_ = tb[0], tb[1], tb[2], tb[3], tb[4], tb[5]
        for jj in range(n_el):
            tax = tax_[jj]
            tay = tay_[jj]
            taz = taz_[jj]
            tex = tex_[jj]
            tey = tey_[jj]
            tez = tez_[jj]
            nx = tay * tez - taz * tey
            ny = taz * tex - tax * tez
            nz = tax * tey - tay * tex
            sgn = np.float32(-1.0) if nz < 0 else np.float32(1.0)
            inv = sgn / np.float32(math.sqrt(nx * nx + ny * ny + nz * nz))
            cx = nx * inv
            cy = ny * inv
            cz = nz * inv
            ox[jj] = cx if math.isfinite(cx) else np.float32(0.0)
            oy[jj] = cy if math.isfinite(cy) else np.float32(0.0)
            oz[jj] = cz if math.isfinite(cz) else np.float32(0.0)


@njit(cache=True, error_model="numpy")
def _robust_cell_z(nvx, nvy, nvz, M, n_el, out):  # type: ignore[no-untyped-def]
    """Vertical component of the robust cell normals (the normalised sum of the four corners'),
    per cell of the padded layout, into ``out (M,)``."""
    ax, ax1, ax2, ax3 = nvx, nvx[1:], nvx[n_el:], nvx[n_el + 1 :]
    ay, ay1, ay2, ay3 = nvy, nvy[1:], nvy[n_el:], nvy[n_el + 1 :]
    az, az1, az2, az3 = nvz, nvz[1:], nvz[n_el:], nvz[n_el + 1 :]
    for f in range(M):
        sx = ax[f] + ax1[f] + ax2[f] + ax3[f]
        sy = ay[f] + ay1[f] + ay2[f] + ay3[f]
        sz = az[f] + az1[f] + az2[f] + az3[f]
        nc = np.float32(math.sqrt(sx * sx + sy * sy + sz * sz))
        nc = nc if nc != 0 else _NAN32
        out[f] = sz / nc
    return out


@njit(cache=True, error_model="numpy")
def _normal_pass(X, Y, Z, V, M, n_el, nx_o, ny_o, nz_o, ok_o):  # type: ignore[no-untyped-def]
    """Pass 3a: unit normals (sign: z up, NaN where unreliable) and C_d of both triangles of
    every cell, written at ``2 f`` and ``2 f + 1`` (``f`` the cell's first vertex)."""
    one = np.float32(1.0)
    X1, X2, X3 = X[1:], X[n_el:], X[n_el + 1 :]
    Y1, Y2, Y3 = Y[1:], Y[n_el:], Y[n_el + 1 :]
    Z1, Z2, Z3 = Z[1:], Z[n_el:], Z[n_el + 1 :]
    V1, V2, V3 = V[1:], V[n_el:], V[n_el + 1 :]
    for f in range(M):
        x00, x01, x10, x11 = X[f], X1[f], X2[f], X3[f]
        y00, y01, y10, y11 = Y[f], Y1[f], Y2[f], Y3[f]
        z00, z01, z10, z11 = Z[f], Z1[f], Z2[f], Z3[f]
        v01 = V1[f] & V2[f]
        ex, ey, ez = x01 - x10, y01 - y10, z01 - z10
        ax, ay, az = x00 - x10, y00 - y10, z00 - z10
        bx, by, bz = x11 - x10, y11 - y10, z11 - z10
        # T_k = (00, 01, 10)
        nx = ay * ez - az * ey
        ny = az * ex - ax * ez
        nz = ax * ey - ay * ex
        nrm = np.float32(math.sqrt(nx * nx + ny * ny + nz * nz))
        good = v01 & V[f] & (nrm > 0)
        s = one / nrm
        s = -s if nz < 0 else s
        s = s if good else _NAN32
        nx_o[2 * f] = nx * s
        ny_o[2 * f] = ny * s
        nz_o[2 * f] = nz * s
        ok_o[2 * f] = good
        # T_{k+1} = (10, 01, 11)
        nx = ey * bz - ez * by
        ny = ez * bx - ex * bz
        nz = ex * by - ey * bx
        nrm = np.float32(math.sqrt(nx * nx + ny * ny + nz * nz))
        good = v01 & V3[f] & (nrm > 0)
        s = one / nrm
        s = -s if nz < 0 else s
        s = s if good else _NAN32
        nx_o[2 * f + 1] = nx * s
        ny_o[2 * f + 1] = ny * s
        nz_o[2 * f + 1] = nz * s
        ok_o[2 * f + 1] = good


@njit(cache=True, error_model="numpy")
def _extent_pass(Z, D, M, n_el, lo_o, hi_o, rg_o):  # type: ignore[no-untyped-def]
    """Pass 3b: z extrema (NaN wins, as ``np.minimum``) and mean range of both triangles."""
    third = np.float32(1.0 / 3.0)
    Z1, Z2, Z3 = Z[1:], Z[n_el:], Z[n_el + 1 :]
    D1, D2, D3 = D[1:], D[n_el:], D[n_el + 1 :]
    for f in range(M):
        z00, z01, z10, z11 = Z[f], Z1[f], Z2[f], Z3[f]
        dsh = D1[f] + D2[f]
        zmn = z01 if (z01 <= z10 or z01 != z01) else z10
        zmx = z01 if (z01 >= z10 or z01 != z01) else z10
        lo_o[2 * f] = zmn if (zmn <= z00 or zmn != zmn) else z00
        hi_o[2 * f] = zmx if (zmx >= z00 or zmx != zmx) else z00
        rg_o[2 * f] = (dsh + D[f]) * third
        lo_o[2 * f + 1] = zmn if (zmn <= z11 or zmn != zmn) else z11
        hi_o[2 * f + 1] = zmx if (zmx >= z11 or zmx != zmx) else z11
        rg_o[2 * f + 1] = (dsh + D3[f]) * third


@njit(cache=True, error_model="numpy")
def _jump_pass(  # type: ignore[no-untyped-def]
    D,
    M,
    n_el,
    lo,
    hi,
    rg,
    nz,
    ok,
    jump_h,
    jump_f,
    ratio,
    use_ratio,
    steep_cos,
    use_steep,
    jp_o,
    code,
):
    """Pass 3c: the height-jump code of H_s (:func:`mesh_kernel`'s tests) of both triangles.

    With ``use_ratio`` in two loops that vectorise: per cell, the range-ratio tests of its
    edges into the work array ``code (2 M,) int8`` (bit 0: the triangle's azimuth edge, bit 1:
    its elevation edge; T_{k+1}'s two edges are the same pair of vertices), then per triangle
    the height test and the steep-edge test. One loop over the cells with both triangles' tests
    stayed scalar on AVX2 (interleaved loads and stores of both triangles)."""
    if not use_ratio:
        for k in range(2 * M):
            jp_o[k] = (hi[k] - lo[k] > jump_h + jump_f * rg[k]) & ok[k]
        return
    D1, D2, D3 = D[1:], D[n_el:], D[n_el + 1 :]
    one = np.int8(1)
    for f in range(M):
        d00, d01, d10, d11 = D[f], D1[f], D2[f], D3[f]
        # (a NaN range fails every test, whatever the minimum is)
        m0 = d00 if d00 < d10 else d10
        m1 = d01 if d01 < d11 else d11
        me = d00 if d00 < d01 else d01
        a0 = abs(d00 - d10) > ratio * m0  # T_k's azimuth edge (00, 10)
        e0 = abs(d00 - d01) > ratio * me  # T_k's elevation edge (00, 01)
        a1 = abs(d01 - d11) > ratio * m1  # T_{k+1}'s edges: both (01, 11)
        code[2 * f] = np.int8(a0) | (np.int8(e0) << one)
        code[2 * f + 1] = np.int8(a1) * np.int8(3)
    for k in range(2 * M):
        lo_k = lo[k]
        c = code[k]
        jp = (hi[k] - lo_k > jump_h + jump_f * rg[k]) | ((c & one) != 0)
        if use_steep:
            e = (c & np.int8(2)) != 0
            jp = jp | (e & ((abs(nz[k]) < steep_cos) | (lo_k > jump_h)))
        jp_o[k] = jp & ok[k]


@njit(cache=True, error_model="numpy")
def _class_pass(  # type: ignore[no-untyped-def]
    X, Y, D, origin, M, n_el, nx, ny, nz, ok, jump, rzc, use_robust, c2, cos_c1, lab_o
):
    """Pass 3d: rules P1-P4 and the class without P5 (-1 unreliable, -4 shadow behind, -3 side
    shadow, -2 P1, 0) of both triangles (:func:`classify_kernel`'s tests)."""
    o0 = np.float32(origin[0])
    o1 = np.float32(origin[1])
    tiny = np.float32(1e-9)
    X2, Y2, D2 = X[n_el:], Y[n_el:], D[n_el:]
    for f in range(M):
        rz = rzc[f] if use_robust else np.float32(0.0)
        for t in range(2):
            k = 2 * f + t
            if t == 0:  # the first vertex's line of sight
                qx, qy, qd = X[f] - o0, Y[f] - o1, D[f]
            else:
                qx, qy, qd = X2[f] - o0, Y2[f] - o1, D2[f]
            q0 = qx / qd
            q1 = qy / qd
            n0 = nx[k]
            n1 = ny[k]
            nzz = nz[k]
            good = ok[k]
            jp = jump[k]
            num = n0 * q0 + n1 * q1
            den = np.float32(math.sqrt(n0 * n0 + n1 * n1)) * np.float32(
                math.sqrt(q0 * q0 + q1 * q1)
            )
            cosz = np.float64(num / den) if den > tiny else 0.0
            p2 = jp & (cosz > c2)
            p3 = jp & (cosz < -c2)
            behind = good & p2
            side = jp and not p2 and not p3
            nzr = nzz
            if use_robust:
                nzr = rz if (not jp and math.isfinite(rz)) else nzz
            p1 = good and not behind and not side and nzr < cos_c1
            lab = np.int8(0)
            lab = np.int8(-2) if p1 else lab
            lab = np.int8(-3) if side else lab
            lab = np.int8(-4) if behind else lab
            lab = np.int8(-1) if not good else lab
            lab_o[k] = lab


@njit(cache=True, error_model="numpy")
def _rules_pass(X, Y, D, origin, M, n_el, nx, ny, ok, jump, lab, c2, p1_o, p2_o, p3_o, p4_o):  # type: ignore[no-untyped-def]
    """The rules P1-P4 for inspection (``want_rules``): the zone tests again, P1 from the class."""
    o0 = np.float32(origin[0])
    o1 = np.float32(origin[1])
    tiny = np.float32(1e-9)
    X2, Y2, D2 = X[n_el:], Y[n_el:], D[n_el:]
    for f in range(M):
        for t in range(2):
            k = 2 * f + t
            if t == 0:
                qx, qy, qd = X[f] - o0, Y[f] - o1, D[f]
            else:
                qx, qy, qd = X2[f] - o0, Y2[f] - o1, D2[f]
            q0 = qx / qd
            q1 = qy / qd
            n0 = nx[k]
            n1 = ny[k]
            num = n0 * q0 + n1 * q1
            den = np.float32(math.sqrt(n0 * n0 + n1 * n1)) * np.float32(
                math.sqrt(q0 * q0 + q1 * q1)
            )
            cosz = np.float64(num / den) if den > tiny else 0.0
            jp = jump[k]
            p1_o[k] = lab[k] == -2
            p2_o[k] = jp & (cosz > c2)
            p3_o[k] = jp & (cosz < -c2)
            p4_o[k] = ok[k] and not jp


@njit(cache=True, error_model="numpy")
def _chain_pass(lab, lo, R, n_el, C2, chain_min, p5_o, want_rules):  # type: ignore[no-untyped-def]
    """Pass 4, P5 along each row of the padded layout: an earlier P1 triangle in the same run
    of non-shadow reliable triangles, with the twin's segmented running minimum (its ``(min -
    s 1e7) + s 1e7`` rounding included)."""
    huge = 1.0e6
    seg_w = 1.0e7
    for r in range(R):
        b0 = 2 * r * n_el
        first = -1
        for k in range(b0, b0 + C2):
            if lab[k] == -2:
                first = k
                break
        if first < 0:
            continue  # no P1 triangle in the row: no P5
        seg = 0
        for k in range(b0, first):
            lk = lab[k]
            seg += 1 if (lk == -1 or lk <= -3) else 0
        run_min = huge
        for k in range(first, b0 + C2):
            lk = lab[k]
            if lk == -1 or lk <= -3:  # a breaker: unreliable or a shadow
                seg += 1
                run_min = huge
                continue
            v = np.float64(lo[k])
            if lk == -2:
                if v < run_min:
                    run_min = v
                if not want_rules:
                    continue
            if run_min < huge:
                sw = seg * seg_w
                b = (run_min - sw) + sw
                if b < huge / 2 and v - b >= chain_min:
                    lab[k] = -2
                    if want_rules:
                        p5_o[k] = True


@njit(cache=True)
def _compact(src, R, n_el, C2, dst):  # type: ignore[no-untyped-def]
    """Rows of the padded layout (``2 n_el`` per row) into ``dst (R * C2,)`` (drop the padding).

    Unsigned indices: with signed ones Numba's negative-index fix-up keeps the copy scalar
    (4-10x slower on a KITTI grid's arrays)."""
    nel2 = np.uint64(2 * n_el)
    c2 = np.uint64(C2)
    for r in range(R):
        a = np.uint64(r) * nel2
        b = np.uint64(r) * c2
        for kk in range(C2):
            q = np.uint64(kk)
            dst[b + q] = src[a + q]


@njit(cache=True)
def _compact_normals(nx, ny, nz, R, n_el, C2, dst):  # type: ignore[no-untyped-def]
    """The three padded components into ``dst (R * C2 * 3,)`` (the ``(R, 2C, 3)`` layout;
    unsigned indices as :func:`_compact`)."""
    nel2 = np.uint64(2 * n_el)
    c6 = np.uint64(3 * C2)
    one = np.uint64(1)
    two = np.uint64(2)
    three = np.uint64(3)
    for r in range(R):
        a = np.uint64(r) * nel2
        b = np.uint64(r) * c6
        for kk in range(C2):
            q = np.uint64(kk)
            o = b + three * q
            dst[o] = nx[a + q]
            dst[o + one] = ny[a + q]
            dst[o + two] = nz[a + q]


@njit(cache=True, error_model="numpy")
def stages_2_5_kernel(  # type: ignore[no-untyped-def]
    points,
    valid,
    origin,
    wrap,
    jump_h32,
    jump_f32,
    ratio32,
    use_ratio,
    steep_cos,
    use_steep,
    use_robust,
    k_scale,
    m_col,
    max_stride,
    jump_h,
    jump_f,
    ratio,
    c2,
    cos_c1,
    chain_min,
    want_rules,
    want_mesh,
    F,
    B,
    lab,
    PR,
    Df,
    kst,
    ok,
    normal,
    vray,
    rng,
    zmin,
    zmax,
    jump,
    labels,
    rules,
):
    """Stages 2-5 over the grid in short passes that the compiler vectorises: the results of
    :func:`mesh_kernel`, :func:`robust_normals_kernel` (with ``use_robust``; only the vertical
    component of the cell normals is used) and :func:`classify_kernel`, bit for bit.

    1. per vertex: float32 coordinates, validity, range, line of sight, in flat arrays with one
       extra row (row 0 again, for the seam);
    2. with ``use_robust``: per vertex the float64 range and the azimuth stride;
    then, block by block of rows (about 4096 cells, so that the per-cell work arrays stay in
    the cache):
    3. with ``use_robust``: the robust vertex normals of the rows the block needs (each row
       once), then the cells' vertical components;
    4. per cell, branch-free, both triangles written at ``2 f, 2 f + 1`` of a padded layout
       (each row has ``n_el`` cells, the last one padding): normals and C_d; z extrema and mean
       range; jumps; zone cosines, rules P1-P4 and the class without P5 - each pass writes at
       most four arrays (more defeat the compiler's vectoriser);
    5. per row, in order along the rising ray: P5's running minimum (rows without a P1
       triangle skipped);
    6. the padded rows copied into the outputs.

    Mesh arguments as :func:`mesh_kernel` (``jump_h32, jump_f32, ratio32, steep_cos`` float32),
    robust ones as :func:`robust_normals_kernel` (``k_scale`` float32, ``jump_h, jump_f, ratio``
    float64), rule ones as :func:`classify_kernel`. Work arrays (any content; ``ne = n_az n_el +
    n_el + 1``, ``M = R n_el``, ``L >= max(ne, 2 M)``): ``F (14, L) float32``, ``B (3, L)
    bool``, ``lab (2 M,) int8``, ``PR (5, 2 M or 0) bool``, ``Df, kst (n_az n_el,)`` float64
    and int64. Outputs, filled: ``ok, normal, vray, rng, zmin, zmax, jump`` as
    :func:`mesh_kernel` returns them, ``labels (R, 2C) int8`` and ``rules (5, R, 2C) bool``
    (P1-P5; ``(5, 0, 0)`` unless ``want_rules``). Without ``want_mesh`` ``ok``, ``vray`` and
    ``rng`` are not written (any shape, e.g. empty): stages 6-8 do not read them.
    """
    n_az, n_el = valid.shape
    R = n_az if wrap else n_az - 1
    C2 = 2 * (n_el - 1)
    nv = n_az * n_el
    X, Y, Z, D = F[0], F[1], F[2], F[3]
    V = B[0]
    _vertex_pass(
        points.reshape(nv, 3),
        valid.reshape(nv),
        origin,
        nv,
        n_el,
        X,
        Y,
        Z,
        V,
        D,
        vray.reshape(-1),
        want_mesh,
    )
    nvx, nvy, nvz = F[4], F[5], F[6]
    jp_tab = np.empty(n_el, np.int64)
    jm_tab = np.empty(n_el, np.int64)
    if use_robust:
        _robust_prep(X, Y, Z, origin, nv, k_scale, max_stride, Df, kst)
        for j in range(n_el):
            jp_tab[j] = min(j + m_col[j], n_el - 1)
            jm_tab[j] = max(j - m_col[j], 0)
    # per-cell work arrays of one block of rows (they stay in the cache)
    rzc, nx, ny, nz, lo, hi, rg = F[7], F[8], F[9], F[10], F[11], F[12], F[13]
    okp, jp = B[1], B[2]
    rows_b = max(1, 4096 // n_el)
    done = 0  # vertex rows with robust normals
    normal_f = normal.reshape(-1)
    outs_f = (zmin.reshape(-1), zmax.reshape(-1), rng.reshape(-1))
    ok_f, jump_f_out, labels_f = ok.reshape(-1), jump.reshape(-1), labels.reshape(-1)
    for r0 in range(0, R, rows_b):
        r1 = min(r0 + rows_b, R)
        nb = r1 - r0
        Mb = nb * n_el
        f0 = r0 * n_el
        if use_robust:
            need = min(r1 + 1, n_az)  # vertex rows r0 .. r1 (the cells' upper corners)
            if need > done:
                _robust_rows(
                    done,
                    need,
                    X,
                    Y,
                    Z,
                    Df,
                    kst,
                    n_az,
                    n_el,
                    jp_tab,
                    jm_tab,
                    wrap,
                    max_stride,
                    jump_h,
                    jump_f,
                    ratio,
                    use_ratio,
                    nvx,
                    nvy,
                    nvz,
                )
                done = need
            if r1 == n_az:  # the seam: row 0 again as the extra row
                for f in range(n_el + 1):
                    nvx[nv + f] = nvx[f]
                    nvy[nv + f] = nvy[f]
                    nvz[nv + f] = nvz[f]
            _robust_cell_z(nvx[f0:], nvy[f0:], nvz[f0:], Mb, n_el, rzc)
        Xb, Yb, Zb, Db, Vb = X[f0:], Y[f0:], Z[f0:], D[f0:], V[f0:]
        _normal_pass(Xb, Yb, Zb, Vb, Mb, n_el, nx, ny, nz, okp)
        _extent_pass(Zb, Db, Mb, n_el, lo, hi, rg)
        _jump_pass(
            Db,
            Mb,
            n_el,
            lo,
            hi,
            rg,
            nz,
            okp,
            jump_h32,
            jump_f32,
            ratio32,
            use_ratio,
            steep_cos,
            use_steep,
            jp,
            lab,
        )
        _class_pass(
            Xb, Yb, Db, origin, Mb, n_el, nx, ny, nz, okp, jp, rzc, use_robust, c2, cos_c1, lab
        )
        if want_rules:
            PR[4, : 2 * Mb] = False
            _rules_pass(
                Xb, Yb, Db, origin, Mb, n_el, nx, ny, okp, jp, lab, c2, PR[0], PR[1], PR[2], PR[3]
            )
        _chain_pass(lab, lo, nb, n_el, C2, chain_min, PR[4], want_rules)
        o = r0 * C2
        _compact_normals(nx, ny, nz, nb, n_el, C2, normal_f[3 * o :])
        _compact(lo, nb, n_el, C2, outs_f[0][o:])
        _compact(hi, nb, n_el, C2, outs_f[1][o:])
        if want_mesh:
            _compact(rg, nb, n_el, C2, outs_f[2][o:])
            _compact(okp, nb, n_el, C2, ok_f[o:])
        _compact(jp, nb, n_el, C2, jump_f_out[o:])
        _compact(lab, nb, n_el, C2, labels_f[o:])
        if want_rules:
            for q in range(5):
                _compact(PR[q], nb, n_el, C2, rules[q].reshape(-1)[o:])
