"""``navkit demo``'s pictures: every simulated sensor rendered at the start pose, with the truth.

:func:`render_sensor_pictures` renders the spinning lidar, the tilting scanner, the RGB-D camera
and the stereo pair (:mod:`navkit.sim`) as :class:`~navkit.mission.settings.DemoSettings` says,
writes one picture per sensor and the rendered data in standard formats.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
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


@dataclass(frozen=True)
class _Shoot:
    """What every picture of :func:`render_sensor_pictures` needs: the scene, the sensors'
    poses, one random stream (used in the pictures' order), the summary being filled."""

    out: Path
    settings: Any
    scene: Any
    rng: Any
    T_lidar: Any
    T_scanner: Any
    T_cam: Any
    camera: Any
    T_stereo: Any
    stereo_camera: Any
    summary: dict[str, Any]


def _setup(out: Path, settings: Any) -> _Shoot:
    """The scene and the sensors' poses at ``settings.robot_pose``."""
    import numpy as np

    from navkit.geometry import R_BODY_FROM_OPTICAL
    from navkit.sensors import PinholeCamera
    from navkit.sim import load_scene

    scene = load_scene(settings.scene)
    x, y, th = settings.robot_pose
    gz = float(scene.ground_height(x, y))
    L, S, C, St = settings.lidar, settings.scanner, settings.camera, settings.stereo
    T_cam = _pose_matrix(x, y, gz + C.height, th, np.radians(C.pitch_down_deg))
    T_cam[:3, :3] = T_cam[:3, :3] @ R_BODY_FROM_OPTICAL  # body axes -> OpenCV optical axes
    T_stereo = _pose_matrix(x, y, gz + St.height, th)  # level, the pan drive at 0
    T_stereo[:3, :3] = T_stereo[:3, :3] @ R_BODY_FROM_OPTICAL
    summary: dict[str, Any] = {
        "scene": scene.name,
        "primitives": len(scene),
        "true_planes": len(scene.true_planes()),
        "robot_pose_xytheta": [x, y, th],
        "sensors": {},
        "outputs": [],
    }
    return _Shoot(
        out,
        settings,
        scene,
        np.random.default_rng(settings.seed),
        _pose_matrix(x, y, gz + L.height, th),
        _pose_matrix(x, y, gz + S.height, th),
        T_cam,
        PinholeCamera.from_fov(C.width_px, C.height_px, C.hfov_deg),
        T_stereo,
        PinholeCamera.from_fov(St.width_px, St.height_px, St.hfov_deg),
        summary,
    )


def _scan_summary(scene: Any, sim: Any, seconds: float) -> dict[str, Any]:
    """Returns of a simulated scan: counts by truth, and per primitive."""
    import numpy as np

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


def _world(r: _Shoot) -> str:
    from navkit.viz import sensors as viz

    pose = tuple(r.settings.robot_pose)
    viz.plot_world(r.scene, r.out / "world.png", poses=[pose], pose_labels=["robot"])
    return "world.png"


def _lidar(r: _Shoot) -> str:
    from navkit.sim import SpinningLidar, render_scan
    from navkit.sim.scanners import RangeNoise
    from navkit.viz import sensors as viz

    L = r.settings.lidar
    t0 = time.perf_counter()
    sensor = SpinningLidar(L.n_beams, L.n_columns, L.elevation_min_deg, L.elevation_max_deg)
    noise = RangeNoise(L.relative_sigma, L.absolute_sigma, L.dropout)
    sim = render_scan(r.scene, sensor, r.T_lidar, noise, r.rng, L.max_range)
    r.summary["sensors"]["lidar"] = _scan_summary(r.scene, sim, time.perf_counter() - t0)
    title = f"spinning lidar {L.n_beams} x {L.n_columns}"
    viz.plot_scan(sim, r.scene, r.out / "lidar.png", title=title)
    write_scan_cloud(r.out / "data" / "lidar.pcd", sim)
    return "lidar.png"


def _scanner(r: _Shoot) -> str:
    from navkit.sim import TiltingScanner, render_scan
    from navkit.sim.scanners import RangeNoise
    from navkit.viz import sensors as viz

    S = r.settings.scanner
    t0 = time.perf_counter()
    sensor = TiltingScanner(
        azimuth_step_deg=S.azimuth_step_deg,
        elevation_min_deg=S.elevation_min_deg,
        elevation_max_deg=S.elevation_max_deg,
        elevation_step_deg=S.elevation_step_deg,
    )
    noise = RangeNoise(S.relative_sigma, S.absolute_sigma, S.dropout)
    sim = render_scan(r.scene, sensor, r.T_scanner, noise, r.rng, S.max_range)
    r.summary["sensors"]["tilting_scanner"] = _scan_summary(r.scene, sim, time.perf_counter() - t0)
    viz.plot_scan(sim, r.scene, r.out / "tilting_scanner.png", title="tilting 2D scanner")
    write_scan_cloud(r.out / "data" / "tilting_scanner.pcd", sim)
    return "tilting_scanner.png"


def _rgbd(r: _Shoot) -> str:
    import numpy as np

    from navkit.io.images import write_depth, write_image
    from navkit.sim import render_rgbd
    from navkit.sim.scanners import RangeNoise
    from navkit.viz import sensors as viz

    C = r.settings.camera
    t0 = time.perf_counter()
    noise = RangeNoise(C.depth_relative_sigma)
    sim = render_rgbd(
        r.scene, r.camera, r.T_cam, noise, r.rng, supersample=2, max_depth=C.max_depth
    )
    d = sim.frame.depth
    r.summary["sensors"]["rgbd"] = {
        "size": [C.width_px, C.height_px],
        "valid_depth": int(np.isfinite(d).sum()),
        "depth_range_m": [float(np.nanmin(d)), float(np.nanmax(d))],
        "render_seconds": round(time.perf_counter() - t0, 3),
    }
    viz.plot_rgbd(sim, r.out / "rgbd.png")
    write_image(r.out / "data" / "rgbd_color.png", sim.frame.color)
    write_depth(r.out / "data" / "rgbd_depth.png", sim.frame.depth, scale=1000.0)
    return "rgbd.png"


def _stereo(r: _Shoot) -> str:
    import numpy as np

    from navkit.io.images import write_image, write_pfm
    from navkit.sensors import StereoRig
    from navkit.sim import render_stereo
    from navkit.viz import sensors as viz

    St = r.settings.stereo
    t0 = time.perf_counter()
    rig = StereoRig(r.stereo_camera, St.baseline)
    sim = render_stereo(r.scene, rig, r.T_stereo, r.rng, pixel_noise=St.pixel_noise)
    disp = sim.disparity
    r.summary["sensors"]["stereo"] = {
        "size": [St.width_px, St.height_px],
        "baseline_m": St.baseline,
        "disparity_px": [float(np.nanmin(disp)), float(np.nanmax(disp))],
        "render_seconds": round(time.perf_counter() - t0, 3),
    }
    viz.plot_stereo(sim, r.out / "stereo.png")
    write_image(r.out / "data" / "stereo_left.png", sim.pair.left)
    write_image(r.out / "data" / "stereo_right.png", sim.pair.right)
    write_pfm(r.out / "data" / "stereo_disparity_true.pfm", disp.astype(np.float32))
    return "stereo.png"


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
    r = _setup(Path(out), settings)
    stages = [_world, _lidar, _scanner, _rgbd, _stereo]  # this order: one random stream
    for stage in progress(stages, "rendering sensors") if progress is not None else stages:
        r.summary["outputs"].append(stage(r))
    return r.summary
