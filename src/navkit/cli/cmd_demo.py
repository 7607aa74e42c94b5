"""``navkit demo``: the built-in mission - out, map, localize, come back - and its report.

Runs :func:`navkit.mission.run_demo` (the "yard" world by default: the robot is driven out
through the yard into the room, the link is lost, it returns along its stored path) and writes
``report.html``, ``metrics.json``, the trajectories, the stored path and the obstacle map into
``--out``; then, as before, one picture per simulated sensor at the start pose (lidar, tilting
scanner, RGB-D, stereo, the world) with the truth. ``settings.toml`` / ``summary.json`` hold both.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import typer

from navkit.cli.common import cli_errors, progress, write_run_files

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class LidarMount:
    """A spinning lidar on the robot: height above the ground (m), beams x columns."""

    height: float = 1.2
    n_beams: int = 64
    n_columns: int = 2048
    elevation_min_deg: float = -24.8
    elevation_max_deg: float = 2.0
    max_range: float = 80.0
    relative_sigma: float = 0.002
    absolute_sigma: float = 0.01
    dropout: float = 0.02


@dataclass(frozen=True)
class ScannerMount:
    """A SICK LMS 200-like scanner tilted in elevation; its height (m) and angle grid (deg)."""

    height: float = 0.8
    azimuth_step_deg: float = 0.5
    elevation_min_deg: float = -30.0
    elevation_max_deg: float = 0.0
    elevation_step_deg: float = 0.5
    max_range: float = 30.0
    relative_sigma: float = 0.0
    absolute_sigma: float = 0.01
    dropout: float = 0.0


@dataclass(frozen=True)
class CameraMount:
    """A forward camera: height (m), pitch down (deg), image size (px), horizontal FOV (deg)."""

    height: float = 1.0
    pitch_down_deg: float = 8.0
    width: int = 640
    height_px: int = 480
    hfov_deg: float = 70.0
    depth_relative_sigma: float = 0.005
    max_depth: float = 10.0
    stereo_baseline: float = 0.12
    stereo_pixel_noise: float = 2.0


@dataclass(frozen=True)
class DemoSettings:
    """Everything the demo used (written to ``settings.toml``)."""

    scene: str = "yard"
    seed: int = 0
    small: bool = False
    robot_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    lidar: LidarMount = field(default_factory=LidarMount)
    scanner: ScannerMount = field(default_factory=ScannerMount)
    camera: CameraMount = field(default_factory=CameraMount)

    @classmethod
    def make(
        cls, scene: str, seed: int, small: bool, pose: tuple[float, float, float]
    ) -> DemoSettings:
        if not small:
            return cls(scene, seed, small, pose)
        return cls(
            scene,
            seed,
            small,
            pose,
            lidar=LidarMount(n_beams=16, n_columns=512),
            scanner=ScannerMount(azimuth_step_deg=2.0, elevation_step_deg=2.0),
            camera=CameraMount(width=160, height_px=120),
        )


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


def render_sensor_pictures(out: Path, settings: DemoSettings) -> dict[str, Any]:
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

    for stage in progress([world, lidar, scanner, rgbd, stereo], "rendering sensors"):
        summary["outputs"].append(stage())
    return summary


def register(app: typer.Typer) -> None:
    @app.command("demo")
    def demo(
        out: Path = typer.Option(
            Path("out/demo"), "--out", help="Folder for the report, metrics, maps and pictures."
        ),
        seed: int = typer.Option(0, "--seed", help="Seed of the sensor noise."),
        scene: str = typer.Option(
            "yard", "--scene", help="Built-in world name or a scene TOML file."
        ),
        x: float = typer.Option(None, "--x", help="Robot x (m); default: the world's start."),  # type: ignore[assignment]
        y: float = typer.Option(None, "--y", help="Robot y (m); default: the world's start."),  # type: ignore[assignment]
        heading_deg: float = typer.Option(None, "--heading-deg", help="Robot heading (deg)."),  # type: ignore[assignment]
        small: bool = typer.Option(False, "--small", help="Low resolution (fast; for tests)."),
    ) -> None:
        """Run the built-in mission (out, map, localize, come back) into report.html, metrics.json
        and maps; then save a picture of every simulated sensor at the start, with the truth."""
        with cli_errors():
            import math

            from navkit.errors import InputError
            from navkit.sim import load_scene

            if out.exists() and not out.is_dir():
                raise InputError(
                    "exists and is not a folder",
                    source=out,
                    field="--out",
                    expected="a folder (created if missing)",
                )
            start = load_scene(scene).start

            pose = (
                start[0] if x is None else x,
                start[1] if y is None else y,
                start[2] if heading_deg is None else math.radians(heading_deg),
            )
            settings = DemoSettings.make(scene, seed, small, pose)
            # the mission (report.html, metrics.json, maps) ...
            import json

            from navkit.mission import run_demo
            from navkit.mission.settings import tomllib  # tomllib / tomli by Python version

            metrics = run_demo(out, seed, progress, scene=scene, small=small, start=pose)
            mission_summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
            # ... and the sensor pictures at the start pose
            summary = render_sensor_pictures(out, settings)
            summary["mission"] = {
                k: v for k, v in mission_summary.items() if k not in ("navkit_version", "argv")
            }

            mission_settings = tomllib.loads((out / "settings.toml").read_text(encoding="utf-8"))
            write_run_files(out, {**dataclasses.asdict(settings), **mission_settings}, summary)
            r = metrics["return"]
            typer.echo(
                f"mission {r['outcome']}: {r['final_distance_to_operator_m']:.2f} m from the operator; "
                f"report in {out / 'report.html'}; {len(summary['outputs'])} sensor pictures"
            )
