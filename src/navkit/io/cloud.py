"""The point-cloud type shared by the KITTI, PCD, PLY and ROS readers.

:class:`PointCloud` validates its arrays at construction; :func:`existing_file` is the readers'
common first check (a missing file raises :class:`navkit.errors.DataNotFoundError`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from navkit.errors import DataNotFoundError, InputError

__all__ = ["PathLike", "PointCloud", "existing_file"]

PathLike = str | os.PathLike[str]


@dataclass(frozen=True, eq=False)
class PointCloud:
    """A point cloud with optional per-point fields, colours and mesh faces.

    Parameters
    ----------
    points : (N, 3) float64 array
        x, y, z of each point (NaN rows = invalid points of an organised cloud).
    fields : dict of str to array, optional
        Other per-point fields, each of length ``N`` (``(N,)`` or ``(N, k)``), in the file's
        dtype, e.g. ``intensity``, ``normal_x``, ``label``.
    width, height : int, optional
        Layout; ``height == 1`` (default) is an unorganised cloud, ``width * height == N``.
    colors : (N, 3) uint8 array, optional
        RGB colours.
    faces : (M, k) int64 array, optional
        Polygon vertex indices (PLY meshes); ``k == 3`` for triangles.
    """

    points: NDArray[np.float64]
    fields: dict[str, NDArray[Any]] = field(default_factory=dict)
    width: int = -1
    height: int = 1
    colors: NDArray[np.uint8] | None = None
    faces: NDArray[np.int64] | None = None

    def __post_init__(self) -> None:
        with np.errstate(invalid="ignore"):  # signalling NaNs (from files) are NaN points
            pts = np.asarray(self.points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise InputError(
                f"points has shape {pts.shape}", field="points", expected="an (N, 3) array"
            )
        n = len(pts)
        object.__setattr__(self, "points", pts)
        width = n if self.width == -1 and self.height == 1 else int(self.width)
        height = int(self.height)
        if width < 0 or height < 1 or width * height != n:
            raise InputError(
                f"width {width} x height {height} does not match {n} points",
                field="width/height",
                expected="width * height == number of points",
            )
        object.__setattr__(self, "width", width)
        object.__setattr__(self, "height", height)
        fields = {}
        for name, value in dict(self.fields).items():
            arr = np.asarray(value)
            if arr.ndim == 0 or len(arr) != n:
                raise InputError(
                    f"has {0 if arr.ndim == 0 else len(arr)} values for {n} points",
                    field=name,
                    expected="one value (or one row) per point",
                )
            fields[str(name)] = arr
        object.__setattr__(self, "fields", fields)
        if self.colors is not None:
            col = np.asarray(self.colors)
            if col.shape != (n, 3):
                raise InputError(
                    f"colors has shape {col.shape}", field="colors", expected=f"({n}, 3) uint8"
                )
            if col.dtype != np.uint8:
                if np.issubdtype(col.dtype, np.floating) and np.nanmax(col, initial=0.0) <= 1.0:
                    col = np.clip(np.round(col * 255.0), 0, 255)
                col = col.astype(np.uint8)
            object.__setattr__(self, "colors", col)
        if self.faces is not None:
            fc = np.asarray(self.faces, dtype=np.int64)
            if fc.ndim != 2 or fc.shape[1] < 3:
                raise InputError(
                    f"faces has shape {fc.shape}", field="faces", expected="an (M, k>=3) array"
                )
            if fc.size and (fc.min() < 0 or fc.max() >= n):
                raise InputError(
                    f"face indices span [{fc.min()}, {fc.max()}] for {n} vertices",
                    field="faces",
                    expected=f"indices in [0, {n - 1}]",
                )
            object.__setattr__(self, "faces", fc)

    def __len__(self) -> int:
        return len(self.points)

    @property
    def is_organized(self) -> bool:
        """True for an image-like cloud (``height > 1``)."""
        return self.height > 1

    def grid(self) -> NDArray[np.float64]:
        """The points as an ``(height, width, 3)`` grid (a view; row-major like the file)."""
        return self.points.reshape(self.height, self.width, 3)

    @property
    def valid(self) -> NDArray[np.bool_]:
        """``(N,)`` True where all three coordinates are finite."""
        return np.asarray(np.isfinite(self.points).all(axis=1))


def existing_file(path: PathLike) -> Path:
    """``path`` as a :class:`~pathlib.Path`; :class:`DataNotFoundError` if it is not a file."""
    p = Path(path)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: no such file")
    return p
