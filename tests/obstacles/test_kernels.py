"""The compiled (Numba) kernels of stages 1-8 against their NumPy twins: the same answers.

Classes, obstacle ids, shadow owners, boundaries and per-vertex labels must be identical; floats
(points, normals, z extrema, shape parameters) equal to 1e-9 relative (in practice bit-identical:
the kernels repeat the twin's float32 / float64 operations in the same order). Run on simulated
scenes (both scanners, with noise) and on every real scan grid in ``NAVKIT_DATA/lidar``
(SemanticKITTI clouds through ``cloud_to_grid``, SqueezeSeg range images through
``organized_to_grid``). Each test names the kernels it compares (``pytest.mark.twin``;
``tests/core/test_twins.py`` checks that every kernel of a ``TWINS`` table has one).
"""

from __future__ import annotations

import math
import pickle
from dataclasses import replace

import numpy as np
import pytest

from navkit import jit
from navkit.errors import ConfigError
from navkit.geometry._validate import MAX_COORDINATE_M
from navkit.obstacles import Mounting, ObstacleSettings, detect_obstacles, detect_obstacles_in_grid
from navkit.obstacles.detector import ObstacleDetection
from navkit.obstacles.grids import cloud_to_grid, organized_to_grid
from navkit.obstacles.mesh import robust_strides, robust_strides_compiled
from navkit.obstacles.rules import _mesh_and_classes, mesh_and_classes

pytest.importorskip("numba")

# all eight stages with the default shapes: stages 1-7, the map's vertex sets, hulls (the
# compiled monotone chain against Qhull), A1-A6, Welzl's circle, MVEE and A7 (A1, MEC)
FAST = ObstacleSettings()


def _close(a: np.ndarray, b: np.ndarray, what: str) -> None:
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape and a.dtype == b.dtype, what
    if a.dtype.kind == "f":
        assert np.array_equal(np.isnan(a), np.isnan(b)), what
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=0, equal_nan=True, err_msg=what)
    else:
        np.testing.assert_array_equal(a, b, err_msg=what)


def assert_same_detection(a: ObstacleDetection, b: ObstacleDetection) -> None:
    """Every array and every obstacle of two detections equal (floats to 1e-9 relative)."""
    for name in (
        "points",
        "valid",
        "triangles",
        "normals",
        "jump",
        "triangle_labels",
        "triangle_obstacle",
        "vertex_labels",
        "vertex_obstacle",
        "boundary",
    ):
        _close(getattr(a, name), getattr(b, name), name)
    assert a.wrap == b.wrap
    assert len(a.obstacles) == len(b.obstacles)
    for oa, ob in zip(a.obstacles, b.obstacles, strict=True):
        assert (oa.id, oa.n_triangles, oa.n_points) == (ob.id, ob.n_triangles, ob.n_points)
        for f in ("z_min", "z_max", "shadow_area"):
            assert getattr(oa, f) == pytest.approx(getattr(ob, f), rel=1e-9, abs=0)
        for f in ("boundary_xy", "polygon_xy", "shadow_xy"):
            _close(getattr(oa, f), getattr(ob, f), f"obstacle {oa.id} {f}")
        # the shapes bit for bit, on any CPU (tests/obstacles/test_shapes.py says why)
        for sa, sb in ((oa.shapes, ob.shapes), (oa.guaranteed, ob.guaranteed)):
            assert sa.keys() == sb.keys()
            for k in sa:
                pa, pb = sa[k].params(), sb[k].params()
                assert pa.keys() == pb.keys()
                for f in pa:
                    if isinstance(pa[f], str):
                        assert pa[f] == pb[f]
                    else:
                        assert np.array_equal(
                            np.float64(pa[f]).view(np.int64), np.float64(pb[f]).view(np.int64)
                        ), f"obstacle {oa.id} {k} {f}: {pa[f]!r} {pb[f]!r}"


def _both(run):  # type: ignore[no-untyped-def]
    """``run(FAST)`` on the NumPy twins and on the kernels."""
    with jit.use("numpy"):
        twin = run(FAST)
    with jit.use("eager"):
        return twin, run(FAST)


def _twin(fn, *args, **kw):  # type: ignore[no-untyped-def]
    with jit.use("numpy"):
        return fn(*args, **kw)


def _kernel(fn, *args, **kw):  # type: ignore[no-untyped-def]
    with jit.use("eager"):
        return fn(*args, **kw)


