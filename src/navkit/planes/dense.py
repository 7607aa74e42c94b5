"""Dense photometric + geometric alignment of two RGB-D frames (the last millimetres).

The planes give a motion that is robust to large displacements but limited by the planes' own
noise (a Kinect wall's normal differs by 1-5 deg between frames). This module refines such a
motion with the data the planes do not use: every pixel with depth. It minimises, over the
motion ``T_1_2`` (frame 2 -> frame 1), the sum of

- a **geometric** residual: point-to-plane distance of frame 2's point moved into frame 1 to
  frame 1's surface at the pixel it projects to (projective association, as KinectFusion /
  Open3D's point-to-plane ICP), ``r_G = n_1 . (R x_2 + t - X_1(pi(R x_2 + t)))``;
- a **photometric** residual: brightness difference ``r_I = I_1(pi(R x_2 + t)) - I_2(x_2)``
  (Kerl, Sturm, Cremers 2013; Open3D's hybrid term, Park et al. 2017),

each divided by its robust scale (1.4826 x MAD of the residuals at the current level) and
weighted by Huber's function, by Gauss-Newton on an image pyramid (coarse to fine). The
perturbation is applied on the left: ``T <- exp(xi) T`` with ``xi = (v, w)`` in frame 1.

Decisions
---------
- Levels: 1/8, 1/4 and 1/2 of the input resolution (80 x 60 ... 320 x 240 for a 640 x 480
  Kinect frame); full resolution adds CPU, not accuracy, on the 7-Scenes frames (measured:
  ``python -m benchmarks planes_seq``).
- Brightness is resampled by ``cv2.pyrDown``; depth by the same Gaussian over the valid depths
  that agree with the centre pixel (:func:`_depth_down`: noise averaged on surfaces, no
  mixing of foreground and background at edges). Both are centred on the even pixels, so a
  level's principal point is ``c / 2**l``.
- Every threshold is in the sensor's noise units (:mod:`navkit.planes.noise`): the geometric
  residual of a point at depth ``z`` is divided by ``sqrt(2) sigma_z(z)`` (``sigma_z = k z^2``,
  Kinect-type depth), the brightness residual by the images' own brightness noise
  (:func:`~navkit.planes.noise.brightness_sigma`). No depth window: far points count less
  (``1 / sigma_z^2``), they are not cut, so a scene at 6 m is aligned like one at 1.5 m.
- Correspondences whose depths disagree by more than ``max_depth_diff_sigmas`` sigma_z
  (doubled per level) are outliers of both terms (occlusions, moving objects).
- Which degree of freedom each term fixed is reported (:attr:`DenseResult.dof_sources`): the
  marginal information ``1 / (H^-1)_kk`` of each term alone about each axis of ``xi``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from navkit.domains import (
    NON_NEGATIVE,
    NON_NEGATIVE_INT,
    POSITIVE,
    POSITIVE_INT,
    Domain,
    domain_field,
)
from navkit.errors import ConfigError
from navkit.geometry._validate import check_settings
from navkit.jit import kernels_enabled
from navkit.planes.noise import DepthNoise, brightness_sigma
from navkit.sensors import PinholeCamera

__all__ = [
    "DENSE_DOF",
    "DenseFrame",
    "DenseGates",
    "DenseResult",
    "DenseSettings",
    "dense_align",
    "rigid",
]

log = logging.getLogger(__name__)

DENSE_DOF = ("tx", "ty", "tz", "rx", "ry", "rz")
"""The six axes of the perturbation ``xi`` (translation then rotation, frame 1's axes)."""


@dataclass(frozen=True)
class DenseSettings:
    """Settings of :func:`dense_align`.

    Attributes
    ----------
    levels : tuple of int
        Pyramid levels used, coarse to fine (level ``l`` = input size / ``2**l``).
    iterations : tuple of int
        Gauss-Newton iterations per level (same length as ``levels``).
    photometric_weight : float
        Weight of the photometric term relative to the geometric one, both normalised by their
        own robust residual scale. 0.3 (decision): the depth is the better-modelled of the two
        (its noise model is the sensor's; the brightness carries exposure changes, blur and,
        on 7-Scenes, colour not registered with the depth). Measured with ``PlaneOdometry``
        on every frame of three sequences - 7-Scenes, TUM fr3 structure-notexture-far and the
        simulated Kinect room of ``tests/planes/test_sequences.py`` - RPE median (cm) at
        weights 0.2, 0.3, 0.4, 0.5, 1.0: 7-Scenes 0.193, 0.189, 0.193, 0.194, 0.225; TUM 0.166,
        0.155, 0.160, 0.165, 0.170; simulated 0.230, 0.260, 0.230, 0.255, 0.411 (ATEs in
        docs/planes.md). 0.3 has the lowest RPE on both real sequences; on the simulated room
        0.2-0.5 are within 0.03 cm of each other, and 1.0 is worst everywhere.
    noise : DepthNoise
        The depth sensor's noise model (``sigma_z = k z^2``).
    max_depth_diff_sigmas : float
        Largest depth difference for a correspondence, in ``sigma_z`` of its depth (at level
        0; doubled per level: a coarse pixel spans ``2**l`` fine ones). 12 sigma_z is 4.3 cm at
        1.5 m for a Kinect v1 (the middle of its range).
    huber : float
        Huber threshold on normalised residuals.
    min_depth, max_depth : float
        Depth range used, metres: the sensor's range (default: every valid depth; the noise
        model already weighs far points down).
    source_points : int
        Source points per level, at most about: a level with more valid pixels takes every
        ``k``-th row and column (the smallest such ``k``; the target images stay whole). Six
        degrees of freedom are fixed long before that many points; more add CPU, and the
        residual left is the model's (normals, brightness), not the points' noise.
    step_tolerance_px : float
        A level ends when a Gauss-Newton step moves the image by less than this many of its
        pixels (rotation ``f |w|``, translation ``f |v| / z`` at the points' median depth):
        smaller steps are below what the level resolves; the next level refines them. The last
        level has no next one: its steps are measured in the input's pixels (``2**l`` of its
        own), so the result is converged to this fraction of an input pixel whichever level
        is the finest used.
    """

    levels: tuple[int, ...] = domain_field(
        (3, 2, 1), Domain(integer=True, lo=0, hi=15, note="pyramid levels, input size / 2**l")
    )
    iterations: tuple[int, ...] = domain_field((10, 8, 5), NON_NEGATIVE_INT)
    photometric_weight: float = domain_field(0.3, Domain(lo=0.0, note="0 = geometry only"))
    noise: DepthNoise = field(default_factory=DepthNoise)
    max_depth_diff_sigmas: float = domain_field(12.0, POSITIVE)
    huber: float = domain_field(1.345, POSITIVE)
    min_depth: float = domain_field(0.0, NON_NEGATIVE)
    max_depth: float = domain_field(
        float("inf"), Domain(lo=0.0, lo_open=True, allow_inf=True, note="metres, inf = no limit")
    )
    source_points: int = domain_field(5000, POSITIVE_INT)
    step_tolerance_px: float = domain_field(0.05, POSITIVE)

    def __post_init__(self) -> None:
        check_settings(self)
        if not self.min_depth < self.max_depth:
            raise ConfigError(
                f"min_depth {self.min_depth} >= max_depth {self.max_depth}",
                source="DenseSettings",
                field="max_depth",
                expected="a depth range with min_depth < max_depth",
            )
        if len(self.levels) != len(self.iterations) or not self.levels:
            raise ConfigError(
                f"{len(self.levels)} levels and {len(self.iterations)} iteration counts",
                source="DenseSettings",
                field="iterations",
                expected="one iteration count per level",
            )


class _Level:
    """One pyramid level of a frame: its points as a *source* (built at once), and the maps it
    is read from as a *target* - vertices, normals, brightness and its gradients - built on
    first use (most frames are only ever a source: only keyframes are aligned against)."""

    def __init__(self, g: NDArray[np.float32], d: NDArray[np.float32], K, stride: int) -> None:
        fx, fy, cx, cy = K
        self.K: tuple[float, float, float, float] = (fx, fy, cx, cy)
        self._g, self._d = g, d
        ok = np.isfinite(d)
        ok[0, :] = ok[-1, :] = ok[:, 0] = ok[:, -1] = False
        if stride > 1:  # a regular subsample of the source points
            sub = np.zeros_like(ok)
            sub[::stride, ::stride] = True
            ok &= sub
        v, u = np.nonzero(ok)
        z = d[v, u]
        uf, vf = u.astype(np.float32), v.astype(np.float32)
        self.src = np.stack([(uf - cx) / fx * z, (vf - cy) / fy * z, z], axis=-1).astype(
            np.float64
        )  # (M, 3) valid points of this frame, as the vertex map has them
        self.src_gray = g[v, u].astype(np.float64)  # (M,) their brightness
        self._target: tuple[NDArray[np.float32], ...] | None = None

    def target(self) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]:
        """``(V, N, G3)``: vertex and normal maps ``(H, W, 3)`` (NaN = none) and brightness
        with its x / y gradients ``(H, W, 3)``, float32."""
        if self._target is None:
            self._target = _target_maps(self._g, self._d, self.K)
        return self._target  # type: ignore[return-value]


