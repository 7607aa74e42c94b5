"""The compiled kernels of the organised extraction against their NumPy oracles.

Same answers, bit for bit: labels, inlier lists, planes (normal, rho,
centroid, RMS), outlines and areas identical on the simulator and on every real organised frame
in the shared data (slambook, CAPE tunnel, pcl-kinect, the 100 7-Scenes frames). This holds on
any CPU because both paths run the same IEEE-754 double / float operations in the same order
and call nothing whose rounding depends on the machine: the float32 block sums in NumPy's
pairwise order, every float64 sum (region rows, the mixed patches' pixels) added one term after
the other from +0 (``numpy.add.at`` / ``numpy.bincount`` in the twins - no BLAS product, whose
grouping depends on the CPU and the thread count), dot products of three terms left to right
(no ``einsum``, whose grouping follows the SIMD width), and ``acos`` / ``cos`` of the
closed-form eigenvalue with one fixed arithmetic (Cephes, :mod:`navkit.geometry.angles`; NumPy's
``arccos`` / ``cos`` are SIMD code on some machines and libm's elsewhere). Numba compiles the
kernels without ``fastmath``, so LLVM neither reassociates nor fuses a product into an addition.
The only rows outside the closed form - a repeated smallest eigenvalue - take LAPACK's vector in
both paths, from the same matrix.
"""

from __future__ import annotations

import numpy as np
import pytest

from navkit.planes.extract import ExtractionSettings, _extract, _patch_moments


def _bits(a: np.ndarray | float) -> np.ndarray:
    """The float64 bit patterns (``-0.0 != 0.0``; NaNs by payload)."""
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def _same_bits(a: np.ndarray | float, b: np.ndarray | float) -> bool:
    x, y = _bits(a), _bits(b)
    return x.shape == y.shape and np.array_equal(x, y)


def assert_same(P: np.ndarray, s: ExtractionSettings | None = None) -> int:
    """Compiled and NumPy extraction of one grid give the same result bit for bit (labels,
    inliers, every float of every plane, outline and area); returns the number of planes."""
    a = _extract(P, s, compiled=True)
    b = _extract(P, s, compiled=False)
    assert np.array_equal(a.labels, b.labels)
    assert len(a.segments) == len(b.segments)
    for x, y in zip(a.segments, b.segments, strict=True):
        assert np.array_equal(x.inliers, y.inliers)
        assert x.plane.count == y.plane.count
        assert _same_bits(x.plane.normal, y.plane.normal)
        assert _same_bits(x.plane.rho, y.plane.rho)
        assert _same_bits(x.plane.centroid, y.plane.centroid)
        assert _same_bits(x.plane.rms, y.plane.rms)
        assert _same_bits(x.area, y.area)
        assert _same_bits(x.outline, y.outline)
    return len(a.segments)


@pytest.mark.twin("patch_moments")
def test_patch_moments_bit_identical(pairs):
    """The fused moments kernel gives NumPy's float32 block sums bit for bit (cells 20 and 7:
    the pairwise summation with and without the eight running sums' remainder)."""
    P = pairs[3].f1.frame.points().copy()
    P[100:140, 200:260] = np.nan  # holes: partial and empty patches
    for cell in (20, 7):
        s = ExtractionSettings(cell=cell)
        hc, wc = P.shape[0] // cell, P.shape[1] // cell
        a = _patch_moments(P, s, hc, wc, True)
        A = (a.M.copy(), a.ref.copy(), a.valid.copy())
        b = _patch_moments(P, s, hc, wc, False)
        for x, y in zip(A, (b.M, b.ref, b.valid), strict=True):
            assert np.array_equal(x, y)
        # the float32 coordinates patch by patch (G, 3, cell^2), 0 where invalid: what the
        # compiled refinement reads instead of the float64 grid
        X = P[: hc * cell, : wc * cell].astype(np.float32)
        X[~b.valid] = 0.0
        X = X.reshape(hc, cell, wc, cell, 3).transpose(0, 2, 4, 1, 3).reshape(hc * wc, 3, -1)
        assert a.XP is not None and np.array_equal(a.XP, X)


