"""Point-cloud files: KITTI ``.bin`` / ``.label``, PCD v0.7 and PLY.

All readers validate what they read and raise :class:`navkit.errors.FormatError` naming the file,
the field and what was expected; a file that does not exist raises
:class:`navkit.errors.DataNotFoundError`. Writers are atomic (:mod:`navkit.io.atomic`): a failed
write never leaves a half-written file.

Conventions
-----------
- Points are returned as ``(N, 3)`` float64 rows (x, y, z in the file's units, normally metres);
  every other per-point field keeps the file's dtype in :attr:`PointCloud.fields` (shape ``(N,)``,
  or ``(N, COUNT)`` for PCD fields with ``COUNT > 1``).
- Colours are ``(N, 3)`` uint8 RGB in :attr:`PointCloud.colors`. In PCD they are the packed
  ``rgb`` / ``rgba`` field (a float32 or uint32 holding ``0xAARRGGBB``); the alpha byte of an
  ``rgba`` field is kept as ``fields["alpha"]``.
- Organised clouds (PCD ``HEIGHT > 1``) keep their ``WIDTH x HEIGHT`` layout: point ``i`` is
  row ``i // width``, column ``i % width``; :meth:`PointCloud.grid` reshapes. Invalid points
  (NaN coordinates) are kept, never dropped.
- PCD ``binary_compressed`` uses LZF (liblzf's format); :func:`lzf_decompress` and
  :func:`lzf_compress` implement it without extra dependencies.

One module per format: :mod:`navkit.io.kitti`, :mod:`navkit.io.pcd`, :mod:`navkit.io.ply`,
:mod:`navkit.io.lzf` (the codec) and :mod:`navkit.io.cloud` (the :class:`PointCloud` type). This
module re-exports their public names, so ``from navkit.io.pointcloud import read_pcd`` keeps
working, and :func:`read_pointcloud` picks the reader by the file's suffix.
"""

from __future__ import annotations

from navkit.errors import FormatError
from navkit.io.cloud import PathLike, PointCloud
from navkit.io.kitti import read_kitti_bin, read_kitti_labels, write_kitti_bin, write_kitti_labels
from navkit.io.lzf import LZFError, lzf_compress, lzf_decompress
from navkit.io.pcd import read_pcd, write_pcd
from navkit.io.ply import read_ply, write_ply

__all__ = [
    "LZFError",
    "PointCloud",
    "lzf_compress",
    "lzf_decompress",
    "read_kitti_bin",
    "read_kitti_labels",
    "read_pcd",
    "read_ply",
    "read_pointcloud",
    "write_kitti_bin",
    "write_kitti_labels",
    "write_pcd",
    "write_ply",
]


def read_pointcloud(path: PathLike) -> PointCloud:
    """Read a ``.pcd``, ``.ply`` or KITTI ``.bin`` file as a :class:`PointCloud` (by suffix).

    A KITTI scan's reflectance becomes ``fields["intensity"]`` (float32).

    Raises
    ------
    FormatError
        For any other suffix, or a file that does not follow its format.
    """
    from pathlib import Path

    suffix = Path(path).suffix.lower()
    if suffix == ".pcd":
        return read_pcd(path)
    if suffix == ".ply":
        return read_ply(path)
    if suffix == ".bin":
        scan = read_kitti_bin(path)
        return PointCloud(scan[:, :3].astype("float64"), {"intensity": scan[:, 3].copy()})
    raise FormatError(
        f"unknown point-cloud suffix {suffix!r}",
        source=path,
        field="suffix",
        expected=".pcd, .ply or .bin (KITTI)",
    )
