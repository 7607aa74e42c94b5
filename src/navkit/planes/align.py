"""Texture matching in the plane: the paper's functionals D(mu, eta, lambda) (eq. 4) and D(mu) (eq. 7).

Both textures of a plane are images on lattices in one 2D frame (see :mod:`navkit.planes.texture`).
Brightness is normalised per texture (zero mean, unit standard deviation over its valid pixels)
before comparing, so a change of exposure between the two frames does not bias D - a decision
the paper leaves open. D is the mean absolute brightness difference over the pixels valid in
both textures (eq. 4 with ``c_ij`` = both valid).

- :func:`search_1d` (two planes): exhaustive search of the shift ``mu`` at pixel resolution over
  the allowed range, then a sub-pixel parabola through the minimum and its two neighbours (eq. 7).
- :func:`search_2d` (one plane): a coarse *global* stage - for a grid of turns ``lambda`` the
  rotated second texture is matched to the first by masked normalised cross-correlation over all
  translations at once (FFT, Padfield 2012) - then a local Nelder-Mead refinement of eq. 4 from
  the best few coarse candidates, so large shifts do not need a good initial guess.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy import fft as sfft
from scipy import optimize

from navkit.planes.texture import PlaneTexture

__all__ = ["Search1D", "Search2D", "masked_ncc", "normalized", "search_1d", "search_2d"]

log = logging.getLogger(__name__)


def normalized(tex: PlaneTexture) -> NDArray[np.float32]:
    """Brightness with zero mean and unit std over the valid pixels (0 elsewhere)."""
    v = tex.image[tex.mask]
    if len(v) < 2:
        return np.zeros(tex.image.shape, np.float32)
    sd = float(np.std(v))
    out = (tex.image - float(np.mean(v))) / max(sd, 1e-6)
    return np.where(tex.mask, out, 0.0).astype(np.float32)


# ----------------------------------------------------------------------------------------------
# 1D search (two planes, eq. 7)


@dataclass(frozen=True)
class Search1D:
    """Result of :func:`search_1d`.

    Attributes
    ----------
    shift : float
        ``mu`` in texture pixels (sub-pixel); multiply by ``nu`` for metres. NaN if no overlap.
    shifts : (S,) int array
        The integer shifts tried.
    D : (S,) array
        Functional per shift (NaN where the overlap was too small).
    overlap : int
        Pixels compared at the best integer shift.
    distinctness : float
        ``(median(D) - min(D)) / median(D)``: 0 for a flat functional (uniform texture).
    """

    shift: float
    shifts: NDArray[np.int64]
    D: NDArray[np.float64]
    overlap: int
    distinctness: float


def search_1d(
    pairs: list[tuple[PlaneTexture, PlaneTexture]], max_shift: int, min_overlap: int = 200
) -> Search1D:
    """Minimise ``D(mu)`` (eq. 7): texture 2 pixel ``(a, b)`` lies on texture 1 pixel ``(a + mu, b)``.

    Parameters
    ----------
    pairs : list of (PlaneTexture, PlaneTexture)
        Frame-1 and frame-2 textures of each plane, on a common lattice (same ``ref``, ``nu``
        and axes after the known rotation), columns along the search direction.
    max_shift : int
        Search ``mu`` in ``[-max_shift, max_shift]`` texture pixels.
    min_overlap : int
        Fewest compared pixels for a shift to count.
    """
    shifts = np.arange(-max_shift, max_shift + 1)
    num = np.zeros(len(shifts))
    den = np.zeros(len(shifts))
    for t1, t2 in pairs:
        e1, e2 = normalized(t1), normalized(t2)
        m1, m2 = t1.mask, t2.mask
        # common rows (lattice index j)
        b_lo = max(t1.index0[1], t2.index0[1])
        b_hi = min(t1.index0[1] + e1.shape[0], t2.index0[1] + e2.shape[0])
        if b_hi <= b_lo:
            continue
        r1 = slice(b_lo - t1.index0[1], b_hi - t1.index0[1])
        r2 = slice(b_lo - t2.index0[1], b_hi - t2.index0[1])
        E1, M1, E2, M2 = e1[r1], m1[r1], e2[r2], m2[r2]
        A1, A2, w1, w2 = int(t1.index0[0]), int(t2.index0[0]), E1.shape[1], E2.shape[1]
        for k, s in enumerate(shifts.tolist()):
            lo = max(A2, A1 - s)
            hi = min(A2 + w2, A1 + w1 - s)
            if hi <= lo:
                continue
            c2 = slice(lo - A2, hi - A2)
            c1 = slice(lo + s - A1, hi + s - A1)
            m = M1[:, c1] & M2[:, c2]
            num[k] += float(np.abs(E1[:, c1] - E2[:, c2])[m].sum())
            den[k] += float(m.sum())
    with np.errstate(invalid="ignore", divide="ignore"):
        D = np.where(den >= min_overlap, num / den, np.nan)
    if not np.any(np.isfinite(D)):
        return Search1D(float("nan"), shifts, D, 0, 0.0)
    k = int(np.nanargmin(D))
    shift = float(shifts[k])
    if 0 < k < len(D) - 1 and np.isfinite(D[k - 1]) and np.isfinite(D[k + 1]):
        a, b, c = D[k - 1], D[k], D[k + 1]
        curv = a - 2 * b + c
        if curv > 0:
            shift += float(np.clip(0.5 * (a - c) / curv, -0.5, 0.5))
    med = float(np.nanmedian(D))
    distinct = (med - float(D[k])) / med if med > 0 else 0.0
    return Search1D(shift, shifts, D, int(den[k]), distinct)


# ----------------------------------------------------------------------------------------------
# 2D search (one plane, eq. 4)


def masked_ncc(fixed, fmask, moving, mmask, min_overlap: int, fixed_spectra=None):
    """Masked normalised cross-correlation for every integer shift (Padfield 2012).

    Returns ``(ncc, offset)``: ``ncc[n]`` compares ``fixed[x]`` with ``moving[x - k]`` for the
    shift ``k = n - offset``; NaN where fewer than ``min_overlap`` pixels overlap.
    ``fixed_spectra``: a dict kept by a caller that correlates the same ``fixed`` / ``fmask``
    with many ``moving`` images (the turns of :func:`search_2d`): the fixed image's three
    spectra per transform size, computed once (the same arrays).
    """
    fm = fmask.astype(np.float64)
    mm = mmask[::-1, ::-1].astype(np.float64)
    F = np.where(fmask, fixed, 0.0)
    M = np.where(mmask, moving, 0.0)[::-1, ::-1]
    shape = [
        sfft.next_fast_len(a + b - 1, real=True) for a, b in zip(F.shape, M.shape, strict=True)
    ]
    out = tuple(a + b - 1 for a, b in zip(F.shape, M.shape, strict=True))

    def spec(a):
        return sfft.rfft2(a, shape)

    def conv(A, B):
        return sfft.irfft2(A * B, shape)[: out[0], : out[1]]

    key = tuple(shape)
    if fixed_spectra is not None and key in fixed_spectra:
        sf, sff, sfm = fixed_spectra[key]
    else:
        sf, sff, sfm = spec(F), spec(F * F), spec(fm)
        if fixed_spectra is not None:
            fixed_spectra[key] = (sf, sff, sfm)
    sm, smm, smk = spec(M), spec(M * M), spec(mm)
    N = np.rint(conv(sfm, smk))
    sF, sM = conv(sf, smk), conv(sfm, sm)
    sFF, sMM, sFM = conv(sff, smk), conv(sfm, smm), conv(sf, sm)
    with np.errstate(invalid="ignore", divide="ignore"):
        num = sFM - sF * sM / N
        den = np.sqrt(np.maximum(sFF - sF**2 / N, 0) * np.maximum(sMM - sM**2 / N, 0))
        ncc = np.where((N >= min_overlap) & (den > 1e-9 * np.maximum(N, 1)), num / den, np.nan)
    return ncc, np.array([M.shape[0] - 1, M.shape[1] - 1])


def _rot(lam: float) -> NDArray[np.float64]:
    c, s = np.cos(lam), np.sin(lam)
    return np.array([[c, -s], [s, c]])


def _resample(tex: PlaneTexture, img: NDArray[np.float32], lam: float, delta: float):
    """Texture turned by ``lam`` on a lattice of step ``delta`` metres: value at metric ``p`` is
    ``tex(Rot(-lam) p)``. Returns (image, mask, lattice index0 (j, i) order rows/cols)."""
    h, w = img.shape
    nu = tex.nu
    corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], float)
    corners = (corners + tex.index0) * nu @ _rot(lam).T
    lo = np.floor(corners.min(0) / delta).astype(np.int64) - 1
    hi = np.ceil(corners.max(0) / delta).astype(np.int64) + 1
    ai = np.arange(lo[0], hi[0] + 1) * delta
    aj = np.arange(lo[1], hi[1] + 1) * delta
    P = np.stack(np.meshgrid(ai, aj), axis=-1)  # (H', W', 2) metric (u, v)
    c, s = np.cos(lam), np.sin(lam)  # Q = Rot(-lam) p, written out (no BLAS on thin arrays)
    Q = np.stack([c * P[..., 0] + s * P[..., 1], -s * P[..., 0] + c * P[..., 1]], axis=-1)
    mx = (Q[..., 0] / nu - tex.index0[0]).astype(np.float32)
    my = (Q[..., 1] / nu - tex.index0[1]).astype(np.float32)
    out = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    msk = cv2.remap(
        tex.mask.astype(np.float32),
        mx,
        my,
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0,
    )
    return out, msk > 0.999, lo


def _smooth(img: NDArray[np.float32], mask: NDArray[np.bool_], sigma: float) -> NDArray[np.float32]:
    """Mask-normalised Gaussian blur (anti-aliasing before coarse resampling)."""
    if sigma <= 0.3:
        return img
    m = mask.astype(np.float32)
    a = cv2.GaussianBlur(img * m, (0, 0), sigma)
    b = cv2.GaussianBlur(m, (0, 0), sigma)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(b > 1e-3, a / b, 0.0).astype(np.float32)


@dataclass(frozen=True)
class Search2D:
    """Result of :func:`search_2d`: ``tex1(Rot(lam) q + t) ~ tex2(q)`` in metric plane coordinates.

    Attributes
    ----------
    lam : float
        Turn lambda, radians (counter-clockwise from axis u to axis v).
    t : (2,) array
        In-plane shift ``(mu, eta)``, metres.
    D : float
        Eq. 4 at the solution (normalised brightness units).
    overlap : int
        Pixels compared at the solution.
    peak : float
        Best coarse normalised cross-correlation (1 = perfect, ~0 = no match).
    candidates : int
        Coarse candidates refined.
    distinctness : float
        ``(D2 - D1) / D2``: how much better the best refined basin is than the best *other*
        one (another turn or shift), on the sparse subsample; NaN with a single candidate.
        Near 0 = two basins explain the textures equally well (ambiguous texture).
    """

    lam: float
    t: NDArray[np.float64]
    D: float
    overlap: int
    peak: float
    candidates: int
    distinctness: float = float("nan")


_NO_OVERLAP = 1e3
"""D where the textures do not overlap enough (finite, so the simplex search stays well defined;
normalised textures give D ~ 1 at worst)."""


def _remap_points(img, x, y):
    """Bilinear samples of ``img`` at float pixel coordinates ``x, y`` ``(n,)`` (0 outside)."""
    n = len(x)
    cols = 256
    pad = (-n) % cols
    mx = np.concatenate([x, np.full(pad, -1e6)]).astype(np.float32).reshape(-1, cols)
    my = np.concatenate([y, np.full(pad, -1e6)]).astype(np.float32).reshape(-1, cols)
    out = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return out.reshape(-1, *img.shape[2:])[:n]


def _D(em1, t1: PlaneTexture, e2v, q2, lam, t, min_overlap):
    """Eq. 4 for texture-2 samples ``e2v`` at metric points ``q2`` ``(n, 2)``; ``em1`` is texture
    1's normalised brightness and validity as one 2-channel image (one bilinear lookup)."""
    return _Eq4(em1, t1, e2v, q2)(lam, t, min_overlap)


