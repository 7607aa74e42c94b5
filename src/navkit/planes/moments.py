"""The organised extraction's building blocks (:mod:`navkit.planes.extract`): its settings, the
closed-form smallest eigenpairs, the per-thread workspace, the patch moments and the planes
fitted to moment rows, and the border patches' record. :mod:`navkit.planes.regions` and
:mod:`navkit.planes.outlines` build on them too."""

from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from navkit.domains import NON_NEGATIVE, POSITIVE, POSITIVE_INT, Domain, domain_field
from navkit.errors import InputError
from navkit.geometry._validate import check_settings
from navkit.geometry.angles import acos, cos

log = logging.getLogger(__name__)

_REFINE_MODES = ("boundary", "full")
_MAX_CELL = 128  # the compiled kernels' largest patch (navkit.planes._kernels.MAX_CELL)
# upper-triangle index pairs of a symmetric 3 x 3 matrix: xx, xy, xz, yy, yz, zz
_IU = (np.array([0, 0, 0, 1, 1, 2]), np.array([0, 1, 2, 1, 2, 2]))


@dataclass(frozen=True)
class ExtractionSettings:
    """Settings of :func:`extract_planes_organized`.

    Attributes
    ----------
    cell : int
        Patch size, pixels (CAPE uses 20 for 640 x 480).
    min_fill : float
        Fraction of valid points a patch needs to be tested.
    rms_base, rms_quadratic : float
        Patch thickness bound ``rms_base + rms_quadratic * r^2`` (metres, range r in metres): the
        structured-light noise model (Khoshelham & Elberink 2012: sigma_z ~ 1.4e-3 z^2 ... 2.9e-3 z^2)
        plus a margin for quantisation.
    angle_deg : float
        Largest normal angle between joined patches / merged regions, degrees.
    distance_factor : float
        Joined patches: centroid-to-plane distance below ``distance_factor`` x the thickness bound.
    min_cells : int
        Smallest region kept, patches.
    inlier_factor : float
        Boundary refinement: a pixel is an inlier when its distance to the plane is below
        ``inlier_factor`` x the thickness bound at its range.
    outline_cell : float
        Raster size for outlines and areas, metres.
    refine : {"boundary", "full"}
        ``"boundary"`` (default, CAPE): the patches inside a region (8 neighbours in the same
        region) are assigned wholesale - all their valid pixels are inliers, as a planar patch is
        within the noise bound by step 2 - and only the patches at and around a region's border
        are refined pixel by pixel. ``"full"``: every pixel of every region's patches is tested
        against its plane too, which also drops the rare far outlier inside a planar patch (a
        flying pixel that did not push the patch's thickness over the bound). Identical labels
        on the simulator and the slambook frames (``docs/planes.md``); ``"full"`` costs the
        per-pixel test of the interior patches (most of a frame with large planes).
    """

    cell: int = domain_field(20, Domain(integer=True, lo=3, note="pixels"))
    min_fill: float = domain_field(0.6, Domain(lo=0.0, hi=1.0, note="a fraction"))
    rms_base: float = domain_field(0.002, POSITIVE)
    rms_quadratic: float = domain_field(0.0025, NON_NEGATIVE)
    angle_deg: float = domain_field(
        12.0, Domain(lo=0.0, hi=90.0, lo_open=True, hi_open=True, note="degrees")
    )
    distance_factor: float = domain_field(3.0, POSITIVE)
    min_cells: int = domain_field(4, POSITIVE_INT)
    inlier_factor: float = domain_field(3.0, POSITIVE)
    outline_cell: float = domain_field(0.02, POSITIVE)
    refine: str = "boundary"

    def __post_init__(self) -> None:
        check_settings(self)
        if self.refine not in _REFINE_MODES:
            raise InputError(
                f"is {self.refine!r}", field="refine", expected=" or ".join(_REFINE_MODES)
            )

    def noise(self, r2: NDArray[np.floating]) -> NDArray[np.floating]:
        """Thickness bound (metres) at squared range ``r2`` (metres^2)."""
        return self.rms_base + self.rms_quadratic * r2