def _depth_down(d: NDArray[np.float32], k: float) -> NDArray[np.float32]:
    """The next pyramid level of a depth image (NaN = none), centred on the even pixels as
    ``cv2.pyrDown`` centres the brightness: the valid depths under pyrDown's 5 x 5 Gaussian,
    averaged (a normalised convolution) where the average agrees with the centre pixel within
    3 ``sigma_z`` of the depth noise (``sigma_z = k z^2``), else the centre pixel itself - a
    depth edge is never blurred into a surface that is not there. A centre pixel without depth
    (a dropout) takes the average when most of the window has depth. The average of ~13 pixels
    cuts the independent part of the depth noise about 4-fold per level, so the coarse normals
    are not noise (KinectFusion smooths its depth for the same reason)."""
    valid = np.isfinite(d)
    num = np.asarray(cv2.pyrDown(np.where(valid, d, 0.0).astype(np.float32)), dtype=np.float32)
    den = np.asarray(cv2.pyrDown(valid.astype(np.float32)), dtype=np.float32)
    centre = d[::2, ::2][: num.shape[0], : num.shape[1]]
    with np.errstate(invalid="ignore", divide="ignore"):
        avg = num / den
        near = np.abs(avg - centre) < 3.0 * k * centre * centre
        ok = (den > 0.5) & (near | (np.isnan(centre) & (den > 0.9)))
    return np.where(ok, avg, centre).astype(np.float32)


