"""Plane extraction against the simulator's true planes and on recorded clouds."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from navkit.errors import InputError
from navkit.geometry import se3_inverse
from navkit.geometry.fitting import canonical_plane, fit_plane
from navkit.planes import (
    CloudExtractionSettings,
    ExtractionSettings,
    extract_planes_cloud,
    extract_planes_organized,
)
from navkit.planes.extract import smallest_eigenpairs

ES = ExtractionSettings(cell=10)


def true_planes_in_camera(scene, T_world_camera):
    """The scene's true planes ``(n, rho)`` expressed in the camera frame."""
    T = se3_inverse(T_world_camera)
    R, t = T[:3, :3], T[:3, 3]
    out = {}
    for name, p in scene.true_planes():
        n = R @ p.normal
        out[name] = canonical_plane(n, p.rho + n @ t)
    return out


def match(seg, truth):
    """Nearest true plane: (name, angle deg, |rho error| m)."""
    best = None
    for name, (n, rho) in truth.items():
        ang = np.degrees(np.arccos(np.clip(abs(seg.normal @ n), -1, 1)))
        d = abs(seg.rho - rho)
        if best is None or ang + 100 * d < best[1] + 100 * best[2]:
            best = (name, ang, d)
    return best


def test_organized_planes_match_the_simulator(pairs):
    p = pairs[3]
    res = extract_planes_organized(p.f1.frame.points(), ES)
    truth = true_planes_in_camera(p.scene, p.f1.T_world_camera)
    found = {}
    for seg in res.segments:
        name, ang, d = match(seg, truth)
        found[name] = (ang, d, seg)
    assert set(found) == {"wall", "floor", "end"}
    for ang, d, seg in found.values():
        # depth noise 0.2 % (<= 16 mm at 8 m) over >= 10^4 inliers spread over metres: the TLS
        # normal error is ~ sigma / (sqrt(N) * extent) < 1e-3 rad; 0.2 deg / 1 cm leave room for
        # the points near plane intersections that the boundary refinement may include
        assert ang < 0.2 and d < 0.01
        # inliers are the pixels that truly see this plane (> 97 %, boundary pixels excepted)
        hit = p.f1.hit_index.ravel()[seg.inliers]
        assert np.bincount(hit[hit >= 0]).max() / len(hit) > 0.97
        # residual matches the simulated noise: sigma = 0.002 * depth (< 0.02 m here)
        assert seg.rms < 0.02
    labels = res.labels
    assert labels.shape == (CAMERA_H, CAMERA_W)
    # every inlier carries its segment's label
    for k, seg in enumerate(res.segments):
        assert np.all(labels.ravel()[seg.inliers] == k)


CAMERA_H, CAMERA_W = 240, 320


def test_outline_area_of_the_floor(pairs):
    """The floor's visible area equals the area of the floor pixels' footprints (truth)."""
    p = pairs[2]
    res = extract_planes_organized(p.f1.frame.points(), ES)
    truth = true_planes_in_camera(p.scene, p.f1.T_world_camera)
    floor = next(s for s in res.segments if match(s, truth)[0] == "floor")
    # outline vertices lie on the plane
    assert np.allclose(floor.plane.distance(floor.outline_3d()), 0, atol=1e-9)
    assert len(floor.outline) >= 3 and floor.area > 1.0


def test_unorganized_cloud_planes(pairs):
    p = pairs[3]
    P = p.f1.frame.points().reshape(-1, 3)
    P = P[np.all(np.isfinite(P), axis=1)]
    rng = np.random.default_rng(0)
    P = P[rng.permutation(len(P))]  # no grid structure left
    res = extract_planes_cloud(P, CloudExtractionSettings(distance=0.03))
    truth = true_planes_in_camera(p.scene, p.f1.T_world_camera)
    names = set()
    for seg in res.segments[:3]:
        name, ang, d = match(seg, truth)
        # RANSAC + TLS refit on >= 10^4 points: same noise argument as the organised case
        assert ang < 0.3 and d < 0.015
        names.add(name)
    assert names == {"wall", "floor", "end"}


def test_bad_input_is_an_input_error():
    with pytest.raises(InputError, match="points"):
        extract_planes_organized(np.zeros((10, 3)))
    with pytest.raises(InputError, match="points"):
        extract_planes_cloud(np.zeros((10, 3, 3)))
    with pytest.raises(InputError, match="cell"):
        ExtractionSettings(cell=1)


def test_empty_and_nan_input_gives_no_planes():
    res = extract_planes_organized(np.full((60, 80, 3), np.nan))
    assert len(res) == 0 and np.all(res.labels == -1)


