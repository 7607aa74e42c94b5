"""Plane extraction: organised grids (CAPE-like cell region growing) and unorganised clouds.

Organised input (depth image back-projected, organised PCD, a range-scan grid), in the spirit of
CAPE (Proenca & Gao, 2018, "Fast cylinder and plane extraction from depth cameras for visual
odometry"):

1. cut the grid into ``cell x cell`` patches and accumulate their moments (count, mean, scatter)
   in one pass of block reductions, in float32 on coordinates centred per patch;
2. a patch is *planar* when it is nearly complete and its PCA thickness (smallest eigenvalue,
   closed form for all patches at once) is below a depth-dependent noise bound
   ``rms_base + rms_quadratic * r^2``;
3. neighbouring planar patches are joined when their normals agree and each centroid lies on the
   other's plane (region growing = connected components of that cell graph, drawn as an image
   for ``cv2.connectedComponents``);
4. each region is refit from its summed moments; patches that disagree with the region's plane are
   dropped and the regions recomputed; coplanar regions are merged;
5. boundary refinement (CAPE): the patches *inside* a region (all eight neighbours in the same
   region) are assigned wholesale - their valid pixels are inliers and their moments enter the
   refit as they are; only the pixels of the patches at a region's border and of the patches
   bordering it are tested against the planes (distance below ``inlier_factor`` x the noise
   bound; the closest plane wins). ``refine="full"`` tests every pixel of every region instead;
6. each plane is refit by total least squares from the moments of its inliers (interior patches
   + boundary pixels); its outline is rasterised in the plane from the densely sampled interior
   patches (one quadrilateral each) and a strided sample of the other pixels - not from all
   inliers; corners and samples of all planes are gathered at once, only the rasterisation runs
   per plane. Each plane's inlier list is searched in the rows of the 8-bit label image its
   region can reach.

Temporaries are kept per thread between calls (:class:`_Workspace`); the results never share
memory with them.

The hot passes - the patch moments, the patches' planes, the planar and edge tests, the
connected components (union-find instead of OpenCV on the cell-graph image; the same numbering),
the border candidates, the border refinement with its outline samples, the label image with the
inliers, the outline samples and rasters - run as compiled kernels (``navkit.planes._kernels*``,
Numba); the NumPy versions here are their oracle (``_extract(..., compiled=False)``;
``tests/planes/test_kernels.py``, ``docs/kernels.md``) and give the same result bit for bit on
any CPU: both run the same IEEE operations in the same order - float64 sums one term
after the other (:func:`_sum_rows`, the weighted ``bincount`` of the mixed patches' pixels; no
BLAS product), three-term dot products left to right (:func:`_dot3`; no ``einsum``), the
closed-form eigenvalue's ``acos`` / ``cos`` with Cephes' arithmetic
(:mod:`navkit.geometry.angles`; not NumPy's SIMD or libm's), no ``fastmath`` in the kernels.
LAPACK runs only for a matrix with a repeated smallest eigenvalue, in both paths on the same
matrix.

Unorganised clouds: :mod:`navkit.planes.extract_cloud` (sequential RANSAC with vectorised
hypotheses, a TLS refit, and the largest connected part of the inliers kept per plane); its names
are re-exported here.
"""

from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.domains import NON_NEGATIVE, POSITIVE, POSITIVE_INT, Domain, domain_field
from navkit.errors import InputError
from navkit.geometry._validate import check_settings
from navkit.geometry.angles import acos, cos
from navkit.geometry.fitting import Plane, canonical_plane
from navkit.jit import kernels_enabled
from navkit.planes.extract_cloud import CloudExtractionSettings, extract_planes_cloud
from navkit.planes.segments import (
    ExtractionResult,
    PlaneSegment,
)

__all__ = [
    "CloudExtractionSettings",
    "ExtractionSettings",
    "extract_planes_cloud",
    "extract_planes_organized",
    "smallest_eigenpairs",
]

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


