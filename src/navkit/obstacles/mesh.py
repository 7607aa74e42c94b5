"""Stages 2-4 of paper 1: the triangle mesh over the scan grid, normals, H_s and C_d.

Triangles are stored *interleaved* in an array of shape ``(R, 2C)``: cell ``(i, j)`` (between
azimuth rows ``i, i+1`` and elevation columns ``j, j+1``) holds triangle ``T_k`` at ``[i, 2j]``
and ``T_{k+1}`` at ``[i, 2j+1]``, so ``k = 2 (i C + j)`` is the paper's numbering and walking
along axis 1 follows the rising ray (increasing elevation). ``R = n_az - 1`` (``n_az`` when the
mesh closes across the azimuth seam), ``C = n_el - 1``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

__all__ = [
    "MeshCharacteristics",
    "build_mesh",
    "robust_cell_normals",
    "robust_strides",
    "smooth_normals",
    "triangle_indices",
]


@functools.lru_cache(maxsize=8)
def _triangle_indices_cached(n_az: int, n_el: int, wrap: bool) -> NDArray[np.int64]:
    out = _triangle_indices(n_az, n_el, wrap)
    out.flags.writeable = False
    return out


def triangle_indices(n_az: int, n_el: int, wrap: bool = False) -> NDArray[np.int64]:
    """Vertex indices ``(R, 2C, 3)`` of the mesh (read-only, cached); see :func:`_triangle_indices`."""
    return _triangle_indices_cached(int(n_az), int(n_el), bool(wrap))


def _triangle_indices(n_az: int, n_el: int, wrap: bool = False) -> NDArray[np.int64]:
    """Vertex indices ``(R, 2C, 3)`` of the mesh over an ``n_az x n_el`` grid (paper 1, stage 2).

    Vertex ``(i, j)`` has index ``n = i N + j`` with ``N = n_el``. Cell ``(i, j)`` gives
    ``T_k = (iN+j, iN+j+1, (i+1)N+j)`` and ``T_{k+1} = ((i+1)N+j, iN+j+1, (i+1)N+j+1)``. With
    azimuth counter-clockwise and elevation rising this order makes the normal of level ground
    point up (counter-clockwise seen from the tip), the same for every triangle. With ``wrap``
    the last azimuth row is joined to the first.
    """
    rows = np.arange(n_az if wrap else n_az - 1)
    nxt = (rows + 1) % n_az
    cols = np.arange(n_el - 1)
    v00 = rows[:, None] * n_el + cols[None, :]
    v01 = v00 + 1
    v10 = nxt[:, None] * n_el + cols[None, :]
    v11 = v10 + 1
    ta = np.stack([v00, v01, v10], axis=-1)
    tb = np.stack([v10, v01, v11], axis=-1)
    return np.stack([ta, tb], axis=2).reshape(len(rows), 2 * (n_el - 1), 3)


@dataclass(frozen=True)
class MeshCharacteristics:
    """Per-triangle quantities of stages 3-4 (arrays ``(R, 2C, ...)``, float32).

    Attributes
    ----------
    triangles : (R, 2C, 3) int array
        Vertex indices into the flattened grid.
    valid : (R, 2C) bool
        All three vertices valid (C_d) and the triangle not degenerate; otherwise "unreliable".
    normal : (R, 2C, 3) float32
        Unit normal ``(A, B, C)`` of the triangle's plane, sign chosen so that ``C >= 0``
        **[reading: "all normals into the same half-space" = the upper half-space; the grid
        winding already gives this for surfaces seen from above, and the flip fixes the
        triangles that contain a line of sight (shadows), whose winding sign is noise]**.
        NaN for unreliable triangles.
    vertex_ray : (n_az, n_el, 3) float32
        Unit lines of sight from the sensor to every vertex (H_s); a triangle's line of sight is
        that of its first vertex (the rays of a triangle differ by one angular step).
    range_mean : (R, 2C) float32
        Mean range of the three vertices, metres.
    z_min, z_max : (R, 2C) float32
        Lowest / highest vertex height, metres.
    jump : (R, 2C) bool
        The "height jump" code of H_s (its negation is rule P4), see :func:`build_mesh`.
    """

    triangles: NDArray[np.int64]
    valid: NDArray[np.bool_]
    normal: NDArray[np.floating[Any]]
    vertex_ray: NDArray[np.float32]
    range_mean: NDArray[np.float32]
    z_min: NDArray[np.float32]
    z_max: NDArray[np.float32]
    jump: NDArray[np.bool_]

    def ray_of(self, mask: NDArray[np.bool_]) -> NDArray[np.float32]:
        """Lines of sight ``(K, 3)`` of the triangles selected by ``mask (R, 2C)``."""
        first = self.triangles[..., 0][mask]
        return self.vertex_ray.reshape(-1, 3)[first]


def _cell_corners(c: NDArray[Any], wrap: bool) -> tuple[NDArray[Any], ...]:
    """Views ``c00, c01, c10, c11`` (each ``(R, C)``) of a per-vertex array ``(n_az, n_el)``."""
    if wrap:
        c = np.concatenate([c, c[:1]], axis=0)
    return c[:-1, :-1], c[:-1, 1:], c[1:, :-1], c[1:, 1:]


def _interleave(a: NDArray[Any], b: NDArray[Any]) -> NDArray[Any]:
    """``(R, C)`` values of triangles a and b -> ``(R, 2C)`` in the paper's order."""
    out = np.empty((a.shape[0], 2 * a.shape[1]), dtype=np.result_type(a, b))
    out[:, 0::2] = a
    out[:, 1::2] = b
    return out