@pytest.mark.twin("patch_moments", "plane_rows", "patch_graph", "prune_merge", "sum_rows")
@pytest.mark.twin("border_patches", "refine_pixels", "label_image", "outline_samples")
@pytest.mark.twin("outline_rasters", "close_rasters")
@pytest.mark.parametrize("n_dirs", [1, 2, 3])
@pytest.mark.parametrize("refine", ["boundary", "full"])
def test_simulator_frames(pairs, n_dirs, refine):
    assert assert_same(pairs[n_dirs].f1.frame.points(), ExtractionSettings(refine=refine)) >= 1


@pytest.mark.twin("refine_pixels", "label_image", "outline_samples", "prune_merge")
def test_real_slambook_and_cape(data_path):
    from navkit.io.rgbd import read_cape_frame, read_simple_rgbd

    seq = read_simple_rgbd(
        data_path("rgbd/slambook-ch5"),
        {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0},
    )
    for i in range(len(seq)):
        assert assert_same(seq.frame(i).points()) >= 5
    assert assert_same(read_cape_frame(data_path("rgbd/cape-tunnel")).points) >= 2


@pytest.mark.twin("refine_pixels", "label_image", "outline_samples", "prune_merge")
def test_real_pcl_kinect(data_path):
    from navkit.io.pointcloud import read_pcd

    for k in (1, 2, 3):
        assert assert_same(read_pcd(data_path(f"rgbd/pcl-kinect/capture000{k}.pcd")).grid()) >= 2


@pytest.mark.twin("refine_pixels", "label_image", "outline_samples", "prune_merge")
def test_real_7scenes(data_path):
    """All 100 frames (depth in mm, 0 and 65535 = no return; fx = fy = 585, c = (320, 240))."""
    import cv2

    root = data_path("rgbd/7scenes-tsdf")
    v, u = np.mgrid[0:480, 0:640].astype(np.float64)
    total = 0
    for path in sorted(root.glob("frame-*.depth.png")):
        d = cv2.imread(str(path), cv2.IMREAD_UNCHANGED).astype(np.float64)
        z = np.where((d > 0) & (d < 65535), d / 1000.0, np.nan)
        P = np.stack([(u - 320.0) / 585.0 * z, (v - 240.0) / 585.0 * z, z], axis=2)
        total += assert_same(P)
    assert total > 100


def test_backproject_same_bits(data_path):
    """``PinholeCamera.backproject`` (broadcast rays) gives ``pixel_rays() * depth``
    bit for bit, NaN where the depth is missing: the extraction's input is unchanged."""
    from navkit.io.rgbd import read_simple_rgbd

    seq = read_simple_rgbd(
        data_path("rgbd/slambook-ch5"),
        {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0},
    )
    f = seq.frame(0)
    a = f.camera.backproject(f.depth)
    b = f.camera.pixel_rays() * f.depth[..., None]
    assert np.isnan(f.depth).any()
    assert np.array_equal(a.view(np.uint64), b.view(np.uint64))


