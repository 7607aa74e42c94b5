"""A unicycle (differential-drive) robot: exact integration of constant (v, omega) steps."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError

__all__ = ["simulate_unicycle", "unicycle_step"]


def _arc(
    theta: NDArray[np.float64], v: NDArray[np.float64], omega: NDArray[np.float64], dt: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Displacement ``(dx, dy)`` of one step along the exact arc (straight line when omega = 0).

    ``dx = v dt cos(theta + omega dt / 2) sinc(omega dt / 2)`` and the same with ``sin`` for
    ``dy`` - the closed form of ``v / omega (sin(theta + omega dt) - sin theta)``, well defined
    at ``omega = 0`` (``np.sinc(x) = sin(pi x) / (pi x)``).
    """
    half = 0.5 * omega * dt
    chord = v * dt * np.sinc(half / np.pi)
    return chord * np.cos(theta + half), chord * np.sin(theta + half)


def unicycle_step(
    state: ArrayLike, v: ArrayLike, omega: ArrayLike, dt: float
) -> NDArray[np.float64]:
    """One step of the unicycle ``x' = v cos theta, y' = v sin theta, theta' = omega``.

    Parameters
    ----------
    state : (..., 3) array
        Poses ``(x, y, theta)`` (metres, radians).
    v, omega : float or (...) arrays
        Forward speed (m/s) and turn rate (rad/s), constant over the step.
    dt : float
        Step length, seconds.

    Returns
    -------
    (..., 3) array
        The poses after the step (exact for constant inputs; theta not wrapped).
    """
    s = np.asarray(state, dtype=np.float64)
    if s.shape[-1:] != (3,):
        raise InputError(
            f"has shape {s.shape}", field="state", expected="(..., 3) poses x, y, theta"
        )
    v_ = np.asarray(v, dtype=np.float64)
    w_ = np.asarray(omega, dtype=np.float64)
    dx, dy = _arc(s[..., 2], v_, w_, float(dt))
    return np.stack(
        np.broadcast_arrays(s[..., 0] + dx, s[..., 1] + dy, s[..., 2] + w_ * dt), axis=-1
    )


def simulate_unicycle(
    v: ArrayLike, omega: ArrayLike, dt: float, start: ArrayLike = (0.0, 0.0, 0.0)
) -> NDArray[np.float64]:
    """Poses of a unicycle driven by ``N`` constant-input steps (vectorised, exact arcs).

    Parameters
    ----------
    v, omega : (N,) arrays
        Forward speed (m/s) and turn rate (rad/s) of each step.
    dt : float
        Step length, seconds.
    start : (3,) array
        Initial pose ``(x, y, theta)``.

    Returns
    -------
    (N + 1, 3) array
        ``start`` followed by the pose after each step (theta unwrapped, continuous).
    """
    v_ = np.atleast_1d(np.asarray(v, dtype=np.float64))
    w_ = np.atleast_1d(np.asarray(omega, dtype=np.float64))
    if v_.ndim != 1 or w_.shape != v_.shape:
        raise InputError(
            f"v {v_.shape} and omega {w_.shape}",
            field="v/omega",
            expected="two (N,) arrays of the same length",
        )
    if not (np.isfinite(dt) and dt > 0):
        raise InputError(f"is {dt}", field="dt", expected="a positive step in seconds")
    if not (np.all(np.isfinite(v_)) and np.all(np.isfinite(w_))):
        raise InputError("contains NaN or inf", field="v/omega", expected="finite inputs")
    x0, y0, th0 = (float(c) for c in np.asarray(start, dtype=np.float64).reshape(3))
    theta = th0 + np.concatenate([[0.0], np.cumsum(w_ * dt)])
    dx, dy = _arc(theta[:-1], v_, w_, float(dt))
    out = np.empty((v_.size + 1, 3))
    out[:, 0] = x0 + np.concatenate([[0.0], np.cumsum(dx)])
    out[:, 1] = y0 + np.concatenate([[0.0], np.cumsum(dy)])
    out[:, 2] = theta
    return out
