"""Simulator benchmarks: ray casting throughput, navkit beside Open3D's RaycastingScene.

Rows:

- ``lidar cast 64x2048, 30 primitives``: one spinning-lidar scan (131,072 rays from one origin)
  of a deterministic 30-primitive scene (flat ground, 4 walls, 10 boxes, 3 ramps, 4 spheres,
  4 hemispheres, 4 cylinders), in million rays per second. navkit: ``Scene.cast`` (analytic
  intersections, float64, one thread; it also returns normals and texture colours). Open3D:
  ``open3d.t.geometry.RaycastingScene.cast_rays`` (Embree BVH, float32, all cores) on the same
  primitives as triangle meshes (spheres / cylinders tessellated). ratio = navkit / Open3D
  throughput (> 1: navkit faster). The note gives the agreement of the two: share of rays with
  the same primitive hit and the median range difference (the tessellation's error).
- ``lidar cast many origins``: the same rays, each from its own origin (the general path).
- ``render_scan / render_rgbd / render_stereo``: navkit end-to-end render times (no peer).

Run: ``python -m benchmarks sim`` (``--quick`` for fewer repeats).
"""

from __future__ import annotations

import logging
import os
from typing import Any

import numpy as np

from benchmarks.common import Row, median_time
from navkit.geometry import R_BODY_FROM_OPTICAL, se3_from_rt
from navkit.sensors import PinholeCamera, StereoRig, grid_directions
from navkit.sim import (
    Box,
    Cylinder,
    Ground,
    Hemisphere,
    Prism,
    Scene,
    Sphere,
    SpinningLidar,
    Wall,
    load_scene,
    render_rgbd,
    render_scan,
    render_stereo,
)

log = logging.getLogger(__name__)

AREA = "sim"


def benchmark_scene(seed: int = 0) -> Scene:
    """A deterministic 30-primitive yard: ground, 4 walls and 25 obstacles within 25 m."""
    rng = np.random.default_rng(seed)

    def xy() -> tuple[float, float]:
        r, a = rng.uniform(3.0, 22.0), rng.uniform(-np.pi, np.pi)
        return float(r * np.cos(a)), float(r * np.sin(a))

    prims: list[Any] = [Ground(name="ground")]
    corners = [(-25.0, -25.0), (25.0, -25.0), (25.0, 25.0), (-25.0, 25.0)]
    for i in range(4):
        (x0, y0), (x1, y1) = corners[i], corners[(i + 1) % 4]
        prims.append(Wall((x0, y0, 0.0), (x1 - x0, y1 - y0, 0.0), (0.0, 0.0, 5.0), name=f"wall{i}"))
    for i in range(10):
        x, y = xy()
        h = rng.uniform(0.4, 1.5)
        prims.append(
            Box(
                (x, y, h / 2),
                (rng.uniform(0.5, 2), rng.uniform(0.5, 2), h),
                yaw=rng.uniform(0, np.pi),
                name=f"box{i}",
            )
        )
    for i in range(3):
        x, y = xy()
        prims.append(
            Prism((x, y, 0.4), (1.5, 1.5, 0.8), yaw=rng.uniform(0, np.pi), name=f"ramp{i}")
        )
    for i in range(4):
        x, y = xy()
        r = rng.uniform(0.3, 0.8)
        prims.append(Sphere((x, y, r + 0.2), r, name=f"sphere{i}"))
    for i in range(4):
        x, y = xy()
        prims.append(Hemisphere((x, y, 0.0), rng.uniform(0.4, 1.0), name=f"rock{i}"))
    for i in range(4):
        x, y = xy()
        prims.append(
            Cylinder((x, y, 0.0), rng.uniform(0.1, 0.3), rng.uniform(1.0, 3.0), name=f"post{i}")
        )
    return Scene(prims, name="bench30")


