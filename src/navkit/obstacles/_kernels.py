"""Compiled (Numba) kernels of paper 1's stages 1-7: one pass over the grid per stage.

Each kernel computes exactly what its NumPy twin computes (the functions in
:mod:`navkit.obstacles.mesh`, :mod:`~navkit.obstacles.rules`, :mod:`~navkit.obstacles.segment`,
:mod:`~navkit.obstacles.ground`, :mod:`~navkit.obstacles.grids`), in the same floating-point
types and the same order of operations, so that classes, ids and masks are identical and floats
agree to the last bit (tested in ``tests/obstacles/test_kernels.py``). Rules kept for that:

- float32 arithmetic stays float32: constants that NumPy 2 treats as *weak* Python scalars
  (``jump_height_m`` in ``z_max - z_min > jump_height_m + ...`` on float32 arrays) are passed in
  as ``np.float32``; square roots of float32 values are rounded back to float32;
- NaN propagates through minima and maxima as in ``np.minimum`` / ``np.maximum``;
- transcendental functions (``arctan2``, ``cos``) stay in NumPy (its SIMD ``arctan2`` differs
  from libm's by an ulp on ~7 % of inputs), the kernels take their results - except the scan
  grid's per-point azimuth, which both paths compute with one fixed arithmetic
  (:func:`navkit.geometry.angles.atan2` and its kernel ``atan2_kernel``, the same bits).

The kernels run on one thread: the targets are CPU time per frame (``parallel=True`` would add
threads, not remove work) and the machine is shared. ``cache=True`` keeps the compiled code on
disk (``NUMBA_CACHE_DIR`` or ``__pycache__``); see ``docs/kernels.md``.

Selecting the backend: the detector's ``ObstacleSettings.backend`` (``"compiled"``, ``"numpy"``
for the reference implementation, ``"auto"`` by default: :mod:`navkit.jit`) and the ``backend``
keyword of :func:`navkit.obstacles.cloud_to_grid`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from navkit._intrinsics import prefetch

__all__ = [
    "boundary_kernel",
    "classify_kernel",
    "cloud_prep_kernel",
    "cloud_valid_kernel",
    "grid_cells_kernel",
    "grid_fill_kernel",
    "grid_order_fill_kernel",
    "mesh_kernel",
    "phase_fractions_kernel",
    "phase_sin_cos_kernel",
    "points_kernel",
    "refine_kernel",
    "rings_by_order_kernel",
    "rings_order_kernel",
    "robust_normals_kernel",
    "robust_strides_kernel",
    "stages_2_5_kernel",
]

_NAN32 = np.float32(np.nan)


@njit(cache=True, error_model="numpy", inline="always")
def _min_nan(a, b):  # type: ignore[no-untyped-def]
    """``np.minimum``: NaN if either is NaN."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a <= b else b