@pytest.mark.twin("outline_rasters", "close_rasters")
def test_outline_rasters_match_outline_from_points(rng):
    """The rasters of all planes in one compiled pass give ``outline_from_points``'s outlines
    and areas: point clouds with NaN rows, quadrilaterals (one with a NaN corner), a plane with
    two points only (empty outline) and one whose raster exceeds 4e6 cells (coarsened)."""
    from navkit.planes.outlines import _outlines_compiled
    from navkit.planes.segments import outline_from_points

    sets = []
    for n, nq, span in ((3000, 5, 2.0), (2, 0, 1.0), (500, 0, 0.3), (400, 2, 60.0), (0, 3, 1.5)):
        uv = rng.uniform(-span, span, (n, 2)) + rng.normal(0, 5, 2)
        if n > 10:
            uv[rng.integers(0, n, 5)] = np.nan
        c0 = rng.uniform(-span, span, (nq, 1, 2))
        q = c0 + np.array([[0, 0], [0.3, 0], [0.3, 0.3], [0, 0.3]])[None]
        if nq > 2:
            q[1, 2, 0] = np.nan
        sets.append((uv, q))
    uv_all = np.concatenate([u for u, _ in sets])
    cuts = np.concatenate([[0], np.cumsum([len(u) for u, _ in sets])])
    quads = np.concatenate([q for _, q in sets])
    qcuts = np.concatenate([[0], np.cumsum([len(q) for _, q in sets])])
    step = np.array([1, 1, 2, 1, 1])
    got = _outlines_compiled(uv_all, cuts, step, quads, qcuts, 0.02)
    for k, (uv, q) in enumerate(sets):
        want = outline_from_points(uv[:: step[k]], 0.02, quads=q)
        assert np.array_equal(got[k][0], want[0])
        assert got[k][1] == want[1]
    assert len(got[1][0]) == 0 and len(got[0][0]) >= 3 and got[3][1] > 0


@pytest.mark.twin("cell_components")
def test_cell_components_match_opencv(rng):
    """The union-find components of the cell graph are OpenCV's ``connectedComponents`` of the
    graph image (numbered by first patch in raster order, small ones dropped), on random
    graphs from sparse to dense."""
    import cv2

    from navkit.planes import _kernels

    for trial in range(40):
        hc, wc = int(rng.integers(1, 30)), int(rng.integers(1, 40))
        p = rng.uniform(0.2, 0.95)
        keep = rng.random((hc, wc)) < p
        eh = rng.random((hc, wc - 1)) < p
        ev = rng.random((hc - 1, wc)) < p
        min_cells = int(rng.integers(1, 5))
        graph = np.zeros((2 * hc - 1, 2 * wc - 1), np.uint8)
        graph[0::2, 0::2] = keep
        graph[0::2, 1::2] = eh & keep[:, :-1] & keep[:, 1:]
        graph[1::2, 0::2] = ev & keep[:-1, :] & keep[1:, :]
        n_comp, lab = cv2.connectedComponents(graph, connectivity=4, ltype=cv2.CV_32S)
        comp = lab[0::2, 0::2].ravel().astype(np.int64) - 1
        sizes = np.bincount(comp[comp >= 0], minlength=n_comp - 1)
        big = sizes >= min_cells
        remap = -np.ones(n_comp, np.int64)
        remap[1:][big] = np.arange(int(big.sum()))
        n, got = _kernels.cell_components(keep, eh, ev, min_cells)
        assert n == int(big.sum()), trial
        assert np.array_equal(got, remap[comp + 1]), trial


@pytest.mark.twin("patch_graph")
def test_patch_graph_same_bits(pairs):
    """The compiled planar test and edge tests give the NumPy formulas' decisions (the bounds
    bit for bit; the dot products of three terms left to right in both)."""
    from navkit.planes import _kernels
    from navkit.planes.extract import _planes_from_rows

    def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]

    P = pairs[3].f1.frame.points().copy()
    P[100:140, 200:260] = np.nan
    for cell in (20, 7):
        s = ExtractionSettings(cell=cell)
        hc, wc = P.shape[0] // cell, P.shape[1] // cell
        M = _patch_moments(P, s, hc, wc, True).M
        normal, d, rms, mean = _planes_from_rows(M, True)
        cos_t = np.cos(np.radians(s.angle_deg))
        bound, planar, eh, ev = _kernels.patch_graph(
            normal, d, mean, M[:, 0].copy(), rms, hc, wc, s.min_fill * cell * cell,
            s.rms_base, s.rms_quadratic, float(cos_t), s.distance_factor,
        )  # fmt: skip
        want = s.noise(dot(mean, mean))
        assert np.array_equal(bound, want)
        assert np.array_equal(planar, (M[:, 0] >= s.min_fill * cell * cell) & (rms < want))
        ids = np.arange(hc * wc).reshape(hc, wc)
        for got, a, b in ((eh, ids[:, :-1], ids[:, 1:]), (ev, ids[:-1, :], ids[1:, :])):
            pa, pb = a.ravel(), b.ravel()
            tol = s.distance_factor * np.maximum(want[pa], want[pb])
            ok = (
                (dot(normal[pa], normal[pb]) > cos_t)
                & (np.abs(dot(normal[pa], mean[pb]) - d[pa]) < tol)
                & (np.abs(dot(normal[pb], mean[pa]) - d[pb]) < tol)
            )
            assert np.array_equal(got.ravel(), ok)
        assert planar.sum() > 20 and eh.sum() > 20