def _refine_border(
    pt: _Patches,
    comp: NDArray[np.int64],
    ids: NDArray[np.int64],
    cand: NDArray[np.int64],
    rn: NDArray[np.float64],
    rd: NDArray[np.float64],
    n_reg: int,
    hc: int,
    wc: int,
    c: int,
    raster: float,
    compiled: bool = True,
) -> _Border:
    """Step 5: the pixels of the border patches against their candidate planes.

    A pixel joins the closest candidate plane whose distance is below ``inlier_factor`` x the
    noise bound at its range. Distances use the centred coordinates: ``n . x - rho =
    n . d + (n . ref - rho)``, one offset per (patch, plane). A region patch whose valid pixels
    all stay in its own region is *complete* (its patch moments stand); the pixels of the other
    (*mixed*) patches give per-pixel moments, grouped by (patch, plane), summed in float64 (the
    products of the float32 coordinates are exact in float64). ``compiled``: one loop over the
    border pixels (:func:`navkit.planes._kernels.refine_pixels`); else NumPy passes per
    candidate slot (the oracle: the same labels, and the same moments bit for bit - per (patch,
    candidate) the pixels' float64 terms added one after the other in raster order, then the
    rows per region in (patch, candidate) order, as the kernel adds them).
    """
    B = len(cand)
    n32 = rn.astype(np.float32)
    rho32 = rd.astype(np.float32)
    own = comp[ids]
    ltype = np.int16 if n_reg < 32767 else np.int32
    if compiled:  # the offsets and strides below are computed in the kernel, the same floats
        label = np.empty((B, c, c), ltype)  # the kernel writes every pixel's label
        complete, M, cpoints, cregion = _kernels().refine_pixels(
            pt.XP, pt.ref, pt.tol_scale, pt.tol_base, ids, own, cand, n32, rho32, pt.M,
            float(raster), wc, c, label, n_reg,
        )  # fmt: skip
        return _Border(ids, label, complete, M, cpoints, cregion)
    ci, cj = np.divmod(ids, wc)
    ref = pt.ref[ids]  # (B, 3) float32
    label = np.full((B, c, c), -1, ltype)
    # n . ref - rho per (patch, candidate), float32 (-1 slots: unused)
    kc = np.maximum(cand, 0)
    nk = n32[kc]  # (B, m, 3)
    off = nk[..., 0] * ref[:, None, 0] + nk[..., 1] * ref[:, None, 1]
    off += nk[..., 2] * ref[:, None, 2]
    off -= rho32[kc]
    complete, G = _refine_border_numpy(pt, ids, ci, cj, own, cand, off, n32, label, hc, wc, c)
    mixed = np.flatnonzero(~complete)
    M = np.zeros((n_reg, _NM))
    points = np.zeros((3, 0), np.float32)
    point_region = np.zeros(0, label.dtype)
    if len(mixed):
        Bm = len(mixed)
        lm = label[mixed].reshape(Bm, -1)
        cm = cand[mixed]
        used = np.flatnonzero(G[:, 0] > 0)
        g = G[used]
        Sdd = np.empty((len(used), 3, 3))
        Sdd[:, _IU[0], _IU[1]] = g[:, 4:]
        Sdd[:, _IU[1], _IU[0]] = g[:, 4:]
        gref = np.repeat(ref[mixed].astype(np.float64), cm.shape[1], axis=0)[used]
        M = _sum_rows(cm.ravel()[used], n_reg, _moment_rows(g[:, 0], gref, g[:, 1:4], Sdd))
        # the pixels of the mixed patches per region for the outlines, every t-th row / column
        # (lattice masks per stride looked up, one index list for all three coordinates)
        t = _sample_stride(pt.M[ids[mixed]], c, raster)
        flat = np.flatnonzero((lm >= 0) & _stride_masks(c)[t])
        bi, pix = np.divmod(flat, c * c)
        pr, pq = np.divmod(pix, c)
        point_region = lm.ravel()[flat]
        rows, cols = ci[mixed][bi] * c + pr, cj[mixed][bi] * c + pq
        points = pt.D[:, rows, cols]  # type: ignore[index]
        points += np.take(np.ascontiguousarray(ref[mixed].T), bi, axis=1)
    return _Border(
        ids=ids, label=label, complete=complete, M=M, points=points, point_region=point_region
    )


