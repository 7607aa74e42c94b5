"""``navkit demo``'s pictures: every simulated sensor rendered at the start pose, with the truth.

:func:`render_sensor_pictures` renders the spinning lidar, the tilting scanner, the RGB-D camera
and the stereo pair (:mod:`navkit.sim`) as :class:`~navkit.mission.settings.DemoSettings` says,
writes one picture per sensor and the rendered data in standard formats.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

__all__ = ["render_sensor_pictures", "write_scan_cloud"]


def _pose_matrix(x: float, y: float, z: float, yaw: float, pitch_down: float = 0.0) -> Any:
    import numpy as np

    from navkit.geometry import se3_from_rt

    cz, sz = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch_down), np.sin(pitch_down)
    Rz = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    Ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])  # +pitch about y tips x down
    return se3_from_rt(Rz @ Ry, [x, y, z])


def write_scan_cloud(path: Path, sim: Any) -> None:
    """A simulated scan as an organised PCD (rows = elevations, body frame, NaN = no return).

    Extra fields: ``label`` (uint8: 0 no return, 1 ground, 2 obstacle - the truth) and
    ``primitive`` (int32 index into the scene, -1 = none).
    """
    import numpy as np

    from navkit.io.pointcloud import PointCloud, write_pcd

    valid = sim.scan.valid.T  # (n_el, n_az): one row per elevation, as lidar rings
    pts = sim.scan.points("body").transpose(1, 0, 2).reshape(-1, 3)
    label = np.where(~valid, 0, np.where(sim.is_ground.T, 1, 2)).astype(np.uint8).ravel()
    prim = np.where(valid, sim.hit_index.T, -1).astype(np.int32).ravel()
    n_el, n_az = valid.shape
    cloud = PointCloud(pts, {"label": label, "primitive": prim}, width=n_az, height=n_el)
    write_pcd(path, cloud, compressed=True)


def render_sensor_pictures(
    out: Path,
    settings: Any,
    progress: Callable[[Iterable[Any], str], Iterator[Any]] | None = None,
) -> dict[str, Any]:
    """Render every sensor, write the pictures into ``out``, return the summary figures.

    The rendered data also go to ``out/data/`` in standard formats: ``lidar.pcd`` and
    ``tilting_scanner.pcd`` (organised PCD with the ground / obstacle truth as a ``label``
    field), ``rgbd_color.png`` + ``rgbd_depth.png`` (16-bit, millimetres), ``stereo_left.png``,
    ``stereo_right.png`` and ``stereo_disparity_true.pfm``.
    """
    import numpy as np

    from navkit.geometry import R_BODY_FROM_OPTICAL
    from navkit.io.images import write_depth, write_image, write_pfm
    from navkit.sensors import PinholeCamera, StereoRig
    from navkit.sim import (
        RangeNoise,
        SpinningLidar,
        TiltingScanner,
        load_scene,
        render_rgbd,
        render_scan,
        render_stereo,
    )
    from navkit.viz import sensors as viz

    rng = np.random.default_rng(settings.seed)
    scene = load_scene(settings.scene)
    x, y, th = settings.robot_pose
    gz = float(scene.ground_height(x, y))
    L, S, C = settings.lidar, settings.scanner, settings.camera
    T_lidar = _pose_matrix(x, y, gz + L.height, th)
    T_scanner = _pose_matrix(x, y, gz + S.height, th)
    T_cam_body = _pose_matrix(x, y, gz + C.height, th, np.radians(C.pitch_down_deg))
    T_cam = T_cam_body.copy()
    T_cam[:3, :3] = T_cam_body[:3, :3] @ R_BODY_FROM_OPTICAL  # body axes -> OpenCV optical axes
    camera = PinholeCamera.from_fov(C.width, C.height_px, C.hfov_deg)
    summary: dict[str, Any] = {
        "scene": scene.name,
        "primitives": len(scene),
        "true_planes": len(scene.true_planes()),
        "robot_pose_xytheta": [x, y, th],
        "sensors": {},
        "outputs": [],
    }

    def scan_summary(sim: Any, seconds: float) -> dict[str, Any]:
        valid = sim.scan.valid
        names = scene.primitive_names(sim.hit_index[valid])
        seen, counts = np.unique(names, return_counts=True)
        return {
            "rays": int(valid.size),
            "returns": int(valid.sum()),
            "ground_returns": int((valid & sim.is_ground).sum()),
            "obstacle_returns": int((valid & ~sim.is_ground).sum()),
            "render_seconds": round(seconds, 3),
            "returns_per_primitive": {str(n): int(c) for n, c in zip(seen, counts, strict=True)},
        }

    def lidar() -> str:
        t0 = time.perf_counter()
        sim = render_scan(
            scene,
            SpinningLidar(L.n_beams, L.n_columns, L.elevation_min_deg, L.elevation_max_deg),
            T_lidar,
            RangeNoise(L.relative_sigma, L.absolute_sigma, L.dropout),
            rng,
            L.max_range,
        )
        summary["sensors"]["lidar"] = scan_summary(sim, time.perf_counter() - t0)
        viz.plot_scan(
            sim, scene, out / "lidar.png", title=f"spinning lidar {L.n_beams} x {L.n_columns}"
        )
        write_scan_cloud(out / "data" / "lidar.pcd", sim)
        return "lidar.png"

    def scanner() -> str:
        t0 = time.perf_counter()
        sensor = TiltingScanner(
            azimuth_step_deg=S.azimuth_step_deg,
            elevation_min_deg=S.elevation_min_deg,
            elevation_max_deg=S.elevation_max_deg,
            elevation_step_deg=S.elevation_step_deg,
        )
        sim = render_scan(
            scene,
            sensor,
            T_scanner,
            RangeNoise(S.relative_sigma, S.absolute_sigma, S.dropout),
            rng,
            S.max_range,
        )
        summary["sensors"]["tilting_scanner"] = scan_summary(sim, time.perf_counter() - t0)
        viz.plot_scan(sim, scene, out / "tilting_scanner.png", title="tilting 2D scanner")
        write_scan_cloud(out / "data" / "tilting_scanner.pcd", sim)
        return "tilting_scanner.png"

    def rgbd() -> str:
        t0 = time.perf_counter()
        sim = render_rgbd(
            scene,
            camera,
            T_cam,
            RangeNoise(C.depth_relative_sigma),
            rng,
            supersample=2,
            max_depth=C.max_depth,
        )
        d = sim.frame.depth
        summary["sensors"]["rgbd"] = {
            "size": [C.width, C.height_px],
            "valid_depth": int(np.isfinite(d).sum()),
            "depth_range_m": [float(np.nanmin(d)), float(np.nanmax(d))],
            "render_seconds": round(time.perf_counter() - t0, 3),
        }
        viz.plot_rgbd(sim, out / "rgbd.png")
        write_image(out / "data" / "rgbd_color.png", sim.frame.color)
        write_depth(out / "data" / "rgbd_depth.png", sim.frame.depth, scale=1000.0)
        return "rgbd.png"

    def stereo() -> str:
        t0 = time.perf_counter()
        rig = StereoRig(camera, C.stereo_baseline)
        sim = render_stereo(scene, rig, T_cam, rng, pixel_noise=C.stereo_pixel_noise)
        disp = sim.disparity
        summary["sensors"]["stereo"] = {
            "size": [C.width, C.height_px],
            "baseline_m": C.stereo_baseline,
            "disparity_px": [float(np.nanmin(disp)), float(np.nanmax(disp))],
            "render_seconds": round(time.perf_counter() - t0, 3),
        }
        viz.plot_stereo(sim, out / "stereo.png")
        write_image(out / "data" / "stereo_left.png", sim.pair.left)
        write_image(out / "data" / "stereo_right.png", sim.pair.right)
        write_pfm(out / "data" / "stereo_disparity_true.pfm", sim.disparity.astype(np.float32))
        return "stereo.png"

    def world() -> str:
        viz.plot_world(scene, out / "world.png", poses=[(x, y, th)], pose_labels=["robot"])
        return "world.png"

    stages = [world, lidar, scanner, rgbd, stereo]
    for stage in progress(stages, "rendering sensors") if progress is not None else stages:
        summary["outputs"].append(stage())
    return summary