def build_mesh(
    points: NDArray[np.floating],
    valid: NDArray[np.bool_],
    sensor_origin: NDArray[np.float64],
    *,
    wrap: bool,
    jump_height_m: float,
    jump_range_fraction: float,
    jump_range_ratio: float = np.inf,
    steep_cos: float | None = None,
) -> MeshCharacteristics:
    """Stages 2-4: mesh, normals, H_s (normal, line of sight, jump) for a grid of points.

    A triangle has a jump when its vertical extent exceeds ``jump_height_m + jump_range_fraction
    * range`` or when the ranges at the two ends of its azimuth edge differ by more than
    ``jump_range_ratio`` of the smaller (an occlusion edge beside an obstacle: neighbouring beams
    of the same elevation land on the obstacle and on the ground far behind it, with little height
    difference; on smooth ground neighbouring azimuths see about the same range). With
    ``steep_cos`` the range test also applies to the elevation edge of steep triangles
    (``|n_z| < steep_cos``): a steep triangle whose consecutive beams jump in range joins two
    surfaces at different depths (a car's side and a wall far behind it); ground, whose range
    grows quickly between beams at grazing angles, is not steep. The same holds for flat
    triangles lifted more than ``jump_height_m`` above the body frame's ground plane (a nearly
    horizontal ray passing over an object's top to something far behind at a similar height)
    **[reading: assumes the paper's "fairly even" terrain around z = 0]**.

    Vectorised over the grid with one float32 array per coordinate and corner views of the grid
    (no gather).

    Parameters
    ----------
    points : (n_az, n_el, 3) float
        Body-frame points (NaN where invalid).
    valid : (n_az, n_el) bool
        The validity codes C_d.
    sensor_origin : (3,) float
        Sensor position in the body frame.

    NumPy only: with the compiled kernels the detector runs stages 2-5 in one kernel that repeats
    this arithmetic (:func:`navkit.obstacles.rules.mesh_and_classes`).
    """
    n_az, n_el = valid.shape
    tri = triangle_indices(n_az, n_el, wrap)
    o = np.asarray(sensor_origin, dtype=np.float32)
    X, Y, Z = (np.ascontiguousarray(points[..., k], dtype=np.float32) for k in range(3))
    with np.errstate(invalid="ignore", divide="ignore"):
        RX, RY, RZ = X - o[0], Y - o[1], Z - o[2]
        D = np.sqrt(RX * RX + RY * RY + RZ * RZ)
        vray = np.stack([RX / D, RY / D, RZ / D], axis=-1)
    x00, x01, x10, x11 = _cell_corners(X, wrap)
    y00, y01, y10, y11 = _cell_corners(Y, wrap)
    z00, z01, z10, z11 = _cell_corners(Z, wrap)
    d00, d01, d10, d11 = _cell_corners(D, wrap)
    v00, v01, v10, v11 = _cell_corners(valid, wrap)

    # T_k = (00, 01, 10), T_{k+1} = (10, 01, 11): both share the edge 01-10
    ex, ey, ez = x01 - x10, y01 - y10, z01 - z10  # shared diagonal, from 10 to 01
    ax_, ay_, az_ = x00 - x10, y00 - y10, z00 - z10  # 10 -> 00
    bx_, by_, bz_ = x11 - x10, y11 - y10, z11 - z10  # 10 -> 11
    # a: (01 - 00) x (10 - 00) == (10 - 00) x (01 - 10)... use the equivalent form on shared edges
    na = (ay_ * ez - az_ * ey, az_ * ex - ax_ * ez, ax_ * ey - ay_ * ex)
    nb = (ey * bz_ - ez * by_, ez * bx_ - ex * bz_, ex * by_ - ey * bx_)
    with np.errstate(invalid="ignore", divide="ignore"):
        nx, ny, nz = (_interleave(a, b) for a, b in zip(na, nb, strict=True))
        norm = np.sqrt(nx * nx + ny * ny + nz * nz)
        ok = _interleave(v00 & v01 & v10, v10 & v01 & v11) & (norm > 0)
        # scale = (-1 if n_z < 0 else +1) / |n|, NaN where unreliable, built in place
        # (-(1 / x) == (-1) / x exactly in IEEE arithmetic); the components written straight
        # into the (R, 2C, 3) result instead of three temporaries and a stack
        scale = np.where(ok, norm, np.float32(np.nan))
        np.divide(np.float32(1.0), scale, out=scale)
        np.negative(scale, out=scale, where=nz < 0)
        normal = np.empty((*nx.shape, 3), dtype=np.float32)
        for k, c in enumerate((nx, ny, nz)):
            np.multiply(c, scale, out=normal[..., k])
        dsh = d01 + d10
        rng = _interleave(dsh + d00, dsh + d11) * np.float32(1.0 / 3.0)
        zmn, zmx = np.minimum(z01, z10), np.maximum(z01, z10)
        z_min = _interleave(np.minimum(zmn, z00), np.minimum(zmn, z11))
        z_max = _interleave(np.maximum(zmx, z00), np.maximum(zmx, z11))
        jump = z_max - z_min > jump_height_m + jump_range_fraction * rng
        if np.isfinite(jump_range_ratio):
            ra = np.abs(d00 - d10) > jump_range_ratio * np.minimum(d00, d10)
            rb = np.abs(d01 - d11) > jump_range_ratio * np.minimum(d01, d11)
            jump |= _interleave(ra, rb)
            if steep_cos is not None:
                ea = np.abs(d00 - d01) > jump_range_ratio * np.minimum(d00, d01)
                eb = np.abs(d01 - d11) > jump_range_ratio * np.minimum(d01, d11)
                # steep, or lifted above the ground plane of the body frame (z = 0 under the
                # sensor): a flat triangle up there joins an object's top to something far behind
                lifted = z_min > jump_height_m
                jump |= _interleave(ea, eb) & ((np.abs(normal[..., 2]) < steep_cos) | lifted)
        jump &= ok
    return MeshCharacteristics(tri, ok, normal, vray, rng, z_min, z_max, jump)