def _refine_border_numpy(
    pt: _Patches,
    ids: NDArray[np.int64],
    ci: NDArray[np.int64],
    cj: NDArray[np.int64],
    own: NDArray[np.int64],
    cand: NDArray[np.int64],
    off: NDArray[np.float32],
    n32: NDArray[np.float32],
    label: NDArray[np.signedinteger],
    hc: int,
    wc: int,
    c: int,
) -> tuple[NDArray[np.bool_], NDArray[np.float64]]:
    """NumPy oracle of :func:`navkit.planes._kernels.refine_pixels`: fills ``label`` and returns
    ``complete (B,)`` and the float64 moments ``(Bm * m, 10)`` of the mixed patches' pixels per
    (patch, candidate slot)."""
    B, m = cand.shape
    assert pt.D is not None and pt.tol is not None
    d = [pt.D[k].reshape(hc, c, wc, c)[ci, :, cj, :] for k in range(3)]  # (B, c, c) each
    tol = pt.tol.reshape(hc, c, wc, c)[ci, :, cj, :]  # -1 where invalid: never an inlier
    e = (slice(None), None, None)
    best_d = _WS.get("best_d", (B, c, c), np.float32)
    best_d.fill(np.inf)
    dist_ws = _WS.get("dist", (B, c, c), np.float32)
    tmp_ws = _WS.get("dist_tmp", (B, c, c), np.float32)
    better_ws = _WS.get("better", (B, c, c), np.bool_)
    ok_ws = _WS.get("ok", (B, c, c), np.bool_)
    n_with = (cand >= 0).sum(axis=0)  # patches with more than `slot` candidates: a prefix
    for slot in range(m):
        b = int(n_with[slot])
        k = cand[:b, slot]
        nk = n32[k]
        dist, tmp, better, ok = dist_ws[:b], tmp_ws[:b], better_ws[:b], ok_ws[:b]
        np.multiply(d[0][:b], nk[:, 0][e], out=dist)
        for a in (1, 2):
            np.multiply(d[a][:b], nk[:, a][e], out=tmp)
            dist += tmp
        dist += off[:b, slot][e]
        np.abs(dist, out=dist)
        np.less(dist, tol[:b], out=better)
        better &= np.less(dist, best_d[:b], out=ok)
        np.copyto(best_d[:b], dist, where=better)
        np.copyto(label[:b], k.astype(label.dtype)[e], where=better)
    complete = (own >= 0) & np.all((label == own[e]) | (tol < 0), axis=(1, 2))
    # per-pixel moments of the mixed patches per (patch, candidate slot): the labelled pixels'
    # [1, d, d d^T] in float64 (the products of float32 values are exact) summed by a weighted
    # bincount per quantity - one addition per pixel from +0, in raster order within a patch,
    # as the kernel adds them
    mixed = np.flatnonzero(~complete)
    Bm = len(mixed)
    G = np.zeros((Bm * m, 10))
    if Bm == 0:
        return complete, G
    lm = label[mixed].reshape(Bm, c * c)
    cm = cand[mixed]
    slot = np.argmax(lm[:, None, :] == cm[:, :, None], axis=1)  # (Bm, c^2), a label's slot
    bi, pix = np.nonzero(lm >= 0)  # raster order within a patch, patches in order
    gid = bi * m + slot[bi, pix]
    q = [a[mixed].reshape(Bm, c * c)[bi, pix].astype(np.float64) for a in d]
    G[:, 0] = np.bincount(gid, minlength=Bm * m)
    for a in range(3):
        G[:, 1 + a] = np.bincount(gid, weights=q[a], minlength=Bm * m)
    for j, (a_, b_) in enumerate(zip(*_IU, strict=True)):
        G[:, 4 + j] = np.bincount(gid, weights=q[a_] * q[b_], minlength=Bm * m)
    return complete, G


# ------------------------------------------------------------------------------ main entry


def extract_planes_organized(
    points: ArrayLike, settings: ExtractionSettings | None = None
) -> ExtractionResult:
    """Planes of an organised point grid (depth image back-projected, organised PCD, scan grid).

    Parameters
    ----------
    points : (H, W, 3) array
        Points in the sensor frame, metres; NaN (or all-zero rows) = no measurement. Depth-like
        range for the noise model is the distance from the origin. Rows / columns beyond the last
        whole ``cell`` are not used.
    settings : ExtractionSettings, optional

    Returns
    -------
    ExtractionResult
        ``labels`` is ``(H, W)``; inlier indices are ``row * W + col``, increasing.
    """
    return _extract(points, settings, compiled=kernels_enabled())


