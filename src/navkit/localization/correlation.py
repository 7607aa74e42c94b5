"""Paper 3's localization: slide the observed wall fragment along the map, known heading.

The robot sees a fragment ``phi_2`` of a wall; the maximum over offsets of the correlation
between the map ``phi_1`` and the shifted fragment gives the fragment's place on the map; with
the heading ``theta`` known (the camera drive's angle sensor) the robot position follows from the
fragment's world and camera coordinates.

- :func:`correlate_profiles` is the paper's discrete form, ``R_i = sum_{j=i}^{i+M-1}
  phi_1(A_j) phi_2(B_{j-i+1})``, ``i = 1 .. N - M + 1`` (or, by default, its normalised version,
  the correlation coefficient the paper names: raw products favour bright / dense stretches).
- :func:`robot_position` is the paper's position formula in navkit's frames.
- :func:`locate_known_heading` applies the method to 2D points: the fragment, turned by the known
  heading, is correlated over every 2D offset with the map's likelihood field (by FFT), the
  maximum is refined to sub-cell by a parabola, and the robot position follows from
  :func:`robot_position`.

Decision (the paper's eq. 2 prints ``R = [[-sin t, cos t], [cos t, sin t]]``, a reflection with
determinant -1 that bakes in its camera axes): navkit uses the body frame (x forward, y left) and
the proper rotation ``R(theta)``; the position formula is then ``t = p_w - R(theta) p_c``, i.e.
``dx = x_w - x_c cos(theta) + y_c sin(theta)``, ``dy = y_w - x_c sin(theta) - y_c cos(theta)``.
The paper's printed ``dx = x_w + x_c sin(theta) - y_c cos(theta)`` is the same formula for its
axes (camera x to the left of travel, y forward, heading measured from world y).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.signal import fftconvolve

from navkit.errors import InputError
from navkit.geometry._validate import as_points
from navkit.localization.field import LikelihoodField

__all__ = ["KnownHeadingFix", "correlate_profiles", "locate_known_heading", "robot_position"]

log = logging.getLogger(__name__)


def correlate_profiles(
    map_profile: ArrayLike, fragment: ArrayLike, *, normalized: bool = True
) -> NDArray[np.float64]:
    """Correlation of a fragment slid along a map profile (paper 3, discrete form).

    Parameters
    ----------
    map_profile : (N,) array
        ``phi_1(A_1 .. A_N)``, the map sampled at equal steps.
    fragment : (M,) array
        ``phi_2(B_1 .. B_M)``, the observed fragment at the same step, ``M <= N``.
    normalized : bool
        True: the correlation coefficient of each window (Pearson; 0 for a constant window);
        False: the paper's raw sum of products.

    Returns
    -------
    (N - M + 1,) array
        ``R_i`` for offsets ``i = 0 .. N - M``; ``argmax`` is the fragment's place.
    """
    A = np.asarray(map_profile, dtype=np.float64).reshape(-1)
    B = np.asarray(fragment, dtype=np.float64).reshape(-1)
    if len(B) == 0 or len(B) > len(A):
        raise InputError(
            f"has {len(B)} samples for a map of {len(A)}",
            field="fragment",
            expected="1 <= M <= N samples",
        )
    if not (np.isfinite(A).all() and np.isfinite(B).all()):
        raise InputError(
            "contains NaN or inf", field="map_profile / fragment", expected="finite samples"
        )
    windows = np.lib.stride_tricks.sliding_window_view(A, len(B))  # (N - M + 1, M)
    if not normalized:
        return windows @ B
    Wc = windows - windows.mean(axis=1, keepdims=True)
    Bc = B - B.mean()
    den = np.linalg.norm(Wc, axis=1) * np.linalg.norm(Bc)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = (Wc @ Bc) / den
    return np.where(den > 0, r, 0.0)


def robot_position(
    fragment_world: ArrayLike, fragment_body: ArrayLike, theta: float | ArrayLike
) -> NDArray[np.float64]:
    """Robot position from a point seen in the body frame and found in the world (paper 3).

    ``t = p_w - R(theta) p_c`` with ``R(theta)`` the rotation by the heading (body x forward,
    y left): ``dx = x_w - x_c cos(theta) + y_c sin(theta)``,
    ``dy = y_w - x_c sin(theta) - y_c cos(theta)``.

    Parameters
    ----------
    fragment_world, fragment_body : (..., 2) arrays
        The same point in the world and in the body frame, metres.
    theta : float or (...,) array
        Heading, radians.

    Returns
    -------
    (..., 2) array
        Robot position ``(dx, dy)``, metres.
    """
    w = np.asarray(fragment_world, dtype=np.float64)
    c = np.asarray(fragment_body, dtype=np.float64)
    th = np.asarray(theta, dtype=np.float64)
    ct, st = np.cos(th), np.sin(th)
    dx = w[..., 0] - c[..., 0] * ct + c[..., 1] * st
    dy = w[..., 1] - c[..., 0] * st - c[..., 1] * ct
    return np.stack([dx, dy], axis=-1)


@dataclass(frozen=True)
class KnownHeadingFix:
    """Result of :func:`locate_known_heading`.

    Attributes
    ----------
    position : (2,) array
        Robot ``(x, y)``, metres.
    fragment_world : (2,) array
        Where the fragment's centroid lies on the map.
    score : float
        Peak correlation divided by the number of fragment cells, ``[0, 1]``.
    correlation : (H, W) array
        ``R(dx, dy)`` over the searched offsets (row = y).
    peak_extent : float
        Metres; length of the set of offsets within 5 % of the peak along its major axis
        (large = ambiguous, e.g. a straight wall).
    peak_direction : (2,) array
        World unit vector of that axis.
    """

    position: NDArray[np.float64]
    fragment_world: NDArray[np.float64]
    score: float
    correlation: NDArray[np.float64]
    peak_extent: float
    peak_direction: NDArray[np.float64]


def locate_known_heading(fld: LikelihoodField, points: ArrayLike, theta: float) -> KnownHeadingFix:
    """Paper 3's correlation localization in 2D with a known heading.

    Stages: (1) turn the fragment's body-frame points by ``theta`` (paper eq. 2); (2) rasterise
    them on the field's grid, relative to their centroid; (3) correlate with the map over every
    offset (``R(dx, dy) = sum phi_1 phi_2``, by FFT); (4) the maximum, refined by a parabola per
    axis, places the fragment's centroid in the world; (5) the robot position from
    :func:`robot_position`.

    Parameters
    ----------
    fld : LikelihoodField
        The map ``phi_1``.
    points : (N, 2) array
        Fragment points in the body frame, metres (NaN rows dropped).
    theta : float
        Known heading, radians.
    """
    P = as_points(points, 2)
    P = P[np.all(np.isfinite(P), axis=1)]
    if len(P) < 2:
        raise InputError(
            f"has {len(P)} finite points", field="points", expected="at least 2 points"
        )
    r = fld.resolution
    c, s = np.cos(theta), np.sin(theta)
    Q = P @ np.array([[c, -s], [s, c]]).T
    centroid_body = P.mean(axis=0)
    q0 = Q.mean(axis=0)
    rel = Q - q0
    ij = np.round(rel / r).astype(np.intp)
    lo = ij.min(axis=0)
    ij -= lo
    kw, kh = (ij.max(axis=0) + 1).tolist()
    kernel = np.zeros((kh, kw))
    np.add.at(kernel, (ij[:, 1], ij[:, 0]), 1.0)
    # correlation = convolution with the flipped kernel; 'full' then keep offsets where the
    # kernel's cell (0, 0) lands on a map cell
    R = fftconvolve(fld.values.astype(np.float64), kernel[::-1, ::-1], mode="full")
    R = R[kh - 1 :, kw - 1 :]  # R[y, x]: kernel cell (0, 0) on map cell (y, x)
    R = R / len(P)
    y, x = np.unravel_index(int(np.argmax(R)), R.shape)

    def parabola(a: float, b: float, cc: float) -> float:
        den = a - 2 * b + cc
        return 0.0 if den >= 0 else float(np.clip(0.5 * (a - cc) / den, -0.5, 0.5))

    dx = parabola(R[y, x - 1], R[y, x], R[y, x + 1]) if 0 < x < R.shape[1] - 1 else 0.0
    dy = parabola(R[y - 1, x], R[y, x], R[y + 1, x]) if 0 < y < R.shape[0] - 1 else 0.0
    # map cell (y, x) has centre origin + (x + 0.5, y + 0.5) r; the kernel cell (0, 0) holds
    # points at rel = lo * r, so the centroid sits at that centre - lo * r
    cell0 = fld.origin + (np.array([x + dx, y + dy]) + 0.5) * r
    frag_world = cell0 - lo * r
    # peak shape
    near = R >= 0.95 * R[y, x]
    yy, xx = np.nonzero(near)
    T = np.stack([xx, yy], axis=1) * r
    if len(T) > 1:
        _, V = np.linalg.eigh(np.cov(T.T))
        d = V[:, 1]
        proj = T @ d
        extent = float(proj.max() - proj.min()) + r
    else:
        d, extent = np.array([1.0, 0.0]), r
    pos = robot_position(frag_world, centroid_body, theta)
    return KnownHeadingFix(
        position=pos,
        fragment_world=frag_world,
        score=float(R[y, x]),
        correlation=R,
        peak_extent=extent,
        peak_direction=d,
    )