def _target_maps(g, d, K) -> tuple[NDArray[np.float32], NDArray[np.float32], NDArray[np.float32]]:
    fx, fy, cx, cy = K
    H, W = d.shape
    u, v = np.meshgrid(np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32))
    V = np.stack([(u - cx) / fx * d, (v - cy) / fy * d, d], axis=-1).astype(np.float32)
    N = np.full_like(V, np.nan)
    dx = V[1:-1, 2:] - V[1:-1, :-2]
    dy = V[2:, 1:-1] - V[:-2, 1:-1]
    n = np.cross(dx, dy)
    nn = np.linalg.norm(n, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        N[1:-1, 1:-1] = n / nn
    # a normal across a depth edge is meaningless: both differences must be short
    span = np.maximum(np.linalg.norm(dx, axis=-1), np.linalg.norm(dy, axis=-1))
    bad = ~(span < 0.1 * np.maximum(d[1:-1, 1:-1], 0.5))
    N[1:-1, 1:-1][bad] = np.nan
    gx = (cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3) / 8).astype(np.float32)
    gy = (cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3) / 8).astype(np.float32)
    return V, N, np.ascontiguousarray(np.dstack([g, gx, gy]))


@dataclass(frozen=True)
class DenseFrame:
    """The image pyramid of one RGB-D frame (built once, used as target and as source).

    ``brightness_sigma``: the image's brightness noise (:func:`~navkit.planes.noise.
    brightness_sigma`, brightness in [0, 1]), the unit of the photometric residuals."""

    levels: dict[int, _Level] = field(default_factory=dict)
    brightness_sigma: float = 1.0 / 255.0

    @classmethod
    def build(
        cls,
        gray: NDArray[np.floating],
        depth: NDArray[np.floating],
        camera: PinholeCamera,
        settings: DenseSettings | None = None,
    ) -> DenseFrame:
        """Pyramid of ``gray`` ((H, W) in [0, 1]) and ``depth`` ((H, W) metres, NaN = none)."""
        s = settings or DenseSettings()
        g = np.asarray(gray, dtype=np.float32)
        d = np.asarray(depth, dtype=np.float32)
        d = np.where((d >= s.min_depth) & (d <= s.max_depth), d, np.nan).astype(np.float32)
        fx, fy, cx, cy = camera.fx, camera.fy, camera.cx, camera.cy
        out: dict[int, _Level] = {}
        sigma_b = brightness_sigma(g)
        for lev in range(max(s.levels) + 1):
            if lev > 0:
                g = np.asarray(cv2.pyrDown(g), dtype=np.float32)
                d = _depth_down(d, s.noise.k)[: g.shape[0], : g.shape[1]]
                fx, fy = fx / 2, fy / 2
                cx, cy = cx / 2, cy / 2
            if lev not in s.levels:
                continue
            n_valid = int(np.count_nonzero(np.isfinite(d)))
            stride = max(1, int(np.ceil(np.sqrt(n_valid / s.source_points))))
            out[lev] = _Level(g, d, (fx, fy, cx, cy), stride)
        return cls(out, sigma_b)