def test_the_implementation_is_no_setting():
    """``navkit.jit`` chooses kernels or twins; a settings file with a ``backend`` key is refused
    with a message that says so."""
    with pytest.raises(ConfigError) as e:
        ObstacleSettings.from_dict({"backend": "numpy"}, source="obstacles.toml")
    assert "obstacles.toml" in str(e.value) and "NAVKIT_JIT" in str(e.value)
    with pytest.raises(TypeError):
        ObstacleSettings(backend="numpy")  # type: ignore[call-arg]


@pytest.mark.twin("points_kernel", "split_kernel", "vertex_kernel", "ground_cells_kernel")
@pytest.mark.twin("refine_kernel", "map_groups_kernel", "stages_2_5_kernel")
@pytest.mark.parametrize(
    ("scene", "scanner", "noise"),
    [("four", "tilting", 0.01), ("four", "spinning64", 0.01), ("box", "spinning64", 0.02)],
)
def test_compiled_equals_numpy_on_simulated_scenes(scene, scanner, noise):
    from navkit.experiments.obstacles import paper_scenes, scanners
    from navkit.geometry import se3_from_rt
    from navkit.sim import render_scan
    from navkit.sim.scanners import RangeNoise

    sc, height = scanners()[scanner]
    T = se3_from_rt(np.eye(3), [0.0, 0.0, height])
    sim = render_scan(
        paper_scenes()[scene], sc, T, noise=RangeNoise(relative_sigma=noise), rng=3, max_range=60.0
    )
    a, b = _both(lambda s: detect_obstacles(sim.scan, s))
    assert len(a.obstacles) > 0  # the comparison is not vacuous
    assert_same_detection(a, b)


def _kitti_grids(data_path):  # type: ignore[no-untyped-def]
    from navkit.io.pointcloud import read_kitti_bin

    folder = data_path("lidar/semantickitti-seq00")
    return [(f.name, _twin(cloud_to_grid, read_kitti_bin(f))) for f in sorted(folder.glob("*.bin"))]


@pytest.mark.twin("stages_2_5_kernel", "robust_strides_kernel")
def test_stages_2_5_kernel_equals_numpy_on_kitti(data_path):
    """Stages 2-5 (the fused kernel) and the robust normals' strides, bit for bit, on every
    SemanticKITTI frame."""
    s = ObstacleSettings()
    for name, grid in _kitti_grids(data_path):
        P = Mounting(1.73).to_body(grid.points)
        valid = np.isfinite(P).all(axis=-1)
        o = np.array([0.0, 0.0, 1.73])
        k_a, m_a = robust_strides(P, valid, o, s.normal_support_m, 32)
        k_b, m_b = robust_strides_compiled(P, valid, o, s.normal_support_m, 32)
        assert k_a.dtype == k_b.dtype == np.float32 and k_a == k_b, name
        np.testing.assert_array_equal(m_a, m_b, err_msg=f"{name} elevation strides")
        _, la, _ = _twin(mesh_and_classes, P, valid, o, s, wrap=True)
        assert (la == -2).sum() > 1000 and (la == 0).sum() > 50000  # a real frame, not empty
        _same_stages_2_5(P, valid, o, name)


_MESH_FIELDS = (
    "triangles",
    "valid",
    "normal",
    "vertex_ray",
    "range_mean",
    "z_min",
    "z_max",
    "jump",
)


