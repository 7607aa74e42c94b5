"""Point-cloud readers and writers: real files, round trips, broken files."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from navkit.errors import DataNotFoundError, FormatError, InputError
from navkit.io.pointcloud import (
    PointCloud,
    read_kitti_bin,
    read_kitti_labels,
    read_pcd,
    read_ply,
    write_kitti_bin,
    write_kitti_labels,
    write_pcd,
    write_ply,
)

KITTI = "lidar/semantickitti-seq00"


def _open3d():
    return pytest.importorskip("open3d", reason="open3d (bench extra) not importable")


def _yaml_label_ids(path: Path) -> set[int]:
    """Class ids of the ``labels:`` block of semantic-kitti.yaml (no YAML dependency)."""
    ids: set[int] = set()
    inside = False
    for line in path.read_text().splitlines():
        if re.match(r"^\S", line):
            inside = line.startswith("labels:")
            continue
        m = re.match(r"^\s+(\d+)\s*:", line)
        if inside and m:
            ids.add(int(m.group(1)))
    return ids


# --------------------------------------------------------------------------- KITTI, real data
@pytest.mark.realdata
@pytest.mark.parametrize("frame", ["000000", "000001", "000002"])
def test_semantickitti_bin_and_labels(data_path, frame):
    pts = read_kitti_bin(data_path(f"{KITTI}/{frame}.bin"))
    assert pts.dtype == np.float32 and pts.ndim == 2 and pts.shape[1] == 4
    assert 100_000 < len(pts) < 140_000  # "about 124k points each" (HDL-64E)
    sem, inst = read_kitti_labels(data_path(f"{KITTI}/{frame}.label"), n_points=len(pts))
    assert len(sem) == len(inst) == len(pts)
    valid_ids = _yaml_label_ids(data_path(f"{KITTI}/semantic-kitti.yaml"))
    assert set(np.unique(sem).tolist()) <= valid_ids
    # reflectance is normalised to [0, 1]
    assert pts[:, 3].min() >= 0.0 and pts[:, 3].max() <= 1.0
    # labels align with points: road points (class 40) lie on the road, about 1.73 m below the
    # sensor (README). A 0.25 m band allows for road camber/slope within the ~20 m where most
    # road returns are; misaligned labels would give the median of random points (~ -1 m, wide).
    road_z = pts[sem == 40, 2]
    assert len(road_z) > 5000
    assert abs(np.median(road_z) + 1.73) < 0.25
    # cars (10, 252) carry instance ids; road does not
    assert np.all(inst[sem == 40] == 0)


def test_kitti_roundtrip(tmp_path, rng):
    pts = rng.normal(size=(1000, 4)).astype(np.float32)
    write_kitti_bin(tmp_path / "a.bin", pts)
    np.testing.assert_array_equal(read_kitti_bin(tmp_path / "a.bin"), pts)
    sem = rng.integers(0, 260, 1000)
    inst = rng.integers(0, 70000, 1000) & 0xFFFF
    write_kitti_labels(tmp_path / "a.label", sem, inst)
    s2, i2 = read_kitti_labels(tmp_path / "a.label", n_points=1000)
    np.testing.assert_array_equal(s2, sem)
    np.testing.assert_array_equal(i2, inst)
    # the packing is the SemanticKITTI one: l = semantic | instance << 16
    raw = np.fromfile(tmp_path / "a.label", dtype="<u4")
    np.testing.assert_array_equal(raw, sem | (inst << 16))


def test_kitti_broken(tmp_path):
    bad = tmp_path / "trunc.bin"
    bad.write_bytes(np.zeros(10, "<f4").tobytes()[:37])
    with pytest.raises(FormatError, match=r"trunc\.bin.*37 bytes"):
        read_kitti_bin(bad)
    lab = tmp_path / "x.label"
    lab.write_bytes(np.zeros(5, "<u4").tobytes())
    with pytest.raises(FormatError, match=r"x\.label.*5 labels.*7 points"):
        read_kitti_labels(lab, n_points=7)
    lab.write_bytes(b"\x00" * 6)
    with pytest.raises(FormatError, match=r"x\.label.*6 bytes"):
        read_kitti_labels(lab)
    with pytest.raises(DataNotFoundError, match=r"nope\.bin"):
        read_kitti_bin(tmp_path / "nope.bin")


# --------------------------------------------------------------------------- PCD, real data
@pytest.mark.realdata
def test_pcl_room_binary_compressed(data_path):
    cloud = read_pcd(data_path("scans3d/pcl-room/room_scan1.pcd"))
    assert len(cloud) == 112586 and not cloud.is_organized
    assert np.isfinite(cloud.points).all()
    # a room: the extent is metres, not kilometres (a garbled LZF decode gives float garbage)
    extent = np.ptp(cloud.points, axis=0)
    assert np.all(extent > 1.0) and np.all(extent < 50.0)


@pytest.mark.realdata
def test_pcl_room_equals_open3d(data_path):
    o3d = _open3d()
    path = data_path("scans3d/pcl-room/room_scan2.pcd")
    ref = np.asarray(o3d.io.read_point_cloud(str(path)).points)
    np.testing.assert_array_equal(read_pcd(path).points, ref)


@pytest.mark.realdata
@pytest.mark.parametrize("sample", ["samp11", "samp22"])
def test_isprs_ground_is_subset(data_path, sample):
    full = read_pcd(data_path(f"lidar/isprs-terrain/{sample}-utm.pcd"))
    ground = read_pcd(data_path(f"lidar/isprs-terrain/{sample}-utm-ground.pcd"))
    assert 0 < len(ground) < len(full)
    # README: the ground file is an exact subset of the full one (same float32 values)
    f32 = np.ascontiguousarray(full.points.astype(np.float32)).view("V12").ravel()
    g32 = np.ascontiguousarray(ground.points.astype(np.float32)).view("V12").ravel()
    assert np.isin(g32, f32).all()
    # UTM coordinates: eastings and northings are hundreds of km / thousands of km
    assert full.points[:, 0].min() > 1e5 and full.points[:, 1].min() > 1e6


@pytest.mark.realdata
def test_pcl_kinect_organised_with_nan(data_path):
    cloud = read_pcd(data_path("rgbd/pcl-kinect/capture0001.pcd"))
    assert cloud.is_organized and (cloud.width, cloud.height) == (640, 480)
    grid = cloud.grid()
    assert grid.shape == (480, 640, 3)
    valid = np.isfinite(grid).all(axis=2)
    assert 0.5 < valid.mean() < 1.0  # NaN points kept, not dropped
    # the grid is the camera image: column u = fx * x / z + cx, row v = fy * y / z + cy. Fit
    # both by least squares over the valid pixels; depth is quantised (a few mm at 2 m) so
    # x/z is exact to ~1e-3 and the residual stays well under a pixel - a transposed or
    # shifted layout gives residuals of hundreds of pixels.
    v, u = np.nonzero(valid)
    p = grid[valid]
    for coord, ratio in ((u, p[:, 0] / p[:, 2]), (v, p[:, 1] / p[:, 2])):
        A = np.column_stack([ratio, np.ones_like(ratio)])
        sol, *_ = np.linalg.lstsq(A, coord.astype(np.float64), rcond=None)
        resid = coord - A @ sol
        assert 400 < sol[0] < 700  # a Kinect focal length in pixels
        assert np.sqrt(np.mean(resid**2)) < 1.0


# --------------------------------------------------------------------------- PCD round trips
def _rich_cloud(rng, organised: bool) -> PointCloud:
    h, w = (6, 7) if organised else (1, 42)
    n = h * w
    pts = rng.normal(scale=5.0, size=(n, 3)).astype(np.float32).astype(np.float64)
    pts[[3, 10]] = np.nan
    fields = {
        "intensity": rng.random(n).astype(np.float32),
        "normal_x": rng.normal(size=n).astype(np.float32),
        "label": rng.integers(0, 2**32 - 1, n, dtype=np.uint32),
        "ring": rng.integers(-100, 100, n).astype(np.int16),
        "time": rng.random(n),  # float64
        "fpfh": rng.random((n, 3)).astype(np.float32),  # COUNT 3
    }
    colors = rng.integers(0, 256, (n, 3)).astype(np.uint8)
    return PointCloud(pts, fields, w, h, colors=colors)


@pytest.mark.parametrize("encoding", ["ascii", "binary", "binary_compressed"])
@pytest.mark.parametrize("organised", [False, True])
def test_pcd_roundtrip(tmp_path, rng, encoding, organised):
    cloud = _rich_cloud(rng, organised)
    path = tmp_path / "c.pcd"
    write_pcd(path, cloud, binary=encoding != "ascii", compressed=encoding == "binary_compressed")
    assert f"DATA {encoding}\n".encode() in path.read_bytes()[:400]
    back = read_pcd(path)
    assert (back.width, back.height) == (cloud.width, cloud.height)
    np.testing.assert_array_equal(back.points, cloud.points)  # float32 values, NaN kept
    np.testing.assert_array_equal(back.colors, cloud.colors)
    assert back.fields.keys() == cloud.fields.keys()
    for name, arr in cloud.fields.items():
        assert back.fields[name].dtype == arr.dtype, name
        np.testing.assert_array_equal(back.fields[name], arr, err_msg=name)


def test_pcd_float64_points_and_rgba(tmp_path, rng):
    pts = rng.normal(size=(50, 3)) * 1e5  # float64 precision needed
    alpha = rng.integers(0, 256, 50).astype(np.uint8)
    cloud = PointCloud(pts, {"alpha": alpha}, colors=rng.integers(0, 256, (50, 3)))
    write_pcd(tmp_path / "d.pcd", cloud, point_dtype=np.float64)
    back = read_pcd(tmp_path / "d.pcd")
    np.testing.assert_array_equal(back.points, pts)
    np.testing.assert_array_equal(back.fields["alpha"], alpha)
    np.testing.assert_array_equal(back.colors, cloud.colors)
    # a plain (N, 3) array is accepted too
    write_pcd(tmp_path / "e.pcd", pts, binary=False)
    np.testing.assert_allclose(read_pcd(tmp_path / "e.pcd").points, pts, rtol=1e-7)


@pytest.mark.parametrize("compressed", [False, True])
def test_pcd_written_is_read_by_open3d(tmp_path, rng, compressed):
    o3d = _open3d()
    pts = rng.normal(size=(3000, 3)).astype(np.float32)
    pts[::7] = pts[3]  # repeated bytes give the compressor back references to encode
    colors = rng.integers(0, 256, (3000, 3)).astype(np.uint8)
    path = tmp_path / "o.pcd"
    write_pcd(path, PointCloud(pts, colors=colors), compressed=compressed)
    ref = o3d.io.read_point_cloud(str(path))
    np.testing.assert_array_equal(np.asarray(ref.points), pts.astype(np.float64))
    np.testing.assert_array_equal(np.round(np.asarray(ref.colors) * 255).astype(np.uint8), colors)


# --------------------------------------------------------------------------- PCD broken files
HEADER = (
    "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\n"
    "WIDTH 4\nHEIGHT 1\nPOINTS 4\nDATA {data}\n"
)


def _write(tmp_path, name, text: str, body: bytes = b"") -> Path:
    p = tmp_path / name
    p.write_bytes(text.encode() + body)
    return p


def test_pcd_missing_fields(tmp_path):
    p = _write(tmp_path, "nofields.pcd", HEADER.replace("FIELDS x y z\n", "").format(data="ascii"))
    with pytest.raises(FormatError, match=r"nofields\.pcd.*'FIELDS'"):
        read_pcd(p)
    p = _write(
        tmp_path, "noz.pcd", HEADER.replace("x y z", "x y w").format(data="ascii"), b"1 2 3\n" * 4
    )
    with pytest.raises(FormatError, match=r"noz\.pcd.*no field 'z'"):
        read_pcd(p)


def test_pcd_size_type_mismatch(tmp_path):
    p = _write(tmp_path, "size.pcd", HEADER.replace("SIZE 4 4 4", "SIZE 4 4").format(data="ascii"))
    with pytest.raises(FormatError, match=r"size\.pcd.*'SIZE'.*2 entries for 3 fields"):
        read_pcd(p)
    p = _write(
        tmp_path, "type.pcd", HEADER.replace("TYPE F F F", "TYPE F F I").format(data="ascii")
    )
    p.write_bytes(p.read_bytes().replace(b"SIZE 4 4 4", b"SIZE 4 4 3"))
    with pytest.raises(FormatError, match=r"type\.pcd.*'TYPE'.*TYPE I with SIZE 3"):
        read_pcd(p)
    p = _write(tmp_path, "pts.pcd", HEADER.replace("POINTS 4", "POINTS 5").format(data="ascii"))
    with pytest.raises(FormatError, match=r"pts\.pcd.*'POINTS'"):
        read_pcd(p)


def test_pcd_truncated_data(tmp_path):
    body = np.zeros((4, 3), "<f4").tobytes()
    p = _write(tmp_path, "bin.pcd", HEADER.format(data="binary"), body[:-5])
    with pytest.raises(FormatError, match=r"bin\.pcd.*'DATA'.*truncated.*expected 48 bytes"):
        read_pcd(p)
    p = _write(tmp_path, "asc.pcd", HEADER.format(data="ascii"), b"1 2 3\n4 5 6\n7 8\n")
    with pytest.raises(FormatError, match=r"asc\.pcd.*'DATA'.*8 values"):
        read_pcd(p)
    p = _write(tmp_path, "asc2.pcd", HEADER.format(data="ascii"), b"1 2 3\n4 5 6\n7 8 x\n1 1 1\n")
    with pytest.raises(FormatError, match=r"asc2\.pcd.*'z'"):
        read_pcd(p)
    # compressed: the header declares more compressed bytes than the file holds
    good = tmp_path / "good.pcd"
    write_pcd(good, PointCloud(np.arange(12.0).reshape(4, 3)), compressed=True)
    raw = good.read_bytes()
    cut = _write(tmp_path, "cut.pcd", "", raw[:-3])
    with pytest.raises(FormatError, match=r"cut\.pcd.*'DATA'.*truncated"):
        read_pcd(cut)


def test_pcd_bad_lzf(tmp_path):
    # a back reference at output offset 0 points before the start of the output
    stream = bytes([0x20, 0x00])
    body = np.array([len(stream), 48], "<u4").tobytes() + stream
    p = _write(tmp_path, "lzf.pcd", HEADER.format(data="binary_compressed"), body)
    with pytest.raises(FormatError, match=r"lzf\.pcd.*'DATA'.*corrupt LZF"):
        read_pcd(p)
    # a stream that decodes to fewer bytes than declared
    stream = bytes([0x03]) + b"abcd"
    body = np.array([len(stream), 48], "<u4").tobytes() + stream
    p = _write(tmp_path, "short.pcd", HEADER.format(data="binary_compressed"), body)
    with pytest.raises(FormatError, match=r"short\.pcd.*corrupt LZF.*4 bytes"):
        read_pcd(p)


# --------------------------------------------------------------------------- PLY
@pytest.mark.parametrize("binary", [True, False])
def test_ply_roundtrip(tmp_path, rng, binary):
    pts = rng.normal(size=(30, 3)).astype(np.float32).astype(np.float64)
    colors = rng.integers(0, 256, (30, 3)).astype(np.uint8)
    faces = rng.integers(0, 30, (12, 3))
    write_ply(tmp_path / "m.ply", pts, colors, faces, binary=binary)
    back = read_ply(tmp_path / "m.ply")
    np.testing.assert_array_equal(back.points, pts)
    np.testing.assert_array_equal(back.colors, colors)
    np.testing.assert_array_equal(back.faces, faces)


def test_ply_big_endian_quads_and_extra_props(tmp_path):
    # hand-made big-endian file: double coords, float intensity, quads, an extra element
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1]], dtype=">f8")
    inten = np.arange(5, dtype=">f4")
    header = (
        "ply\nformat binary_big_endian 1.0\ncomment test\nelement vertex 5\n"
        "property double x\nproperty double y\nproperty double z\nproperty float intensity\n"
        "element face 2\nproperty list uchar uint vertex_index\n"
        "element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n"
    )
    vert = np.empty(5, dtype=[("x", ">f8"), ("y", ">f8"), ("z", ">f8"), ("i", ">f4")])
    vert["x"], vert["y"], vert["z"], vert["i"] = pts[:, 0], pts[:, 1], pts[:, 2], inten
    face = np.empty(2, dtype=[("n", "u1"), ("v", ">u4", (4,))])
    face["n"] = 4
    face["v"] = [[0, 1, 2, 3], [1, 2, 3, 4]]
    edge = np.array([(0, 4)], dtype=[("a", ">i4"), ("b", ">i4")])
    p = tmp_path / "be.ply"
    p.write_bytes(header.encode() + vert.tobytes() + face.tobytes() + edge.tobytes())
    back = read_ply(p)
    np.testing.assert_array_equal(back.points, pts.astype(np.float64))
    np.testing.assert_array_equal(back.fields["intensity"], inten)
    np.testing.assert_array_equal(back.faces, [[0, 1, 2, 3], [1, 2, 3, 4]])
    assert back.colors is None


def test_ply_mixed_polygons_fan_triangulated(tmp_path):
    text = (
        "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
        "property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n1 1 0\n0 1 0\n2 0 0\n3 0 1 2\n4 0 1 2 3\n"
    )
    p = tmp_path / "mix.ply"
    p.write_text(text)
    back = read_ply(p)
    np.testing.assert_array_equal(back.faces, [[0, 1, 2], [0, 1, 2], [0, 2, 3]])


def test_ply_broken(tmp_path):
    p = tmp_path / "x.ply"
    p.write_text(
        "ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\n"
        "property float y\nproperty float z\nend_header\n"
    )
    p.write_bytes(p.read_bytes() + b"\x00" * 50)
    with pytest.raises(FormatError, match=r"x\.ply.*'vertex'.*truncated.*120 bytes"):
        read_ply(p)
    p.write_text("not a ply\n")
    with pytest.raises(FormatError, match=r"x\.ply.*not a PLY"):
        read_ply(p)
    p.write_text(
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
        "end_header\n0 0 0\n3 0 1 2\n"
    )
    with pytest.raises(FormatError, match=r"x\.ply.*face indices"):
        read_ply(p)


def test_pointcloud_validation():
    with pytest.raises(InputError, match="points"):
        PointCloud(np.zeros((4, 2)))
    with pytest.raises(InputError, match="width"):
        PointCloud(np.zeros((4, 3)), width=3, height=2)
    with pytest.raises(InputError, match="intensity"):
        PointCloud(np.zeros((4, 3)), {"intensity": np.zeros(3)})
    c = PointCloud(np.zeros((6, 3)), width=3, height=2)
    assert c.is_organized and c.grid().shape == (2, 3, 3)


def test_pcd_ascii_rgb_float_form_and_padding(tmp_path):
    # older PCL / other tools write the packed colour as a float; a '_' field is padding
    packed = np.array([0x00FF8000, 0x000102FF], dtype="<u4")
    as_float = packed.view("<f4")
    text = (
        "VERSION .7\nFIELDS x y z _ rgb\nSIZE 4 4 4 1 4\nTYPE F F F U F\nCOUNT 1 1 1 4 1\n"
        "WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n"
        f"1 2 3 0 0 0 0 {as_float[0]:.9g}\n4 5 nan 0 0 0 0 {as_float[1]:.9g}\n"
    )
    p = tmp_path / "rgbf.pcd"
    p.write_text(text)
    cloud = read_pcd(p)
    np.testing.assert_array_equal(cloud.colors, [[255, 128, 0], [1, 2, 255]])
    np.testing.assert_array_equal(cloud.points, [[1, 2, 3], [4, 5, np.nan]])
    assert cloud.fields == {}
    # the same colours as PCL's integer form
    p.write_text(
        text.replace(f"{as_float[0]:.9g}", str(packed[0])).replace(
            f"{as_float[1]:.9g}", str(packed[1])
        )
    )
    np.testing.assert_array_equal(read_pcd(p).colors, [[255, 128, 0], [1, 2, 255]])


@settings(max_examples=25, deadline=None, database=None)
@given(
    n=st.integers(0, 300),
    encoding=st.sampled_from(["ascii", "binary", "binary_compressed"]),
    seed=st.integers(0, 2**31),
)
def test_pcd_roundtrip_property(tmp_path_factory, n, encoding, seed):
    rng = np.random.default_rng(seed)
    pts = rng.normal(scale=100.0, size=(n, 3)).astype(np.float32).astype(np.float64)
    pts[rng.random(n) < 0.1] = np.nan
    label = rng.integers(0, 20, n).astype(np.uint16)
    cloud = PointCloud(pts, {"label": label})
    path = tmp_path_factory.mktemp("pcd") / "p.pcd"
    write_pcd(path, cloud, binary=encoding != "ascii", compressed=encoding == "binary_compressed")
    back = read_pcd(path)
    np.testing.assert_array_equal(back.points, pts)
    np.testing.assert_array_equal(back.fields["label"], label)


def test_ply_ascii_faces_with_colours(tmp_path):
    # Meshlab-style ascii: a face element with a list and per-face colour scalars
    text = (
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
        "property float z\nelement face 2\nproperty list uchar int vertex_indices\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n"
        "0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2 255 0 0\n3 0 2 3 0 255 0\n"
    )
    p = tmp_path / "fc.ply"
    p.write_text(text)
    np.testing.assert_array_equal(read_ply(p).faces, [[0, 1, 2], [0, 2, 3]])
    p.write_text(text.replace("3 0 2 3 0 255 0", "3 0 2 3 0 255"))
    with pytest.raises(FormatError, match=r"fc\.ply.*line 2 of element 'face'"):
        read_ply(p)
