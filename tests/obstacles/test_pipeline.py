"""Stages 2-7 on small grids: the mesh, normals, rules, components, boundaries (vs brute force)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from navkit import jit
from navkit.obstacles import ObstacleSettings, detect_obstacles, detect_obstacles_grid
from navkit.obstacles.mesh import build_mesh, triangle_indices
from navkit.obstacles.rules import GROUND, OBSTACLE
from navkit.obstacles.segment import boundary_vertices, label_components, vertex_labels
from navkit.sensors import RangeScan


def flat_scan(height=1.5, n_az=61, n_el=21, noise=0.0, rng=None):
    az = np.radians(np.linspace(-60, 60, n_az))
    el = np.radians(np.linspace(-40, -5, n_el))
    d = np.tile(height / np.sin(-el), (n_az, 1))
    if noise:
        d = d * (1 + noise * rng.standard_normal(d.shape))
    return RangeScan(d, az, el, sensor_height=height)


def test_triangle_indices_follow_the_paper():
    n_az, n_el = 5, 4
    tri = triangle_indices(n_az, n_el)
    # N_t = 2 (N_alpha - 1)(N_beta - 1); T_k = (iN+j, iN+j+1, (i+1)N+j),
    # T_{k+1} = ((i+1)N+j, iN+j+1, (i+1)N+j+1) with N = n_el
    assert tri.shape == (n_az - 1, 2 * (n_el - 1), 3)
    flat = tri.reshape(-1, 3)
    assert len(flat) == 2 * (n_az - 1) * (n_el - 1)
    N = n_el
    for i in range(n_az - 1):
        for j in range(n_el - 1):
            k = 2 * (i * (n_el - 1) + j)
            assert flat[k].tolist() == [i * N + j, i * N + j + 1, (i + 1) * N + j]
            assert flat[k + 1].tolist() == [(i + 1) * N + j, i * N + j + 1, (i + 1) * N + j + 1]
    wrapped = triangle_indices(n_az, n_el, wrap=True)
    assert wrapped.shape[0] == n_az and wrapped[-1, 0].tolist() == [
        (n_az - 1) * N,
        (n_az - 1) * N + 1,
        0,
    ]


def test_winding_gives_upward_normals_on_level_ground_before_any_flip():
    scan = flat_scan()
    P = scan.points("body")
    tri = triangle_indices(*scan.shape)
    V = P.reshape(-1, 3)[tri]
    raw = np.cross(V[..., 1, :] - V[..., 0, :], V[..., 2, :] - V[..., 0, :])
    assert np.all(raw[..., 2] > 0)  # counter-clockwise seen from above, every triangle
    mesh = build_mesh(
        P,
        scan.valid,
        np.array([0, 0, 1.5]),
        wrap=False,
        jump_height_m=0.3,
        jump_range_fraction=0.01,
    )
    assert np.allclose(mesh.normal[..., 2], 1.0, atol=1e-6)
    assert not mesh.jump.any()


def test_flat_ground_is_all_ground_even_with_noise(rng):
    # 1 % range noise on level ground: height noise ~ 0.01 * 1.5 m, far below every threshold
    for noise in (0.0, 0.01):
        det = detect_obstacles(flat_scan(noise=noise, rng=rng))
        assert det.obstacles == ()
        assert det.counts["obstacle"] == 0
        assert np.all(det.vertex_labels == GROUND)


def step_scan():
    """Level ground with a 0.6 m high, 2 m deep wall-like block from x = 6 m in a 20 deg sector
    (41 x 41 grid, sensor at 2 m): the scan and the block's sector (per azimuth row)."""
    scan = flat_scan(height=2.0, n_az=41, n_el=41)
    el = scan.elevation
    d = scan.ranges.copy()
    sector = np.abs(np.degrees(scan.azimuth)) <= 10
    for i in np.flatnonzero(sector):
        ca = math.cos(scan.azimuth[i])
        for j, b in enumerate(el):
            # intersect the ray with the block: front face x = 6/ca (along the ray's horizontal),
            # top z = 0.6 for horizontal range in [6, 8]
            h0 = 6.0 / ca
            z_at_front = 2.0 + h0 * math.tan(b)
            if 0 <= z_at_front <= 0.6:
                d[i, j] = h0 / math.cos(b)
                continue
            h_top = (2.0 - 0.6) / math.tan(-b)
            if h0 <= h_top <= 8.0 / ca:
                d[i, j] = h_top / math.cos(b)
    return RangeScan(d, scan.azimuth, scan.elevation, sensor_height=2.0), sector


def test_a_step_is_an_obstacle_and_its_far_side_a_shadow():
    # the block's front face is steep (P1), its top is carried by P5, the ground hidden behind it
    # spans a jump down (shadow behind)
    scan, sector = step_scan()
    az_deg = np.degrees(scan.azimuth)
    det = detect_obstacles(scan)
    assert len(det.obstacles) == 1
    ob = det.obstacles[0]
    assert ob.height == pytest.approx(0.6, abs=0.05)
    assert det.counts["shadow_behind"] > 0
    P = det.points
    on_block = sector[:, None] & (np.hypot(P[..., 0], P[..., 1]) > 6.05) & (P[..., 2] > 0.55)
    assert np.all(det.vertex_labels[on_block] == OBSTACLE)  # the whole top, through P5
    # no obstacle far from the block
    far = np.abs(az_deg)[:, None] > 20
    assert not np.any((det.vertex_labels == OBSTACLE) & far)