def _extract(
    points: ArrayLike, settings: ExtractionSettings | None, *, compiled: bool
) -> ExtractionResult:
    """:func:`extract_planes_organized` with the compiled kernels (``compiled=True``; the public
    function passes the process's policy, :func:`navkit.jit.kernels_enabled`) or their NumPy
    oracles (the tests compare the two)."""
    from navkit.planes.outlines import _label_image_numpy, _outlines
    from navkit.planes.regions import _border_patches, _grow_regions

    s = settings or _DEFAULT_SETTINGS  # validated once (check_settings costs ~50 us a call)
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 3 or P.shape[2] != 3:
        raise InputError(
            f"has shape {P.shape}", field="points", expected="(H, W, 3) organised grid"
        )
    H, W = P.shape[:2]
    c = int(s.cell)
    hc, wc = H // c, W // c
    if hc == 0 or wc == 0:
        return ExtractionResult((), -np.ones((H, W), np.int64))
    compiled = compiled and c <= _MAX_CELL
    if compiled:
        P = np.ascontiguousarray(P)  # the kernels' layout (a no-op for a fresh grid)
    # 1. patch moments
    pt = _patch_moments(P, s, hc, wc, compiled)
    # 2.-4. planar patches, region growing, pruning, merging
    n_reg, comp, n_planar, reg_planes = _grow_regions(pt.M, hc, wc, s, compiled)
    if n_reg == 0:
        return ExtractionResult((), -np.ones((H, W), np.int64))
    # 5. wholesale patches; the others pixel by pixel against the region planes
    if reg_planes is None:  # regions were merged: their planes anew
        rn, rd, _, _ = _planes_from_rows(_sum_rows(comp, n_reg, pt.M))
    else:
        rn, rd = reg_planes
    cellmap = comp.reshape(hc, wc)
    if compiled:
        wholesale, ids, cand = _kernels().border_patches(cellmap, s.refine == "full")
    else:
        wholesale, ids, cand = _border_patches(cellmap, s.refine == "full")
    bd = _refine_border(pt, comp, ids, cand, rn, rd, n_reg, hc, wc, c, s.outline_cell, compiled)
    wholesale = wholesale.ravel()
    wholesale[ids[bd.complete]] = True
    # 6. final planes from the moments of their inliers: wholesale patches + mixed pixels
    whole = np.where(wholesale, comp, -1)
    Mf = _kernels().sum_rows(whole, n_reg, pt.M) if compiled else _sum_rows(whole, n_reg, pt.M)
    Mf += bd.M
    normal, rho, rms, mean = _planes_from_rows(Mf, compiled, rayleigh=True)
    count = np.rint(Mf[:, 0]).astype(np.int64)
    keep = np.flatnonzero(count >= s.min_cells * c * c * s.min_fill)
    keep = keep[np.argsort(-count[keep], kind="stable")]  # segments by decreasing inlier count
    new_id = np.full(n_reg + 1, -1, np.int64)  # region + 1 -> segment index
    new_id[keep + 1] = np.arange(len(keep))
    mixed = ~bd.complete
    segmap = new_id[cellmap + 1]
    lab_cell = new_id[np.where(wholesale, comp, -1) + 1].reshape(hc, wc)
    if compiled:
        labels, inl, cuts = _outline_kernels().label_image(
            pt.valid, lab_cell, ids, bd.complete, bd.label, new_id, count[keep], H, W
        )
        inliers = [inl[cuts[k] : cuts[k + 1]] for k in range(len(keep))]
    else:
        labels, inliers = _label_image_numpy(
            pt.valid, lab_cell, ids, mixed, bd, new_id, segmap, H, W
        )
    kept = count[keep]
    cn, cr = _canonical_planes(normal[keep], rho[keep])
    planes = [
        Plane(normal=cn[i], rho=float(cr[i]), centroid=mean[k], rms=float(rms[k]), count=int(n))
        for i, (k, n) in enumerate(zip(keep, kept, strict=True))
    ]
    outlines = _outlines(
        pt,
        labels,
        wholesale.reshape(hc, wc),
        segmap,
        bd.points,
        bd.point_region,
        new_id,
        planes,
        c,
        s.outline_cell,
        compiled,
    )
    segs = [
        PlaneSegment(
            plane=plane,
            inliers=inl_k,
            outline=ol,
            area=area,
        )
        for plane, inl_k, (ol, area) in zip(planes, inliers, outlines, strict=True)
    ]
    log.debug(
        "organised extraction: %d planar patches of %d, %d refined (%d pixel by pixel), %d planes",
        n_planar,
        hc * wc,
        len(ids),
        int(mixed.sum()),
        len(segs),
    )
    return ExtractionResult(tuple(segs), labels)


def _canonical_planes(
    normal: NDArray[np.float64], rho: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """:func:`navkit.geometry.fitting.canonical_plane` of every row ``(K, 3)``, ``(K,)`` at once, the
    same bits on every CPU (the same IEEE operations in the same order: three products and two
    sums, a square root, two divisions). A zero or non-finite normal or a plane
    through the origin (``_orient``'s special cases) takes ``canonical_plane`` row by row."""
    n0, n1, n2 = normal[:, 0], normal[:, 1], normal[:, 2]
    norm = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = rho / norm
    if not (np.all(np.isfinite(norm) & (norm > 0)) and np.all(r > 1e-12)):
        rows = [canonical_plane(n, float(d)) for n, d in zip(normal, rho, strict=True)]
        return np.array([n for n, _ in rows]).reshape(-1, 3), np.array([d for _, d in rows])
    return normal / norm[:, None], r
