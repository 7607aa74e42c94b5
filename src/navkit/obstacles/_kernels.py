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
  from libm's by an ulp on ~7 % of inputs), the kernels take their results.

The kernels run on one thread: the targets are CPU time per frame (``parallel=True`` would add
threads, not remove work) and the machine is shared. ``cache=True`` keeps the compiled code on
disk (``NUMBA_CACHE_DIR`` or ``__pycache__``); see ``docs/kernels.md``.

Selecting the backend: the detector's ``ObstacleSettings.backend`` (``"compiled"`` by default,
``"numpy"`` for the reference implementation) and the ``backend`` keyword of
:func:`navkit.obstacles.cloud_to_grid`.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit

__all__ = [
    "classify_kernel",
    "mesh_kernel",
    "robust_normals_kernel",
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
                        jp = jp or abs(d00 - d10) > ratio * _min_nan(d00, d10)
                    else:
                        jp = jp or abs(d01 - d11) > ratio * _min_nan(d01, d11)
                    if use_steep and not jp:
                        if t == 0:
                            e = abs(d00 - d01) > ratio * _min_nan(d00, d01)
                        else:
                            e = abs(d01 - d11) > ratio * _min_nan(d01, d11)
                        jp = e and (abs(nzz) < steep_cos or lo > jump_h)
                jump[r, k] = jp
    return ok, normal, vray, rng, zmin, zmax, jump


# ------------------------------------------------------------------------------------------
# stage 5 input: robust normals (twin: mesh.robust_cell_normals)


@njit(cache=True, error_model="numpy", inline="always")
def _endpoint(Z, Df, g, f, zc, dc, lim, use_ratio, ratio):  # type: ignore[no-untyped-def]
    """End point ``g`` of a tangent, or the centre ``f`` when it lies across a discontinuity."""
    if not np.float64(abs(Z[g] - zc)) <= lim:
        return f
    if use_ratio:
        di = Df[g]
        if not abs(di - dc) <= ratio * _min_nan(di, dc):
            return f
    return g


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
            rh = np.float32(math.hypot(X[f] - ox32, Y[f] - oy32))
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
            e0 = _endpoint(Z, Df, ip * n_el + j, f, zc, dc, lim, use_ratio, ratio)
            e1 = _endpoint(Z, Df, im * n_el + j, f, zc, dc, lim, use_ratio, ratio)
            e2 = _endpoint(Z, Df, i * n_el + jp, f, zc, dc, lim, False, ratio)
            e3 = _endpoint(Z, Df, i * n_el + jm, f, zc, dc, lim, False, ratio)
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


NUMBA_VERSION = numba.__version__


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
