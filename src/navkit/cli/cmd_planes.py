"""``navkit planes``: plane extraction and plane-based odometry (paper 2)."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

import typer

from navkit.cli.common import cli_errors, expand_inputs, progress, write_run_files

log = logging.getLogger(__name__)

planes_app = typer.Typer(
    name="planes",
    help="Planes from RGB-D / range images and motion from 1, 2 or >= 3 textured planes.",
    no_args_is_help=True,
)


@dataclass(frozen=True)
class CameraOverride:
    """Intrinsics given on the command line (0 = not given)."""

    fx: float = 0.0
    fy: float = 0.0
    cx: float = 0.0
    cy: float = 0.0
    depth_scale: float = 0.0

    def as_dict(self) -> dict[str, float]:
        return {k: v for k, v in vars(self).items() if v > 0}


@dataclass(frozen=True)
class PlanesRunSettings:
    """Resolved settings of a ``navkit planes`` run (written to ``settings.toml``)."""

    input: str = ""
    frame: int = 0
    nu: float = 0.01
    cell: int = 20
    camera: CameraOverride = field(default_factory=CameraOverride)
    max_frames: int = 0
    reference: str = ""


def _camera_opts(fx, fy, cx, cy, depth_scale) -> CameraOverride:
    return CameraOverride(fx or 0.0, fy or 0.0, cx or 0.0, cy or 0.0, depth_scale or 0.0)


def _load_observation(path: Path, frame: int, cam: CameraOverride, cell: int):
    """An observation, the picture to draw on (or None) and a description of the input kind."""
    from navkit.errors import InputError
    from navkit.planes import (
        CloudExtractionSettings,
        ExtractionSettings,
        observe_points,
        observe_rgbd,
    )

    es = ExtractionSettings(cell=cell)
    if path.is_dir() and (path / "calib_params.xml").is_file():
        from navkit.io.rgbd import read_cape_frame

        f = read_cape_frame(path, frame)
        obs = observe_points(
            f.points,
            gray=f.color,
            camera=f.camera,
            T_camera_sensor=f.T_camera_sensor,
            organized_settings=es,
        )
        # the overlay is drawn in the depth camera's pixels: the colour registered to them
        return (
            obs,
            f.color_registered,
            "CAPE frame (depth camera + separately calibrated RGB camera)",
            None,
        )
    if path.is_dir():
        from navkit.io.rgbd import open_rgbd_sequence

        seq = open_rgbd_sequence(path, cam.as_dict())
        if not 0 <= frame < len(seq):
            raise InputError(
                f"frame {frame} of {len(seq)}",
                source=path,
                field="--frame",
                expected=f"0 <= frame < {len(seq)}",
            )
        rgbd = seq.frame(frame)
        return observe_rgbd(rgbd, es), rgbd.color, "RGB-D frame", None
    suffix = path.suffix.lower()
    if suffix in (".pcd", ".ply"):
        from navkit.io.pointcloud import read_pcd, read_ply

        cloud = read_pcd(path) if suffix == ".pcd" else read_ply(path)
        if cloud.is_organized:
            return (
                observe_points(cloud.grid(), organized_settings=es),
                None,
                "organised cloud",
                None,
            )
        return (
            observe_points(cloud.points, cloud_settings=CloudExtractionSettings()),
            None,
            "unorganised cloud",
            None,
        )
    raise InputError(
        "unsupported input",
        source=path,
        expected="an RGB-D folder (TUM or color/ + depth/), a CAPE folder, a .pcd or .ply file",
    )


@planes_app.command("extract")
def extract_cmd(
    input: Path = typer.Argument(
        ..., help="RGB-D folder (TUM or color/+depth/+camera.yaml), CAPE folder, .pcd or .ply."
    ),
    out: Path = typer.Option(Path("out/planes"), "--out", "-o", help="Output folder."),
    frame: int = typer.Option(0, "--frame", help="Frame index in a sequence folder."),
    nu: float = typer.Option(0.01, "--nu", help="Texture pixel size [m]."),
    cell: int = typer.Option(20, "--cell", help="Patch size of the organised extraction [px]."),
    fx: float | None = typer.Option(
        None, "--fx", help="Focal length x [px] (overrides camera.yaml)."
    ),
    fy: Optional[float] = typer.Option(None, "--fy", help="Focal length y [px]."),  # noqa: UP045
    cx: Optional[float] = typer.Option(None, "--cx", help="Principal point x [px]."),  # noqa: UP045
    cy: Optional[float] = typer.Option(None, "--cy", help="Principal point y [px]."),  # noqa: UP045
    depth_scale: float | None = typer.Option(
        None, "--depth-scale", help="Raw depth units per metre."
    ),
) -> None:
    """Extract planes: planes.json, one texture PNG per plane, overlay.png."""
    with cli_errors():
        import numpy as np

        from navkit.io.atomic import write_json
        from navkit.io.images import write_image
        from navkit.planes import plane_frame
        from navkit.viz.planes import extraction_overlay, texture_to_uint8

        cam = _camera_opts(fx, fy, cx, cy, depth_scale)
        settings = PlanesRunSettings(input=str(input), frame=frame, nu=nu, cell=cell, camera=cam)
        t0 = time.perf_counter()
        obs, color, kind, gray = _load_observation(input, frame, cam, cell)
        ms = 1000 * (time.perf_counter() - t0)
        out.mkdir(parents=True, exist_ok=True)
        planes: list[dict[str, Any]] = []
        for k, seg in enumerate(progress(obs.segments, "textures")):
            origin, axes = plane_frame(seg.plane)
            entry: dict[str, Any] = {
                "id": k,
                "normal": seg.normal,
                "rho": seg.rho,
                "rms": seg.rms,
                "inliers": int(seg.plane.count),
                "area_m2": seg.area,
                "centroid": seg.plane.centroid,
                "frame_origin": origin,
                "frame_axes": axes,
                "outline": seg.outline,
                "outline_3d": seg.outline_3d(),
            }
            if obs.has_texture:
                tex = obs.texture(k, nu=nu)
                name = f"texture_{k:02d}.png"
                write_image(out / name, texture_to_uint8(tex.image))
                entry.update(
                    texture=name,
                    texture_nu=nu,
                    texture_index0=tex.index0,
                    texture_valid=tex.valid_count,
                    texture_contrast=tex.contrast(),
                )
            planes.append(entry)
        write_json(
            out / "planes.json",
            {
                "input": str(input),
                "kind": kind,
                "frame": "sensor (camera: OpenCV x right, y down, z forward)",
                "planes": planes,
            },
        )
        if color is not None:
            write_image(out / "overlay.png", extraction_overlay(color, obs.extraction.labels))
        elif obs.extraction.labels.ndim == 2:
            base = gray if gray is not None else np.full(obs.extraction.labels.shape, 128, np.uint8)
            if base.shape != obs.extraction.labels.shape:
                base = np.full(obs.extraction.labels.shape, 128, np.uint8)
            write_image(out / "overlay.png", extraction_overlay(base, obs.extraction.labels))
        summary = {
            "input": str(input),
            "kind": kind,
            "planes": len(planes),
            "extract_and_load_ms": ms,
            "textured": obs.has_texture,
        }
        write_run_files(out, settings, summary)
        typer.echo(f"{len(planes)} planes ({kind}) -> {out}")


def _reference_poses(path: Path, n: int):
    """Reference poses: TUM (8 columns) or 'tx ty tz qx qy qz qw' lines (slambook pose.txt)."""
    import numpy as np

    from navkit.errors import FormatError
    from navkit.geometry import se3_from_xyz_quat

    try:
        tab = np.loadtxt(path, comments="#", ndmin=2)
    except ValueError as exc:
        raise FormatError(
            f"not a numeric table ({exc})",
            source=path,
            expected="TUM or 'tx ty tz qx qy qz qw' lines",
        ) from None
    if tab.shape[1] == 8:
        tab = tab[:, 1:]
    if tab.shape[1] != 7 or len(tab) < n:
        raise FormatError(
            f"table of shape {tab.shape}",
            source=path,
            field="reference",
            expected=f">= {n} rows of 7 (or 8 with time) columns",
        )
    return se3_from_xyz_quat(tab[:n, :3], tab[:n, 3:])


@planes_app.command("odometry")
def odometry_cmd(
    sequence: list[str] = typer.Argument(
        ..., help="RGB-D folder (TUM or color/+depth/), or organised .pcd files / a folder of them."
    ),
    out: Path = typer.Option(Path("out/planes-odometry"), "--out", "-o", help="Output folder."),
    max_frames: int = typer.Option(
        0, "--max-frames", help="Use at most this many frames (0 = all)."
    ),
    cell: int = typer.Option(20, "--cell", help="Patch size of the organised extraction [px]."),
    nu: float = typer.Option(0.01, "--nu", help="Texture pixel size [m]."),
    reference: Path | None = typer.Option(
        None, "--reference", help="Reference poses (TUM, or slambook pose.txt) for ATE / RPE."
    ),
    fx: Optional[float] = typer.Option(None, "--fx", help="Focal length x [px]."),  # noqa: UP045
    fy: Optional[float] = typer.Option(None, "--fy", help="Focal length y [px]."),  # noqa: UP045
    cx: Optional[float] = typer.Option(None, "--cx", help="Principal point x [px]."),  # noqa: UP045
    cy: Optional[float] = typer.Option(None, "--cy", help="Principal point y [px]."),  # noqa: UP045
    depth_scale: float | None = typer.Option(
        None, "--depth-scale", help="Raw depth units per metre."
    ),
) -> None:
    """Track a sequence: trajectory.tum, map.json, map.ply, map.png, summary.json."""
    with cli_errors():
        import numpy as np

        from navkit.geometry import se3_inverse
        from navkit.io.atomic import write_json
        from navkit.io.pointcloud import write_ply
        from navkit.io.trajectory import Trajectory, write_tum
        from navkit.planes import (
            ExtractionSettings,
            OdometrySettings,
            PlaneOdometry,
            observe_points,
            observe_rgbd,
        )
        from navkit.planes.metrics import ate, rpe
        from navkit.planes.motion import MotionSettings
        from navkit.planes.solve import SolverSettings
        from navkit.viz.planes import plot_map

        cam = _camera_opts(fx, fy, cx, cy, depth_scale)
        settings = PlanesRunSettings(
            input=" ".join(sequence),
            nu=nu,
            cell=cell,
            camera=cam,
            max_frames=max_frames,
            reference=str(reference or ""),
        )
        es = ExtractionSettings(cell=cell)
        first = Path(sequence[0])
        if len(sequence) == 1 and first.is_dir() and not any(first.glob("*.pcd")):
            from navkit.io.rgbd import open_rgbd_sequence

            seq = open_rgbd_sequence(first, cam.as_dict())
            n = len(seq) if max_frames <= 0 else min(max_frames, len(seq))
            stamps = np.asarray(seq.timestamps[:n], dtype=np.float64)

            def observe(i: int):
                return observe_rgbd(seq.frame(i), es)
        else:
            from navkit.io.pointcloud import read_pcd

            files = expand_inputs(sequence, (".pcd",))
            n = len(files) if max_frames <= 0 else min(max_frames, len(files))
            stamps = np.arange(n, dtype=np.float64)

            def observe(i: int):
                cloud = read_pcd(files[i])
                return observe_points(
                    cloud.grid() if cloud.is_organized else cloud.points, organized_settings=es
                )

        if len(np.unique(stamps)) != len(stamps) or np.any(np.diff(stamps) <= 0):
            stamps = np.arange(n, dtype=np.float64)  # repeated files (A -> B -> A): index as time
        odo = PlaneOdometry(OdometrySettings(motion=MotionSettings(solver=SolverSettings(nu=nu))))
        frames = []
        for i in progress(range(n), "frames"):
            t0 = time.perf_counter()
            obs = observe(i)
            t_extract = 1000 * (time.perf_counter() - t0)
            r = odo.register_frame(obs)
            frames.append(
                {
                    "index": i,
                    "timestamp": float(stamps[i]),
                    "status": r.status,
                    "case": r.case,
                    "planes": r.n_planes,
                    "extract_ms": t_extract,
                    "motion_ms": r.ms,
                    "texture_dof": list(getattr(r.motion, "texture_dof", ())),
                    "free_dof": list(getattr(r.motion, "free_dof", ())),
                    "prior_dof": list(getattr(r.motion, "prior_dof", ())),
                    "source": r.source,
                }
            )
        poses = odo.trajectory
        out.mkdir(parents=True, exist_ok=True)
        write_tum(out / "trajectory.tum", Trajectory(stamps, poses))
        mp = odo.map.to_dict()
        write_json(out / "map.json", mp)
        V, C, F = odo.map.mesh()
        write_ply(out / "map.ply", V, colors=C, faces=F if len(F) else None)
        summary: dict[str, Any] = {
            "frames": n,
            "ok": sum(str(f["status"]).startswith("ok") for f in frames),
            "failed": sum(str(f["status"]).startswith("failed") for f in frames),
            "cases": {str(c): sum(f["case"] == c for f in frames[1:]) for c in (1, 2, 3)},
            "map_planes": len(mp["planes"]),
            "mean_extract_ms": float(np.mean([f["extract_ms"] for f in frames])),
            "mean_motion_ms": float(np.mean([f["motion_ms"] for f in frames[1:]]))
            if n > 1
            else None,
            "per_frame": frames,
        }
        truth = None
        if reference is not None:
            Q = _reference_poses(reference, n)
            truth = se3_inverse(Q[0]) @ Q  # reference relative to the first frame
            t_rmse, r_rmse = rpe(poses, truth)
            summary.update(ate_m=ate(poses, truth), rpe_trans_m=t_rmse, rpe_rot_deg=r_rmse)
        plot_map(out / "map.png", mp["planes"], poses, truth=truth)
        write_run_files(out, settings, summary)
        typer.echo(
            f"{n} frames, {summary['ok']} tracked, {summary['failed']} failed, {len(mp['planes'])} map planes -> {out}"
        )


def register(app: typer.Typer) -> None:
    app.add_typer(planes_app, name="planes")