class _Eq4:
    """:func:`_D` for fixed textures and samples, evaluated many times (the simplex search):
    the sample coordinates, the padded float32 maps and the lookup's output are prepared once.
    The same operations in the same order as :func:`_remap_points` on fresh arrays, so the same
    values bit for bit."""

    _COLS = 256

    def __init__(self, em1, t1: PlaneTexture, e2v, q2) -> None:
        n = len(q2)
        rows = -(-n // self._COLS)
        self.em1, self.nu, self.i0, self.e2v, self.n = em1, t1.nu, t1.index0, e2v, n
        self.qx, self.qy = np.ascontiguousarray(q2[:, 0]), np.ascontiguousarray(q2[:, 1])
        self.mx = np.full((rows, self._COLS), -1e6, np.float32)
        self.my = np.full((rows, self._COLS), -1e6, np.float32)
        self.a, self.b = np.empty(n), np.empty(n)

    def __call__(self, lam, t, min_overlap):
        c, s = np.cos(lam), np.sin(lam)
        a, b, n = self.a, self.b, self.n
        # x = (c qx - s qy + t0) / nu - i0 and y = (s qx + c qy + t1) / nu - i1, as _D wrote them
        np.multiply(c, self.qx, out=a)
        np.multiply(s, self.qy, out=b)
        np.subtract(a, b, out=a)
        np.add(a, t[0], out=a)
        np.divide(a, self.nu, out=a)
        np.subtract(a, self.i0[0], out=a)
        self.mx.reshape(-1)[:n] = a
        np.multiply(s, self.qx, out=a)
        np.multiply(c, self.qy, out=b)
        np.add(a, b, out=a)
        np.add(a, t[1], out=a)
        np.divide(a, self.nu, out=a)
        np.subtract(a, self.i0[1], out=a)
        self.my.reshape(-1)[:n] = a
        out = cv2.remap(
            self.em1, self.mx, self.my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
            borderValue=0,
        )  # fmt: skip
        EM = out.reshape(-1, 2)[:n]
        M = EM[:, 1] > 0.999
        k = int(M.sum())
        if k < min_overlap:
            return _NO_OVERLAP, k
        return float(np.abs(EM[M, 0] - self.e2v[M]).mean()), k


def search_2d(
    t1: PlaneTexture,
    t2: PlaneTexture,
    *,
    max_angle: float = np.radians(90.0),
    max_shift: float = 1.0,
    coarse_pixels: int = 64,
    min_overlap: int = 400,
    min_fraction: float = 0.2,
    candidates: int = 3,
) -> Search2D:
    """Global minimum of ``D(mu, eta, lambda)`` (eq. 4) over turns ``|lambda| <= max_angle`` and
    shifts ``|mu|, |eta| <= max_shift`` metres. Overlaps smaller than ``min_overlap`` pixels or
    than ``min_fraction`` of the smaller texture do not count.

    Coarse stage: both textures blurred and resampled at ``delta`` (the longer texture side
    divided by ``coarse_pixels``); for each turn on a grid of step ``delta / radius`` the masked
    NCC over all shifts picks the best shift. Fine stage: Nelder-Mead on eq. 4 at full
    resolution from the ``candidates`` best coarse (turn, shift) pairs.
    """
    e1, e2 = normalized(t1), normalized(t2)
    nu = t1.nu
    size = max(*t1.image.shape, *t2.image.shape) * nu
    delta = max(nu, size / coarse_pixels)
    f = delta / nu
    c1 = _smooth(e1, t1.mask, 0.5 * f)
    c2 = _smooth(e2, t2.mask, 0.5 * f)
    F, Fm, oF = _resample(t1, c1, 0.0, delta)
    # the turn step: one coarse pixel at the textures' radius
    radius = 0.5 * size
    step = float(np.clip(delta / radius, np.radians(0.25), np.radians(5.0)))
    lams = np.arange(-max_angle, max_angle + 0.5 * step, step) if max_angle > 0 else np.zeros(1)
    kmax = max_shift / delta
    # a match must cover a good part of the smaller texture: tiny overlaps correlate by chance
    min_ov = max(
        16, int(min_overlap / f**2), int(min_fraction * min(Fm.sum(), t2.valid_count / f**2))
    )
    found = []
    spectra: dict[tuple[int, ...], tuple[Any, Any, Any]] = {}  # F's, per transform size
    for lam in lams:
        G, Gm, oG = _resample(t2, c2, float(lam), delta)
        ncc, off = masked_ncc(F, Fm, G, Gm, min_ov, spectra)
        # shift in metres: (k + oF - oG) * delta, k = index - off (rows j, cols i)
        kj = np.arange(ncc.shape[0]) - off[0] + oF[1] - oG[1]
        ki = np.arange(ncc.shape[1]) - off[1] + oF[0] - oG[0]
        win = (np.abs(kj)[:, None] <= kmax) & (np.abs(ki)[None, :] <= kmax)
        ncc = np.where(win, ncc, np.nan)
        if not np.any(np.isfinite(ncc)):
            continue
        n = int(np.nanargmax(ncc))
        r, c = divmod(n, ncc.shape[1])
        found.append((float(ncc[r, c]), float(lam), np.array([ki[c], kj[r]]) * delta))
    if not found:
        return Search2D(float("nan"), np.full(2, np.nan), float("nan"), 0, float("nan"), 0)
    found.sort(key=lambda x: -x[0])
    # keep distinct candidates (different turn or shift)
    picks: list[tuple[float, float, NDArray[np.float64]]] = []
    for cand in found:
        if all(
            abs(cand[1] - p[1]) > 1.5 * step or np.linalg.norm(cand[2] - p[2]) > 2 * delta
            for p in picks
        ):
            picks.append(cand)
        if len(picks) >= candidates:
            break
    # fine stage on eq. 4
    jj, ii = np.nonzero(t2.mask)
    q2 = np.stack([ii + t2.index0[0], jj + t2.index0[1]], axis=1) * nu
    e2v = e2[jj, ii]
    if len(q2) > 30_000:  # a regular subsample keeps the cost bounded on huge textures
        sel = np.arange(0, len(q2), len(q2) // 30_000 + 1)
        q2, e2v = q2[sel], e2v[sel]
    em1 = np.dstack([e1, t1.mask.astype(np.float32)])
    scale = np.array([radius, 1.0, 1.0])  # optimise (lam * radius, tx, ty) in metres
    min_fine = max(min_overlap, int(min_fraction * min(t1.valid_count, len(q2))))
    # candidates are refined on a sparse subsample first, the winner then on all samples
    sub = slice(None, None, max(1, len(q2) // 6000))

    eq4_sub, eq4 = _Eq4(em1, t1, e2v[sub], q2[sub]), _Eq4(em1, t1, e2v, q2)

    def cost_sub(x):
        return eq4_sub(x[0] / radius, x[1:], min_fine // max(1, len(q2) // 6000))[0]

    def cost(x):
        return eq4(x[0] / radius, x[1:], min_fine)[0]

    def nelder_mead(fun, x0, step, xatol):
        simplex = x0 + np.vstack([np.zeros(3), np.eye(3) * step])
        return optimize.minimize(
            fun,
            x0,
            method="Nelder-Mead",
            options={"initial_simplex": simplex, "xatol": xatol, "fatol": 1e-5, "maxiter": 300},
        )

    def bounded(fun, x0, r):
        """``fun`` inside the box ``|x - x0| <= r`` (metres; the turn as arc at the radius),
        the no-overlap value outside: the fine stage refines *within* the coarse candidate's
        cell and cannot wander into another basin of eq. 4 (on a low-contrast real floor it
        otherwise slid 40 cm / 11 deg away from a coarse candidate 2 cm from the truth)."""
        return lambda x: _NO_OVERLAP if np.max(np.abs(x - x0)) > r else fun(x)

    best = None
    basins: list[tuple[float, NDArray[np.float64]]] = []
    for peak, lam0, tt in picks:
        x0 = np.array([lam0, *tt]) * scale
        # coarse uncertainty: half a coarse pixel of shift, half a turn step (one coarse pixel
        # at the radius), plus the blur: 1.5 coarse pixels
        res = nelder_mead(bounded(cost_sub, x0, 1.5 * delta), x0, delta, 0.2 * nu)
        basins.append((float(res.fun), res.x))
        if best is None or res.fun < best[0]:
            best = (float(res.fun), res.x, peak)
    assert best is not None
    # the best other basin: a refined candidate that did not converge to the winner
    others = [f for f, x in basins if np.linalg.norm(x - best[1]) > 2 * delta]
    distinct = float("nan")
    if others and min(others) < _NO_OVERLAP and best[0] < _NO_OVERLAP:
        distinct = (min(others) - best[0]) / max(min(others), 1e-12)
    res = nelder_mead(bounded(cost, best[1], delta), best[1], 2 * nu, 0.05 * nu)
    lam, tx, ty = res.x / scale
    D, n = eq4(lam, np.array([tx, ty]), min_fine)
    if D >= _NO_OVERLAP:
        D = float("nan")
    return Search2D(float(lam), np.array([tx, ty]), D, n, float(picks[0][0]), len(picks), distinct)
