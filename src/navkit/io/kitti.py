"""KITTI / SemanticKITTI Velodyne scans (``.bin``) and point labels (``.label``).

Readers check the file's size before reading (a ``.bin`` holds 16-byte records, a ``.label``
4-byte ones) and raise :class:`navkit.errors.FormatError` naming the file; writers are atomic.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import FormatError, InputError
from navkit.io.atomic import atomic_write
from navkit.io.cloud import PathLike
from navkit.io.cloud import existing_file as _existing

__all__ = ["read_kitti_bin", "read_kitti_labels", "write_kitti_bin", "write_kitti_labels"]


def read_kitti_bin(path: PathLike) -> NDArray[np.float32]:
    """Read a KITTI / SemanticKITTI Velodyne scan.

    Parameters
    ----------
    path : str or path
        A ``.bin`` file: little-endian float32 records ``x, y, z, reflectance`` (metres, [0, 1]).

    Returns
    -------
    (N, 4) float32 array
        One row per point, in the Velodyne frame (x forward, y left, z up).

    Raises
    ------
    FormatError
        If the size is not a multiple of 16 bytes (a truncated or foreign file).
    """
    p = _existing(path)
    size = p.stat().st_size
    if size % 16:
        raise FormatError(
            f"size is {size} bytes, not a multiple of 16 (truncated?)",
            source=p,
            field="points",
            expected="float32 records x, y, z, reflectance (16 bytes each)",
        )
    return np.fromfile(p, dtype="<f4").reshape(-1, 4)


def write_kitti_bin(path: PathLike, points: ArrayLike) -> None:
    """Write ``(N, 4)`` (x, y, z, reflectance) or ``(N, 3)`` (reflectance 0) as a KITTI ``.bin``."""
    pts = np.asarray(points, dtype=np.float32)
    if pts.ndim != 2 or pts.shape[1] not in (3, 4):
        raise InputError(
            f"points has shape {pts.shape}", field="points", expected="an (N, 3) or (N, 4) array"
        )
    if pts.shape[1] == 3:
        pts = np.column_stack([pts, np.zeros(len(pts), np.float32)])
    with atomic_write(path, "wb") as fh:
        fh.write(np.ascontiguousarray(pts, dtype="<f4").tobytes())


def read_kitti_labels(
    path: PathLike, n_points: int | None = None
) -> tuple[NDArray[np.uint16], NDArray[np.uint16]]:
    """Read SemanticKITTI point labels.

    Parameters
    ----------
    path : str or path
        A ``.label`` file: one little-endian uint32 per point.
    n_points : int, optional
        Number of points of the matching scan; a different label count is an error.

    Returns
    -------
    semantic : (N,) uint16
        Class id ``l & 0xFFFF`` (names in ``semantic-kitti.yaml``).
    instance : (N,) uint16
        Instance id ``l >> 16``.
    """
    p = _existing(path)
    size = p.stat().st_size
    if size % 4:
        raise FormatError(
            f"size is {size} bytes, not a multiple of 4 (truncated?)",
            source=p,
            field="labels",
            expected="one uint32 per point",
        )
    raw = np.fromfile(p, dtype="<u4")
    if n_points is not None and len(raw) != n_points:
        raise FormatError(
            f"holds {len(raw)} labels but the scan has {n_points} points",
            source=p,
            field="labels",
            expected=f"{n_points} labels",
        )
    return (raw & 0xFFFF).astype(np.uint16), (raw >> 16).astype(np.uint16)


def write_kitti_labels(
    path: PathLike, semantic: ArrayLike, instance: ArrayLike | None = None
) -> None:
    """Write SemanticKITTI labels ``semantic | instance << 16`` as uint32."""
    sem = np.asarray(semantic).astype(np.uint32)
    inst = np.zeros_like(sem) if instance is None else np.asarray(instance).astype(np.uint32)
    if sem.ndim != 1 or inst.shape != sem.shape:
        raise InputError(
            f"semantic {sem.shape} / instance {inst.shape}",
            field="labels",
            expected="two (N,) arrays of the same length",
        )
    with atomic_write(path, "wb") as fh:
        fh.write(((sem & 0xFFFF) | (inst << 16)).astype("<u4").tobytes())
