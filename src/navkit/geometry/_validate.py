"""Array checks shared by the geometry functions (clear errors instead of NumPy tracebacks)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError


def as_points(
    points: ArrayLike, dim: int, name: str = "points", min_count: int = 0
) -> NDArray[np.float64]:
    """Return ``points`` as a float64 ``(N, dim)`` array, or raise :class:`InputError`."""
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"cannot be read as numbers: {exc}", field=name, expected=f"(N, {dim}) array of floats"
        ) from exc
    if arr.ndim == 1 and arr.shape[0] == dim:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise InputError(f"has shape {arr.shape}", field=name, expected=f"(N, {dim}) array")
    if arr.shape[0] < min_count:
        raise InputError(
            f"has {arr.shape[0]} rows", field=name, expected=f"at least {min_count} points"
        )
    return arr


def as_matrices(T: ArrayLike, size: int, name: str = "T") -> NDArray[np.float64]:
    """Return ``T`` as float64 ``(..., size, size)``, or raise :class:`InputError`."""
    arr = np.asarray(T, dtype=np.float64)
    if arr.ndim < 2 or arr.shape[-2:] != (size, size):
        raise InputError(
            f"has shape {arr.shape}",
            field=name,
            expected=f"({size}, {size}) or (N, {size}, {size}) array",
        )
    return arr
