"""The sensor's own noise: the unit every accept / reject threshold of the plane odometry is in.

Two noises are modelled:

- **depth**: a Kinect-type (structured light or active stereo, triangulating) camera measures
  disparity with a roughly constant error, so its depth error grows with the square of the
  distance, ``sigma_z(z) = k z^2`` (differentiate ``z = b f / d``: ``sigma_z = z^2 sigma_d /
  (b f)``). ``k`` is a property of the sensor, in 1/m. Default: Kinect v1, Khoshelham and
  Elberink, "Accuracy and Resolution of Kinect Depth Data for Indoor Mapping Applications",
  Sensors 12(2), 2012: the random error "increases quadratically with increasing distance from
  the sensor and reaches 4 cm at the maximum range of 5 m", ``k = 0.04 / 5^2 = 1.6e-3`` 1/m
  (1.6 mm at 1 m, 6.4 mm at 2 m);
- **brightness**: estimated from each image itself (:func:`brightness_sigma`, Immerkaer 1996),
  so a dark, a bright, a compressed or a rendered image each give their own unit.

A point-to-plane residual between two depth images combines two depth errors, both seen along
the surface normal; :meth:`DepthNoise.point_to_plane` uses ``sqrt(2) sigma_z`` (the normal
within a few tens of degrees of the ray, where the planes that carry the motion are seen).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.domains import POSITIVE, domain_field
from navkit.geometry._validate import check_settings

__all__ = [
    "DOF_NAMES",
    "KINECT_V1_K",
    "DepthNoise",
    "PlaneFit",
    "brightness_sigma",
    "fit_plane",
    "free_directions",
    "plane_pair_information",
    "segments_information",
]

KINECT_V1_K = 1.6e-3
"""``k`` of ``sigma_z = k z^2`` for a Kinect v1, 1/m (Khoshelham and Elberink 2012: 4 cm at
5 m)."""


@dataclass(frozen=True)
class DepthNoise:
    """Depth noise model ``sigma_z(z) = k z^2`` (module docstring).

    Attributes
    ----------
    k : float
        1/m. :data:`KINECT_V1_K` for Kinect v1 / Xtion-type structured light; a stereo camera's
        is ``sigma_disparity / (baseline f)``.
    """

    k: float = domain_field(KINECT_V1_K, POSITIVE)

    def __post_init__(self) -> None:
        check_settings(self)

    def sigma(self, z: ArrayLike) -> NDArray[np.float64]:
        """``sigma_z`` (metres) of depths ``z`` (metres)."""
        z = np.asarray(z, dtype=np.float64)
        return self.k * z * z

    def point_to_plane(self, z: ArrayLike) -> NDArray[np.float64]:
        """Standard deviation (metres) of a point-to-plane residual between two depth images
        at depth ``z``: two independent depth errors, ``sqrt(2) sigma_z(z)``."""
        return np.sqrt(2.0) * self.sigma(z)


_LAPLACE2 = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], dtype=np.float32)


def brightness_sigma(gray: ArrayLike, floor: float = 1.0 / 255.0) -> float:
    """Standard deviation of the brightness noise of an image (values in [0, 1]).

    Immerkaer, "Fast Noise Variance Estimation", CVIU 64(2), 1996: the image is filtered with
    the difference of two Laplacians (which cancels brightness that varies linearly, i.e. most
    of the scene), ``sigma = sqrt(pi / 2) / (6 (W - 2) (H - 2)) sum |I * N|``. Textured images
    leak some structure into the estimate (it errs high, the safe side for a threshold). At
    least ``floor`` (one 8-bit step: below it the quantisation dominates)."""
    g = np.asarray(gray, dtype=np.float32)
    if g.ndim != 2 or min(g.shape) < 3:
        return float(floor)
    r = cv2.filter2D(g, cv2.CV_32F, _LAPLACE2, borderType=cv2.BORDER_REFLECT)[1:-1, 1:-1]
    r = r[np.isfinite(r)]
    if r.size == 0:
        return float(floor)
    s = float(np.sqrt(np.pi / 2.0) / 6.0 * np.mean(np.abs(r)))
    return max(s, float(floor))


@dataclass(frozen=True)
class PlaneFit:
    """A plane fitted to points weighted by their depth noise, with its covariance.

    ``normal . x = rho``; the covariance is of ``(a, b, d)``: the normal turned by ``a`` towards
    ``axes[0]`` and ``b`` towards ``axes[1]`` (radians), and the plane moved by ``d`` metres
    along the normal at ``centroid`` (where the offset is measured: no lever arm)."""

    normal: NDArray[np.float64]
    rho: float
    centroid: NDArray[np.float64]
    axes: NDArray[np.float64]  # (2, 3) in-plane directions (largest spread first)
    cov: NDArray[np.float64]  # (3, 3) of (a, b, d)
    count: int


def fit_plane(points: ArrayLike, noise: DepthNoise | None = None) -> PlaneFit:
    """Weighted total-least-squares plane of ``(N, 3)`` sensor-frame points (N >= 3).

    Each point weighs ``1 / sigma_z(z)^2`` (:class:`DepthNoise`: the depth error is taken along
    the normal, exact for a plane seen head-on, optimistic by ``1 / cos`` of the incidence
    angle otherwise). With the weighted centroid ``c`` and the weighted scatter's eigenpairs
    ``(lambda_k, e_k)``, the normal's tilt towards ``e_k`` has variance ``1 / lambda_k`` and the
    offset at ``c`` ``1 / sum w`` (the Fisher information of the fit; Pathak et al., "Fast
    Registration Based on Noisy Planes with Unknown Correspondences", IEEE T-RO 26(3), 2010).
    """
    X = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    X = X[np.all(np.isfinite(X), axis=1)]
    if len(X) < 3:
        from navkit.errors import InputError

        raise InputError(f"{len(X)} finite points", field="points", expected="at least 3")
    nz = noise or DepthNoise()
    w = 1.0 / np.maximum(nz.sigma(X[:, 2]), 1e-6) ** 2
    c = (w[:, None] * X).sum(0) / w.sum()
    D = X - c
    S = (D * w[:, None]).T @ D
    lam, V = np.linalg.eigh(S)
    n = V[:, 0]
    rho = float(n @ c)
    if rho < 0:
        n, rho = -n, -rho
    axes = np.stack([V[:, 2], V[:, 1]])
    cov = np.diag([1.0 / max(lam[2], 1e-300), 1.0 / max(lam[1], 1e-300), 1.0 / w.sum()])
    return PlaneFit(n, rho, c, axes, cov, len(X))


def plane_pair_information(
    f1: PlaneFit, f2: PlaneFit, R: NDArray[np.float64], t: NDArray[np.float64]
) -> NDArray[np.float64]:
    """``(6, 6)`` information (inverse covariance) that one matched plane pair gives about the
    motion ``T_1_2 = (R, t)``, perturbed as ``(dt, w)``: ``X1 = exp(w) R X2 + t + dt``.

    Three constraints: the normals agree across their two tilt directions (``e_k . (R n2) = 0``
    for frame 1's in-plane axes ``e_k``; variance: both fits' tilts) and frame 2's centroid,
    moved, lies on frame 1's plane (``n1 . (R c2 + t - c1) = 0``; variance: both offsets plus the
    normal tilt times the distance between the centroids)."""
    n1, Rn2 = f1.normal, R @ f2.normal
    if n1 @ Rn2 < 0:
        Rn2 = -Rn2
    rows, var = [], []
    tilt2 = R @ (f2.axes.T @ f2.cov[:2, :2] @ f2.axes) @ R.T  # frame 2's tilt covariance
    for k in range(2):
        e = f1.axes[k]
        rows.append(np.concatenate([np.zeros(3), np.cross(Rn2, e)]))
        var.append(f1.cov[k, k] + float(e @ tilt2 @ e))
    y = R @ f2.centroid + t
    lever = y - f1.centroid
    tilt1 = f1.axes.T @ f1.cov[:2, :2] @ f1.axes
    rows.append(np.concatenate([n1, np.cross(y, n1)]))
    var.append(f1.cov[2, 2] + f2.cov[2, 2] + float(lever @ (tilt1 + tilt2) @ lever))
    J = np.array(rows)
    return J.T @ (J / np.maximum(np.array(var), 1e-300)[:, None])


DOF_NAMES = ("tx", "ty", "tz", "rx", "ry", "rz")


def free_directions(
    H: NDArray[np.float64], max_translation: float, max_rotation_deg: float
) -> tuple[tuple[str, ...], NDArray[np.float64], NDArray[np.float64]]:
    """Degrees of freedom a ``(6, 6)`` information matrix leaves free.

    The translation block's marginal covariance (``(H^-1)[:3, :3]``, the rotation not assumed
    known) and the rotation block's are eigen-decomposed; a direction whose 3-sigma exceeds
    ``max_translation`` metres (``max_rotation_deg`` degrees) is free. Returns the names of the
    frame axes each free direction leans on most (``tx`` ... ``rz``), the translation and the
    rotation 1-sigma along each eigen-direction (metres, degrees)."""
    Hs = H + 1e-12 * max(np.trace(H), 1e-300) * np.eye(6)
    try:
        C = np.linalg.inv(Hs)
    except np.linalg.LinAlgError:
        return DOF_NAMES, np.full(3, np.inf), np.full(3, np.inf)
    free: list[str] = []
    sig_t, sig_r = np.zeros(3), np.zeros(3)
    for blk, limit, out, scale in (
        (slice(0, 3), max_translation, sig_t, 1.0),
        (slice(3, 6), np.radians(max_rotation_deg), sig_r, np.degrees(1.0)),
    ):
        lam, V = np.linalg.eigh(C[blk, blk])
        s = np.sqrt(np.maximum(lam, 0.0))
        out[:] = s * scale
        for k in range(3):
            if 3 * s[k] > limit:
                name = DOF_NAMES[blk.start + int(np.argmax(np.abs(V[:, k])))]
                if name not in free:
                    free.append(name)
    return tuple(free), sig_t, sig_r


_FIT_POINTS = 500
"""Points per plane fit of :func:`segments_information` (a regular subsample: the fit is a
report - which directions the planes leave free - and 500 points give its covariance to ~6 %)."""


def segments_information(
    points: NDArray[np.float64], inliers: list[NDArray[np.int64]], noise: DepthNoise
) -> NDArray[np.float64]:
    """``(6, 6)`` information the planes of one frame give about its motion: each segment's
    points (``points[inliers[k]]``, ``(N, 3)`` sensor frame) fitted with the depth noise
    (:func:`fit_plane`; every k-th point, at most about 500: a regular subsample's covariance
    divided by the step is the whole set's in expectation, at a fraction of the CPU), each fit
    standing for both sides of its pair (:func:`plane_pair_information` at the identity).
    Segments with fewer than 3 finite points add nothing."""
    H = np.zeros((6, 6))
    I3, z3 = np.eye(3), np.zeros(3)
    for inl in inliers:
        step = max(1, len(inl) // _FIT_POINTS)
        P = points[inl[::step]]
        P = P[np.isfinite(P).all(axis=1)]
        if len(P) < 3:
            continue
        f = fit_plane(P, noise)
        f = PlaneFit(f.normal, f.rho, f.centroid, f.axes, f.cov / step, len(P) * step)
        H += plane_pair_information(f, f, I3, z3)
    return H
