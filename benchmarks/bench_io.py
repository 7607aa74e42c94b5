"""I/O benchmarks: reading point clouds, navkit beside Open3D (or NumPy where Open3D cannot).

Rows (milliseconds per read / write, median after a warm-up, ratio = peer / navkit, > 1 means
navkit is faster):

- KITTI ``.bin`` (SemanticKITTI 000000, ~124k points): ``read_kitti_bin`` vs a bare
  ``np.fromfile(...).reshape(-1, 4)`` - Open3D has no KITTI reader, so the peer is the NumPy
  floor (navkit adds the size check and the path handling).
- PCD ``binary_compressed``: pcl-room scan 1 (112k points), pcl-kinect capture 1 (organised
  640 x 480, NaN kept) and ISPRS samp11 (38k airborne points, UTM) - ``read_pcd`` vs
  ``open3d.io.read_point_cloud``.
- PCD ``binary`` and ``ascii``: the room scan written to a temp folder by navkit, read by both.
- PCD ``binary_compressed`` *writing*: ``write_pcd(compressed=True)`` vs
  ``open3d.io.write_point_cloud(compressed=True)`` on the room scan.
- LZF decompression and compression throughput (MB/s) on the room scan's payload.

Run: ``python -m benchmarks io`` (``--quick`` for fewer repeats).
"""

from __future__ import annotations

import logging
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import Row, median_time, time_ratio
from navkit import datasets
from navkit.errors import DataNotFoundError
from navkit.io.pointcloud import (
    lzf_compress,
    lzf_decompress,
    read_kitti_bin,
    read_pcd,
    write_pcd,
)

log = logging.getLogger(__name__)

AREA = "io"


def _open3d() -> Any:
    try:
        import open3d as o3d
    except ImportError as exc:  # missing package or a missing system library (libusb)
        log.warning("open3d not importable (%s): peer columns left empty", exc)
        return None
    return o3d


def _find(relative: str) -> Path | None:
    try:
        return datasets.find(relative)
    except DataNotFoundError as exc:
        log.warning("skipping: %s", exc)
        return None


def _ms(seconds: float | None) -> float | None:
    return None if seconds is None else seconds * 1e3


def _row(name: str, nk_s: float, peer_s: float | None, peer_name: str, note: str) -> Row:
    return Row(
        area=AREA,
        benchmark=name,
        unit="ms",
        navkit=_ms(nk_s),
        peer=_ms(peer_s),
        peer_name=peer_name if peer_s is not None else "",
        ratio=time_ratio(nk_s, peer_s),
        note=note,
    )


def run(quick: bool = False) -> list[Row]:
    """Time the readers and writers; see the module docstring for the rows."""
    repeats = 3 if quick else 9
    o3d = _open3d()
    rows: list[Row] = []

    # KITTI .bin: navkit vs the bare NumPy read
    kitti = _find("lidar/semantickitti-seq00/000000.bin")
    if kitti is not None:
        n = len(read_kitti_bin(kitti))
        nk = median_time(lambda: read_kitti_bin(kitti), repeats=repeats * 3)
        ref = median_time(
            lambda: np.fromfile(kitti, dtype="<f4").reshape(-1, 4), repeats=repeats * 3
        )
        rows.append(
            _row(
                f"read KITTI .bin ({n} pts)",
                nk,
                ref,
                "np.fromfile",
                "Open3D has no KITTI reader: the peer is the bare NumPy floor",
            )
        )

    def o3d_read(path: Path) -> Any:
        return o3d.io.read_point_cloud(
            str(path), remove_nan_points=False, remove_infinite_points=False
        )

    for rel, label in (
        ("scans3d/pcl-room/room_scan1.pcd", "pcl-room scan1"),
        ("rgbd/pcl-kinect/capture0001.pcd", "pcl-kinect 640x480"),
        ("lidar/isprs-terrain/samp11-utm.pcd", "ISPRS samp11 UTM"),
    ):
        path = _find(rel)
        if path is None:
            continue
        cloud = read_pcd(path)
        nk = median_time(lambda p=path: read_pcd(p), repeats=repeats)
        peer = median_time(lambda p=path: o3d_read(p), repeats=repeats) if o3d else None
        note = "LZF decode in pure Python (per token)"
        if o3d is not None:
            same = np.array_equal(np.asarray(o3d_read(path).points), cloud.points, equal_nan=True)
            note += "; points identical to Open3D" if same else "; POINTS DIFFER from Open3D"
        rows.append(
            _row(
                f"read PCD binary_compressed, {label} ({len(cloud)} pts)", nk, peer, "open3d", note
            )
        )

    room = _find("scans3d/pcl-room/room_scan1.pcd")
    if room is not None:
        cloud = read_pcd(room)
        with tempfile.TemporaryDirectory() as tmp:
            for encoding in ("binary", "ascii"):
                out = Path(tmp) / f"room_{encoding}.pcd"
                write_pcd(out, cloud, binary=encoding == "binary")
                nk = median_time(lambda o=out: read_pcd(o), repeats=repeats)
                peer = median_time(lambda o=out: o3d_read(o), repeats=repeats) if o3d else None
                rows.append(
                    _row(
                        f"read PCD {encoding}, pcl-room scan1 written by navkit",
                        nk,
                        peer,
                        "open3d",
                        "vectorised: np.frombuffer / string-array parse",
                    )
                )
            out_nk = Path(tmp) / "w_navkit.pcd"
            out_o3d = Path(tmp) / "w_open3d.pcd"
            nk = median_time(
                lambda: write_pcd(out_nk, cloud, compressed=True), repeats=max(3, repeats // 3)
            )
            peer = None
            note = f"navkit file {out_nk.stat().st_size / 1e6:.2f} MB"
            if o3d is not None:
                pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.points))
                peer = median_time(
                    lambda: o3d.io.write_point_cloud(str(out_o3d), pc, compressed=True),
                    repeats=max(3, repeats // 3),
                )
                note += f", Open3D file {out_o3d.stat().st_size / 1e6:.2f} MB"
            rows.append(
                _row("write PCD binary_compressed, pcl-room scan1", nk, peer, "open3d", note)
            )

        payload = b"".join(cloud.points[:, k].astype("<f4").tobytes() for k in range(3))
        comp = lzf_compress(payload)
        mb = len(payload) / 1e6
        t_dec = median_time(lambda: lzf_decompress(comp, len(payload)), repeats=repeats)
        t_enc = median_time(lambda: lzf_compress(payload), repeats=max(3, repeats // 3))
        ratio_note = f"{mb:.2f} MB payload, compressed to {len(comp) / len(payload):.0%}"
        rows.append(Row(AREA, "LZF decompress throughput", "MB/s", mb / t_dec, note=ratio_note))
        rows.append(Row(AREA, "LZF compress throughput", "MB/s", mb / t_enc, note=ratio_note))
    return rows