@dataclass(frozen=True)
class DenseResult:
    """Outcome of :func:`dense_align`.

    Attributes
    ----------
    T : (4, 4) array
        Refined ``T_1_2``.
    overlap : float
        Fraction of frame 2's points (finest level) that land on a valid pixel of frame 1 with
        agreeing depth.
    inliers : float
        Fraction of those whose geometric residual is within 3 robust sigmas (never fewer
        than 3 sigmas of the depth noise).
    rms_geometric : float
        RMS of the inliers' point-to-plane residuals, metres.
    rms_photometric : float
        RMS of the inliers' brightness residuals (brightness in [0, 1]).
    iterations : int
    converged : bool
        The last step at the finest level moved the image by less than
        :attr:`DenseSettings.step_tolerance_px` pixels.
    dof_sources : dict
        For each of :data:`DENSE_DOF`: ``"depth"``, ``"image"`` or ``"depth+image"`` - the
        term that carries at least 80 % of the information about that axis (else both).
    geometric_sigmas : float
        RMS of the inliers' point-to-plane residuals in sigmas of the depth noise at their
        depth (``sqrt(2) sigma_z(z)``, :class:`~navkit.planes.noise.DepthNoise`).
    photometric_sigmas : float
        RMS of the inliers' brightness residuals in sigmas of the images' brightness noise.
    brightness_sigma : float
        That brightness noise (both images combined), brightness in [0, 1].
    information : (6, 6) array
        The Gauss-Newton information of the last step about ``xi = (v, w)`` (frame 1's axes,
        ``T <- exp(xi) T``): both terms, each residual in its noise sigmas times its robust
        scale. Its inverse is the motion's covariance if the residuals were independent; the
        pixels' errors are correlated (model errors, colour offset), so it is a lower bound
        (:attr:`navkit.planes.FrameMotion.covariance` scales it).
    brightness_gain : float
        The exposure change between the frames the photometric term compensated: frame 2's
        brightness ``g`` is compared as ``gain g`` (:func:`dense_align`).
    """

    T: NDArray[np.float64]
    overlap: float
    inliers: float
    rms_geometric: float
    rms_photometric: float
    iterations: int
    converged: bool
    dof_sources: dict[str, str]
    geometric_sigmas: float = float("nan")
    photometric_sigmas: float = float("nan")
    brightness_sigma: float = float("nan")
    information: NDArray[np.float64] = field(default_factory=lambda: np.zeros((6, 6)))
    brightness_gain: float = 1.0


@dataclass(frozen=True)
class DenseGates:
    """When a densely refined motion (:func:`~navkit.planes.dense.dense_align`) is accepted.

    All must hold at the finest level, else the frame becomes an explicit failure (never a
    silent pose). The residual gates are in the sensor's own noise units
    (:mod:`navkit.planes.noise`): the point-to-plane RMS in sigmas of the depth noise at each
    point's depth (``sqrt(2) k z^2``), the brightness RMS in sigmas of the images' own
    brightness noise; overlap and inliers are fractions. One set serves every sequence.

    Calibration (``docs/planes.md``, "How the gates were chosen"; ``python -m
    benchmarks.planes_gates``): the dense step was started from the reference motion spoiled
    by 0-80 cm (0-20 deg) on pairs 1 and 10 frames apart of both shared sequences. Right
    results (within 3 cm / 1.5 deg) left <= 0.98 depth sigmas on 7-Scenes and <= 0.83 on TUM,
    overlap >= 0.84 and inliers >= 0.99 on both, <= 13.1 brightness sigmas on 7-Scenes (colour
    not registered with depth) and <= 2.0 on TUM; all pass these gates. Of the results off by
    more than 5 cm or 2 deg, 1 of 30 passes on 7-Scenes (7.2 cm) and 4 of 19 on TUM (at most
    16.7 cm / 1.0 deg, from starts 40-80 cm / 10-20 deg off in its repeating zig-zag; no
    odometry start is that far off).

    Attributes
    ----------
    max_geometric_sigmas : float
        RMS of the inliers' point-to-plane residuals, in depth-noise sigmas.
    max_photometric_sigmas : float
        RMS of the inliers' brightness residuals, in brightness-noise sigmas.
    min_overlap : float
        Fraction of the frame's points landing on the reference frame with agreeing depth.
    min_inliers : float
        Fraction of those within 3 robust sigmas.
    """

    max_geometric_sigmas: float = 1.5
    max_photometric_sigmas: float = 20.0
    min_overlap: float = 0.3
    min_inliers: float = 0.6

    def __post_init__(self) -> None:
        check_settings(self)

    def check(self, r: DenseResult) -> str:
        """Empty when ``r`` passes, else the reason."""
        bad = []
        if not r.photometric_sigmas <= self.max_photometric_sigmas:
            bad.append(
                f"photometric rms {r.photometric_sigmas:.1f} sigma > "
                f"{self.max_photometric_sigmas} (brightness sigma {r.brightness_sigma:.4f})"
            )
        if not r.geometric_sigmas <= self.max_geometric_sigmas:
            bad.append(
                f"geometric rms {r.geometric_sigmas:.2f} sigma_depth > "
                f"{self.max_geometric_sigmas} ({100 * r.rms_geometric:.1f} cm)"
            )
        if not r.overlap >= self.min_overlap:
            bad.append(f"overlap {r.overlap:.2f} < {self.min_overlap}")
        if not r.inliers >= self.min_inliers:
            bad.append(f"inliers {r.inliers:.2f} < {self.min_inliers}")
        return "; ".join(bad)


