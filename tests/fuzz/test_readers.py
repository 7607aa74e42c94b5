"""Every file reader fed mutations of small valid files: truncations, flipped bytes, lying size
fields, random bytes and non-UTF-8 text. Each case must end in a navkit error or a valid result,
with no other exception and a bounded peak of memory (see ``conftest.check``)."""

from __future__ import annotations

import gzip
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from navkit import datasets
from navkit.errors import DataNotFoundError

from .conftest import check

HUGE = [b"4294967295", b"4294967296", b"99999999999999", b"-1", b"0", b"nan", b"1e308", b"-0"]


def mutations(base: bytes) -> st.SearchStrategy[bytes]:
    """Mutations of ``base``: each kind the issue lists, plus combinations."""
    n = len(base)
    truncate = st.integers(0, max(n - 1, 0)).map(lambda k: base[:k])
    flip = st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, 255)), min_size=1, max_size=8)

    def apply_flips(flips: list[tuple[int, int]]) -> bytes:
        b = bytearray(base)
        for i, v in flips:
            b[i] = v
        return bytes(b)

    numbers = [m.span() for m in re.finditer(rb"-?\d+(\.\d+)?(e[-+]?\d+)?", base[:2048])]

    def lie(choice: tuple[int, int]) -> bytes:
        (a, b), k = numbers[choice[0] % len(numbers)], choice[1]
        return base[:a] + HUGE[k % len(HUGE)] + base[b:]

    kinds = [
        truncate,
        flip.map(apply_flips),
        st.binary(max_size=4096),
        st.integers(0, n).map(lambda k: base[:k] + b"\xff\xfe\x80\xc3(" + base[k:]),
        st.integers(0, n).map(lambda k: base[:k] + base[k:] * 2),  # duplicated tail
    ]
    if numbers:
        kinds.append(st.tuples(st.integers(0, 10**6), st.integers(0, 10**6)).map(lie))
    return st.one_of(*kinds)


# ------------------------------------------------------------------ the small valid files
def _cloud():  # type: ignore[no-untyped-def]
    from navkit.io.pointcloud import PointCloud

    rng = np.random.default_rng(0)
    pts = rng.normal(size=(40, 3))
    pts[3] = np.nan
    return PointCloud(
        pts,
        {"intensity": rng.random(40).astype(np.float32)},
        colors=rng.integers(0, 255, (40, 3), dtype=np.uint8),
    )


def _trajectory():  # type: ignore[no-untyped-def]
    from navkit.geometry import se3_from_rt
    from navkit.io.trajectory import Trajectory

    t = np.arange(12) * 0.1
    poses = np.stack([se3_from_rt(np.eye(3), [k * 0.1, np.sin(k), 0.0]) for k in range(12)])
    return Trajectory(t, poses)


def _write(kind: str, folder: Path) -> Path:
    """Write a small valid file of ``kind`` into ``folder``; return its path."""
    from navkit.io import images, maps, pointcloud, trajectory
    from navkit.io.pathjson import write_path_json

    p = folder / kind
    if kind == "kitti.bin":
        pointcloud.write_kitti_bin(p, np.random.default_rng(1).normal(size=(30, 4)))
    elif kind == "kitti.label":
        pointcloud.write_kitti_labels(p, np.arange(30) % 7, np.arange(30) % 3)
    elif kind in ("ascii.pcd", "binary.pcd", "compressed.pcd"):
        pointcloud.write_pcd(
            p, _cloud(), binary=kind != "ascii.pcd", compressed=kind == "compressed.pcd"
        )
    elif kind in ("ascii.ply", "binary.ply"):
        c = _cloud()
        faces = np.array([[0, 1, 2], [2, 4, 5], [5, 6, 7]])
        pointcloud.write_ply(p, c.points, c.colors, faces, binary=kind == "binary.ply")
    elif kind == "tum.txt":
        trajectory.write_tum(p, _trajectory())
    elif kind == "kitti_poses.txt":
        trajectory.write_kitti_poses(p, _trajectory())
    elif kind == "euroc.csv":
        rows = [
            f"{1403636579758555392 + k * 5000000},{k * 0.01},{np.sin(k)},0.8,1,0,0,0"
            for k in range(12)
        ]
        p.write_text("#timestamp,p_x,p_y,p_z,q_w,q_x,q_y,q_z\n" + "\n".join(rows) + "\n")
    elif kind == "odometry.dat":
        p.write_text("".join(f"{k * 0.1:.3f} {0.2:.3f} {0.1 * np.sin(k):.3f}\n" for k in range(12)))
    elif kind == "image.png":
        images.write_image(p, np.random.default_rng(2).integers(0, 255, (6, 8, 3), dtype=np.uint8))
    elif kind == "depth.png":
        images.write_depth(p, np.random.default_rng(3).uniform(0.5, 4, (6, 8)))
    elif kind == "disparity.pfm":
        images.write_pfm(p, np.random.default_rng(4).uniform(0, 60, (6, 8)).astype(np.float32))
    elif kind == "map.yaml":
        grid = np.full((6, 8), -1, np.int8)
        grid[2:4, 2:6] = 0
        grid[0] = 100
        maps.write_occupancy_grid(folder / "map", grid, 0.05, (1.0, -2.0))
    elif kind == "path.json":
        from navkit.path.approximator import approximate

        s = np.linspace(0, 3, 60)
        write_path_json(p, approximate(np.c_[s, np.sin(s)], timed=False).spline)
    elif kind == "middlebury_calib.txt":
        p.write_text(
            "cam0=[1758.23 0 370.34; 0 1758.23 248.29; 0 0 1]\n"
            "cam1=[1758.23 0 370.34; 0 1758.23 248.29; 0 0 1]\n"
            "doffs=0\nbaseline=111.53\nwidth=741\nheight=497\nndisp=290\nvmin=23\nvmax=245\n"
        )
    elif kind == "generic_calib.yaml":
        from navkit.io.stereo import write_generic_yaml_calib
        from navkit.sensors import PinholeCamera, StereoRig

        write_generic_yaml_calib(p, StereoRig(PinholeCamera.from_fov(64, 48, 90.0), 0.2))
    elif kind == "array.npy":
        np.save(p, np.random.default_rng(5).normal(size=(6, 4)))
    elif kind == "scan.npz":
        np.savez_compressed(p, ranges=np.ones((4, 5)), azimuth=np.arange(4.0))
    elif kind == "carmen.log":
        try:
            src = datasets.find("laser2d/intel-corrected.log.gz")
        except DataNotFoundError as exc:
            pytest.skip(f"recorded data absent: {exc}")
        keep: list[str] = []
        with gzip.open(src, "rt") as fh:
            for ln in fh:
                if ln.startswith("FLASER") or (ln.startswith("ODOM") and len(keep) % 7 == 0):
                    keep.append(ln)
                if sum(k.startswith("FLASER") for k in keep[-1:]) and len(keep) > 12:
                    break
        p.write_text("".join(keep))
    else:  # pragma: no cover
        raise AssertionError(kind)
    return p