@njit(cache=True, error_model="numpy", inline="always")
def _max_nan(a, b):  # type: ignore[no-untyped-def]
    """``np.maximum``: NaN if either is NaN."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a >= b else b


# ------------------------------------------------------------------------------------------
# stages 2-4: mesh, normals, H_s (twin: mesh.build_mesh)


@njit(cache=True, error_model="numpy")
def mesh_kernel(  # type: ignore[no-untyped-def]
    points,
    valid,
    origin32,
    wrap,
    jump_h,
    jump_f,
    ratio,
    use_ratio,
    steep_cos,
    use_steep,
):
    """One pass over the cells: normals, validity, mean range, z extrema, jump (float32).

    ``points (n_az, n_el, 3) float64``, ``valid (n_az, n_el) bool``, ``origin32 (3,) float32``;
    ``jump_h, jump_f, ratio, steep_cos`` float32. Returns ``ok, normal, vray, rng, z_min, z_max,
    jump`` as :class:`~navkit.obstacles.mesh.MeshCharacteristics` holds them.
    """
    n_az, n_el = valid.shape
    R = n_az if wrap else n_az - 1
    C = n_el - 1
    X = np.empty((n_az, n_el), np.float32)
    Y = np.empty((n_az, n_el), np.float32)
    Z = np.empty((n_az, n_el), np.float32)
    D = np.empty((n_az, n_el), np.float32)
    vray = np.empty((n_az, n_el, 3), np.float32)
    for i in range(n_az):
        for j in range(n_el):
            x = np.float32(points[i, j, 0])
            y = np.float32(points[i, j, 1])
            z = np.float32(points[i, j, 2])
            X[i, j] = x
            Y[i, j] = y
            Z[i, j] = z
            rx = x - origin32[0]
            ry = y - origin32[1]
            rz = z - origin32[2]
            d = np.float32(math.sqrt(rx * rx + ry * ry + rz * rz))
            D[i, j] = d
            vray[i, j, 0] = rx / d
            vray[i, j, 1] = ry / d
            vray[i, j, 2] = rz / d
    ok = np.zeros((R, 2 * C), np.bool_)
    normal = np.empty((R, 2 * C, 3), np.float32)
    rng = np.empty((R, 2 * C), np.float32)
    zmin = np.empty((R, 2 * C), np.float32)
    zmax = np.empty((R, 2 * C), np.float32)
    jump = np.zeros((R, 2 * C), np.bool_)
    third = np.float32(1.0 / 3.0)
    one = np.float32(1.0)
    for r in range(R):
        r1 = r + 1
        if r1 == n_az:
            r1 = 0
        for c in range(C):
            x00, x01, x10, x11 = X[r, c], X[r, c + 1], X[r1, c], X[r1, c + 1]
            y00, y01, y10, y11 = Y[r, c], Y[r, c + 1], Y[r1, c], Y[r1, c + 1]
            z00, z01, z10, z11 = Z[r, c], Z[r, c + 1], Z[r1, c], Z[r1, c + 1]
            d00, d01, d10, d11 = D[r, c], D[r, c + 1], D[r1, c], D[r1, c + 1]
            v00, v01, v10, v11 = valid[r, c], valid[r, c + 1], valid[r1, c], valid[r1, c + 1]
            ex, ey, ez = x01 - x10, y01 - y10, z01 - z10
            ax, ay, az = x00 - x10, y00 - y10, z00 - z10
            bx, by, bz = x11 - x10, y11 - y10, z11 - z10
            dsh = d01 + d10
            zmn = _min_nan(z01, z10)
            zmx = _max_nan(z01, z10)
            for t in range(2):
                k = 2 * c + t
                if t == 0:
                    nx = ay * ez - az * ey
                    ny = az * ex - ax * ez
                    nz = ax * ey - ay * ex
                    vt = v00 and v01 and v10
                    rg = (dsh + d00) * third
                    lo = _min_nan(zmn, z00)
                    hi = _max_nan(zmx, z00)
                else:
                    nx = ey * bz - ez * by
                    ny = ez * bx - ex * bz
                    nz = ex * by - ey * bx
                    vt = v10 and v01 and v11
                    rg = (dsh + d11) * third
                    lo = _min_nan(zmn, z11)
                    hi = _max_nan(zmx, z11)
                nrm = np.float32(math.sqrt(nx * nx + ny * ny + nz * nz))
                good = vt and nrm > 0
                if good:
                    s = one / nrm
                    if nz < 0:
                        s = -s
                else:
                    s = _NAN32
                nzz = nz * s
                normal[r, k, 0] = nx * s
                normal[r, k, 1] = ny * s
                normal[r, k, 2] = nzz
                rng[r, k] = rg
                zmin[r, k] = lo
                zmax[r, k] = hi
                ok[r, k] = good
                if not good:
                    continue
                jp = hi - lo > jump_h + jump_f * rg
                if use_ratio:
                    if t == 0:
                        jp = jp or abs(d00 - d10) > ratio * min(d00, d10)
                    else:
                        jp = jp or abs(d01 - d11) > ratio * min(d01, d11)
                    if use_steep and not jp:
                        if t == 0:
                            e = abs(d00 - d01) > ratio * min(d00, d01)
                        else:
                            e = abs(d01 - d11) > ratio * min(d01, d11)
                        jp = e and (abs(nzz) < steep_cos or lo > jump_h)
                jump[r, k] = jp
    return ok, normal, vray, rng, zmin, zmax, jump


# ------------------------------------------------------------------------------------------
# stage 5 input: robust normals (twin: mesh.robust_cell_normals)


@njit(cache=True, error_model="numpy")
def robust_normals_kernel(  # type: ignore[no-untyped-def]
    points,
    origin,
    k_scale,
    m_col,
    wrap,
    max_stride,
    jump_h,
    jump_f,
    ratio,
    use_ratio,
):
    """Per-vertex tangents by strided central differences, then per-cell normals ``(R, C, 3)``.

    ``k_scale`` float32: ``support_m / (2 dalpha)`` (the azimuth stride is
    ``rint(k_scale / r_h)`` with ``r_h`` the horizontal range, clipped to ``[1, max_stride]``);
    ``m_col (n_el,) intp`` the elevation strides; ``origin (3,) float64``; ``jump_h, jump_f,
    ratio`` float64 (the end-point tests run in float64 like the twin's).
    """
    n_az, n_el = points.shape[0], points.shape[1]
    ox32 = np.float32(origin[0])
    oy32 = np.float32(origin[1])
    X = np.empty(n_az * n_el, np.float32)
    Y = np.empty(n_az * n_el, np.float32)
    Z = np.empty(n_az * n_el, np.float32)
    Df = np.empty(n_az * n_el, np.float64)
    for i in range(n_az):
        for j in range(n_el):
            f = i * n_el + j
            x = np.float32(points[i, j, 0])
            y = np.float32(points[i, j, 1])
            z = np.float32(points[i, j, 2])
            X[f] = x
            Y[f] = y
            Z[f] = z
            dx = np.float64(x) - origin[0]
            dy = np.float64(y) - origin[1]
            dz = np.float64(z) - origin[2]
            Df[f] = math.sqrt(dx * dx + dy * dy + dz * dz)
    vn = np.empty((n_az, n_el, 3), np.float32)
    for i in range(n_az):
        for j in range(n_el):
            f = i * n_el + j
            # float32 hypot as glibc's hypotf computes it: in double, rounded once
            hx = np.float64(X[f] - ox32)
            hy = np.float64(Y[f] - oy32)
            rh = np.float32(math.sqrt(hx * hx + hy * hy))
            kf = np.rint(k_scale / rh)
            if kf != kf:
                k = 1
            elif kf > max_stride:
                k = max_stride
            elif kf < 1:
                k = 1
            else:
                k = int(kf)
            if wrap:
                ip = (i + k) % n_az
                im = (i - k) % n_az
            else:
                ip = min(i + k, n_az - 1)
                im = max(i - k, 0)
            m = m_col[j]
            jp = min(j + m, n_el - 1)
            jm = max(j - m, 0)
            zc = Z[f]
            dc = Df[f]
            lim = jump_h + jump_f * dc
            # an end point across a discontinuity is replaced by the centre (a NaN anywhere
            # fails the tests, as in the twin); written out: ~1.5x faster than a helper
            e0 = ip * n_el + j
            d0 = Df[e0]
            if not (
                np.float64(abs(Z[e0] - zc)) <= lim
                and (not use_ratio or abs(d0 - dc) <= ratio * min(d0, dc))
            ):
                e0 = f
            e1 = im * n_el + j
            d1 = Df[e1]
            if not (
                np.float64(abs(Z[e1] - zc)) <= lim
                and (not use_ratio or abs(d1 - dc) <= ratio * min(d1, dc))
            ):
                e1 = f
            e2 = i * n_el + jp
            if not np.float64(abs(Z[e2] - zc)) <= lim:
                e2 = f
            e3 = i * n_el + jm
            if not np.float64(abs(Z[e3] - zc)) <= lim:
                e3 = f
            tax = X[e0] - X[e1]
            tay = Y[e0] - Y[e1]
            taz = Z[e0] - Z[e1]
            tex = X[e2] - X[e3]
            tey = Y[e2] - Y[e3]
            tez = Z[e2] - Z[e3]
            nx = tay * tez - taz * tey
            ny = taz * tex - tax * tez
            nz = tax * tey - tay * tex
            sgn = np.float32(-1.0) if nz < 0 else np.float32(1.0)
            inv = sgn / np.float32(math.sqrt(nx * nx + ny * ny + nz * nz))
            cx, cy, cz = nx * inv, ny * inv, nz * inv
            vn[i, j, 0] = cx if math.isfinite(cx) else np.float32(0.0)
            vn[i, j, 1] = cy if math.isfinite(cy) else np.float32(0.0)
            vn[i, j, 2] = cz if math.isfinite(cz) else np.float32(0.0)
    R = n_az if wrap else n_az - 1
    C = n_el - 1
    out = np.empty((R, C, 3), np.float32)
    for r in range(R):
        r1 = r + 1
        if r1 == n_az:
            r1 = 0
        for c in range(C):
            sx = vn[r, c, 0] + vn[r, c + 1, 0] + vn[r1, c, 0] + vn[r1, c + 1, 0]
            sy = vn[r, c, 1] + vn[r, c + 1, 1] + vn[r1, c, 1] + vn[r1, c + 1, 1]
            sz = vn[r, c, 2] + vn[r, c + 1, 2] + vn[r1, c, 2] + vn[r1, c + 1, 2]
            nrm = np.float32(math.sqrt(sx * sx + sy * sy + sz * sz))
            if nrm == 0:
                nrm = _NAN32
            out[r, c, 0] = sx / nrm
            out[r, c, 1] = sy / nrm
            out[r, c, 2] = sz / nrm
    return out


# ------------------------------------------------------------------------------------------
# stage 5: rules P1-P5 (twin: rules.classify with normal_support = 0)


@njit(cache=True, error_model="numpy")
def classify_kernel(  # type: ignore[no-untyped-def]
    ok,
    jump,
    normal,
    vray,
    zmin,
    robust_z,
    use_robust,
    n_az,
    c2,
    cos_c1,
    chain_min,
):
    """Labels and rules P1-P5 in one pass along each row (the rising rays).

    ``robust_z (R, C) float32`` is the vertical component of the robust cell normals (ignored
    unless ``use_robust``); ``cos_c1`` float32, ``c2`` and ``chain_min`` float64.
    """
    R, C2 = ok.shape
    labels = np.empty((R, C2), np.int8)
    p1a = np.zeros((R, C2), np.bool_)
    p2a = np.zeros((R, C2), np.bool_)
    p3a = np.zeros((R, C2), np.bool_)
    p4a = np.zeros((R, C2), np.bool_)
    p5a = np.zeros((R, C2), np.bool_)
    huge = 1.0e6
    seg_w = 1.0e7
    tiny = np.float32(1e-9)
    for r in range(R):
        seg = 0
        run_min = huge
        for k in range(C2):
            good = ok[r, k]
            jp = jump[r, k]
            p2 = False
            p3 = False
            if jp:
                # zone cosine (twin: rules.zone_cosine) with the first vertex's line of sight
                c = k // 2
                if k % 2 == 0:
                    vi, vj = r, c
                else:
                    vi = r + 1
                    if vi == n_az:
                        vi = 0
                    vj = c
                n0, n1 = normal[r, k, 0], normal[r, k, 1]
                q0, q1 = vray[vi, vj, 0], vray[vi, vj, 1]
                num = n0 * q0 + n1 * q1
                den = np.float32(math.sqrt(n0 * n0 + n1 * n1)) * np.float32(
                    math.sqrt(q0 * q0 + q1 * q1)
                )
                if den > tiny:
                    cosz = np.float64(num / den)
                else:
                    cosz = 0.0
                p2 = cosz > c2
                p3 = cosz < -c2
            p4 = good and not jp
            behind = good and p2 and not p4
            side = good and not p2 and not p3 and not p4
            shadow = behind or side
            if jp or not use_robust:
                nz = normal[r, k, 2]
            else:
                nz = robust_z[r, k // 2]
                if not math.isfinite(nz):
                    nz = normal[r, k, 2]
            p1 = good and not shadow and nz < cos_c1
            breaker = (not good) or shadow
            if breaker:  # a new run: the twin's segmented running minimum restarts here
                seg += 1
                run_min = huge
            elif p1:
                v = np.float64(zmin[r, k])  # finite: the triangle is reliable
                if v < run_min:
                    run_min = v
            p5 = False
            if not breaker:
                s = seg * seg_w
                base = (run_min - s) + s
                p5 = base < huge / 2 and np.float64(zmin[r, k]) - base >= chain_min
            obstacle = good and not shadow and (p1 or p5)
            if not good:
                lab = -1
            elif behind:
                lab = -4
            elif side:
                lab = -3
            elif obstacle:
                lab = -2
            else:
                lab = 0
            labels[r, k] = lab
            p1a[r, k] = p1
            p2a[r, k] = p2
            p3a[r, k] = p3
            p4a[r, k] = p4
            p5a[r, k] = p5
    return labels, p1a, p2a, p3a, p4a, p5a


# ------------------------------------------------------------------------------------------
# stages 2-5 fused: mesh, robust normals, H_s, rules, classes in one pass over the grid
# (twins: mesh.build_mesh, mesh.robust_cell_normals, rules.classify with normal_support = 0)


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


@njit(cache=True)
def _kth_banded(values, k, work):  # type: ignore[no-untyped-def]
    """The k-th smallest of ``values`` (0-based; no NaN), exactly: a strided sample brackets
    the k-th value, one pass counts what lies below the bracket and copies what lies inside it
    into ``work``, and a selection runs on that copy only (the whole array when the bracket
    misses)."""
    n = len(values)
    s = min(n, 2048)
    stride = max(n // s, 1)
    sample = np.empty(s)
    for q in range(s):
        sample[q] = values[q * stride]
    sample.sort()
    pos = int(s * (k / n))
    lo = sample[max(pos - 64, 0)]
    hi = sample[min(pos + 64, s - 1)]
    below = 0
    m = 0
    for q in range(n):  # branch-free: always write, advance when inside the bracket
        v = values[q]
        below += 1 if v < lo else 0
        work[np.uint64(m)] = v  # m >= 0: no negative-index fix-up
        m += 1 if (v >= lo and v <= hi) else 0
    if below <= k < below + m:
        return _kth(work[:m], k - below)
    for q in range(n):
        work[q] = values[q]
    return _kth(work[:n], k)


@njit(cache=True)
def _median_banded(values, work):  # type: ignore[no-untyped-def]
    """``np.median`` of ``values`` (no NaN, at least one), exactly: the middle order statistic,
    or the mean of the two middle ones from **one** bracket pass (:func:`_kth_banded`): after
    the selection of the lower one in the bracket's copy, every later entry of the copy is at
    least as large, so the upper one is their minimum."""
    n = len(values)
    h = n // 2
    if n % 2:
        return _kth_banded(values, h, work)
    k = h - 1
    s = min(n, 2048)
    stride = max(n // s, 1)
    sample = np.empty(s)
    for q in range(s):
        sample[q] = values[q * stride]
    sample.sort()
    pos = int(s * (k / n))
    lo = sample[max(pos - 64, 0)]
    hi = sample[min(pos + 64, s - 1)]
    below = 0
    m = 0
    for q in range(n):  # branch-free: always write, advance when inside the bracket
        v = values[q]
        below += 1 if v < lo else 0
        work[np.uint64(m)] = v
        m += 1 if (v >= lo and v <= hi) else 0
    if below <= k and k + 1 < below + m:
        a = _kth(work[:m], k - below)
        b = work[k - below + 1]
        for q in range(k - below + 2, m):
            b = work[q] if work[q] < b else b
        return (a + b) / 2
    for q in range(n):
        work[q] = values[q]
    a = _kth(work[:n], k)
    b = work[k + 1]
    for q in range(k + 2, n):
        b = work[q] if work[q] < b else b
    return (a + b) / 2


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
# stage 6: components (union-find), filters, merging, shadow owners (twin: detector + segment)


@njit(cache=True, inline="always")
def _find(parent, a):  # type: ignore[no-untyped-def]
    """Root of ``a`` with path halving."""
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@njit(cache=True, inline="always")
def _union(parent, a, b):  # type: ignore[no-untyped-def]
    """Join the sets of ``a`` and ``b``; the smaller root stays the root."""
    ra = _find(parent, a)
    rb = _find(parent, b)
    if ra < rb:
        parent[rb] = ra
    elif rb < ra:
        parent[ra] = rb


_OFF_I = (0, 0, 1, -1)
_OFF_J = (1, -1, -1, 1)


@njit(cache=True)
def _renumber_by_min(parent, n):  # type: ignore[no-untyped-def]
    """``lut (n + 1,)``: labels 1..n to their merged component, numbered by smallest member."""
    lut = np.zeros(n + 1, np.int32)
    m = 0
    for a in range(1, n + 1):
        r = _find(parent, a)
        if r == a:
            m += 1
            lut[a] = m
        else:
            lut[a] = lut[r]
    return lut, m


@njit(cache=True)
def _incident(values, p, q, k, R, C, wrap, fill):  # type: ignore[no-untyped-def]
    """Value of the k-th triangle around vertex ``(p, q)`` (``segment._incident_slices``)."""
    if k == 0:
        r, c, t = p, q, 0
    elif k == 1:
        r, c, t = p, q - 1, 0
    elif k == 2:
        r, c, t = p - 1, q, 0
    elif k == 3:
        r, c, t = p - 1, q, 1
    elif k == 4:
        r, c, t = p, q - 1, 1
    else:
        r, c, t = p - 1, q - 1, 1
    if c < 0 or c >= C or r >= R:
        return fill
    if r < 0:
        if not wrap:
            return fill
        r = R - 1
    return values[r, 2 * c + t]


@njit(cache=True)
def boundary_kernel(obstacle_id, n_az, n_el, wrap):  # type: ignore[no-untyped-def]
    """``segment.boundary_vertices``: obstacle id per vertex (largest incident) and boundary."""
    R = obstacle_id.shape[0]
    C = obstacle_id.shape[1] // 2
    vid = np.zeros((n_az, n_el), np.int32)
    bnd = np.zeros((n_az, n_el), np.bool_)
    for p in range(n_az):
        for q in range(n_el):
            v = _incident(obstacle_id, p, q, 0, R, C, wrap, 0)
            lo = v
            hi = v
            for k in range(1, 6):
                v = _incident(obstacle_id, p, q, k, R, C, wrap, 0)
                if v > hi:
                    hi = v
                if v < lo:
                    lo = v
            vid[p, q] = hi
            bnd[p, q] = hi > 0 and lo != hi
    return vid, bnd


@njit(cache=True)
def _kth(values, k):  # type: ignore[no-untyped-def]
    """The k-th smallest of ``values`` (0-based), by a selection in place (reorders them)."""
    lo, hi = 0, len(values) - 1
    while lo < hi:
        pivot = values[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while values[i] < pivot:
                i += 1
            while values[j] > pivot:
                j -= 1
            if i <= j:
                values[i], values[j] = values[j], values[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            return values[k]
    return values[k]


# ------------------------------------------------------------------------------------------
# stage 7: boundaries, per-vertex classes, main ground, refinement by height above the ground


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


@njit(cache=True)
def _median(values):  # type: ignore[no-untyped-def]
    """``np.median`` of a 1-D array (reorders a copy)."""
    v = values.copy()
    m = len(v)
    h = m // 2
    if m % 2:
        return _kth(v, h)
    a = _kth(v, h - 1)
    b = _kth(v, h)
    return (a + b) / 2


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
# stage 8 input: per-obstacle vertex sets (twin: detector._build_obstacles' groupings)


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