def _cross(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Row-wise ``a x b`` of two ``(M, 3)`` arrays (np.cross is 3x slower on rows)."""
    out = np.empty_like(a)
    out[:, 0] = a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1]
    out[:, 1] = a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2]
    out[:, 2] = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return out


def _bilinear(img: NDArray[np.float32], u: NDArray, v: NDArray) -> NDArray[np.float64]:
    """Bilinear samples of the ``(H, W, C)`` image ``img`` at ``(u, v)``: ``(M, C)``."""
    u0 = u.astype(np.int64)  # u, v >= 0: truncation is floor
    v0 = v.astype(np.int64)
    a = (u - u0)[:, None]
    b = (v - v0)[:, None]
    W = img.shape[1]
    flat = img.reshape(-1, img.shape[2]).astype(np.float64)
    i = v0 * W + u0
    top = flat[i] * (1 - a) + flat[i + 1] * a
    bot = flat[i + W] * (1 - a) + flat[i + W + 1] * a
    return top * (1 - b) + bot * b


def rigid(T: NDArray[np.floating]) -> NDArray[np.float64]:
    """``T`` with its rotation block projected onto SO(3) (nearest rotation, SVD).

    Plane solutions can carry a slightly non-orthonormal rotation (float32 texture steps,
    chained products); chained over a sequence that shrank the poses' determinant to 0.7 in 60
    frames. Every pose that enters or leaves the dense step is made rigid here."""
    out = np.array(T, dtype=np.float64)
    U, _, Vt = np.linalg.svd(out[:3, :3])
    if np.linalg.det(U @ Vt) < 0:
        U[:, 2] = -U[:, 2]
    out[:3, :3] = U @ Vt
    out[3] = (0.0, 0.0, 0.0, 1.0)
    return out


def _exp_se3(xi: NDArray[np.float64]) -> NDArray[np.float64]:
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(xi[3:].reshape(3, 1))[0]
    T[:3, 3] = xi[:3]
    return T


def _robust_scale(r: NDArray[np.float64], floor: float) -> float:
    """1.4826 x MAD (from a regular subsample of at most ~2000 residuals: the scale's relative
    standard error is then about 3 %), at least ``floor``."""
    if len(r) == 0:
        return floor
    r = r[:: max(1, len(r) // 1000)]
    return max(1.4826 * float(np.median(np.abs(r - np.median(r)))), floor)


_Terms = tuple[
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.float64],
    NDArray[np.int64],
    NDArray[np.float64],
]
_DENSE_KERNELS: list = []  # the compiled module, imported on first use (no Numba at import)


def _kernels():  # type: ignore[no-untyped-def]
    """The compiled kernels (:mod:`navkit.planes._kernels_dense`), imported on first use."""
    if not _DENSE_KERNELS:
        from navkit.planes import _kernels_dense

        _DENSE_KERNELS.append(_kernels_dense)
    return _DENSE_KERNELS[0]


def _level_args(
    tgt: _Level,
    src: _Level,
    T,
    s: DenseSettings,
    lev: int,
    sigma_b: float,
    gain: float = 1.0,
) -> tuple:
    """The arguments of :func:`~navkit.planes._kernels_dense.dense_terms` and its twin
    (``gain``: the source brightness compared as ``gain g``)."""
    R = np.ascontiguousarray(T[:3, :3], dtype=np.float64)
    t = np.ascontiguousarray(T[:3, 3], dtype=np.float64)
    K = np.array(tgt.K, dtype=np.float64)
    V, N, G3 = tgt.target()
    gray = src.src_gray if gain == 1.0 else gain * src.src_gray
    return (
        src.src,
        gray,
        R,
        t,
        K,
        V,
        N,
        G3,
        float(s.max_depth_diff_sigmas),
        float(s.noise.k),
        float(2**lev),
        float(sigma_b),
    )


def _terms(
    tgt: _Level,
    src: _Level,
    T,
    s: DenseSettings,
    lev: int,
    sigma_b: float,
    compiled: bool,
    gain: float = 1.0,
) -> _Terms:
    """Residuals and Jacobians of both terms at one level for the current ``T``, each in
    sigmas of its noise (depth: ``sqrt(2) sigma_z`` at the target's depth, also returned in
    metres per correspondence; brightness: ``sigma_b``, the source's brightness times
    ``gain``), and the correspondences' source indices: ``(rG, JG, rI, JI, idx, sig)``."""
    args = _level_args(tgt, src, T, s, lev, sigma_b, gain)
    f = _kernels().dense_terms if compiled else _terms_numpy
    n, idx, rG, JG, rI, JI, sig = f(*args)
    return rG[:n], JG[:n], rI[:n], JI[:n], idx[:n], sig[:n]


def _terms_numpy(
    src_pts, src_gray, R, t, K, V, N, G3, max_diff, noise_k, level_scale, sigma_b
) -> tuple[int, NDArray, NDArray, NDArray, NDArray, NDArray, NDArray]:
    """NumPy twin of :func:`navkit.planes._kernels_dense.dense_terms` (same operations, same
    order: same bits)."""
    fx, fy, cx, cy = (float(k) for k in K)
    H, W = V.shape[:2]
    x, y, zs = src_pts[:, 0], src_pts[:, 1], src_pts[:, 2]
    Y0 = x * R[0, 0] + y * R[0, 1] + zs * R[0, 2] + t[0]
    Y1 = x * R[1, 0] + y * R[1, 1] + zs * R[1, 2] + t[1]
    z = x * R[2, 0] + y * R[2, 1] + zs * R[2, 2] + t[2]
    keep = np.nonzero(z > 0.1)[0]
    Y0, Y1, z = Y0[keep], Y1[keep], z[keep]
    u = fx * Y0 / z + cx
    v = fy * Y1 / z + cy
    inside = (u >= 0.0) & (v >= 0.0) & (u < W - 1) & (v < H - 1)
    keep, Y0, Y1, z, u, v = keep[inside], Y0[inside], Y1[inside], z[inside], u[inside], v[inside]
    ui, vi = np.rint(u).astype(np.int64), np.rint(v).astype(np.int64)
    Vp = V[vi, ui].astype(np.float64)
    Np = N[vi, ui].astype(np.float64)
    good = np.isfinite(Vp[:, 2]) & np.isfinite(Np[:, 0])
    with np.errstate(invalid="ignore"):
        good &= np.abs(Vp[:, 2] - z) < max_diff * (noise_k * z * z) * level_scale
    keep, Y0, Y1, z, u, v = keep[good], Y0[good], Y1[good], z[good], u[good], v[good]
    V0, V1, V2 = Vp[good, 0], Vp[good, 1], Vp[good, 2]
    N0, N1, N2 = Np[good, 0], Np[good, 1], Np[good, 2]
    p = np.sqrt(2.0) * (noise_k * V2 * V2)
    isg = 1.0 / p
    rG = (N0 * (Y0 - V0) + N1 * (Y1 - V1) + N2 * (z - V2)) * isg
    JG = np.stack(
        [
            N0 * isg,
            N1 * isg,
            N2 * isg,
            (Y1 * N2 - z * N1) * isg,
            (z * N0 - Y0 * N2) * isg,
            (Y0 * N1 - Y1 * N0) * isg,
        ],
        axis=1,
    )
    S = _bilinear(G3, u, v)
    gxs, gys = S[:, 1] * fx, S[:, 2] * fy
    rI = (S[:, 0] - src_gray[keep]) / sigma_b
    iz = 1.0 / z
    j0, j1, j2 = gxs * iz, gys * iz, -(gxs * Y0 + gys * Y1) * iz * iz
    JI = np.stack(
        [
            j0 / sigma_b,
            j1 / sigma_b,
            j2 / sigma_b,
            (Y1 * j2 - z * j1) / sigma_b,
            (z * j0 - Y0 * j2) / sigma_b,
            (Y0 * j1 - Y1 * j0) / sigma_b,
        ],
        axis=1,
    )
    return len(keep), keep, rG, JG, rI, JI, p


_UPPER = np.triu_indices(6)


def _normal_equations(
    J: NDArray[np.float64], w: NDArray[np.float64], r: NDArray[np.float64], compiled: bool
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(J^T W J, J^T W r)`` (:func:`navkit.planes._kernels_dense.normal_equations`)."""
    f = _kernels().normal_equations if compiled else _normal_equations_numpy
    return f(np.ascontiguousarray(J), np.ascontiguousarray(w), np.ascontiguousarray(r))


def _normal_equations_numpy(
    J: NDArray[np.float64], w: NDArray[np.float64], r: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """NumPy twin of :func:`navkit.planes._kernels_dense.normal_equations`: every entry summed
    over the rows in order from +0 (``np.cumsum`` after a zero row; no BLAS)."""
    Jw = J * w[:, None]
    prod = np.concatenate([Jw[:, _UPPER[0]] * J[:, _UPPER[1]], Jw * r[:, None]], axis=1)
    sums = np.cumsum(np.vstack([np.zeros((1, prod.shape[1])), prod]), axis=0)[-1]
    H = np.zeros((6, 6))
    H[_UPPER] = sums[: len(_UPPER[0])]
    H = np.triu(H) + np.triu(H, 1).T
    return H, np.ascontiguousarray(sums[len(_UPPER[0]) :])


def _huber(r: NDArray[np.float64], k: float) -> NDArray[np.float64]:
    a = np.abs(r)
    return np.where(a <= k, 1.0, k / np.maximum(a, 1e-12))


def dense_align(
    frame1: DenseFrame,
    frame2: DenseFrame,
    T_init: NDArray[np.float64],
    settings: DenseSettings | None = None,
) -> DenseResult:
    """Refine ``T_1_2`` (frame 2 -> frame 1) by dense photometric + geometric alignment.

    Parameters
    ----------
    frame1, frame2 : DenseFrame
        Target (frame 1) and source (frame 2) pyramids, built with the same settings.
    T_init : (4, 4) array
        Starting motion (the plane solution, or a prediction).
    settings : DenseSettings, optional

    Returns
    -------
    DenseResult
        Always a result; its ``overlap``, ``inliers`` and residuals say how much to trust it
        (the caller gates on them).
    """
    return _dense_align(frame1, frame2, T_init, settings, compiled=kernels_enabled())


def _dense_align(
    frame1: DenseFrame,
    frame2: DenseFrame,
    T_init: NDArray[np.float64],
    settings: DenseSettings | None,
    *,
    compiled: bool,
) -> DenseResult:
    """:func:`dense_align` with the implementation chosen by the caller (compiled kernels or
    their NumPy twins; an online object decides once, when it is built)."""
    s = settings or DenseSettings()
    T = rigid(T_init)
    its = 0
    converged = False
    # the photometric residual's unit: both images' brightness noise
    sigma_b = float(np.hypot(frame1.brightness_sigma, frame2.brightness_sigma))
    gain = 1.0  # frame 2's brightness g is compared as gain g (refitted at every step)
    H_G = H_I = np.zeros((6, 6))
    for lev, n_it in zip(s.levels, s.iterations, strict=True):
        tgt, src = frame1.levels[lev], frame2.levels[lev]
        # a step that moves the image by less than step_tolerance_px pixels of this level
        # ends it: rotation w moves a pixel by f |w|, translation v by f |v| / z
        f = max(tgt.K[0], tgt.K[1])
        z_typ = (
            float(np.median(src.src[:: max(1, len(src.src) // 1000), 2])) if len(src.src) else 1.0
        )
        # the last level has no finer one after it: its tolerance is in input pixels
        tol_px = s.step_tolerance_px / (2**lev if lev == s.levels[-1] else 1)
        converged = False
        for _ in range(n_it):
            its += 1
            rG, JG, rI, JI, idx, _ = _terms(tgt, src, T, s, lev, sigma_b, compiled, gain)
            if len(rG) < 50:
                break
            # residuals are in noise sigmas; the robust scale (never below one sigma) absorbs
            # what the noise model misses (misalignment at coarse levels, model error)
            sG = _robust_scale(rG, 1.0)
            sI = _robust_scale(rI, 1.0)
            wG = _huber(rG / sG, s.huber) / sG**2
            wI = s.photometric_weight * _huber(rI / sI, s.huber) / sI**2
            gain_next = _exposure(src.src_gray[idx], rI, sigma_b, gain, wI)
            H_G, g_G = _normal_equations(JG, wG, rG, compiled)
            H_I, g_I = _normal_equations(JI, wI, rI, compiled)
            g = g_G + g_I
            Hm = H_G + H_I
            try:
                xi = -np.linalg.solve(Hm + 1e-6 * np.trace(Hm) / 6 * np.eye(6), g)
            except np.linalg.LinAlgError:
                break
            T = _exp_se3(xi) @ T
            gain = gain_next  # pose and exposure, both from this step's residuals
            moved_px = f * (np.abs(xi[3:]).max() + np.abs(xi[:3]).max() / max(z_typ, 0.1))
            converged = bool(moved_px < tol_px)
            if converged:
                break
    # quality at the finest level
    lev = s.levels[-1]
    rG, JG, rI, JI, _, sig = _terms(
        frame1.levels[lev], frame2.levels[lev], T, s, lev, sigma_b, compiled, gain
    )
    overlap = len(rG) / max(len(frame2.levels[lev].src), 1)
    sG = _robust_scale(rG, 1.0)
    inl = np.abs(rG) < 3 * sG
    nan = float("nan")
    return DenseResult(
        T=T,
        overlap=float(overlap),
        inliers=float(inl.mean()) if len(rG) else 0.0,
        rms_geometric=float(np.sqrt(np.mean((rG[inl] * sig[inl]) ** 2))) if inl.any() else nan,
        rms_photometric=float(sigma_b * np.sqrt(np.mean(rI[inl] ** 2))) if inl.any() else nan,
        iterations=its,
        converged=converged,
        dof_sources=_dof_sources(H_G, H_I),
        information=H_G + H_I,
        geometric_sigmas=float(np.sqrt(np.mean(rG[inl] ** 2))) if inl.any() else nan,
        photometric_sigmas=float(np.sqrt(np.mean(rI[inl] ** 2))) if inl.any() else nan,
        brightness_sigma=sigma_b,
        brightness_gain=gain,
    )


def _exposure(
    g: NDArray[np.float64],
    rI: NDArray[np.float64],
    sigma_b: float,
    current: float,
    w: NDArray[np.float64],
) -> float:
    """The exposure gain with which the source brightness ``g`` of the correspondences best
    predicts the target's (``gain g``; the target's brightness is ``current g + rI sigma_b``):
    the least-squares fit through the origin with the photometric term's robust weights ``w``
    of this Gauss-Newton step (refitted at every step, it is reweighted as the alignment
    converges). Auto-exposure scales a camera's brightness from frame to frame; without this
    the photometric term reads the change as motion. A gain, not gain and offset: an exposure
    change multiplies the light a pixel collects, and an offset free to move takes up other
    misfits too (on 7-Scenes, whose colour is not registered with its depth, it cost
    accuracy). The gain stays within [0.5, 2] (a larger jump is a scene change, not an
    exposure step); with fewer than 50 correspondences it stays ``current``."""
    if len(g) < 50:
        return current
    wg = w * g
    den = float(wg @ g)
    if den <= 0.0:
        return current
    a = float(wg @ (current * g + rI * sigma_b)) / den
    return float(np.clip(a, 0.5, 2.0))


def _marginal_information(H: NDArray[np.float64]) -> NDArray[np.float64]:
    try:
        C = np.linalg.inv(H + 1e-12 * np.trace(H) * np.eye(6))
    except np.linalg.LinAlgError:
        return np.zeros(6)
    d = np.diag(C)
    return np.where(d > 0, 1.0 / np.maximum(d, 1e-300), 0.0)


def _dof_sources(H_G: NDArray[np.float64], H_I: NDArray[np.float64]) -> dict[str, str]:
    iG, iI = _marginal_information(H_G), _marginal_information(H_I)
    out = {}
    for k, name in enumerate(DENSE_DOF):
        tot = iG[k] + iI[k]
        frac = iG[k] / tot if tot > 0 else 0.5
        out[name] = "depth" if frac >= 0.8 else ("image" if frac <= 0.2 else "depth+image")
    return out