def test_pcl_kinect_capture_has_walls_and_floor(data_path):
    from navkit.io.pointcloud import read_pcd

    cloud = read_pcd(data_path("rgbd/pcl-kinect/capture0001.pcd"))
    res = extract_planes_organized(cloud.grid(), ExtractionSettings())
    assert len(res) >= 3
    # real Kinect data: the biggest planes are flat to within the sensor's noise (~1-2 cm at 2-3 m)
    for seg in res.segments[:3]:
        assert seg.rms < 0.03
    normals = np.array([s.normal for s in res.segments[:6]])
    # a staircase beside a wall: treads / floor (normal ~ camera y) and the wall (normal mostly
    # along the optical axis) - two directions more than 60 deg apart
    cross = np.linalg.norm(np.cross(normals[:, None], normals[None]), axis=2)
    assert cross.max() > np.sin(np.radians(60))


def test_pcl_room_scan_planes(data_path):
    from navkit.io.pointcloud import read_pcd

    cloud = read_pcd(data_path("scans3d/pcl-room/room_scan1.pcd"))
    res = extract_planes_cloud(cloud.points)
    assert len(res) >= 3
    # a room: floor / ceiling and walls give three independent directions
    normals = np.array([s.normal for s in res.segments])
    assert np.linalg.svd(normals, compute_uv=False)[2] > 0.2
    for seg in res.segments[:3]:
        assert seg.rms < 0.02  # RANSAC band +-2 cm


def test_wall_area_and_outline_match_the_view(pairs):
    """The wall fills the whole 1-plane view: its area is the frustum's footprint at 2 m."""
    from .conftest import CAMERA

    p = pairs[1]
    res = extract_planes_organized(p.f1.frame.points(), ES)
    wall = res.segments[0]
    d = 2.0  # camera at y = 0.5, wall at y = -1.5, looking straight at it
    width = CAMERA.width / CAMERA.fx * d
    height = CAMERA.height / CAMERA.fy * d
    # a 2 cm raster cell counts when any point falls in it: the border adds up to one cell along
    # the perimeter, 0.02 m x 8.5 m = 0.17 m^2 (3.8 %); depth noise (4 mm) moves points < 1 mm
    assert wall.area == pytest.approx(width * height, rel=0.06)
    from navkit.geometry.polygons import polygon_area

    assert polygon_area(wall.outline) == pytest.approx(width * height, rel=0.06)
    assert wall.area >= width * height  # the raster never loses covered area


def test_boundary_refinement_recovers_the_pixels_of_each_plane(pairs):
    """Recall at pixel level: the pixels that truly see a plane are labelled with it, also in
    the patches that straddle a crease or a plane's edge (the vectorised boundary pass). Only
    the pixels within ~one noise band of the other plane at a crease, and mixed pixels, can be
    lost: about one pixel row per crease (~1-2 % of a 10^4-pixel plane; measured 98.3-99.9 %)."""
    p = pairs[3]
    res = extract_planes_organized(p.f1.frame.points(), ES)
    hit = p.f1.hit_index.ravel()
    for seg in res.segments:
        h = hit[seg.inliers]
        k = np.bincount(h[h >= 0]).argmax()
        truth = np.flatnonzero(hit == k)
        assert np.isin(truth, seg.inliers).mean() > 0.97


# ---------------------------------------------------------------- the organised extraction's parts


@settings(max_examples=200, deadline=None)
@given(
    st.integers(0, 2**32 - 1),
    st.floats(1e-8, 1e-2),
    st.floats(2.0, 1e4),
    st.floats(1.0, 1e4),
)
def test_smallest_eigenpairs_match_lapack(seed, lam_min, gap, spread):
    """The closed form's smallest eigenpair equals LAPACK's (``numpy.linalg.eigh``).

    Scatter matrices of planar patches: smallest eigenvalue ``lam_min`` (thickness^2, m^2), the
    others ``gap`` and ``gap * spread`` times larger. Both use float64; the eigenvalue agrees to
    ~1e-12 of the largest one (the closed form's cancellation in ``q + 2 p cos``), the eigenvector
    to ``eps * lambda_max / (lambda_2 - lambda_min)`` (Davis-Kahan; <= 1e-9 rad here, 1e-7
    allowed).
    """
    rng = np.random.default_rng(seed)
    R = Rotation.random(random_state=rng).as_matrix()
    w = np.array([lam_min, lam_min * gap, lam_min * gap * spread])
    C = (R * w) @ R.T
    lam, vec = smallest_eigenpairs(C[None])
    assert lam[0] == pytest.approx(lam_min, abs=1e-12 * w[2])
    assert np.linalg.norm(vec[0]) == pytest.approx(1.0)
    ref = np.linalg.eigh(C)[1][:, 0]
    assert np.degrees(np.arccos(min(1.0, abs(vec[0] @ ref)))) < np.degrees(1e-7)