_DEFAULT_SETTINGS = ExtractionSettings()


# ------------------------------------------------------------------------------ linear algebra


def smallest_eigenpairs(
    C: NDArray[np.float64], *, rayleigh: bool = False
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Smallest eigenvalue and its unit eigenvector of many symmetric 3 x 3 matrices.

    Closed form (Smith 1961, "Eigenvalues of a symmetric 3 x 3 matrix"): with ``q = tr(C) / 3``,
    ``p = sqrt(tr((C - qI)^2) / 6)`` and ``r = det((C - qI) / p) / 2``, the eigenvalues are
    ``q + 2 p cos(acos(r) / 3 + 2 pi k / 3)``, the smallest for ``k = 1``. Its eigenvector is the
    longest cross product of two rows of ``C - lambda I`` (the null space of a rank-2 matrix).
    ~20x faster than ``numpy.linalg.eigh`` on 768 matrices, and as accurate for a plane's scatter
    (smallest eigenvalue well separated from the others); a matrix with a repeated smallest
    eigenvalue (no defined normal: a line or a blob of points) gets one eigenvector of its
    eigenspace, an all-zero matrix ``(0, 0, 1)``.

    ``acos`` and ``cos`` are :mod:`navkit.geometry.angles`' fixed Cephes arithmetic (within 1-2
    ulp of libm's), the operations of :func:`navkit.planes._kernels.plane_rows` in its order:
    the same bits as the compiled path on any CPU.

    The closed-form eigenvalue loses accuracy when the spread is extreme: its absolute error is
    ~eps x the largest eigenvalue (a floor seen to 20 m: 1e3 m^2 against a thickness of 4e-6
    m^2, 1e-6 relative; LAPACK's ``eigh`` 1e-8). ``rayleigh``: the eigenvalue is the Rayleigh
    quotient ``v^T C v`` of the unit vector instead - its first-order error vanishes, and the
    vector is accurate to ~eps x the eigenvalue gap - which matched an extended-precision
    inverse iteration to 12 digits on that floor (the rows with a repeated smallest eigenvalue
    keep the closed form's value).

    Parameters
    ----------
    C : (G, 3, 3) array
        Symmetric matrices (covariances, m^2).
    rayleigh : bool
        Eigenvalues as Rayleigh quotients (see above; the final planes of an extraction).

    Returns
    -------
    lam : (G,) array
        Smallest eigenvalues (clipped at 0).
    vec : (G, 3) array
        Unit eigenvectors (sign arbitrary).
    """
    a00, a11, a22 = C[:, 0, 0], C[:, 1, 1], C[:, 2, 2]
    a01, a02, a12 = C[:, 0, 1], C[:, 0, 2], C[:, 1, 2]
    q = (a00 + a11 + a22) / 3.0
    b00, b11, b22 = a00 - q, a11 - q, a22 - q
    p2 = (b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)) / 6.0
    p = np.sqrt(p2)
    det = (
        b00 * (b11 * b22 - a12 * a12)
        - a01 * (a01 * b22 - a12 * a02)
        + a02 * (a01 * a12 - b11 * a02)
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.where(p > 0, det / (2.0 * p * p2), 0.0)
    phi = acos(np.clip(r, -1.0, 1.0)) / 3.0  # Cephes' arithmetic: the kernel's bits
    lam = q + 2.0 * p * cos(phi + 2.0 * np.pi / 3.0)
    # null vector of C - lam I: the longest cross product of two of its rows
    m00, m11, m22 = a00 - lam, a11 - lam, a22 - lam
    rows = (
        (m00, a01, a02),
        (a01, m11, a12),
        (a02, a12, m22),
    )
    best = np.zeros((len(q), 3))
    best[:, 2] = 1.0
    best_n = np.zeros(len(q))
    for i, j in ((0, 1), (0, 2), (1, 2)):
        (x0, y0, z0), (x1, y1, z1) = rows[i], rows[j]
        cx, cy, cz = y0 * z1 - z0 * y1, z0 * x1 - x0 * z1, x0 * y1 - y0 * x1
        n2 = cx * cx + cy * cy + cz * cz
        take = n2 > best_n
        best[take] = np.stack([cx, cy, cz], axis=1)[take]
        best_n = np.where(take, n2, best_n)
    # a repeated smallest eigenvalue (rank <= 1): any unit vector orthogonal to the largest row
    rank1 = best_n <= 1e-30 * np.maximum(p2 * p2, 1e-300)
    if rank1.any():
        _, V = np.linalg.eigh(C[rank1])
        best[rank1] = V[:, :, 0]
        best_n[rank1] = 1.0
    best /= np.sqrt(_dot3(best, best))[:, None]
    if rayleigh:  # v^T (C v), left to right (navkit.planes._kernels.plane_rows' order)
        v0, v1, v2 = best[:, 0], best[:, 1], best[:, 2]
        u0 = a00 * v0 + a01 * v1 + a02 * v2
        u1 = a01 * v0 + a11 * v1 + a12 * v2
        u2 = a02 * v0 + a12 * v1 + a22 * v2
        lam = np.where(rank1, lam, v0 * u0 + v1 * u1 + v2 * u2)
    return np.maximum(lam, 0.0), best


class _Workspace(threading.local):
    """Per-thread scratch buffers reused from call to call (CAPE preallocates its buffers the
    same way). Only temporaries that never leave :func:`extract_planes_organized` live here; the
    results are fresh arrays. Fresh multi-megabyte temporaries cost a page fault per 4 kB on
    first touch - measured 7-8 ms of a ~16 ms frame on a loaded 2-core machine. Holds
    ~20 MB per thread after a 640 x 480 frame."""

    def __init__(self) -> None:
        self.buffers: dict[str, NDArray] = {}

    def get(self, name: str, shape: tuple[int, ...], dtype: type) -> NDArray:
        n = math.prod(shape)  # Python ints (numpy.prod: ~5 us a call)
        buf = self.buffers.get(name)
        if buf is None or buf.dtype != np.dtype(dtype) or buf.size < n:
            buf = np.empty(max(n, 1), dtype)
            self.buffers[name] = buf
        return buf[:n].reshape(shape)


_WS = _Workspace()


_KERNELS: list = []  # the kernel module once imported (~10 look-ups a frame)


def _kernels():  # type: ignore[no-untyped-def]
    """The compiled kernels (:mod:`navkit.planes._kernels`), imported on first use so that
    ``import navkit`` does not load Numba."""
    if not _KERNELS:
        from navkit.planes import _kernels

        _KERNELS.append(_kernels)
    return _KERNELS[0]


_OUTLINE_KERNELS: list = []


def _outline_kernels():  # type: ignore[no-untyped-def]
    """The compiled kernels of the last step, the label image and the outlines
    (:mod:`navkit.planes._kernels_outline`), imported on first use."""
    if not _OUTLINE_KERNELS:
        from navkit.planes import _kernels_outline

        _OUTLINE_KERNELS.append(_kernels_outline)
    return _OUTLINE_KERNELS[0]


# ------------------------------------------------------------------------------ moments

# a moment row: [n, S (3), SS (3 x 3, row-major)] - count, sums and sums of outer products (raw)
_NM = 13


def _moment_rows(
    n: NDArray[np.float64],
    ref: NDArray[np.float64],
    Sd: NDArray[np.float64],
    SSd: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Raw float64 moment rows ``(G, 13)`` from moments about a reference point per group:
    ``S = n ref + Sd`` and ``SS = SSd + ref Sd^T + Sd ref^T + n ref ref^T``."""
    M = np.empty((len(n), _NM))
    M[:, 0] = n
    M[:, 1:4] = n[:, None] * ref + Sd
    rS = ref[:, :, None] * Sd[:, None, :]
    SS = SSd + rS + rS.transpose(0, 2, 1) + n[:, None, None] * ref[:, :, None] * ref[:, None, :]
    M[:, 4:] = SS.reshape(-1, 9)
    return M


def _dot3(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``a . b`` over the last axis (length 3, broadcasting) as ``(a0 b0 + a1 b1) + a2 b2``: the
    order of the kernels' dot products (:func:`navkit.planes._kernels._dot3`), the same bits on
    every CPU - ``numpy.einsum`` and matrix products group the terms by the SIMD width or the
    BLAS in use."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _sum_rows(
    groups: NDArray[np.int64], n_groups: int, M: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Sums of the rows of ``M`` per group (``-1`` = none): ``(n_groups, M.shape[1])``, each
    group's rows added one after the other in their order, from +0 (``numpy.add.at``: one
    unbuffered addition per row) - the additions of :func:`navkit.planes._kernels.sum_rows`, so
    the same bits on every CPU (a one-hot matrix product would group them per BLAS build and
    thread count)."""
    R = np.zeros((n_groups, M.shape[1]))
    sel = groups >= 0
    np.add.at(R, groups[sel], M[sel])
    return R


def _planes_from_rows(
    M: NDArray[np.float64], compiled: bool = False, rayleigh: bool = False
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """TLS planes of moment rows: normals ``(G, 3)`` pointing away from the origin, rho ``(G,)``,
    RMS orthogonal residual ``(G,)`` and means ``(G, 3)`` (metres), by the closed form of
    :func:`smallest_eigenpairs`. ``compiled``: row by row in one loop
    (:func:`navkit.planes._kernels.plane_rows`: the NumPy closed form's operations in its order,
    the same bits). ``rayleigh``: the RMS from the Rayleigh quotient of the
    normal (:func:`smallest_eigenpairs`; accurate for the final planes' extreme spreads)."""
    if compiled:
        normal, rho, rms, mean, rank1 = _kernels().plane_rows(np.ascontiguousarray(M), rayleigh)
        if rank1.any():  # a repeated smallest eigenvalue: LAPACK's vector, as the NumPy path
            _rank1_normals(M, rank1, normal, rho)
        return normal, rho, rms, mean
    n = np.maximum(M[:, 0], 1.0)
    m = M[:, 1:4] / n[:, None]
    C = M[:, 4:].reshape(-1, 3, 3) / n[:, None, None] - m[:, :, None] * m[:, None, :]
    # the closed form for any number of rows (the few dozen region rows too: LAPACK's eigh had
    # less overhead there, but the compiled path fits them with the same closed form)
    lam, normal = smallest_eigenpairs(C, rayleigh=rayleigh)
    d = _dot3(normal, m)
    normal[d < 0] *= -1
    return normal, np.abs(d), np.sqrt(lam), m


def _rank1_normals(
    M: NDArray[np.float64],
    rank1: NDArray[np.bool_],
    normal: NDArray[np.float64],
    rho: NDArray[np.float64],
) -> None:
    """The normals (and rho) of the rows whose smallest eigenvalue is repeated, in place, as
    :func:`smallest_eigenpairs` gives them: LAPACK's first eigenvector, normalised, pointing
    away from the origin. The empty patches (all-zero rows, ~100 of a Kinect frame's 768) all
    have the zero matrix, whose plane is computed once per process (:func:`_zero_row_plane`,
    the same LAPACK call on the same matrix); LAPACK runs only for the other rows (usually
    none)."""
    idx = np.flatnonzero(rank1)
    zero = ~M[idx].any(axis=1)
    z, nz = idx[zero], idx[~zero]
    if len(nz):
        normal[nz], rho[nz] = _lapack_planes(M[nz])
    if len(z):
        normal[z], rho[z] = _zero_row_plane()


def _lapack_planes(M: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Unit normals (LAPACK's first eigenvector, away from the origin) and rho of moment rows."""
    n = np.maximum(M[:, 0], 1.0)
    m = M[:, 1:4] / n[:, None]
    C = M[:, 4:].reshape(-1, 3, 3) / n[:, None, None] - m[:, :, None] * m[:, None, :]
    _, V = np.linalg.eigh(C)
    v = V[:, :, 0] / np.sqrt(_dot3(V[:, :, 0], V[:, :, 0]))[:, None]
    d = _dot3(v, m)
    v[d < 0] *= -1
    return v, np.abs(d)


_ZERO_ROW_PLANE: list[tuple[NDArray[np.float64], float]] = []


def _zero_row_plane() -> tuple[NDArray[np.float64], float]:
    """:func:`_lapack_planes` of an all-zero moment row (the zero matrix), computed on first
    use (LAPACK's eigenvectors of a matrix do not depend on the other matrices of a call)."""
    if not _ZERO_ROW_PLANE:
        v, d = _lapack_planes(np.zeros((1, _NM)))
        _ZERO_ROW_PLANE.append((v[0].copy(), float(d[0])))
    return _ZERO_ROW_PLANE[0]


def _block_sum(a: NDArray[np.float32], hc: int, wc: int, c: int) -> NDArray[np.float32]:
    """Sums over ``c x c`` blocks of the last two axes: ``(..., hc*c, wc*c) -> (..., hc, wc)``."""
    lead = a.shape[:-2]
    b = a.reshape(*lead, hc, c, wc * c).sum(axis=-2)
    return b.reshape(*lead, hc, wc, c).sum(axis=-1)


_RegionPlanes = tuple[NDArray[np.float64], NDArray[np.float64]]  # normals (n, 3), rho (n,)


@dataclass(frozen=True)
class _Patches:
    """Pixels and patch moments (internal)."""

    P: NDArray[np.float64]  # (H, W, 3) the input points
    valid: NDArray[np.bool_]  # (Hc, Wc) over the whole patches
    ref: NDArray[np.float32]  # (G, 3) each patch's reference point (its float32 mean)
    M: NDArray[np.float64]  # (G, 13) raw moment rows
    tol_scale: np.float32  # the inlier bound at range r: tol_scale r^2 + tol_base
    tol_base: np.float32
    # compiled path only: each patch's float32 coordinates (G, 3, c c), 0 where invalid
    XP: NDArray[np.float32] | None = None
    # NumPy path only (the compiled refinement recomputes them for the patches it needs):
    D: NDArray[np.float32] | None = None  # (3, Hc, Wc) coordinates minus their patch's ref
    tol: NDArray[np.float32] | None = None  # (Hc, Wc) inlier bound, -1 where invalid


def _patch_moments(
    P: NDArray[np.float64], s: ExtractionSettings, hc: int, wc: int, compiled: bool = True
) -> _Patches:
    """Step 1: moments of every patch in one pass of block reductions (float32, centred).

    A patch's scatter about its mean is ~1e-3 m^2 along the plane and ~1e-6 m^2 across it (the
    thickness), while raw second moments at 5 m are ~25 m^2: in float32 (eps 6e-8) raw moments
    would lose the thickness to cancellation (25 * 6e-8 = 1.5e-6 m^2). Centred on the patch's
    float32 mean, the products are <= ~0.01 m^2 and keep ~1e-9 m^2; the moments about the
    reference are converted to raw float64 moments for the region sums. ``compiled``: two
    fused sweeps per band of patches (:func:`navkit.planes._kernels.patch_moments`, same
    bits); else the NumPy block reductions below (the oracle), where the coordinates are
    centred in place and one scratch image serves all products.
    """
    c = int(s.cell)
    Hc, Wc = hc * c, wc * c
    valid = _WS.get("valid", (Hc, Wc), np.bool_)
    tol_scale = np.float32(s.inlier_factor * s.rms_quadratic)
    tol_base = np.float32(s.inlier_factor * s.rms_base)
    if compiled:
        XP = _WS.get("XP", (hc * wc, 3, c * c), np.float32)
        M, ref_g = _kernels().patch_moments(np.ascontiguousarray(P), hc, wc, c, valid, XP)
        return _Patches(P, valid, ref_g, M, tol_scale, tol_base, XP=XP)
    X = _WS.get("X", (3, Hc, Wc), np.float32)
    r2 = _WS.get("r2", (Hc, Wc), np.float32)
    for k in range(3):
        X[k] = P[:Hc, :Wc, k]
    x, y, z = X
    np.multiply(x, x, out=r2)
    tmp = np.multiply(y, y, out=_WS.get("tmp", (Hc, Wc), np.float32))
    r2 += tmp
    np.multiply(z, z, out=tmp)
    r2 += tmp  # NaN / inf anywhere -> not finite
    np.greater(r2, 0, out=valid)
    invalid = np.less(r2, np.inf, out=_WS.get("invalid", (Hc, Wc), np.bool_))
    valid &= invalid
    np.logical_not(valid, out=invalid)
    for k in range(3):  # per coordinate: 2x faster than a mask broadcast over the three
        np.copyto(X[k], np.float32(0), where=invalid)
    np.copyto(tmp, valid)
    cnt = _block_sum(tmp, hc, wc, c)
    ref = _block_sum(X, hc, wc, c) / np.maximum(cnt, 1)  # (3, hc, wc) float32 means
    X.reshape(3, hc, c, wc, c)[...] -= ref[:, :, None, :, None]
    X *= tmp  # tmp is still the 0 / 1 validity: zero again (finite here, 5x faster than copyto)
    D = X
    Sd = _block_sum(D, hc, wc, c).reshape(3, -1).T.astype(np.float64)  # (G, 3)
    SSd = np.empty((hc * wc, 3, 3))
    for a, b in zip(*_IU, strict=True):
        np.multiply(D[a], D[b], out=tmp)
        v = _block_sum(tmp, hc, wc, c).ravel()
        SSd[:, a, b] = v
        SSd[:, b, a] = v
    ref_g = np.ascontiguousarray(ref.reshape(3, -1).T, dtype=np.float32)
    M = _moment_rows(cnt.ravel().astype(np.float64), ref_g.astype(np.float64), Sd, SSd)
    # the refinement's per-pixel bound inlier_factor * noise(r^2), in place of r^2
    r2 *= tol_scale
    r2 += tol_base
    np.copyto(r2, np.float32(-1), where=invalid)
    return _Patches(P, valid, ref_g, M, tol_scale, tol_base, D=D, tol=r2)


def _stride_masks(c: int) -> NDArray[np.bool_]:
    """``(c + 1, c * c)``: row ``t`` marks the pixels of a ``c x c`` patch on every ``t``-th row
    and column (row 0 unused)."""
    px = np.arange(c)
    t = np.maximum(np.arange(c + 1), 1)[:, None, None]
    return ((px[None, :, None] % t == 0) & (px[None, None, :] % t == 0)).reshape(c + 1, c * c)


def _sample_stride(M: NDArray[np.float64], c: int, raster: float) -> NDArray[np.int64]:
    """Pixel stride per patch for rasterising outlines: every ``t``-th row and column of a patch
    still puts a point in every raster cell it covers.

    A patch's pixel spacing is ~ its side / ``c``; the side from its scatter (a uniformly
    sampled square of side L has trace 2 L^2 / 12, so L = sqrt(6 trace), an upper bound for an
    elongated patch's mean side). Points ``t`` pixels apart fill a ``raster`` grid in any
    orientation when ``t * spacing <= raster / sqrt(2)``.
    """
    n = np.maximum(M[:, 0], 1.0)
    m = M[:, 1:4] / n[:, None]
    tr = M[:, 4] / n - m[:, 0] ** 2 + M[:, 8] / n - m[:, 1] ** 2 + M[:, 12] / n - m[:, 2] ** 2
    spacing = np.sqrt(6.0 * np.maximum(tr, 0.0)) / c
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.floor(raster / (np.sqrt(2.0) * spacing))
    t[~(t >= 1.0)] = 1.0  # NaN (no pixels) and < 1
    return np.minimum(t, c).astype(np.int64)


@dataclass(frozen=True)
class _Border:
    """Pixel-level result of the border patches (internal)."""

    ids: NDArray[np.int64]  # (B,) patch ids
    label: NDArray[np.signedinteger]  # (B, c, c) region of each pixel, -1 = none
    complete: NDArray[np.bool_]  # (B,) region patches whose valid pixels all stayed in it
    M: NDArray[np.float64]  # (n_reg, 13) raw moments of the pixels of the mixed patches
    points: NDArray[np.float32]  # (3, K) sampled pixels of the mixed patches, raster order
    point_region: NDArray[np.signedinteger]  # (K,) their regions
