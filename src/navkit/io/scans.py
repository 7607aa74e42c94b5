"""Range data of any supported format as a :class:`~navkit.obstacles.ScanGrid`.

One reader for every input ``navkit obstacles detect`` accepts:

- ``.npz``: ``ranges (n_az, n_el)``, ``azimuth``, ``elevation`` (rad), optionally
  ``sensor_height`` (m), ``R_body_sensor (3, 3)`` and ``max_range`` (a
  :class:`~navkit.sensors.RangeScan`);
- ``.bin``: a KITTI Velodyne scan (float32 ``x, y, z, reflectance``);
- ``.pcd`` / ``.ply``: organised clouds keep their grid, others are spinning-lidar clouds;
- ``.npy``: an organised ``(H, W, >=3)`` cloud or an ``(N, >=3)`` cloud;
- depth images (``.png``, ``.pgm``, ``.tif``): need the pinhole intrinsics and the depth scale.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from navkit.errors import ConfigError, FormatError, InputError

__all__ = ["SCAN_SUFFIXES", "ScanInput", "check_scan_input", "read_scan_grid"]

SCAN_SUFFIXES = (".npz", ".bin", ".pcd", ".ply", ".npy", ".png", ".pgm", ".tif", ".tiff")
"""File suffixes :func:`read_scan_grid` reads."""


@dataclass(frozen=True, eq=False)
class ScanInput:
    """One input read as a scan grid.

    Attributes
    ----------
    grid : ScanGrid
        Sensor-frame points on an azimuth x elevation grid, with the way back to the input.
    kind : str
        ``"grid"`` (a ``.npz`` range scan), ``"cloud"`` (an unorganised lidar cloud),
        ``"organized"`` or ``"depth"``.
    sensor_height_m : float or None
        The height stored in the file (``.npz`` only), metres.
    R_body_sensor : (3, 3) array or None
        The mounting rotation stored in the file (``.npz`` only).
    """

    grid: Any
    kind: str
    sensor_height_m: float | None = None
    R_body_sensor: NDArray[np.float64] | None = None


def _read_npz(path: Path) -> ScanInput:
    from navkit.obstacles.grids import ScanGrid
    from navkit.sensors import RangeScan

    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (OSError, ValueError) as exc:
        raise FormatError(f"cannot be read as .npz: {exc}", source=path) from exc
    for key in ("ranges", "azimuth", "elevation"):
        if key not in data:
            raise FormatError(
                f"has no array {key!r} (it has {sorted(data)})",
                source=path,
                field=key,
                expected="ranges (n_azimuth, n_elevation), azimuth, elevation (rad), "
                "sensor_height (m)",
            )
        if data[key].dtype.kind not in "fiu":
            raise FormatError(
                f"has dtype {data[key].dtype}", source=path, field=key, expected="numbers"
            )
    height = float(data["sensor_height"]) if "sensor_height" in data else None
    try:
        scan = RangeScan(
            data["ranges"],
            data["azimuth"],
            data["elevation"],
            sensor_height=height or 0.0,
            R_body_sensor=data.get("R_body_sensor", np.eye(3)),
            max_range=float(data.get("max_range", np.inf)),
        )
    except InputError as exc:
        raise FormatError(exc.message, source=path, field=exc.field, expected=exc.expected) from exc
    ia = np.argsort(scan.azimuth, kind="stable")
    ie = np.argsort(scan.elevation, kind="stable")
    pts = scan.points("sensor")[ia][:, ie]
    n_az, n_el = scan.shape
    cell = np.empty((n_az, n_el), dtype=np.int64)
    cell[np.ix_(ia, ie)] = np.arange(n_az * n_el).reshape(n_az, n_el)  # input (a, e) -> cell
    cell_of_point = cell.ravel().copy()
    cell_of_point[~scan.valid.ravel()] = -1
    az = scan.azimuth[ia]
    step = float(np.median(np.diff(az))) if len(az) > 2 else 0.0
    wraps = bool(len(az) > 2 and np.ptp(az) + 1.5 * step >= 2 * np.pi)
    grid = ScanGrid(pts, cell_of_point, az, wraps, "npz")
    R = np.asarray(scan.R_body_sensor, dtype=np.float64) if "R_body_sensor" in data else None
    return ScanInput(grid, "grid", height, R)


def read_scan_grid(
    path: str | Path,
    *,
    rings: int | None = None,
    columns: int | None = None,
    ring_method: str = "auto",
    intrinsics: tuple[float, float, float, float] | None = None,
    depth_scale: float = 1000.0,
) -> ScanInput:
    """Read one range-data file as a scan grid (see the module docstring for the formats).

    Parameters
    ----------
    path : str or path
    rings, columns : int, optional
        Beam count and azimuth columns of an unorganised lidar cloud (default: recovered).
    ring_method : {"auto", "order", "elevation"}
        How an unorganised cloud's rings are recovered (:func:`~navkit.obstacles.grids.cloud_to_grid`).
    intrinsics : (fx, fy, cx, cy), optional
        Pinhole intrinsics of a depth image (pixels); required for depth images.
    depth_scale : float
        Raw depth units per metre of a 16-bit depth image (1000 = millimetres).

    Raises
    ------
    FormatError, ConfigError
        Unreadable files, missing arrays, a depth image without intrinsics.
    """
    from navkit.obstacles.grids import cloud_to_grid, depth_to_grid, organized_to_grid

    path = Path(path)
    suffix = path.suffix.lower()

    def from_cloud(points: Any) -> ScanInput:
        grid = cloud_to_grid(
            points, n_rings=rings, n_columns=columns, ring_method=ring_method, source=str(path)
        )
        return ScanInput(grid, "cloud")

    if suffix == ".npz":
        return _read_npz(path)
    if suffix == ".bin":
        from navkit.io.pointcloud import read_kitti_bin

        return from_cloud(read_kitti_bin(path))
    if suffix in (".pcd", ".ply"):
        from navkit.io.pointcloud import read_pcd, read_ply

        cloud = read_pcd(path) if suffix == ".pcd" else read_ply(path)
        if cloud.height > 1:
            return ScanInput(organized_to_grid(cloud.grid(), source=str(path)), "organized")
        return from_cloud(cloud.points)
    if suffix == ".npy":
        try:
            arr = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise FormatError(f"cannot be read as .npy: {exc}", source=path) from exc
        if arr.ndim == 3:
            return ScanInput(organized_to_grid(arr[..., :3], source=str(path)), "organized")
        if arr.ndim == 2:
            return from_cloud(arr)
        raise FormatError(
            f"has shape {arr.shape}", source=path, expected="(H, W, >=3) organised or (N, >=3)"
        )
    from navkit.io.images import read_depth
    from navkit.sensors import PinholeCamera

    if intrinsics is None:
        raise ConfigError(
            "a depth image needs the camera intrinsics",
            source=path,
            field="--intrinsics",
            expected="--intrinsics FX,FY,CX,CY (pixels) or a depth-camera --sensor preset",
        )
    depth = read_depth(path, depth_scale)
    fx, fy, cx, cy = intrinsics
    cam = PinholeCamera(fx, fy, cx, cy, depth.shape[1], depth.shape[0])
    return ScanInput(depth_to_grid(depth, cam, source=str(path)), "depth")


def check_scan_input(path: str | Path) -> None:
    """Check an input's container before any run writes an output: the cheap part of reading it
    (a ``.bin`` size that is a whole number of points, a ``.npy`` header whose declared size the
    file holds, an ``.npz`` directory with ``ranges``, a PCD or PLY header).

    A file that passes can still fail when read in full (a corrupt body); a run reports that
    frame as failed and goes on.

    Raises
    ------
    DataNotFoundError, FormatError
        Naming the file and what is wrong.
    """
    import zipfile

    from navkit.errors import DataNotFoundError

    p = Path(path)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: no such file")
    size = p.stat().st_size
    suffix = p.suffix.lower()
    if size == 0:
        raise FormatError("is empty", source=p, expected=f"a {suffix} scan")
    if suffix == ".bin" and size % 16:
        raise FormatError(
            f"{size} bytes is not a whole number of points",
            source=p,
            expected="KITTI float32 x, y, z, reflectance (16 bytes a point)",
        )
    if suffix == ".npy":
        _check_npy_header(p, size)
    elif suffix == ".npz":
        try:
            with zipfile.ZipFile(p) as z:
                names = z.namelist()
        except (zipfile.BadZipFile, OSError) as exc:
            raise FormatError(
                f"not an .npz archive ({exc})", source=p, expected="an .npz"
            ) from None
        if "ranges.npy" not in names:
            raise FormatError(
                "has no 'ranges' array", source=p, field="ranges", expected="a range scan .npz"
            )
    elif suffix in (".pcd", ".ply"):
        with open(p, "rb") as fh:
            head = fh.read(65536)
        if suffix == ".pcd":
            from navkit.io.pcd import _parse_pcd_header

            _parse_pcd_header(p, head)
        else:
            from navkit.io.ply import _parse_ply_header

            _parse_ply_header(p, head)


def _check_npy_header(p: Path, size: int) -> None:
    fmt = np.lib.format
    try:
        with open(p, "rb") as fh:
            major, _ = fmt.read_magic(fh)
            read = fmt.read_array_header_1_0 if major == 1 else fmt.read_array_header_2_0
            shape, _, dtype = read(fh, max_header_size=65536)
            offset = fh.tell()
    except (ValueError, OSError, SyntaxError) as exc:
        raise FormatError(f"not a .npy array ({exc})", source=p, expected="a .npy file") from None
    need = int(np.prod(shape, dtype=np.float64)) * dtype.itemsize
    if need > size - offset:
        raise FormatError(
            f"declares {need} bytes of data, the file holds {size - offset}",
            source=p,
            expected="a complete .npy file",
        )