def test_smallest_eigenpairs_of_degenerate_matrices():
    """An all-zero scatter (an empty patch) and repeated eigenvalues (a line, a blob) give a
    finite unit vector of the smallest eigenspace, never NaN."""
    C = np.zeros((3, 3, 3))
    C[1] = np.diag([0.0, 0.0, 1.0])  # points on a line along z: normal anywhere in x-y
    C[2] = np.eye(3) * 0.5  # isotropic blob
    lam, vec = smallest_eigenpairs(C)
    assert np.all(np.isfinite(vec)) and np.allclose(np.linalg.norm(vec, axis=1), 1.0)
    assert lam == pytest.approx([0.0, 0.0, 0.5])
    assert abs(vec[1, 2]) < 1e-12  # orthogonal to the line


def test_patch_moments_match_float64(pairs):
    """float32 moments centred per patch equal a float64 computation patch by patch.

    Both start from the same float32-rounded coordinates, so only the accumulation differs:
    sums of 100 products of centred coordinates (<= 0.05 m here) in float32 carry a relative
    error <= 100 * 6e-8 = 6e-6 of the largest term; the thickness (smallest eigenvalue, the
    planarity test) is compared to 1e-4 of the patch's largest eigenvalue.
    """
    from navkit.planes.extract import _patch_moments, _planes_from_rows

    P = pairs[3].f1.frame.points()
    s = ExtractionSettings(cell=10)
    hc, wc = P.shape[0] // 10, P.shape[1] // 10
    pt = _patch_moments(P, s, hc, wc)
    blocks = P[: hc * 10, : wc * 10].astype(np.float32).astype(np.float64)
    blocks = blocks.reshape(hc, 10, wc, 10, 3).transpose(0, 2, 1, 3, 4).reshape(hc * wc, 100, 3)
    ok = np.all(np.isfinite(blocks), axis=2)
    n = ok.sum(axis=1)
    full = n == 100
    assert full.sum() > 300
    X = blocks[full]
    mean = X.mean(axis=1)
    C = np.einsum("gpi,gpj->gij", X - mean[:, None], X - mean[:, None]) / 100
    w = np.linalg.eigh(C)[0]
    assert np.array_equal(pt.M[:, 0], n.astype(float))
    _, _, rms, m = _planes_from_rows(pt.M[full])
    assert np.allclose(m, mean, atol=1e-6)
    assert np.all(np.abs(rms**2 - np.maximum(w[:, 0], 0)) <= 1e-4 * w[:, 2])


def test_refinement_modes_agree_with_the_truth(pairs):
    """``refine="boundary"`` (interior patches wholesale) and ``"full"`` (every pixel tested)
    both meet the simulator's planes to the tolerances of the first test, and differ in at most
    0.5 % of the labels (the outliers of interior patches: none in the simulated planes)."""
    p = pairs[3]
    P = p.f1.frame.points()
    truth = true_planes_in_camera(p.scene, p.f1.T_world_camera)
    res = {
        m: extract_planes_organized(P, ExtractionSettings(cell=10, refine=m))
        for m in ("boundary", "full")
    }
    for r in res.values():
        assert len(r) == 3
        for seg in r.segments:
            _, ang, d = match(seg, truth)
            assert ang < 0.2 and d < 0.01
    assert (res["boundary"].labels != res["full"].labels).mean() < 0.005


def test_refinement_modes_on_a_real_frame(data_path):
    """Real Kinect frame (slambook-ch5): the two refinement modes give the same planes - the
    label images differ in < 0.5 % of the pixels and matched normals by < 0.5 deg (a plane's
    normal moves by ~ f * (outlier distance / extent) for a fraction f of outliers; f <= 2 %,
    distances <= 4.5 x the 5-7 cm bound over >= 0.5 m extents)."""
    from navkit.io.rgbd import read_simple_rgbd

    root = data_path("rgbd/slambook-ch5")
    seq = read_simple_rgbd(
        root, {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0}
    )
    P = seq.frame(0).points()
    b = extract_planes_organized(P, ExtractionSettings())
    f = extract_planes_organized(P, ExtractionSettings(refine="full"))
    assert len(b) >= 5 and len(b) == len(f)
    assert (b.labels != f.labels).mean() < 0.005
    for sb, sf in zip(b.segments, f.segments, strict=True):
        assert np.degrees(np.arccos(min(1.0, abs(sb.normal @ sf.normal)))) < 0.5