def test_components_and_boundaries_against_brute_force(rng):
    for wrap in (False, True):
        n_az, n_el = 9, 7
        tri = triangle_indices(n_az, n_el, wrap)
        mask = rng.random(tri.shape[:2]) < 0.3
        lab, _ = label_components(mask, wrap)
        # brute force: union-find over triangles sharing an edge or the structure's vertex link
        flat = tri.reshape(-1, 3)
        idx = np.flatnonzero(mask.ravel())
        parent = {k: k for k in idx}

        def find(k, parent=parent):
            while parent[k] != k:
                parent[k] = parent[parent[k]]
                k = parent[k]
            return k

        for a in idx:
            for b in idx:
                if a < b and len(set(flat[a]) & set(flat[b])) == 2:
                    parent[find(a)] = find(b)
        groups = {}
        for k in idx:
            groups.setdefault(find(k), set()).add(int(lab.ravel()[k]))
        # every edge-connected group has one label (the structure may merge more, never split)
        assert all(len(g) == 1 for g in groups.values())
        vid, b = boundary_vertices(lab, n_az, n_el, wrap)
        for v in range(n_az * n_el):
            around = lab.ravel()[np.any(flat == v, axis=1)]
            m = around.max() if len(around) else 0
            assert vid.ravel()[v] == m
            assert b.ravel()[v] == (m > 0 and not (len(around) == 6 and np.all(around == m)))
        labels = np.where(mask, OBSTACLE, GROUND).astype(np.int8)
        vl = vertex_labels(labels, np.ones((n_az, n_el), bool), wrap)
        for v in range(n_az * n_el):
            around = labels.ravel()[np.any(flat == v, axis=1)]
            assert vl.ravel()[v] == (OBSTACLE if np.any(around == OBSTACLE) else GROUND)


def test_settings_change_the_outcome():
    # a 15 deg slope is ground for c0 = 20 deg and an obstacle for c0 = 10 deg (rule P1)
    az = np.radians(np.linspace(-20, 20, 41))
    el = np.radians(np.linspace(-40, -10, 31))
    slope = math.radians(15)
    # plane z = tan(slope) * (x - 4) for x > 4 m; sensor at 1.5 m
    d = np.empty((41, 31))
    for i, a in enumerate(az):
        for j, b in enumerate(el):
            dx = math.cos(b) * math.cos(a)
            dz = math.sin(b)
            t_ground = -1.5 / dz
            if t_ground * dx <= 4:
                d[i, j] = t_ground
            else:
                d[i, j] = (1.5 + math.tan(slope) * 4) / (math.tan(slope) * dx - dz)
    scan = RangeScan(d, az, el, sensor_height=1.5)
    assert detect_obstacles(scan, ObstacleSettings(c0_deg=20)).counts["obstacle"] == 0
    steep = detect_obstacles(scan, ObstacleSettings(c0_deg=10))
    assert steep.counts["obstacle"] > 0 and len(steep.obstacles) >= 1


def test_grid_entry_takes_points_directly():
    scan = flat_scan()
    P = scan.points("body")
    det = detect_obstacles_grid(P, (0.0, 0.0, 1.5))
    assert det.obstacles == () and det.triangle_labels.shape == (60, 40)


@pytest.mark.parametrize("implementation", ["numpy", "eager"])
def test_build_map_false_stops_after_stage_7_with_the_same_labels(implementation):
    """``build_map=False`` (stages 1-7 only): the same per-point and per-triangle classes,
    obstacle ids and boundaries as the full detection of a scan with obstacles, and no records."""
    from navkit.experiments.obstacles import paper_scenes, scanners
    from navkit.geometry import se3_from_rt
    from navkit.sim import render_scan

    sc, height = scanners()["spinning64"]
    sim = render_scan(
        paper_scenes()["four"], sc, se3_from_rt(np.eye(3), [0.0, 0.0, height]), max_range=60.0
    )
    with jit.use(implementation):
        full = detect_obstacles(sim.scan, ObstacleSettings())
        part = detect_obstacles(sim.scan, ObstacleSettings(build_map=False))
    assert len(full.obstacles) >= 3 and part.obstacles == ()
    for name in ("vertex_labels", "vertex_obstacle", "boundary", "triangle_labels"):
        assert np.array_equal(getattr(part, name), getattr(full, name)), name
    assert set(np.unique(part.vertex_obstacle[part.vertex_obstacle > 0])) == {
        o.id for o in full.obstacles
    }


def test_a_detection_keeps_its_arrays_when_the_next_frame_runs():
    """The compiled stages keep work arrays between frames of one grid shape
    (``_buffers.cached_work``): every array a detection returns must stay as it was when the
    next frame of the same shape is detected, and equal the NumPy twins'."""
    step, _ = step_scan()
    flat = flat_scan(height=2.0, n_az=41, n_el=41)
    st = ObstacleSettings()
    with jit.use("eager"):
        first = detect_obstacles(step, st)
    names = ("points", "valid", "normals", "jump", "triangle_labels", "triangle_obstacle")
    names += ("vertex_labels", "vertex_obstacle", "boundary")
    kept = {k: getattr(first, k).copy() for k in names}
    assert first.triangle_obstacle.max() >= 1 and first.boundary.any()
    with jit.use("eager"):
        second = detect_obstacles(flat, st)
    assert second.triangle_obstacle.max() == 0
    with jit.use("numpy"):
        ref = detect_obstacles(step, st)
    for k in names:
        assert np.array_equal(getattr(first, k), kept[k], equal_nan=k in ("points", "normals")), k
        if k != "normals":  # float32 normals: the twins agree to rounding (test_kernels)
            assert np.array_equal(getattr(first, k), getattr(ref, k), equal_nan=k == "points"), k