def _same_stages_2_5(P, valid, o, name, settings=None):  # type: ignore[no-untyped-def]
    """The fused stage 2-5 kernel against the twin's three functions: every mesh field, the
    classes and the rules P1-P5 bit for bit, wrapped and not, with and without robust normals
    and the range-ratio test."""
    base = settings or ObstacleSettings()
    variants = [base, replace(base, normal_support_m=0.0), replace(base, jump_range_ratio=math.inf)]
    for s in variants:
        for wrap in (True, False):
            ma, la, ra = _twin(mesh_and_classes, P, valid, o, s, wrap=wrap, rules=True)
            mb, lb, rb = _kernel(mesh_and_classes, P, valid, o, s, wrap=wrap, rules=True)
            what = f"{name} wrap={wrap} {s.normal_support_m} {s.jump_range_ratio}"
            for f in _MESH_FIELDS:
                np.testing.assert_array_equal(getattr(ma, f), getattr(mb, f), err_msg=f"{what} {f}")
            np.testing.assert_array_equal(la, lb, err_msg=f"{what} labels")
            assert ra.keys() == rb.keys() == {"P1", "P2", "P3", "P4", "P5"}
            for k in ra:
                np.testing.assert_array_equal(ra[k], rb[k], err_msg=f"{what} {k}")
            # without the rules, the same mesh and labels
            mc, lc, rc = _kernel(mesh_and_classes, P, valid, o, s, wrap=wrap)
            np.testing.assert_array_equal(lc, lb, err_msg=what)
            for f in _MESH_FIELDS:
                np.testing.assert_array_equal(getattr(mc, f), getattr(mb, f), err_msg=what)
            assert rc == {}
            # the detector's lean call: the same labels and the fields stages 6-8 read, without
            # the ones nothing reads after stage 5
            md, ld, rd = _mesh_and_classes(
                P, valid, o, s, wrap=wrap, rules=False, full_mesh=False, compiled=True
            )
            np.testing.assert_array_equal(ld, lb, err_msg=f"{what} lean labels")
            for f in ("triangles", "normal", "z_min", "z_max", "jump"):
                np.testing.assert_array_equal(getattr(md, f), getattr(mb, f), err_msg=f"{what} {f}")
            assert md.valid.size == md.vertex_ray.size == md.range_mean.size == 0
            assert rd == {}


@pytest.mark.twin("stages_2_5_kernel")
def test_fused_stages_equal_numpy_on_simulated_grids():
    """The fused kernel on simulated grids with holes, both scanners, 1-2 % range noise, a
    grid with empty elevation columns (``np.interp`` of the strides) and a tiny grid."""
    from navkit.experiments.obstacles import paper_scenes, scanners
    from navkit.geometry import se3_from_rt
    from navkit.sim import render_scan
    from navkit.sim.scanners import RangeNoise

    P = o = None
    for scene, scanner, noise in (("four", "tilting", 0.01), ("box", "spinning64", 0.02)):
        sc, height = scanners()[scanner]
        T = se3_from_rt(np.eye(3), [0.0, 0.0, height])
        sim = render_scan(
            paper_scenes()[scene],
            sc,
            T,
            noise=RangeNoise(relative_sigma=noise),
            rng=3,
            max_range=60.0,
        )
        det = _twin(detect_obstacles, sim.scan, FAST)  # stage 1's grid
        P, valid, o = det.points, det.valid, det.sensor_origin
        _same_stages_2_5(P, valid, o, f"{scene} {scanner}")
        holes = P.copy()
        holes[::3, 5:9] = np.nan  # whole elevation columns empty on every 4th row and more
        holes[:, 2] = np.nan
        _same_stages_2_5(holes, np.isfinite(holes).all(axis=-1), o, f"{scene} holes")
    assert P is not None
    tiny = P[:3, :4].copy()
    _same_stages_2_5(tiny, np.isfinite(tiny).all(axis=-1), o, "3 x 4 grid")


@pytest.mark.twin("points_kernel", "body_points_kernel", "split_kernel", "vertex_kernel")
@pytest.mark.twin("ground_cells_kernel", "refine_kernel", "map_groups_kernel")
def test_compiled_equals_numpy_on_kitti(data_path):
    for name, grid in _kitti_grids(data_path):
        a, b = _both(
            lambda s, g=grid, n=name: detect_obstacles_in_grid(g, Mounting(1.73), s, source=n)
        )
        assert len(a.obstacles) > 20
        assert_same_detection(a, b)


def test_compiled_equals_numpy_on_squeezeseg(data_path):
    folder = data_path("lidar/squeezeseg-kitti-raw")
    files = sorted(folder.glob("*.npy"))
    assert files
    for f in files:
        x = np.load(f)
        P = x[..., :3].astype(np.float64)
        P[x[..., 4] == 0] = np.nan
        grid = organized_to_grid(P, source=f.name)
        a, b = _both(lambda s, g=grid: detect_obstacles_in_grid(g, Mounting(1.73), s))
        assert_same_detection(a, b)


def _same_grid(a, b) -> None:  # type: ignore[no-untyped-def]
    assert (a.method, a.wraps, a.shape) == (b.method, b.wraps, b.shape)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.cell_of_point, b.cell_of_point)
    np.testing.assert_array_equal(a.azimuth, b.azimuth)