def _readers() -> dict[str, Callable[[Path], Any]]:
    from navkit.io import images, maps, pointcloud, trajectory
    from navkit.io.arrays import read_npy, read_npz
    from navkit.io.carmen import read_carmen
    from navkit.io.pathjson import read_path_json
    from navkit.io.stereo import read_stereo_calib

    return {
        "kitti.bin": pointcloud.read_kitti_bin,
        "kitti.label": lambda p: pointcloud.read_kitti_labels(p, n_points=30),
        "ascii.pcd": pointcloud.read_pcd,
        "binary.pcd": pointcloud.read_pcd,
        "compressed.pcd": pointcloud.read_pcd,
        "ascii.ply": pointcloud.read_ply,
        "binary.ply": pointcloud.read_ply,
        "tum.txt": trajectory.read_tum,
        "kitti_poses.txt": trajectory.read_kitti_poses,
        "euroc.csv": trajectory.read_euroc,
        "odometry.dat": trajectory.read_odometry_log,
        "image.png": images.read_image,
        "depth.png": lambda p: images.read_depth(p, 1000.0),
        "disparity.pfm": images.read_pfm,
        "map.yaml": maps.read_occupancy_grid,
        "path.json": read_path_json,
        "middlebury_calib.txt": lambda p: read_stereo_calib(p, (741, 497)),
        "generic_calib.yaml": lambda p: read_stereo_calib(p, (64, 48)),
        "carmen.log": read_carmen,
        "array.npy": read_npy,
        "scan.npz": read_npz,
    }


KINDS = list(_readers())
EXAMPLES = 40


@pytest.fixture(scope="module")
def valid_files(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("valid")


@pytest.mark.parametrize("kind", KINDS)
def test_valid_file_reads(kind: str, valid_files: Path) -> None:
    """The unmutated file is read back (the mutations below start from a good file)."""
    path = _write(kind, valid_files)
    assert check("readers", _readers()[kind], path) is not None


@pytest.mark.parametrize("kind", KINDS)
def test_mutated_file(kind: str, valid_files: Path) -> None:
    path = _write(kind, valid_files)
    base = path.read_bytes()
    reader = _readers()[kind]
    target = valid_files / f"mutated-{kind}"

    @settings(max_examples=EXAMPLES, database=None)
    @given(mutations(base))
    def case(data: bytes) -> None:
        target.write_bytes(data)
        if kind == "map.yaml":  # the YAML names its image: keep the mutated YAML's partner
            (valid_files / "map.pgm").exists()
        check("readers", reader, target)

    case()


def test_missing_and_folder_inputs(valid_files: Path) -> None:
    for kind, reader in _readers().items():
        check("readers", reader, valid_files / f"missing-{kind}")
        check("readers", reader, valid_files)  # a folder, not a file