def test_inliers_labels_and_counts_are_consistent(pairs):
    """Inliers are increasing raster indices, as many as the plane's count, each labelled with
    its segment; every labelled pixel is an inlier of exactly that segment; the plane is the TLS
    fit of exactly its inliers (float64 reference)."""
    P = pairs[3].f1.frame.points()
    res = extract_planes_organized(P, ES)
    flat = res.labels.ravel()
    assert flat.dtype == np.int64
    total = 0
    for k, seg in enumerate(res.segments):
        assert np.all(np.diff(seg.inliers) > 0)
        assert seg.plane.count == len(seg.inliers)
        assert np.all(flat[seg.inliers] == k)
        total += len(seg.inliers)
        X = P.reshape(-1, 3)[seg.inliers].astype(np.float32).astype(np.float64)
        ref = fit_plane(X)
        assert np.degrees(np.arccos(min(1.0, abs(ref.normal @ seg.normal)))) < 1e-3
        assert seg.rho == pytest.approx(ref.rho, abs=1e-6)
        assert seg.rms == pytest.approx(ref.rms, rel=1e-4)
    assert total == (flat >= 0).sum()


def test_outline_from_patches_covers_what_the_pixels_cover(pairs):
    """The outline rasterised from whole patches (quadrilaterals) and border pixels covers the
    same area as all inlier pixels rasterised (the former definition, computed here): the two
    rasters can differ only in the cells along the outline, <= one 2 cm cell x perimeter."""
    from navkit.geometry.polygons import polygon_perimeter
    from navkit.planes.segments import outline_from_points, plane_frame

    for n_dirs in (1, 3):
        P = pairs[n_dirs].f1.frame.points().reshape(-1, 3)
        for seg in extract_planes_organized(pairs[n_dirs].f1.frame.points(), ES).segments:
            o, ax = plane_frame(seg.plane)
            ref_outline, ref_area = outline_from_points((P[seg.inliers] - o) @ ax.T, 0.02)
            band = 0.02 * polygon_perimeter(ref_outline)
            assert seg.area == pytest.approx(ref_area, abs=band)


def test_refine_setting_is_checked():
    with pytest.raises(InputError, match="refine"):
        ExtractionSettings(refine="exact")


def test_outline_from_quadrilaterals_and_points():
    """Quadrilaterals alone, and with points elsewhere, never lose covered area and over-cover
    by a bounded margin: a unit square (no points), then plus a separate 0.5 x 1 m strip sampled
    every 5 mm, at a 2 cm raster. Upper bound: ``cv2.fillPoly`` paints the cells its edges
    touch (side L -> L + 1 cell) and the 3 x 3 closing fills the raster's one-cell margin where
    a shape reaches it (OpenCV's erosion treats outside the image as set: + 1 cell on each such
    side), so a side is at most L + 3 cells: (1 + 0.06)^2 m^2 for the square and
    (0.5 + 0.06) x (1 + 0.06) m^2 more for the strip. The outline is the largest component, the
    square, to within that margin."""
    from navkit.planes.segments import outline_from_points

    square = np.array([[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]])
    outline, area = outline_from_points(np.zeros((0, 2)), 0.02, quads=square)
    assert 1.0 <= area <= 1.06**2 + 1e-9
    assert np.all(np.abs(outline.min(axis=0)) <= 0.04)
    assert np.all(np.abs(outline.max(axis=0) - 1.0) <= 0.04)
    g = np.arange(0.0, 1.0 + 1e-9, 0.005)
    strip = np.stack(np.meshgrid(1.5 + g[g <= 0.5 + 1e-9], g), axis=-1).reshape(-1, 2)
    outline, area = outline_from_points(strip, 0.02, quads=square)
    assert 1.5 <= area <= 1.06**2 + 0.56 * 1.06 + 1e-9
    assert outline[:, 0].max() < 1.05  # the square, not the strip


def test_rayleigh_eigenvalue_of_an_extreme_spread(rng):
    """A far floor's scatter (eigenvalues 1372, 3.8 and 4.1e-6 m^2, the simulated corridor's
    floor): the closed-form eigenvalue has an absolute error ~eps x 1372; the Rayleigh quotient
    of its unit vector (the final planes' RMS) agrees with LAPACK's ``eigh`` to 1e-7 relative,
    and the vector is the same."""
    for _ in range(20):
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        C = Q @ np.diag([1372.0, 3.8, 4.1e-6]) @ Q.T
        C = (C + C.T) / 2
        w, V = np.linalg.eigh(C)
        lam, vec = smallest_eigenpairs(C[None], rayleigh=True)
        assert abs(lam[0] - w[0]) <= 1e-7 * w[0]
        assert abs(abs(vec[0] @ V[:, 0]) - 1.0) <= 1e-12
