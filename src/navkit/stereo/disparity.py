"""Dense disparity of a rectified pair with OpenCV, plus a left-right consistency check.

Stages: (1) grey images; (2) OpenCV's semi-global matcher (``StereoSGBM``, Hirschmueller 2008)
or block matcher (``StereoBM``) on the left image, which already refines each disparity to
1/16 pixel with a parabola through the matching costs (sub-pixel); (3) the right image's
disparity: by default (``lr_method="warp"``) the left disparity forward-warped to the right
view, each right pixel keeping the largest disparity that lands on it (the nearest surface: a
z-buffer, the uniqueness constraint), :func:`warp_right_disparity`; with ``lr_method="rematch"``
the same matcher run again on the mirrored pair (twice the time); (4) left-right consistency: a
left pixel whose disparity ``d`` disagrees by more than ``lr_max_diff`` with the right disparity
at ``x - d`` is an occlusion or a mismatch and becomes NaN; (5) optionally (``subpixel="lk"``)
the matcher's sub-pixel bias ("pixel locking") is estimated by a Lucas-Kanade refinement on the
images and removed (:func:`refine_subpixel`).

Why warping is the default (measured on Middlebury 2014 motorcycle Q, 80 disparities,
3 px window; ``benchmarks/stereo_check_options.py``, ``benchmarks/stereo_kernels_vs_numpy.py``):
the re-matched check costs a second SGBM run (2.2x one plain SGBM run in all); the warped one
costs one pass over the image (1.2x in all). A warped check rejects occluded pixels (a farther
surface hidden by a nearer one on the right view) and pixels that collide with a nearer match -
not isolated mismatches whose right pixel nothing else claims. Measured: bad-2.0 of the filled
map 8.26 % (re-matched) -> 6.10 % (warped; the re-match rejects more good pixels, which the
fill then gets wrong); without the fill 60.9 % -> 66.0 % of the scored pixels keep a disparity
and 3.07 % -> 3.51 % of those are off by more than 2 px.

OpenCV's own ``disp12MaxDiff`` is passed as ``-1`` ("off"), but SGBM (all three modes, OpenCV
5.0) gives the same map for -1, 0 and 1: its built-in check (right disparity from its own cost
volume) always runs at 1 px at least. That is the "no check" of the figures above (66.4 % kept,
3.70 % of them bad); the explicit check comes on top of it, the same for every matcher.

Disparity convention: ``d = x_left - x_right`` in pixels, ``> 0``; NaN = no valid match.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.domains import IMAGE_SIDE, Domain, domain_field
from navkit.errors import ConfigError, InputError
from navkit.geometry._validate import check_settings
from navkit.jit import kernels_enabled

__all__ = [
    "DisparityResult",
    "DisparitySettings",
    "bad_pixel_rate",
    "compute_disparity",
    "fill_background",
    "lr_consistency",
    "refine_subpixel",
    "warp_right_disparity",
]

log = logging.getLogger(__name__)

Matcher = Literal["sgbm", "sgbm3way", "hh", "bm"]
LRMethod = Literal["warp", "rematch"]

#: No disparity (nor window) exceeds the widest image navkit reads, pixels.
_MAX_DISPARITY = int(IMAGE_SIDE.hi or 100_000)  # pixels: the widest image navkit reads


@dataclass(frozen=True)
class DisparitySettings:
    """Stereo matcher settings (defaults tuned on Middlebury 2014 quarter-size images).

    Attributes
    ----------
    matcher : {"sgbm", "sgbm3way", "hh", "bm"}
        OpenCV SGBM (5 paths), SGBM 3-way, SGBM full 8-path ("hh") or block matching.
    min_disparity : int
        Pixels.
    num_disparities : int
        Search range in pixels, a positive multiple of 16.
    block_size : int
        Odd matching window (3..11 for SGBM, 5..51 for BM).
    p1, p2 : int or None
        SGBM smoothness penalties; None = ``8 * c * block^2`` and ``32 * c * block^2``
        (OpenCV's documented choice, ``c`` = channels = 1).
    uniqueness : int
        Percent margin the best cost must win by.
    speckle_window, speckle_range : int
        Speckle filter: blobs of fewer than ``speckle_window`` pixels varying by more than
        ``speckle_range`` pixels are removed (0 = off).
    pre_filter_cap : int
        Clamp of the prefiltered x-derivative.
    lr_check : bool
        Left-right consistency check.
    lr_method : {"warp", "rematch"}
        Where the check's right disparity comes from: ``"warp"`` (default) the left disparity
        forward-warped with a z-buffer (:func:`warp_right_disparity`, one pass, no second matcher
        run); ``"rematch"`` the matcher run again on the mirrored pair (twice the time, rejects
        also isolated mismatches: fewer pixels kept, slightly fewer of them wrong - see the
        module docstring for the figures).
    lr_max_diff : float
        Pixels; tolerance of the check.
    fill : {"none", "background"}
        ``"background"``: each invalid pixel takes the smaller of the nearest valid disparities
        to its left and right in the same row (occlusions belong to the farther surface) - the
        usual filling before scoring dense maps; the unfilled map stays in ``DisparityResult``.
    min_texture : float
        Grey levels; pixels whose ``block_size`` window has a standard deviation below this
        (blank sky, a white wall) get no disparity - smoothness alone would invent one there.
        0 = off.
    subpixel : {"parabola", "lk"}
        ``"parabola"``: OpenCV's own sub-pixel step (a parabola through the costs; biased
        toward integer disparities - "pixel locking", up to +-0.2 px on the simulated rooms);
        ``"lk"``: then :func:`refine_subpixel` estimates that bias with a 1D Lucas-Kanade
        refinement on the images and removes it (for metric measurements: wall maps,
        localization).
    subpixel_window : int
        Odd Lucas-Kanade window (pixels) of the ``"lk"`` correction.
    subpixel_smooth : int
        Odd window (pixels) over which the ``"lk"`` correction averages the bias.
    """

    matcher: Matcher = "sgbm"
    min_disparity: int = domain_field(
        0,
        Domain(
            integer=True,
            lo=-_MAX_DISPARITY,
            hi=_MAX_DISPARITY,
            note="pixels; negative when the rectification shifts the right image",
        ),
    )
    num_disparities: int = domain_field(
        128, Domain(integer=True, lo=16, hi=_MAX_DISPARITY, multiple_of=16, note="pixels")
    )
    block_size: int = domain_field(
        5, Domain(integer=True, lo=1, hi=51, note="pixels, odd; >= 5 for bm")
    )
    p1: int | None = domain_field(None, Domain(integer=True, lo=0, note="0 = OpenCV's default"))
    p2: int | None = domain_field(None, Domain(integer=True, lo=0, note="0 = OpenCV's default"))
    uniqueness: int = domain_field(10, Domain(integer=True, lo=0, hi=100, note="percent"))
    speckle_window: int = domain_field(100, Domain(integer=True, lo=0, note="pixels, 0 = off"))
    speckle_range: int = domain_field(2, Domain(integer=True, lo=0, note="pixels"))
    pre_filter_cap: int = domain_field(63, Domain(integer=True, lo=1, note="bm clamps it to 63"))
    lr_check: bool = True
    lr_method: LRMethod = "warp"
    lr_max_diff: float = domain_field(1.0, Domain(lo=0.0, note="pixels"))
    fill: Literal["none", "background"] = "none"
    min_texture: float = domain_field(2.0, Domain(lo=0.0, note="grey levels, 0 = off"))
    subpixel: Literal["parabola", "lk"] = "parabola"
    subpixel_window: int = domain_field(7, Domain(integer=True, lo=3, hi=31, note="pixels, odd"))
    subpixel_smooth: int = domain_field(
        15, Domain(integer=True, lo=0, hi=_MAX_DISPARITY, note="pixels, 0 = no averaging")
    )

    def __post_init__(self) -> None:
        check_settings(self)
        if self.matcher not in ("sgbm", "sgbm3way", "hh", "bm"):
            raise ConfigError(
                f"is {self.matcher!r}", field="matcher", expected="sgbm, sgbm3way, hh or bm"
            )
        # rules beyond the declared ranges: OpenCV's windows are odd, and its block matcher's
        # window is at least 5 pixels
        lo = 5 if self.matcher == "bm" else 1
        if self.block_size % 2 == 0 or self.block_size < lo:
            raise ConfigError(
                f"is {self.block_size}",
                field="block_size",
                expected=f"odd and in [{lo}, 51] for matcher {self.matcher!r}",
            )
        if self.subpixel_window % 2 == 0:
            raise ConfigError(
                f"is {self.subpixel_window}", field="subpixel_window", expected="odd, in [3, 31]"
            )
        if self.lr_method not in ("warp", "rematch"):
            raise ConfigError(
                f"is {self.lr_method!r}", field="lr_method", expected="warp or rematch"
            )
        if self.fill not in ("none", "background"):
            raise ConfigError(f"is {self.fill!r}", field="fill", expected="none or background")
        if self.subpixel not in ("parabola", "lk"):
            raise ConfigError(f"is {self.subpixel!r}", field="subpixel", expected="parabola or lk")


@dataclass(frozen=True)
class DisparityResult:
    """Disparity of the left image.

    Attributes
    ----------
    disparity : (H, W) float64
        Pixels; NaN where no valid / consistent match.
    raw : (H, W) float64
        The matcher's disparity before the left-right check (NaN where the matcher failed).
    checked : (H, W) float64
        After the left-right check, before filling (NaN = rejected).
    seconds : float
        Wall time of the matching (the matcher run(s), the check, the mask, the fill).
    """

    disparity: NDArray[np.float64]
    raw: NDArray[np.float64]
    checked: NDArray[np.float64]
    seconds: float

    @property
    def density(self) -> float:
        """Fraction of pixels with a valid disparity."""
        return float(np.isfinite(self.disparity).mean())


def _gray(img: ArrayLike, name: str) -> NDArray[np.uint8]:
    import cv2

    a = np.asarray(img)
    if a.ndim == 3 and a.shape[2] == 3:
        a = cv2.cvtColor(np.ascontiguousarray(a.astype(np.uint8)), cv2.COLOR_RGB2GRAY)
    elif a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.ndim != 2:
        raise InputError(
            f"has shape {a.shape}", field=name, expected="(H, W) grey or (H, W, 3) RGB image"
        )
    if a.dtype != np.uint8:
        if np.issubdtype(a.dtype, np.floating) and np.nanmax(a) <= 1.0:
            a = a * 255.0
        a = np.clip(np.nan_to_num(a), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(a)


def _matcher(s: DisparitySettings):  # type: ignore[no-untyped-def]
    import cv2

    if s.matcher == "bm":
        m = cv2.StereoBM_create(  # type: ignore[attr-defined]
            numDisparities=s.num_disparities, blockSize=s.block_size
        )
        m.setMinDisparity(s.min_disparity)
        m.setUniquenessRatio(s.uniqueness)
        m.setSpeckleWindowSize(s.speckle_window)
        m.setSpeckleRange(s.speckle_range)
        m.setPreFilterCap(min(s.pre_filter_cap, 63))
        m.setDisp12MaxDiff(-1)
        return m
    mode = {
        "sgbm": cv2.STEREO_SGBM_MODE_SGBM,
        "sgbm3way": cv2.STEREO_SGBM_MODE_SGBM_3WAY,
        "hh": cv2.STEREO_SGBM_MODE_HH,
    }[s.matcher]
    area = s.block_size**2
    return cv2.StereoSGBM_create(  # type: ignore[attr-defined]
        minDisparity=s.min_disparity,
        numDisparities=s.num_disparities,
        blockSize=s.block_size,
        P1=s.p1 if s.p1 is not None else 8 * area,
        P2=s.p2 if s.p2 is not None else 32 * area,
        disp12MaxDiff=-1,
        preFilterCap=s.pre_filter_cap,
        uniquenessRatio=s.uniqueness,
        speckleWindowSize=s.speckle_window,
        speckleRange=s.speckle_range,
        mode=mode,
    )


def _run(
    m, left: NDArray[np.uint8], right: NDArray[np.uint8], s: DisparitySettings
) -> NDArray[np.float64]:  # type: ignore[no-untyped-def]
    raw = m.compute(left, right).astype(np.float64) / 16.0  # fixed point, 4 fractional bits
    raw[raw < s.min_disparity] = np.nan  # OpenCV marks failures with min_disparity - 1
    return raw


def lr_consistency(
    disp_left: ArrayLike,
    disp_right: ArrayLike,
    max_diff: float = 1.0,
) -> NDArray[np.bool_]:
    """Pixels whose left disparity agrees with the right disparity at ``x - d`` (within ``max_diff``).

    Parameters
    ----------
    disp_left : (H, W) array
        Left disparity, pixels (NaN invalid).
    disp_right : (H, W) array
        Right disparity, pixels, positive, ``x_right + d = x_left`` (NaN invalid).

    One compiled pass (:func:`navkit.stereo._kernels.lr_consistency`, the same mask) when the
    process runs the kernels (:mod:`navkit.jit`); else the NumPy passes below (the oracle).
    """
    dl = np.asarray(disp_left, dtype=np.float64)
    dr = np.asarray(disp_right, dtype=np.float64)
    if kernels_enabled() and dl.ndim == 2 and dl.shape == dr.shape:
        from navkit.stereo import _kernels

        return _kernels.lr_consistency(  # type: ignore[no-any-return]
            np.ascontiguousarray(dl), np.ascontiguousarray(dr), float(max_diff)
        )
    H, W = dl.shape
    x = np.arange(W)[None, :]
    xr = np.rint(x - np.nan_to_num(dl, nan=-1e9)).astype(np.int64)
    inside = np.isfinite(dl) & (xr >= 0) & (xr < W)
    rows = np.broadcast_to(np.arange(H)[:, None], (H, W))
    other = np.full((H, W), np.nan)
    other[inside] = dr[rows[inside], xr[inside]]
    return inside & (np.abs(other - dl) <= max_diff)


def warp_right_disparity(disp_left: ArrayLike) -> NDArray[np.float64]:
    """The right view's disparity from the left one by forward warping (uniqueness by z-buffer).

    Every finite left disparity ``d`` at pixel ``x`` lands on the right pixel ``rint(x - d)``
    (``x_right = x_left - d``); a right pixel reached by several left pixels keeps the largest
    disparity (the nearest surface hides the others: the uniqueness constraint), a right pixel
    reached by none is NaN (occluded in the left view, or no match). With
    :func:`lr_consistency` this rejects left pixels that lose their right pixel to a nearer
    surface (occlusions, colliding mismatches) without running the matcher a second time.

    One compiled pass (:func:`navkit.stereo._kernels.warp_right`, the same map) when the process
    runs the kernels (:mod:`navkit.jit`); else the NumPy passes below (the oracle).

    Parameters
    ----------
    disp_left : (H, W) array
        Left disparity, pixels (NaN / inf invalid).

    Returns
    -------
    (H, W) float64
        Right disparity, pixels, positive, ``x_right + d = x_left``; NaN where nothing lands.
    """
    dl = np.asarray(disp_left, dtype=np.float64)
    if dl.ndim != 2:
        raise InputError(f"has shape {dl.shape}", field="disp_left", expected="an (H, W) map")
    if kernels_enabled():
        from navkit.stereo import _kernels

        return _kernels.warp_right(np.ascontiguousarray(dl))  # type: ignore[no-any-return]
    H, W = dl.shape
    finite = np.isfinite(dl)
    xr = np.rint(np.arange(W)[None, :] - np.where(finite, dl, -1e9))
    inside = finite & (xr >= 0) & (xr < W)
    rows = np.broadcast_to(np.arange(H)[:, None], (H, W))
    flat = rows[inside] * W + xr[inside].astype(np.int64)
    out = np.full(H * W, -np.inf)
    np.maximum.at(out, flat, dl[inside])
    out[out == -np.inf] = np.nan
    return out.reshape(H, W)


def refine_subpixel(
    left: ArrayLike,
    right: ArrayLike,
    disparity: ArrayLike,
    *,
    window: int = 7,
    smooth: int = 15,
    iterations: int = 3,
    max_change: float = 1.0,
) -> NDArray[np.float64]:
    """Remove the matcher's sub-pixel bias ("pixel locking") with a Lucas-Kanade estimate.

    A matcher's parabola through three integer costs is biased toward integer disparities
    (Shimizu & Okutomi 2005): on a wall seen head-on every pixel has about the same fractional
    disparity, so the bias does not average out (+-0.2 px on the simulated rooms, i.e. +-7 cm
    at 3.5 m for a ``b f = 32`` px m rig).

    1. Each disparity is refined by Gauss-Newton on the brightness constancy
       ``I_L(x, y) = I_R(x - d, y)`` summed over a ``window`` square (Lucas & Kanade 1981,
       one unknown)::

           d_LK <- d_LK + sum_W G (I_R(x - d_LK) - I_L) / sum_W G^2,   G = dI_R/dx at x - d_LK

       with the right image and its Sobel gradient resampled bilinearly at ``x - d_LK(x)``
       (OpenCV ``remap``), steps clipped to +-0.5 px. ``d_LK`` is unbiased but noisier than
       the matcher on smooth textures.
    2. The bias varies slowly over the image (with the fractional disparity), so it is
       estimated as the mean of ``d - d_LK`` over a ``smooth`` square and subtracted:
       ``d_out = d - mean_smooth(d - d_LK)`` keeps the matcher's low noise without its bias
       (``smooth = 0``: return ``d_LK`` itself). Measured on the simulated rooms: bias per
       fractional disparity from +-0.2 to +-0.04 px, robust spread 0.20 -> 0.09 px
       (``docs/benchmarks/rooms.md``).

    Vectorised over the image.

    Parameters
    ----------
    left, right : (H, W) arrays
        Grey rectified images.
    disparity : (H, W) array
        Start disparity, pixels (NaN invalid, kept NaN).
    window : int
        Odd Lucas-Kanade window, pixels.
    smooth : int
        Odd window of the bias average, pixels (0 = no averaging).
    iterations : int
        Gauss-Newton steps.
    max_change : float
        Pixels; pixels moved farther than this from the start (a window straddling a depth
        edge, no texture) become NaN.

    Returns
    -------
    (H, W) array
        Refined disparity, pixels.
    """
    import cv2

    Lf = np.asarray(left, dtype=np.float32)
    Rf = np.asarray(right, dtype=np.float32)
    d0 = np.asarray(disparity, dtype=np.float64)
    if Lf.shape != Rf.shape or Lf.shape != d0.shape or Lf.ndim != 2:
        raise InputError(
            f"left {Lf.shape}, right {Rf.shape}, disparity {d0.shape}",
            field="disparity",
            expected="grey images and a disparity of the same (H, W) shape",
        )
    H, W = Lf.shape
    gx = cv2.Sobel(Rf, cv2.CV_32F, 1, 0, ksize=3, scale=1.0 / 8.0)
    xs, ys = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
    valid = np.isfinite(d0)
    d = np.where(valid, d0, 0.0).astype(np.float32)
    k = (window, window)
    for _ in range(iterations):
        mx = xs - d
        warped = cv2.remap(Rf, mx, ys, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
        G = cv2.remap(gx, mx, ys, cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
        num = cv2.boxFilter(G * (warped - Lf), -1, k, normalize=False)
        den = cv2.boxFilter(G * G, -1, k, normalize=False)
        step = np.where(den > 1e-3, num / np.maximum(den, 1e-3), 0.0)
        d = d + np.clip(step, -0.5, 0.5).astype(np.float32)
    out = np.where(valid, d.astype(np.float64), np.nan)
    out[np.abs(out - d0) > max_change] = np.nan
    if smooth <= 1:
        return out
    diff = d0 - out
    v = np.isfinite(diff)
    ks = (smooth, smooth)
    num = cv2.boxFilter(np.where(v, diff, 0.0).astype(np.float32), -1, ks, normalize=False)
    cnt = cv2.boxFilter(v.astype(np.float32), -1, ks, normalize=False)
    bias = np.where(cnt > 0, num / np.maximum(cnt, 1.0), 0.0)
    return np.where(valid, d0 - bias, np.nan)


def fill_background(disparity: ArrayLike) -> NDArray[np.float64]:
    """Fill NaN pixels with the smaller of the nearest valid disparities left and right in the row.

    Rows without any valid pixel stay NaN. One pass per row
    (:func:`navkit.stereo._kernels.fill_background`, the same result) when the process runs the
    kernels (:mod:`navkit.jit`); else vectorised with running maxima of valid indices (the
    oracle).
    """
    d = np.asarray(disparity, dtype=np.float64)
    if kernels_enabled() and d.ndim == 2:
        from navkit.stereo import _kernels

        return _kernels.fill_background(np.ascontiguousarray(d))  # type: ignore[no-any-return]
    H, W = d.shape
    valid = np.isfinite(d)
    idx = np.where(valid, np.arange(W)[None, :], -1)
    left = np.maximum.accumulate(idx, axis=1)
    idx_r = np.where(valid, np.arange(W)[None, :], W)
    right = np.minimum.accumulate(idx_r[:, ::-1], axis=1)[:, ::-1]
    rows = np.arange(H)[:, None]
    pad = np.concatenate([d, np.full((H, 1), np.nan)], axis=1)  # index W and -1 -> NaN
    dl = pad[rows, np.where(left >= 0, left, W)]
    dr = pad[rows, np.where(right < W, right, W)]
    filled = np.fmin(dl, dr)
    return np.where(valid, d, filled)


def compute_disparity(
    left: ArrayLike, right: ArrayLike, settings: DisparitySettings | None = None
) -> DisparityResult:
    """Disparity of the left image of a rectified pair.

    Parameters
    ----------
    left, right : (H, W) or (H, W, 3) arrays
        Rectified images (uint8, or float in [0, 1]); RGB is converted to grey.
    settings : DisparitySettings, optional

    Returns
    -------
    DisparityResult
    """
    s = settings or DisparitySettings()
    L = _gray(left, "left")
    R = _gray(right, "right")
    if L.shape != R.shape:
        raise InputError(
            f"left {L.shape} and right {R.shape} differ",
            field="right",
            expected="images of the same size (a rectified pair)",
        )
    if L.shape[1] <= s.num_disparities + s.min_disparity:
        raise ConfigError(
            f"{s.num_disparities} for an image {L.shape[1]} px wide",
            field="num_disparities",
            expected="fewer disparities than the image width",
        )
    t0 = time.perf_counter()
    m = _matcher(s)
    raw = _run(m, L, R, s)
    disp = raw.copy()
    if s.lr_check:
        if s.lr_method == "rematch":
            # the right view's disparity: match the mirrored pair (right becomes the reference)
            mirrored = _run(
                m, np.ascontiguousarray(R[:, ::-1]), np.ascontiguousarray(L[:, ::-1]), s
            )
            right_disp = mirrored[:, ::-1]
        else:
            right_disp = warp_right_disparity(raw)
        disp[~lr_consistency(raw, right_disp, s.lr_max_diff)] = np.nan
    if s.min_texture > 0:
        import cv2

        g = L.astype(np.float64)
        k = (s.block_size, s.block_size)
        var = cv2.blur(g * g, k) - cv2.blur(g, k) ** 2
        disp[var < s.min_texture**2] = np.nan
    if s.subpixel == "lk":
        disp = refine_subpixel(L, R, disp, window=s.subpixel_window, smooth=s.subpixel_smooth)
    checked = disp.copy()
    if s.fill == "background":
        disp = fill_background(disp)
    dt = time.perf_counter() - t0
    log.debug(
        "%s disparity: %.1f%% valid, %.1f ms", s.matcher, 100 * np.isfinite(disp).mean(), 1e3 * dt
    )
    return DisparityResult(disparity=disp, raw=raw, checked=checked, seconds=dt)


def bad_pixel_rate(
    disparity: ArrayLike, ground_truth: ArrayLike, threshold: float, mask: ArrayLike | None = None
) -> tuple[float, float]:
    """Middlebury's bad-``threshold`` figure.

    Parameters
    ----------
    disparity : (H, W) array
        Estimate, NaN = no estimate.
    ground_truth : (H, W) array
        Truth; non-finite = unknown (not scored).
    threshold : float
        Pixels (2.0 for bad-2.0 at the quarter size the data are stored at...).
    mask : (H, W) bool array, optional
        Pixels to score (e.g. non-occluded).

    Returns
    -------
    bad_all : float
        Percent of scored pixels with ``|d - gt| > threshold`` *or no estimate* (Middlebury's
        convention: invalid estimates count as bad).
    bad_valid : float
        Percent among scored pixels that do have an estimate.
    """
    d = np.asarray(disparity, dtype=np.float64)
    g = np.asarray(ground_truth, dtype=np.float64)
    if d.shape != g.shape:
        raise InputError(
            f"disparity {d.shape} vs ground truth {g.shape}",
            field="ground_truth",
            expected="the same shape as the disparity",
        )
    scored = np.isfinite(g)
    if mask is not None:
        scored &= np.asarray(mask, dtype=bool)
    if not scored.any():
        raise InputError(
            "no pixel to score", field="ground_truth", expected="finite ground truth under the mask"
        )
    err = np.abs(d - g)
    has = np.isfinite(d) & scored
    bad = scored & (~np.isfinite(d) | (err > threshold))
    bad_valid = float(100.0 * (has & (err > threshold)).sum() / max(has.sum(), 1))
    return float(100.0 * bad.sum() / scored.sum()), bad_valid