@pytest.mark.twin("cloud_valid_kernel", "rings_order_kernel", "grid_order_fill_kernel")
@pytest.mark.twin("phase_sin_cos_kernel", "cloud_prep_kernel", "rings_by_order_kernel")
@pytest.mark.twin("grid_cells_kernel", "grid_fill_kernel")
def test_cloud_to_grid_compiled_equals_numpy_on_kitti(data_path):
    from navkit.io.pointcloud import read_kitti_bin

    folder = data_path("lidar/semantickitti-seq00")
    for f in sorted(folder.glob("*.bin")):
        pts = read_kitti_bin(f)
        a = _twin(cloud_to_grid, pts)
        b = _kernel(cloud_to_grid, pts)
        assert a.method == "order"
        _same_grid(a, b)
        # rings by elevation (the other recovery), and a shuffled cloud that is not a sweep
        sub = pts[::7]
        _same_grid(
            _twin(cloud_to_grid, sub, ring_method="elevation", n_rings=64),
            _kernel(cloud_to_grid, sub, ring_method="elevation", n_rings=64),
        )


def test_cloud_to_grid_fixed_atan2_keeps_the_grids_of_numpys_arctan2(data_path, monkeypatch):
    """The per-point azimuth with navkit's fixed arithmetic (``geometry.angles.atan2``, within 2
    ulp of ``np.arctan2``) recovers the same grid as NumPy's ``arctan2`` on every SemanticKITTI
    frame: the same points in the same cells; only the columns' azimuths move, in the last
    bits of the phase."""
    from navkit.io.pointcloud import read_kitti_bin
    from navkit.obstacles import grids

    folder = data_path("lidar/semantickitti-seq00")
    for f in sorted(folder.glob("*.bin")):
        pts = read_kitti_bin(f)
        fixed = _twin(cloud_to_grid, pts)
        with monkeypatch.context() as m:
            m.setattr(grids, "atan2", np.arctan2)
            libm = _twin(cloud_to_grid, pts)
        assert np.array_equal(fixed.points, libm.points, equal_nan=True)
        assert np.array_equal(fixed.cell_of_point, libm.cell_of_point)
        np.testing.assert_allclose(fixed.azimuth, libm.azimuth, rtol=0, atol=1e-13)


@pytest.mark.twin("cloud_prep_kernel", "grid_fill_kernel")
def test_cloud_to_grid_compiled_equals_numpy_on_a_shuffled_cloud(rng):
    az = np.repeat(np.linspace(-np.pi, np.pi, 720, endpoint=False), 16)
    el = np.tile(np.radians(np.linspace(-20, 5, 16)), 720)
    r = rng.uniform(3, 40, size=az.size)
    P = np.c_[np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)] * r[:, None]
    P = np.concatenate([P, P[rng.integers(0, len(P), 3000)] * 1.01])[rng.permutation(len(P) + 3000)]
    P[rng.random(len(P)) < 0.05] = 0.0  # no-returns stored as zeros
    a = _twin(cloud_to_grid, P)
    assert a.method == "elevation"
    _same_grid(a, _kernel(cloud_to_grid, P))


@pytest.mark.twin("rings_order_kernel", "grid_order_fill_kernel")
def test_cloud_to_grid_by_order_decides_near_ties_as_numpy(rng):
    """The compiled order path ranks rings and picks each cell's nearest point without the
    twin's ``hypot`` unless the answer is close: rings at the same elevation (tied keys), exact
    duplicates, copies scaled by 1 +- 1e-15 and copies turned by 1e-7 rad (ranges tied up to
    rounding: deciding those by the squared range alone fails this test) must take its exact
    branches and still give the twin's grid."""
    n_az = 720
    el_deg = np.array([-10.0, -8.0, -8.0, -6.0, -4.0, -4.0, -2.0, 0.0])  # two tied pairs
    az = np.tile(np.linspace(-np.pi, np.pi, n_az, endpoint=False), len(el_deg))
    az += rng.normal(0, 1e-4, az.size)
    el = np.repeat(np.radians(el_deg), n_az)
    r = rng.uniform(3, 40, size=az.size)
    P = np.c_[np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)] * r[:, None]
    c, s = np.cos(1e-7), np.sin(1e-7)
    rows = []
    for k, p in enumerate(P):  # storage order kept: the copies follow their original
        rows.append(p)
        if k % 5 == 0:
            rows.append(p * (1 + (1e-15 if k % 10 else -1e-15)))
        if k % 7 == 0:
            rows.append(p.copy())
        if k % 3 == 0:  # the same range up to rounding: sqrt(x^2 + y^2 + z^2) cannot decide
            rows.append(np.array([p[0] * c - p[1] * s, p[0] * s + p[1] * c, p[2]]))
    Q = np.array(rows)
    Q[rng.random(len(Q)) < 0.03] = 0.0  # no-returns stored as zeros
    a = _twin(cloud_to_grid, Q)
    assert a.method == "order"
    _same_grid(a, _kernel(cloud_to_grid, Q))
    Q32 = Q.astype(np.float32)  # float32 input, as KITTI's: read by the kernel itself
    _same_grid(_twin(cloud_to_grid, Q32), _kernel(cloud_to_grid, Q32))


