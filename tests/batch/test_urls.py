"""fsspec URLs as inputs of the batch commands: the same arrays as the plain paths, errors that
name the URL, a clear error for a protocol that cannot be opened or a missing fsspec."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from navkit.errors import ConfigError, DataNotFoundError, FormatError, OptionalDependencyError
from navkit.io.urls import expand_url, is_url, local_copy, url_name

fsspec = pytest.importorskip("fsspec", reason="fsspec (comes with the cluster extra) is absent")


@pytest.fixture
def memfs(request):
    """fsspec's in-memory file system under a folder of this test's own, emptied afterwards."""
    fs = fsspec.filesystem("memory")
    root = f"/navkit-test-{request.node.name}"
    yield fs, root
    if fs.exists(root):
        fs.rm(root, recursive=True)


def test_urls_and_paths_are_told_apart():
    assert is_url("file:///data/a.bin") and is_url("s3://bucket/a.bin")
    assert not is_url("/data/a.bin") and not is_url("C:/data/a.bin") and not is_url("a.bin")
    assert url_name("s3://bucket/x/000001.bin?version=3") == "000001.bin"


def test_local_copy_reads_the_bytes_and_errors_name_the_url(memfs, tmp_path):
    from navkit.io.pointcloud import read_pcd

    fs, root = memfs
    fs.pipe(f"{root}/ok.txt", b"hello")
    with local_copy(f"memory://{root}/ok.txt") as p:
        assert p.read_bytes() == b"hello" and p.name == "ok.txt"
    assert not p.exists()  # the private copy is gone
    with local_copy(tmp_path / "plain.txt") as q:  # a path is used as it is, not copied
        assert q == tmp_path / "plain.txt"
    fs.pipe(f"{root}/cut.pcd", b"# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\n")
    url = f"memory://{root}/cut.pcd"
    with pytest.raises(FormatError) as err, local_copy(url) as p:
        read_pcd(p)
    assert str(err.value).startswith(f"{url}:") and "navkit-url-" not in str(err.value)
    with pytest.raises(DataNotFoundError, match="no such file"), local_copy(f"{url}.missing"):
        pass
    with pytest.raises(ConfigError, match="protocol"), local_copy("nosuchproto://x/a.bin"):
        pass
    assert expand_url(f"memory://{root}/*.pcd") == [f"memory://{root}/cut.pcd"]
    with pytest.raises(DataNotFoundError):
        expand_url(f"memory://{root}/*.bin")


def test_a_url_without_fsspec_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "fsspec", None)  # import fsspec -> ImportError
    with pytest.raises(OptionalDependencyError, match=r"navkit\[cluster\]"):
        with local_copy("s3://bucket/a.bin"):
            pass
    with local_copy("/plain/path.bin") as p:  # plain paths never need it
        assert str(p) == "/plain/path.bin"


def test_obstacles_from_a_file_url_glob_equal_the_paths(cli, data_path, tmp_path):
    f0 = data_path("lidar/semantickitti-seq00/000000.bin")
    folder = f0.parent
    common = ("--sensor", "hdl64e-kitti", "--outputs", "labels,obstacles")
    a, b = tmp_path / "paths", tmp_path / "urls"
    r = cli("obstacles", "detect", folder / "000000.bin", folder / "000001.bin", "-o", a, *common)
    assert r.exit_code == 0, r.output
    r = cli("obstacles", "detect", f"file://{folder}/00000[01].bin", "-o", b, *common, "--resume")
    assert r.exit_code == 0, r.output
    for f in ("000000", "000001"):
        np.testing.assert_array_equal(np.load(a / f / "labels.npy"), np.load(b / f / "labels.npy"))
        oa = json.loads((a / f / "obstacles.json").read_text())
        ob = json.loads((b / f / "obstacles.json").read_text())
        assert oa["obstacles"] == ob["obstacles"]


def test_path_record_and_planes_from_memory_urls_equal_the_paths(cli, data_path, memfs, tmp_path):
    fs, root = memfs
    tum = data_path("trajectories/freiburg1_xyz-groundtruth.txt")
    pcd = data_path("rgbd/pcl-kinect/capture0001.pcd")
    fs.pipe(f"{root}/{tum.name}", tum.read_bytes())
    fs.pipe(f"{root}/{pcd.name}", pcd.read_bytes())
    assert cli("path", "record", tum, "-o", tmp_path / "p1").exit_code == 0
    r = cli("path", "record", f"memory://{root}/{tum.name}", "-o", tmp_path / "p2")
    assert r.exit_code == 0, r.output
    ja = json.loads((tmp_path / "p1" / "path.json").read_text())
    jb = json.loads((tmp_path / "p2" / "path.json").read_text())
    assert jb["frame"].pop("source") == f"memory://{root}/{tum.name}"  # the URL, not a copy
    assert ja["frame"].pop("source") == str(tum)
    assert ja == jb
    assert cli("planes", "extract", pcd, "-o", tmp_path / "e1").exit_code == 0
    r = cli("planes", "extract", f"memory://{root}/{pcd.name}", "-o", tmp_path / "e2")
    assert r.exit_code == 0, r.output
    pa = json.loads((tmp_path / "e1" / "planes.json").read_text())["planes"]
    pb = json.loads((tmp_path / "e2" / "planes.json").read_text())["planes"]
    assert pa == pb and len(pa) >= 4
    assert (tmp_path / "e1" / "overlay.png").read_bytes() == (
        tmp_path / "e2" / "overlay.png"
    ).read_bytes()


def test_map_locate_from_memory_urls_equals_the_paths(cli, data_path, memfs, tmp_path):
    fs, root = memfs
    log = data_path("laser2d/aces-corrected.log.gz")
    r = cli("map", "build", log, "-o", tmp_path / "map", "--every", "4")
    assert r.exit_code == 0, r.output
    fs.pipe(f"{root}/{log.name}", log.read_bytes())
    for name in ("map.json", "map.yaml", "map.pgm"):  # the map and the grid it names
        fs.pipe(f"{root}/{name}", (tmp_path / "map" / name).read_bytes())
    args = ("--every", "40", "--prior", "odometry")
    assert (
        cli(
            "map", "locate", tmp_path / "map" / "map.json", log, "-o", tmp_path / "l1", *args
        ).exit_code
        == 0
    )
    r = cli(
        "map",
        "locate",
        f"memory://{root}/map.json",
        f"memory://{root}/{log.name}",
        "-o",
        tmp_path / "l2",
        *args,
    )
    assert r.exit_code == 0, r.output

    def fixes(folder):  # fixes.csv without its milliseconds column
        rows = (folder / "fixes.csv").read_text().splitlines()
        ms = rows[0].split(",").index(next(c for c in rows[0].split(",") if c.startswith("ms")))
        return [[c for i, c in enumerate(r.split(",")) if i != ms] for r in rows]

    assert fixes(tmp_path / "l1") == fixes(tmp_path / "l2")
    assert (tmp_path / "l1" / "poses.tum").read_bytes() == (
        tmp_path / "l2" / "poses.tum"
    ).read_bytes()
