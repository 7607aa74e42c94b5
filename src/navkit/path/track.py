"""Preparing a recorded trajectory for the path memory: cleaning, ground plane, wheel odometry.

Pure array functions (the file readers live in ``navkit.io.trajectory``).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import ConfigError, InputError

__all__ = ["GroundPlane", "clean_track", "ground_plane", "integrate_odometry", "to_plane"]

log = logging.getLogger(__name__)

_AXES = {"x": 0, "y": 1, "z": 2}


def clean_track(
    timestamps: ArrayLike | None, positions: ArrayLike, *, source: str | None = None
) -> tuple[NDArray[np.float64] | None, NDArray[np.float64]]:
    """Drop samples with non-finite positions and samples whose time goes backwards.

    A sample whose timestamp is not later than the latest kept one is dropped (a log replayed
    twice, a clock jump back): the trajectory stays in time order. Each kind of drop is logged once
    as a warning with its count.

    Parameters
    ----------
    timestamps : (N,) array or None
    positions : (N, D) array
    source : str, optional
        Named in the messages.

    Returns
    -------
    (timestamps, positions) with the bad samples removed.
    """
    P = np.asarray(positions, dtype=np.float64)
    if P.ndim != 2 or len(P) == 0:
        raise InputError(
            f"has shape {P.shape}", source=source, field="positions", expected="(N, D) with N >= 1"
        )
    keep = np.isfinite(P).all(axis=1)
    if (~keep).any():
        log.warning(
            "%s: skipped %d samples with NaN / inf positions",
            source or "trajectory",
            int((~keep).sum()),
        )
    if timestamps is None:
        return None, P[keep]
    t = np.asarray(timestamps, dtype=np.float64).reshape(-1)
    if len(t) != len(P):
        raise InputError(
            f"{len(t)} timestamps for {len(P)} positions",
            source=source,
            field="timestamps",
            expected="one timestamp per pose",
        )
    keep &= np.isfinite(t)
    tk = np.where(keep, t, -np.inf)
    running = np.maximum.accumulate(tk)
    prev = np.concatenate([[-np.inf], running[:-1]])
    backwards = keep & (t <= prev)
    if backwards.any():
        log.warning(
            "%s: skipped %d samples whose timestamps go backwards (or repeat)",
            source or "trajectory",
            int(backwards.sum()),
        )
    keep &= ~backwards
    return t[keep], P[keep]


@dataclass(frozen=True)
class GroundPlane:
    """How 3D positions were mapped to the path's 2D frame: ``xy = (P - origin) @ axes.T``.

    Attributes
    ----------
    origin : (3,) array
    axes : (2, 3) array
        Orthonormal in-plane axes (rows).
    method : str
        ``"fit"`` (total least squares plane of the positions) or ``"xy" | "xz" | "yz"``.
    rms : float
        RMS distance of the positions from the plane, metres (0 for a coordinate plane).
    """

    origin: NDArray[np.float64]
    axes: NDArray[np.float64]
    method: str
    rms: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """The ``frame`` entry of ``path.json``."""
        return {
            "kind": "plane",
            "method": self.method,
            "origin": self.origin.tolist(),
            "axes": self.axes.tolist(),
            "rms_m": self.rms,
        }


def ground_plane(positions: ArrayLike, plane: str = "auto") -> GroundPlane:
    """The plane the path lies in.

    ``"xy" | "xz" | "yz"`` take the two coordinates as they are (origin 0). ``"auto"`` fits a
    plane to the positions (total least squares, :func:`navkit.geometry.fitting.fit_plane`) and uses its
    in-plane basis, origin at the first position, so e.g. KITTI camera poses (y down, ground =
    x-z) and TUM poses in any frame give a planar path. The in-plane axes are oriented so the
    path is seen from above: up is taken as -y when the plane's normal is closest to y (camera
    frames, y down) and +z otherwise (z-up world frames). If the positions are collinear (no plane)
    the line's own direction and a perpendicular are used.
    """
    from navkit.errors import DegenerateGeometryError
    from navkit.geometry.fitting import fit_plane

    P = np.asarray(positions, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] not in (2, 3) or len(P) == 0:
        raise InputError(
            f"has shape {P.shape}", field="positions", expected="(N, 2) or (N, 3) with N >= 1"
        )
    if not (np.isfinite(P).all() and np.abs(P).max() < 1e9):
        raise InputError(
            "has NaN, inf or coordinates beyond 1e9 m",
            field="positions",
            expected="finite positions (clean_track drops the bad ones)",
        )
    if plane in ("xy", "xz", "yz"):
        if P.shape[1] < 3 and plane != "xy":
            raise ConfigError(
                f"plane {plane!r} needs 3D positions", field="plane", expected="xy for 2D data"
            )
        i, j = _AXES[plane[0]], _AXES[plane[1]]
        axes = np.zeros((2, max(P.shape[1], 3)))
        axes[0, i] = axes[1, j] = 1.0
        return GroundPlane(origin=np.zeros(axes.shape[1]), axes=axes, method=plane)
    if plane != "auto":
        raise ConfigError(f"unknown plane {plane!r}", field="plane", expected="auto | xy | xz | yz")
    if P.shape[1] == 2:
        return GroundPlane(
            origin=np.zeros(3), axes=np.array([[1.0, 0, 0], [0, 1.0, 0]]), method="xy"
        )
    try:
        if len(P) < 3:
            raise DegenerateGeometryError("fewer than 3 positions")
        fit = fit_plane(P)
        axes = fit.basis()
        rms = fit.rms
    except DegenerateGeometryError:
        # collinear or identical positions: principal axes of the 3 x 3 scatter matrix (never
        # the N x N factor of a full SVD of the N x 3 data, which needs O(N^2) memory)
        axes, rms = _line_plane_axes(P), 0.0
    # Orientation: seen from "up" the path must not be mirrored (a left turn stays a left turn).
    # Up is not in the data; guess it from the frame convention: a plane normal along y is a
    # camera frame (OpenCV / KITTI / TUM cameras: y down, so up = -y), along z a z-up world
    # frame (up = +z).
    normal = np.cross(axes[0], axes[1])
    k = int(np.argmax(np.abs(normal)))
    up = {1: -1.0, 2: 1.0}.get(k, 1.0)
    if normal[k] * up < 0:
        axes = np.stack([axes[0], -axes[1]])
    return GroundPlane(origin=P[0].copy(), axes=axes, method="fit", rms=float(rms))


def _line_plane_axes(P: NDArray[np.float64]) -> NDArray[np.float64]:
    """In-plane axes for collinear positions: the line and a horizontal perpendicular.

    The line's direction is the principal axis of the 3 x 3 scatter matrix (O(N) memory, never
    the N x N factor of a full SVD). The second axis is perpendicular to the line and to a guessed
    up (z, or y when the line runs along z, as in a camera frame). Identical positions (no line)
    give the x-y axes.
    """
    c = P - P.mean(0)
    w, V = np.linalg.eigh(c.T @ c)
    if w[-1] <= 1e-24 * max(1.0, float(np.abs(P).max()) ** 2):
        return np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    d = V[:, -1]
    up = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([0.0, -1.0, 0.0])
    second = np.cross(up, d)
    return np.stack([d, second / np.linalg.norm(second)])


def to_plane(positions: ArrayLike, frame: GroundPlane) -> NDArray[np.float64]:
    """``(N, 2)`` in-plane coordinates of positions ``(N, 2 | 3)``."""
    P = np.asarray(positions, dtype=np.float64)
    if P.shape[1] == 2:
        P = np.c_[P, np.zeros(len(P))]
    return (P - frame.origin) @ frame.axes.T


def integrate_odometry(
    t: ArrayLike, v: ArrayLike, omega: ArrayLike, start: ArrayLike = (0.0, 0.0, 0.0)
) -> NDArray[np.float64]:
    """Dead-reckon wheel odometry ``time v omega`` into poses ``(N, 3)`` x, y, theta.

    Each interval holds the command of its first sample (zero-order hold) and is integrated
    exactly along the arc: ``dtheta = omega dt``,
    ``dx = v dt sinc(dtheta / 2) cos(theta + dtheta / 2)`` (the same for y with sin). Vectorised:
    the headings are a cumulative sum, then the displacements are too.
    """
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    v = np.asarray(v, dtype=np.float64).reshape(-1)
    w = np.asarray(omega, dtype=np.float64).reshape(-1)
    if not (len(t) == len(v) == len(w)) or len(t) == 0:
        raise InputError(
            f"lengths {len(t)}, {len(v)}, {len(w)}",
            field="odometry",
            expected="equal-length time, v, omega with at least one sample",
        )
    x0, y0, th0 = (float(a) for a in np.asarray(start, dtype=np.float64).reshape(3))
    dt = np.diff(t)
    dth = w[:-1] * dt
    theta = th0 + np.concatenate([[0.0], np.cumsum(dth)])
    chord = v[:-1] * dt * np.sinc(dth / (2.0 * np.pi))  # np.sinc(x) = sin(pi x) / (pi x)
    mid = theta[:-1] + 0.5 * dth
    x = x0 + np.concatenate([[0.0], np.cumsum(chord * np.cos(mid))])
    y = y0 + np.concatenate([[0.0], np.cumsum(chord * np.sin(mid))])
    return np.stack([x, y, theta], axis=1)