@pytest.mark.twin("phase_sin_cos_kernel", "phase_fractions_kernel")
def test_cloud_to_grid_phase_without_libm_sin_cos(rng, monkeypatch):
    """Where NumPy's ``sin`` / ``cos`` would not be libm's, the phase takes NumPy's: the twin's
    grid either way (the branch forced here)."""
    from navkit.obstacles import grids

    n_az = 900
    az = np.tile(np.linspace(-np.pi, np.pi, n_az, endpoint=False), 6) + 0.37 * 2 * np.pi / n_az
    el = np.repeat(np.radians([-12.0, -8.0, -5.0, -2.0, 1.0, 3.0]), n_az)
    r = rng.uniform(2, 30, size=az.size)
    P = np.c_[np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)] * r[:, None]
    a = _twin(cloud_to_grid, P)
    assert a.method == "order"
    monkeypatch.setattr(grids, "_LIBM_SIN_COS", [False])
    _same_grid(a, _kernel(cloud_to_grid, P))
    monkeypatch.setattr(grids, "_LIBM_SIN_COS", [True])
    _same_grid(a, _kernel(cloud_to_grid, P))


@pytest.mark.twin("rings_order_kernel", "grid_order_fill_kernel")
def test_ring_ranking_falls_back_to_exact_keys():
    """Ring keys closer than their error bound are not ranked by the approximate sums: two rings
    whose elevations differ by 1e-13 relative, the approximate sums of the higher one lowered
    (within the bound) so that they rank it first - the ranking must be the exact keys', as
    the twin's, and so the grid."""
    from navkit.obstacles import _kernels_grid as _kernels
    from navkit.obstacles.grids import _ring_lut

    n_az = 400
    az0 = np.linspace(-np.pi, np.pi, n_az, endpoint=False) + 0.3 / n_az
    az = np.tile(az0, 2)
    el = np.repeat([0.1 * (1 + 1e-13), 0.1], n_az)  # ring 0 is the higher one
    P = np.c_[np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)] * 10.0
    twin = _twin(cloud_to_grid, P)
    assert twin.method == "order"
    qx, qy, qz = (np.ascontiguousarray(P[:, k]) for k in range(3))
    n = len(P)
    azk = np.arctan2(qy, qx)
    d, ad, work = np.empty(n), np.empty(n), np.empty(n)
    ring = np.empty(n, np.int64)
    sums, abs_sums = np.empty(513), np.empty(513)
    counts = np.empty(513, np.int64)
    found, _step, n_r, lo = _kernels.rings_order_kernel(
        azk, qx, qy, qz, d, ad, work, ring, sums, abs_sums, counts
    )
    assert found and n_r == 2
    assert sums[0] / counts[0] > sums[1] / counts[1]
    lut, n_el = _ring_lut(qx, qy, qz, ring[:n], lo, sums[:2], abs_sums[:2], counts[:2])
    assert n_el == 2 and list(lut) == [1, 0]
    sums[0] = sums[1] * (1 - 2e-15)  # approximate key of ring 0 now below ring 1's
    lut, n_el = _ring_lut(qx, qy, qz, ring[:n], lo, sums[:2], abs_sums[:2], counts[:2])
    assert n_el == 2 and list(lut) == [1, 0]  # the exact keys decided
    n_columns = twin.shape[0]
    phase = (twin.azimuth[0] + np.pi) * n_columns / (2 * np.pi)
    win, best = np.empty(n_columns * 2, np.int32), np.empty(n_columns * 2)
    grid, cop = np.empty((n_columns * 2, 3)), np.empty(n, np.int64)
    _kernels.grid_order_fill_kernel(
        qx, qy, qz, azk, np.arange(n), ring, lo, lut, n_el, n_columns, phase, win, best,
        np.empty(n), grid, cop,
    )  # fmt: skip
    np.testing.assert_array_equal(grid.reshape(n_columns, 2, 3), twin.points)
    np.testing.assert_array_equal(cop, twin.cell_of_point)
    sums[0] = sums[1] * (1 - 1e-6)  # far beyond the bound: the approximate keys decide
    lut, _ = _ring_lut(qx, qy, qz, ring[:n], lo, sums[:2], abs_sums[:2], counts[:2])
    assert list(lut) == [0, 1]