@pytest.mark.twin("border_patches", "dense_components")
def test_border_patches_and_dense_components(rng):
    """The compiled border-patch candidates and coplanar-region components equal the NumPy
    versions on random region maps and adjacency matrices."""
    from navkit.planes import _kernels
    from navkit.planes.regions import _border_patches, _dense_components

    for trial in range(30):
        hc, wc = int(rng.integers(1, 25)), int(rng.integers(1, 33))
        cellmap = rng.integers(-1, int(rng.integers(1, 8)), (hc, wc))
        cellmap[: hc // 2, : wc // 2] = cellmap[0, 0]  # some interior patches
        for full in (False, True):
            want = _border_patches(cellmap, full)
            got = _kernels.border_patches(cellmap, full)
            for a, b in zip(got, want, strict=True):
                assert a.shape == b.shape and np.array_equal(a, b), trial
        n = int(rng.integers(1, 40))
        adj = rng.random((n, n)) < rng.uniform(0.0, 0.15)
        adj |= adj.T
        k, comp = _kernels.dense_components(adj)
        k0, comp0 = _dense_components(adj)
        assert k == k0 and np.array_equal(comp, comp0), trial


def test_largest_contour_is_opencvs(rng):
    """The largest contour without the areas of 1- and 2-point contours is ``max(contours,
    key=cv2.contourArea)`` (the first of equal areas), on the contours of random rasters."""
    import cv2

    from navkit.planes.segments import _largest_contour

    n = 0
    for _ in range(60):
        shape = (int(rng.integers(3, 60)), int(rng.integers(3, 60)))
        grid = (rng.random(shape) < rng.uniform(0.02, 0.4)).astype(np.uint8)
        contours, _ = cv2.findContours(grid, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        if not contours:
            continue
        n += 1
        assert _largest_contour(contours) is max(contours, key=cv2.contourArea)
    assert n > 40


@pytest.mark.twin("close_rasters")
def test_close_rasters_is_opencvs_closing(rng):
    """The compiled 3 x 3 closing of rasters packed one after the other gives OpenCV's
    ``morphologyEx(MORPH_CLOSE)`` cells (its default border) and their count, on random
    rasters down to 1 x 1; rasters of another status are left alone."""
    import cv2

    from navkit.planes._kernels_outline import close_rasters

    shapes = [(int(rng.integers(1, 40)), int(rng.integers(1, 40))) for _ in range(40)]
    shapes += [(1, 1), (1, 7), (9, 1), (2, 2)]
    grids = [(rng.random(s) < rng.uniform(0.05, 0.9)).astype(np.uint8) for s in shapes]
    start = np.concatenate([[0], np.cumsum([g.size for g in grids])]).astype(np.int64)
    shape = np.array([(g.shape[1], g.shape[0]) for g in grids], np.int64)
    status = np.zeros(len(grids), np.int64)
    status[3] = 2
    buf = np.concatenate([g.ravel() for g in grids])
    cells = close_rasters(buf, start, shape, status)
    kernel = np.ones((3, 3), np.uint8)
    for k, g in enumerate(grids):
        got = buf[start[k] : start[k + 1]].reshape(g.shape)
        want = g if status[k] else cv2.morphologyEx(g, cv2.MORPH_CLOSE, kernel)
        assert np.array_equal(got, want)
        assert cells[k] == (0 if status[k] else np.count_nonzero(want))


@pytest.mark.twin("prune_merge", "cell_components")
def test_degenerate_region_takes_the_numpy_steps(monkeypatch):
    """A region whose points lie on a line (repeated smallest eigenvalue: the closed form has
    no LAPACK vector) makes the compiled steps 3-4 (``prune_merge``) report it; the extraction
    then takes the NumPy steps and still agrees with the oracle."""
    from navkit.planes import regions

    P = np.zeros((100, 120, 3))  # y = 0, z = 2: the covariances are exactly diag(a, 0, 0)
    P[:, :, 0] = np.linspace(-1.0, 1.0, 120)[None, :]
    P[:, :, 2] = 2.0
    steps = []
    numpy_steps = regions._prune_merge
    monkeypatch.setattr(
        regions, "_prune_merge", lambda *a, **k: steps.append(k) or numpy_steps(*a, **k)
    )
    assert assert_same(P) >= 1
    assert len(steps) == 2  # the compiled path's fallback, then the oracle's own call


def test_canonical_planes_are_canonical_plane_bit_for_bit(rng):
    """The extraction's vectorised :func:`navkit.geometry.fitting.canonical_plane` gives its bits on
    random nearly-unit normals, and its special cases (a plane through the origin) row by
    row. Bit for bit holds on any CPU: both compute the same IEEE-exact operations (products,
    sums, a square root, divisions) in the same order, with no BLAS call that may fuse them."""
    from navkit.geometry.fitting import canonical_plane
    from navkit.planes.extract import _canonical_planes

    n = rng.normal(size=(500, 3))
    n /= np.sqrt((n * n).sum(axis=1))[:, None]
    n *= 1 + rng.normal(scale=1e-15, size=(500, 1))
    rho = rng.uniform(0.1, 5.0, 500)
    for k in (500, 3):
        if k == 3:
            rho[:3] = [1.0, 0.0, 2.0]  # one through the origin: the row-by-row path
        got_n, got_r = _canonical_planes(n[:k], rho[:k])
        for i in range(k):
            want_n, want_r = canonical_plane(n[i], float(rho[i]))
            assert np.array_equal(got_n[i], want_n) and got_r[i] == want_r


@pytest.mark.twin("acos_scalar", "cos_scalar")
def test_fixed_acos_cos_are_the_kernels_bits_and_libm_close(rng):
    """The closed-form eigenvalue's ``acos`` and ``cos`` (Cephes, :mod:`navkit.geometry.angles`)
    give the compiled scalar versions' bits - the same IEEE operations in the same order, so on
    any CPU - over ``[-1, 1]`` (both ``asin`` branches, the ends, values within 1e-17 of +-1)
    and the eigenvalue's angles ``[2 pi / 3, pi]`` (and a wider range). Against libm (``math``):
    within Cephes' documented peak errors, 2.2e-16 relative for ``acos`` (2 ulp) and 2.2e-16
    absolute for ``cos`` (2 ulp where ``|cos| >= 0.5``, as on the eigenvalue's angles)."""
    import math

    from navkit.geometry.angles import acos, cos
    from navkit.planes._kernels import acos_scalar, cos_scalar

    x = np.concatenate(
        [
            rng.uniform(-1.0, 1.0, 4000),
            1.0 - 10.0 ** rng.uniform(-17, 0, 1000),
            -1.0 + 10.0 ** rng.uniform(-17, 0, 1000),
            10.0 ** rng.uniform(-20, 0, 500) * rng.choice([-1.0, 1.0], 500),
            [-1.0, -0.625, -0.5, -0.0, 0.0, 0.5, 0.625, 1.0, 1e-8, np.nextafter(0.625, 1.0)],
        ]
    )
    got = acos(x)
    assert _same_bits(got, [acos_scalar(v) for v in x])
    want = np.array([math.acos(v) for v in x])
    assert np.all(np.abs(got - want) <= 2 * np.spacing(want))
    assert np.isnan(acos(1.0 + 1e-15)) and np.isnan(acos_scalar(-1.0 - 1e-15))

    t = np.concatenate(
        [rng.uniform(2 * np.pi / 3, np.pi, 4000), rng.uniform(-40.0, 40.0, 4000), [0.0, np.pi]]
    )
    got = cos(t)
    assert _same_bits(got, [cos_scalar(v) for v in t])
    want = np.array([math.cos(v) for v in t])
    assert np.all(np.abs(got - want) <= 2.3e-16)
    big = np.abs(want) >= 0.5
    assert np.all(np.abs(got - want)[big] <= 2 * np.spacing(np.abs(want[big])))


@pytest.mark.twin("sum_rows")
def test_sum_rows_bit_for_bit(rng):
    """The region sums of moment rows: ``moments._sum_rows`` (``numpy.add.at``) gives the
    kernel's bits - each group's rows added one after the other from +0 in both - on rows whose
    magnitudes span 1e-6 to 1e6 (where another order of the additions changes the last bits, as
    the reversed order shows)."""
    from navkit.planes import _kernels
    from navkit.planes.extract import _sum_rows

    G, n = 3000, 17
    groups = rng.integers(-1, n, G)
    M = rng.normal(size=(G, 13)) * 10.0 ** rng.uniform(-6, 6, (G, 1))
    got = _sum_rows(groups, n, M)
    assert _same_bits(got, _kernels.sum_rows(groups, n, M))
    assert not _same_bits(got, _sum_rows(groups[::-1], n, M[::-1]))  # the order matters
    assert _same_bits(_sum_rows(np.full(5, -1), 3, M[:5]), np.zeros((3, 13)))


@pytest.mark.twin("plane_rows")
def test_plane_rows_bit_for_bit(rng):
    """The TLS planes of moment rows, compiled (``plane_rows``) and NumPy
    (``smallest_eigenpairs``), with and without the Rayleigh quotient: the same normals, rho,
    RMS and means bit for bit, on patches of noisy planes from 0.3 to 20 m, rows of collinear
    points, of one repeated point and empty rows (the last two: a repeated smallest eigenvalue,
    LAPACK's vector in both)."""
    from navkit.planes.extract import _NM, _planes_from_rows

    rows = []
    for _ in range(600):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        u = np.cross(n, rng.normal(size=3))
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        k = int(rng.integers(3, 400))
        a, b = rng.uniform(-0.05, 0.05, (2, k)) * rng.uniform(0.2, 40.0)
        X = rng.uniform(0.3, 20.0) * rng.normal(size=3) + np.outer(a, u) + np.outer(b, v)
        X += rng.normal(scale=rng.uniform(0.0, 0.01), size=(k, 1)) * n
        if len(rows) % 50 == 0:  # on the line y = 0, z = 2, x on a 1/1024 lattice (exact
            # sums): the covariance is exactly diag(., 0, 0)
            x = rng.integers(-500, 500, k) / 1024.0
            X = np.stack([x, np.zeros(k), np.full(k, 2.0)], axis=1)
        elif len(rows) % 50 == 25:  # one point k times (on the lattice): the zero covariance
            X = np.repeat(rng.integers(-500, 500, (1, 3)) / 1024.0, k, axis=0)
        rows.append(np.concatenate([[k], X.sum(axis=0), (X.T @ X).ravel()]))
    M = np.vstack([np.array(rows), np.zeros((5, _NM))])
    from navkit.planes import _kernels

    assert _kernels.plane_rows(M)[4].sum() >= 12 + 5  # repeated eigenvalues: points, empty rows
    for rayleigh in (False, True):
        a = _planes_from_rows(M, True, rayleigh)
        b = _planes_from_rows(M, False, rayleigh)
        for x, y in zip(a, b, strict=True):
            assert _same_bits(x, y)