def smooth_normals(
    normal: NDArray[Any], weight: NDArray[np.bool_], support: int, wrap: bool
) -> NDArray[Any]:
    """Normals averaged over a window of ``2 support + 1`` cells (robust normals).

    A normalised convolution: the sum of ``weight * normal`` over the window divided by the sum
    of weights, renormalised; triangles with zero weight (unreliable, height jumps) neither
    contribute nor receive a smoothed normal (NaN). ``support = 0`` returns the input.
    """
    if support <= 0:
        return normal
    size = (2 * support + 1, 4 * support + 1)  # interleaved columns: two triangles per cell
    mode = ("wrap" if wrap else "constant", "constant")
    w = weight.astype(np.float64)
    den = ndimage.uniform_filter(w, size=size, mode=mode)
    out = np.empty_like(normal)
    filled = np.where(weight[..., None], normal, 0.0)
    for c in range(3):  # three components, each a vectorised filter over the whole grid
        out[..., c] = ndimage.uniform_filter(filled[..., c], size=size, mode=mode)
    with np.errstate(invalid="ignore", divide="ignore"):
        out /= np.where(den > 0, den, np.nan)[..., None]
        out /= np.linalg.norm(out, axis=-1, keepdims=True)
    out[~weight] = np.nan
    return out


def _nanmedian_rows(a: NDArray[Any]) -> NDArray[Any]:
    """``np.nanmedian(a, axis=0)`` for a 2-D array by one sort along axis 0 (NaNs sort last);
    NumPy's version goes through masked arrays for short axes. All-NaN columns give NaN."""
    s = np.sort(a, axis=0)
    cnt = np.count_nonzero(~np.isnan(a), axis=0)
    cols = np.arange(a.shape[1])
    lo = s[np.maximum((cnt - 1) // 2, 0), cols]
    hi = s[np.maximum(cnt // 2, 0) - (cnt == 0), cols]
    with np.errstate(invalid="ignore"):
        out = (lo + hi) / 2
    return np.where(cnt > 0, out, np.nan)


def _strides(
    X: NDArray[np.float32],
    Y: NDArray[np.float32],
    valid: NDArray[np.bool_],
    sensor_origin: NDArray[np.float64],
    support_m: float,
    max_stride: int,
) -> tuple[np.float32, NDArray[np.intp], NDArray[np.float32]]:
    """:func:`robust_strides` from the float32 coordinates, with the horizontal ranges."""
    n_el = valid.shape[1]
    step = max(1, n_el // 8)
    rh = np.hypot(X - np.float32(sensor_origin[0]), Y - np.float32(sensor_origin[1]))
    rh4 = rh[::4]
    Xs, Ys = X[:, ::step], Y[:, ::step]
    # azimuth step from neighbouring rows: angles, not distances (range noise moves a point
    # along its ray, which changes the distance to its neighbour but not its azimuth)
    az = np.arctan2(Ys - sensor_origin[1], Xs - sensor_origin[0])
    dal = np.abs((np.diff(az, axis=0) + np.pi) % (2 * np.pi) - np.pi)
    dal = dal[np.isfinite(dal) & (dal > 0)]
    dalpha = float(np.median(dal)) if dal.size else 1.0
    k_scale = np.float32(support_m / (2.0 * dalpha))
    with np.errstate(invalid="ignore", divide="ignore"):
        # elevation spacing per column from the medians of the horizontal range over the rows
        # (robust to range noise, which inflates the spacing measured between single points)
        cols = valid[::4].any(axis=0)
        rh_col = _nanmedian_rows(np.where(valid[::4], rh4, np.nan)[:, cols])
        rh_col = (
            np.interp(np.arange(n_el), np.flatnonzero(cols), rh_col)
            if rh_col.size
            else np.ones(n_el)
        )
        se_col = np.abs(np.diff(rh_col))
        se_col = np.concatenate([se_col, se_col[-1:]])
        se_col = np.maximum(np.fmin(se_col, np.roll(se_col, 1)), 1e-3)
        m_col = np.clip(np.rint(support_m / (2.0 * se_col)), 1, max_stride).astype(np.intp)
    return k_scale, m_col, rh


def robust_strides(
    points: NDArray[np.float64],
    valid: NDArray[np.bool_],
    sensor_origin: NDArray[np.float64],
    support_m: float,
    max_stride: int = 32,
) -> tuple[np.float32, NDArray[np.intp]]:
    """The strides of :func:`robust_cell_normals`: ``k_scale`` (float32; a vertex at horizontal
    range ``r`` gets the azimuth stride ``rint(k_scale / r)`` clipped to ``[1, max_stride]``) and
    the elevation stride per column ``(n_el,) intp`` in ``[1, max_stride]``."""
    X, Y = (np.ascontiguousarray(points[..., k], dtype=np.float32) for k in range(2))
    k_scale, m_col, _ = _strides(X, Y, valid, sensor_origin, support_m, max_stride)
    return k_scale, m_col


def robust_strides_compiled(
    points: NDArray[np.float64],
    valid: NDArray[np.bool_],
    sensor_origin: NDArray[np.float64],
    support_m: float,
    max_stride: int,
) -> tuple[np.float32, NDArray[np.intp]]:
    """:func:`robust_strides` by :func:`navkit.obstacles._kernels_mesh.robust_strides_kernel`:
    the same values. NumPy computes only the ``arctan2`` of the sampled columns (its SIMD
    ``arctan2`` differs from libm's in the last bit)."""
    from navkit.obstacles import _kernels_mesh

    step = max(1, valid.shape[1] // 8)
    Xs, Ys = (points[:, ::step, k].astype(np.float32) for k in range(2))
    az = np.arctan2(Ys - sensor_origin[1], Xs - sensor_origin[0])
    dalpha, m_col = _kernels_mesh.robust_strides_kernel(
        np.ascontiguousarray(points, dtype=np.float64),
        np.ascontiguousarray(valid, dtype=np.bool_),
        np.asarray(sensor_origin, dtype=np.float64).reshape(3),
        az,
        float(support_m),
        int(max_stride),
    )
    return np.float32(support_m / (2.0 * dalpha)), m_col


def robust_cell_normals(
    points: NDArray[np.float64],
    valid: NDArray[np.bool_],
    sensor_origin: NDArray[np.float64],
    *,
    support_m: float,
    wrap: bool,
    max_stride: int = 32,
    jump_height_m: float = 0.3,
    jump_range_fraction: float = 0.01,
    jump_range_ratio: float = 0.2,
) -> NDArray[np.float64]:
    """Noise-robust unit normals per grid cell ``(R, C, 3)`` from a support of about ``support_m``.

    At each vertex the two tangents are central differences whose strides (in cells) are chosen
    so that they span about ``support_m`` metres: along azimuth ``k = support_m / (2 r dalpha)``
    with ``r`` the horizontal range and ``dalpha`` the grid's azimuth step, along elevation from
    the measured spacing to the next point (both clipped to ``[1, max_stride]``). The normal is
    their cross product (sign: z up); a cell's normal is the normalised sum of its four corners'.
    On level ground the height noise is about ``sigma_rel * z_D`` whatever the range, so a fixed
    metric support gives a slope noise of about ``sqrt(2) sigma_rel z_D / support_m`` rad, instead
    of the per-triangle ``sqrt(2) sigma_rel z_D / (r dalpha)``, which explodes close to a
    spinning lidar. An end point across a discontinuity (the jump tests of :func:`build_mesh`)
    is replaced by the centre vertex, so the difference becomes one-sided rather than mixing the
    ground with an obstacle or with the ground far behind it; what remains is a mixing over
    ``support_m / 2`` across the foot of an obstacle.
    Cells whose corners have no valid robust normal get NaN.

    NumPy only: with the compiled kernels the detector computes these normals inside the stage
    2-5 kernel (:func:`navkit.obstacles.rules.mesh_and_classes`), the same values.
    """
    n_az, n_el = valid.shape
    X, Y, Z = (np.ascontiguousarray(points[..., k], dtype=np.float32) for k in range(3))
    k_scale, m_col, rh = _strides(X, Y, valid, sensor_origin, support_m, max_stride)
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.rint(k_scale / rh)
    k = np.clip(np.nan_to_num(k, nan=1.0, posinf=max_stride), 1, max_stride).astype(np.intp)
    ii = np.arange(n_az)[:, None]
    jj = np.arange(n_el)[None, :]
    if wrap:
        ip, im = (ii + k) % n_az, (ii - k) % n_az
    else:
        ip, im = np.minimum(ii + k, n_az - 1), np.maximum(ii - k, 0)
    jp = np.minimum(jj + m_col[None, :], n_el - 1)
    jm = np.maximum(jj - m_col[None, :], 0)
    ip_f, im_f = ip * n_el + jj, im * n_el + jj
    jp_f, jm_f = ii * n_el + jp, ii * n_el + jm
    Xf, Yf, Zf = X.ravel(), Y.ravel(), Z.ravel()
    Df = np.sqrt(
        (Xf - sensor_origin[0]) ** 2 + (Yf - sensor_origin[1]) ** 2 + (Zf - sensor_origin[2]) ** 2
    )
    centre = np.arange(n_az * n_el).reshape(n_az, n_el)
    zc, dc = Zf.reshape(n_az, n_el), Df.reshape(n_az, n_el)

    def endpoint(idx: NDArray[np.intp], azimuth_edge: bool) -> NDArray[np.intp]:
        # an end point across a discontinuity (a height jump, or a range jump along azimuth)
        # is replaced by the centre: the difference becomes one-sided instead of mixing surfaces
        zi, di = np.take(Zf, idx), np.take(Df, idx)
        with np.errstate(invalid="ignore"):
            ok = np.abs(zi - zc) <= jump_height_m + jump_range_fraction * dc
            if azimuth_edge and np.isfinite(jump_range_ratio):
                ok &= np.abs(di - dc) <= jump_range_ratio * np.minimum(di, dc)
        return np.where(ok, idx, centre)

    ip_f, im_f = endpoint(ip_f, True), endpoint(im_f, True)
    jp_f, jm_f = endpoint(jp_f, False), endpoint(jm_f, False)
    tax, tay, taz = (np.take(c, ip_f) - np.take(c, im_f) for c in (Xf, Yf, Zf))
    tex, tey, tez = (np.take(c, jp_f) - np.take(c, jm_f) for c in (Xf, Yf, Zf))
    nx = tay * tez - taz * tey
    ny = taz * tex - tax * tez
    nz = tax * tey - tay * tex
    with np.errstate(invalid="ignore", divide="ignore"):
        inv = np.where(nz < 0, np.float32(-1.0), np.float32(1.0)) / np.sqrt(
            nx * nx + ny * ny + nz * nz
        )
    comps = []
    for c in (nx, ny, nz):
        with np.errstate(invalid="ignore"):
            c = c * inv
        c[~np.isfinite(c)] = 0.0
        c00, c01, c10, c11 = _cell_corners(c, wrap)
        comps.append(c00 + c01 + c10 + c11)
    cx, cy, cz = comps
    with np.errstate(invalid="ignore", divide="ignore"):
        norm = np.sqrt(cx * cx + cy * cy + cz * cz)
        norm[norm == 0] = np.nan
        return np.stack([cx / norm, cy / norm, cz / norm], axis=-1)