def test_cells_pass_equals_the_modulo(rng):
    """The columns as two selects are the twin's ``floor(...) % n_columns`` for every phase
    ``arctan2 / 2 pi`` can give, the ends of both ranges included; the points that are not
    valid (not in ``idx``) get -1."""
    from navkit.obstacles import _kernels_grid as _kernels

    n, n_columns, n_el = 5000, 360, 4
    az = rng.uniform(-np.pi, np.pi, n)
    az[:3] = (-np.pi, np.pi, 0.0)
    ring = rng.integers(0, n_el, n).astype(np.int64) + 3  # raw rings, lowest 3
    lut = np.array([2, 0, 3, 1], dtype=np.int64)
    q = rng.normal(size=(3, n))
    idx = np.sort(rng.choice(n + 100, n, replace=False)).astype(np.int64)
    for phase in (0.25, -0.49, 0.5, -0.5, 0.0, -0.0):
        x = (az + np.pi) / (2 * np.pi) * n_columns
        i = np.floor(x - phase + 0.5).astype(np.int64) % n_columns
        j = lut[ring - 3]
        rk = ring.copy()
        cop = np.full(n + 100, -7, dtype=np.int64)
        r2w = np.empty(n)
        _kernels._cells_pass(az, rk, 3, lut, phase, n_columns, n_el, *q, idx, r2w, cop)
        np.testing.assert_array_equal(cop[idx], i * n_el + j)
        others = np.ones(n + 100, dtype=bool)
        others[idx] = False
        assert others.sum() == 100 and np.all(cop[others] == -1)
        np.testing.assert_array_equal(rk, j * n_columns + i)
        np.testing.assert_array_equal(r2w, q[0] * q[0] + q[1] * q[1] + q[2] * q[2])


@pytest.mark.twin("mvee_weights_kernel", "a6_search_kernel")
def test_mvee_and_a6_compiled_equal_numpy(rng):
    from navkit.geometry.shapes import ellipse_a5, ellipses_a6_batch, hull_points, mvee_batch

    sets = []
    for _ in range(40):
        k = int(rng.integers(3, 300))
        P = rng.normal(size=(k, 2)) * rng.uniform(0.05, 4.0, size=2) + rng.uniform(-30, 30, 2)
        sets.append(hull_points(P))
    sets.append(hull_points(np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])))  # a triangle
    starts = [ellipse_a5(h) for h in sets]
    pairs = list(zip(_twin(mvee_batch, sets), _kernel(mvee_batch, sets), strict=True)) + list(
        zip(
            _twin(ellipses_a6_batch, sets, starts),
            _kernel(ellipses_a6_batch, sets, starts),
            strict=True,
        )
    )
    for a, b in pairs:  # bit for bit (tests/obstacles/test_shapes.py says why on any CPU)
        pa, pb = a.params(), b.params()
        for f in pa:
            if not isinstance(pa[f], str):
                assert np.float64(pa[f]).view(np.int64) == np.float64(pb[f]).view(np.int64), f