def _mesh_arrays(p: Any, segments: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(V, 3)`` and triangles ``(T, 3)`` of a primitive (curved ones tessellated)."""
    kind = p.kind
    if kind == "ground":
        s = 1000.0
        v = np.array([[-s, -s, p.height], [s, -s, p.height], [s, s, p.height], [-s, s, p.height]])
        return v, np.array([[0, 1, 2], [0, 2, 3]])
    if kind == "wall":
        o, u, w = (np.asarray(a) for a in (p.origin, p.u, p.v))
        return np.array([o, o + u, o + u + w, o + w]), np.array([[0, 1, 2], [0, 2, 3]])
    if kind in ("box", "prism"):
        hx, hy, hz = 0.5 * np.asarray(p.size)
        if kind == "box":
            v = np.array([[x, y, z] for z in (-hz, hz) for y in (-hy, hy) for x in (-hx, hx)])
            tri = np.array(
                [
                    [0, 2, 1],
                    [1, 2, 3],
                    [4, 5, 6],
                    [5, 7, 6],
                    [0, 1, 4],
                    [1, 5, 4],
                    [2, 6, 3],
                    [3, 6, 7],
                    [0, 4, 2],
                    [2, 4, 6],
                    [1, 3, 5],
                    [3, 7, 5],
                ]
            )
        else:  # wedge: bottom rectangle + top edge at +x
            v = np.array(
                [
                    [-hx, -hy, -hz],
                    [hx, -hy, -hz],
                    [hx, hy, -hz],
                    [-hx, hy, -hz],
                    [hx, -hy, hz],
                    [hx, hy, hz],
                ]
            )
            tri = np.array(
                [
                    [0, 2, 1],
                    [0, 3, 2],
                    [1, 2, 5],
                    [1, 5, 4],
                    [0, 1, 4],
                    [3, 5, 2],
                    [0, 4, 5],
                    [0, 5, 3],
                ]
            )
        c, s = np.cos(p.yaw), np.sin(p.yaw)
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
        return v @ R.T + np.asarray(p.center), tri
    if kind in ("sphere", "hemisphere"):
        n_el = segments // 2 if kind == "sphere" else segments // 4
        el = np.linspace(-np.pi / 2 if kind == "sphere" else 0.0, np.pi / 2, n_el + 1)
        az = np.linspace(0, 2 * np.pi, segments, endpoint=False)
        E, A = np.meshgrid(el, az, indexing="ij")
        v = p.radius * np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], -1)
        v = v.reshape(-1, 3) + np.asarray(p.center)
        i, j = np.meshgrid(np.arange(n_el), np.arange(segments), indexing="ij")
        a, b = i * segments + j, i * segments + (j + 1) % segments
        c_, d = a + segments, b + segments
        tri = np.concatenate(
            [np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c_], -1).reshape(-1, 3)]
        )
        return v, tri
    if kind == "cylinder":
        az = np.linspace(0, 2 * np.pi, segments, endpoint=False)
        ring = np.stack([p.radius * np.cos(az), p.radius * np.sin(az), np.zeros(segments)], -1)
        c = np.asarray(p.center)
        top = c + np.array([0.0, 0.0, p.height])
        v = np.concatenate([ring + c, ring + top, [c, top]])
        j = np.arange(segments)
        k = (j + 1) % segments
        n = segments
        tri = np.concatenate(
            [
                np.stack([j, k, k + n], -1),
                np.stack([j, k + n, j + n], -1),
                np.stack([np.full(n, 2 * n + 1), j + n, k + n], -1),
                np.stack([np.full(n, 2 * n), k, j], -1),
            ]
        )
        return v, tri
    raise ValueError(kind)


def open3d_scene(scene: Scene) -> tuple[Any, np.ndarray] | None:
    """Open3D RaycastingScene of the primitives and the map geometry id -> primitive index."""
    try:
        import open3d as o3d
    except ImportError as exc:
        log.warning("open3d not importable (%s): peer columns left empty", exc)
        return None
    rc = o3d.t.geometry.RaycastingScene()
    ids = []
    for k, p in enumerate(scene.primitives):
        v, t = _mesh_arrays(p)
        gid = rc.add_triangles(
            o3d.core.Tensor(v.astype(np.float32)), o3d.core.Tensor(t.astype(np.uint32))
        )
        ids.append((gid, k))
    lut = np.full(max(g for g, _ in ids) + 1, -1)
    for g, k in ids:
        lut[g] = k
    return rc, lut


def run(quick: bool = False) -> list[Row]:
    repeats = 3 if quick else 7
    rows: list[Row] = []
    scene = benchmark_scene()
    lidar = SpinningLidar(64, 2048)
    origin = np.array([0.0, 0.0, 1.8])
    D = grid_directions(lidar.azimuth, lidar.elevation).reshape(-1, 3)
    n = D.shape[0]
    t_nav = median_time(lambda: scene.cast(origin, D, with_color=False), repeats=repeats)
    t_col = median_time(lambda: scene.cast(origin, D), repeats=repeats)
    hits = scene.cast(origin, D)
    peer = open3d_scene(scene)
    t_o3d = None
    note = (
        f"navkit float64 1 thread (+points, normals); Open3D Embree float32 {os.cpu_count()} "
        f"threads; load average {os.getloadavg()[0]:.1f}"
    )
    if peer is not None:
        import open3d as o3d

        rc, lut = peer
        rays = o3d.core.Tensor(np.hstack([np.tile(origin, (n, 1)), D]).astype(np.float32))
        t_o3d = median_time(lambda: rc.cast_rays(rays), repeats=repeats)
        ans = rc.cast_rays(rays)
        t_hit = ans["t_hit"].numpy().astype(np.float64)
        gid = ans["geometry_ids"].numpy().astype(np.int64)
        miss = ~np.isfinite(t_hit)
        idx_o3d = np.where(miss, -1, lut[np.clip(gid, 0, len(lut) - 1)])
        same = idx_o3d == hits.index
        both = same & hits.hit
        dr = np.abs(t_hit[both] - hits.distance[both])
        kinds = np.array([p.kind for p in scene.primitives] + [""])
        curved = np.isin(kinds[hits.index[both]], ["sphere", "hemisphere", "cylinder"])
        note += (
            f"; same primitive on {100 * same.mean():.2f}% of rays; |dr| max "
            f"{1000 * dr[~curved].max():.2f} mm on flat faces (float32), median "
            f"{1000 * np.median(dr[curved]):.1f} mm on tessellated curved ones"
        )
    rows.append(
        Row(
            AREA,
            "lidar cast 64x2048, 30 primitives",
            "Mrays/s",
            n / t_nav / 1e6,
            None if t_o3d is None else n / t_o3d / 1e6,
            "open3d RaycastingScene",
            None if t_o3d is None else t_o3d / t_nav,
            note,
        )
    )
    rows.append(
        Row(
            AREA,
            "lidar cast 64x2048 + texture colours",
            "Mrays/s",
            n / t_col / 1e6,
            note="the same cast also evaluating the procedural textures",
        )
    )
    # many origins: every ray from its own point (the general, per-ray origin path)
    origins = origin + np.random.default_rng(1).normal(scale=0.05, size=(n, 3))
    t_many = median_time(lambda: scene.cast(origins, D, with_color=False), repeats=repeats)
    t_many_o3d = None
    if peer is not None:
        rays_many = o3d.core.Tensor(np.hstack([origins, D]).astype(np.float32))
        t_many_o3d = median_time(lambda: rc.cast_rays(rays_many), repeats=repeats)
    rows.append(
        Row(
            AREA,
            "lidar cast, 131k origins, 30 primitives",
            "Mrays/s",
            n / t_many / 1e6,
            None if t_many_o3d is None else n / t_many_o3d / 1e6,
            "open3d RaycastingScene",
            None if t_many_o3d is None else t_many_o3d / t_many,
            "rays from distinct origins",
        )
    )
    # end-to-end renders on the shipped yard
    yard = load_scene("yard")
    T = se3_from_rt(np.eye(3), [0.0, 0.0, 1.2])
    t = median_time(lambda: render_scan(yard, lidar, T), repeats=repeats)
    rows.append(Row(AREA, "render_scan yard 64x2048", "s", t, note="with truth labels, one thread"))
    cam = PinholeCamera.from_fov(640, 480, 70.0)
    Tc = se3_from_rt(R_BODY_FROM_OPTICAL, [0.0, 0.0, 1.0])
    t = median_time(lambda: render_rgbd(yard, cam, Tc), repeats=max(2, repeats // 2))
    rows.append(Row(AREA, "render_rgbd yard 640x480", "s", t, note="supersample=1"))
    t = median_time(
        lambda: render_stereo(yard, StereoRig(cam, 0.12), Tc), repeats=max(2, repeats // 2)
    )
    rows.append(Row(AREA, "render_stereo yard 640x480", "s", t, note="two cameras, supersample=2"))
    return rows