@pytest.mark.twin("body_points_kernel", "points_kernel")
def test_stage_1_from_sensor_points_equals_to_body(rng):
    """The fused stage 1 (``body_points_kernel``) gives ``Mounting.to_body`` + the validity
    codes bit for bit (signed zeros included) for the rotations it takes (identity, axis swaps),
    with holes, infinities and zeros in the input; whole detections through it are compared with
    the twin in ``test_compiled_equals_numpy_on_kitti``."""
    from navkit.obstacles import _kernels_grid as _kernels

    S = rng.normal(scale=20.0, size=(40, 16, 3))
    S[rng.random((40, 16)) < 0.1] = np.nan
    S[3, 4, 1] = np.inf
    S[5, 6, 0] = -np.inf
    S[7, 8] = (-0.0, 0.0, -0.0)
    S[9, 10] = (0.0, -0.0, -1.73)
    S[11, :, 2] = np.nan
    swap = ((0.0, -1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    for mounting in (Mounting(1.73), Mounting(0.5, rotation=swap), Mounting(2.0, roll_deg=0.0)):
        R = mounting.R_body_sensor
        with np.errstate(invalid="ignore"):  # inf * 0 in the matmul
            ref = mounting.to_body(S)
        ref_ok = np.isfinite(ref).all(axis=2)
        ref[~ref_ok] = np.nan
        out = np.empty_like(S)
        ok = np.empty(S.shape[:2], dtype=bool)
        n_valid, n_far = _kernels.body_points_kernel(
            S, R, float(mounting.height_m), out, ok, MAX_COORDINATE_M
        )
        assert (n_valid, n_far) == (ref_ok.sum(), 0)
        np.testing.assert_array_equal(ok, ref_ok)
        assert ok.sum() < ok.size - 40  # the holes stay holes
        assert np.array_equal(out.view(np.int64)[ok], ref.view(np.int64)[ok])  # same bits
        assert np.isnan(out[~ok]).all()
    # stage 1 on body points (detect_obstacles_grid): the same codes and NaN rows as the twin
    ok_ref = np.isfinite(S).all(axis=2)
    out = np.empty_like(S)
    ok = np.empty(S.shape[:2], dtype=bool)
    assert _kernels.points_kernel(S, out, ok, MAX_COORDINATE_M) == (ok_ref.sum(), 0)
    np.testing.assert_array_equal(ok, ok_ref)
    ref = np.where(ok_ref[..., None], S, np.nan)
    assert np.array_equal(out.view(np.int64)[ok], ref.view(np.int64)[ok])
    assert np.isnan(out[~ok]).all()
    # the far count: finite coordinates beyond the bound, per point (NaN / inf rows are not)
    far = S.copy()
    far[0, 0, 1] = 2 * MAX_COORDINATE_M
    far[0, 1, 2] = -np.inf
    far[1, 0] = -1.5 * MAX_COORDINATE_M
    fin = np.isfinite(far).all(axis=2)
    n_far = (fin & (np.abs(far) > MAX_COORDINATE_M).any(axis=2)).sum()
    assert n_far >= 1
    assert _kernels.points_kernel(far, out, ok, MAX_COORDINATE_M) == (fin.sum(), n_far)


def test_banded_median_equals_numpy(rng):
    """The exact median of the ring recovery and the strides (one bracket pass for both middle
    order statistics) is ``np.median`` on odd and even sizes, ties, and brackets that miss."""
    from navkit.obstacles import _kernels_common as _kernels

    cases = [rng.random(n) for n in (1, 2, 3, 4, 5, 100, 101, 4096, 4097, 20000, 20001)]
    cases += [rng.integers(0, 3, n).astype(float) for n in (10, 11, 5000, 5001)]  # ties
    cases += [np.sort(rng.random(30000)), np.sort(rng.random(30001))[::-1].copy()]
    cases += [np.r_[np.zeros(9000), rng.random(9000) * 1e-3 + 1.0]]  # the middle at a jump
    for values in cases:
        got = _kernels._median_banded(values.copy(), np.empty(len(values)))
        assert got == np.median(values), len(values)


def test_stage_6_7_row_windows_equal_numpy(rng):
    """The row-window kernels of stages 6-7 (boundary ids, merging of close components) against
    their NumPy twins on random small grids, wrapped and not, edges included."""
    from navkit.obstacles import _kernels_map
    from navkit.obstacles.segment import boundary_vertices, merge_close_components

    merges = 0
    for _ in range(150):
        n_az, n_el = int(rng.integers(2, 24)), int(rng.integers(2, 10))
        wrap = bool(rng.integers(2))
        R, C = (n_az if wrap else n_az - 1), n_el - 1
        ids = rng.integers(0, 5, size=(R, 2 * C)) * (rng.random((R, 2 * C)) < 0.5)
        ids = ids.astype(np.int32)
        vid, bnd = _kernels_map._boundary_ids(ids, n_az, n_el, wrap)
        vid_t, bnd_t = boundary_vertices(ids, n_az, n_el, wrap)
        np.testing.assert_array_equal(vid, vid_t)
        np.testing.assert_array_equal(bnd, bnd_t)
        P = rng.random((n_az, n_el, 3)) * 3.0
        out, m = _kernels_map._merge_close_rows(ids.copy(), 4, P, wrap, 0.5, 2)
        out_t, m_t = merge_close_components(ids, 4, P, wrap, 0.5, 2)
        assert m == m_t
        np.testing.assert_array_equal(out, out_t)
        merges += m < 4
    assert merges > 20  # the draws do merge components


def test_branch_free_select_is_the_order_statistic(rng):
    """Stage 7's per-cell selection (``_kernels_map._kth_select``) returns the k-th smallest
    value exactly (``np.sort(v)[k]``), with many ties, few values and sorted / reversed input."""
    from navkit.obstacles import _kernels_map

    for t in range(400):
        m = int(rng.integers(1, 300))
        v = rng.integers(0, 4 if t % 3 == 0 else 10**6, m).astype(np.float64) * 0.01
        if t % 7 == 0:
            v = np.sort(v)[:: 1 if t % 2 else -1].copy()
        k = int(rng.integers(0, m))
        assert _kernels_map._kth_select(v.copy(), k) == np.sort(v)[k]


@pytest.mark.twin("map_cells_kernel")
def test_map_update_compiled_equals_numpy(data_path, rng):
    """``ObstacleMapper.update`` on the kernel and on its twin: the same hits, seen counts,
    recent obstacle cells and per-scan figures, scan after scan. The SemanticKITTI clouds from
    moving (4, 4) poses and planar (3, 3) ones, the map's edge crossing the clouds (points
    dropped on every side), with NaN / infinite points marked valid, points exactly on cell
    edges and a range bound that cuts the cloud."""
    from navkit.obstacles import ObstacleMapper, ObstacleMapperSettings

    mounting = Mounting(height_m=1.73)
    dets = [detect_obstacles_in_grid(g, mounting, FAST) for _, g in _kitti_grids(data_path)]
    # a detection with broken returns marked valid and points on the 0.2 m cell edges
    d = dets[0]
    P = d.points.copy()
    valid = d.valid.copy()
    flat_p, flat_v = P.reshape(-1, 3), valid.reshape(-1)
    k = rng.choice(len(flat_p), 400, replace=False)
    flat_p[k[:100]] = np.nan
    flat_p[k[100:200], 0] = np.inf
    flat_p[k[200:], :2] = np.round(flat_p[k[200:], :2] / 0.2) * 0.2
    flat_v[k] = True
    dets.append(replace(d, points=P, valid=valid))
    st = ObstacleMapperSettings(resolution=0.2, max_range=25.0)
    out = {}
    for mode in ("numpy", "eager"):
        with jit.use(mode):
            mapper = ObstacleMapper([-30.0, -20.0], [30.0, 40.0], st)
            ups = []
            for k in range(12):
                yaw = 0.3 * k
                c, s = math.cos(yaw), math.sin(yaw)
                if k % 3:
                    T = np.eye(4)
                    T[:2, :2] = [[c, -s], [s, c]]
                    T[:3, 3] = [1.5 * k, 2.0 * k, 1.73]
                else:
                    T = np.array([[c, -s, 1.5 * k], [s, c, 2.0 * k], [0.0, 0.0, 1.0]])
                ups.append(mapper.update(dets[k % len(dets)], T))
                if k == 5:
                    recent = [r.copy() for r in mapper.recent]
                assert not mapper._mark.any()  # the scratch is zero between scans
                rows, cols = np.nonzero(mapper.seen)  # the window: the box of the cells seen
                box = [rows.min(), rows.max(), cols.min(), cols.max()]
                assert mapper._box.tolist() == box
            out[mode] = (mapper.hits, mapper.seen, list(mapper.recent), recent, ups)
            clone = pickle.loads(pickle.dumps(mapper))  # a checkpoint: the scratch not kept
            assert clone._mark is None and np.array_equal(clone.seen, mapper.seen)
            assert clone.update(dets[0], np.eye(3)) == replace(ups[0], scan=12)
    (ha, sa, ra, qa, ua), (hb, sb, rb, qb, ub) = out["numpy"], out["eager"]
    assert ha.sum() > 0 and sa.sum() > ha.sum()  # not vacuous
    assert all(u.obstacle_cells > 0 for u in ua[:3])
    np.testing.assert_array_equal(ha, hb)
    np.testing.assert_array_equal(sa, sb)
    assert ua == ub
    for a, b in zip(ra + qa, rb + qb, strict=True):
        assert a.dtype == b.dtype and np.array_equal(a, b)
        assert np.all(np.diff(a) > 0)  # ascending, each cell once
