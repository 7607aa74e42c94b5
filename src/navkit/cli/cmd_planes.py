"""``navkit planes``: plane extraction and plane-based odometry (paper 2)."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import typer

from navkit.batch.planes_extract import CameraOverride, open_rgbd
from navkit.cli.batching import RESUME, SCHEDULER, WORKERS, exit_if_failed, run_inputs
from navkit.cli.common import (
    check_out_dir,
    cli_errors,
    expand_inputs,
    option,
    progress,
    write_run_files,
)
from navkit.domains import NON_NEGATIVE_INT, POSITIVE, Domain

log = logging.getLogger(__name__)

planes_app = typer.Typer(
    name="planes",
    help="Planes from RGB-D / range images and motion from 1, 2 or >= 3 textured planes.",
    no_args_is_help=True,
)


@dataclass(frozen=True)
class PlanesRunSettings:
    """Resolved settings of a ``navkit planes`` run (written to ``settings.toml``; the same
    keys are read from ``--config FILE.toml``, top level or a ``[planes]`` table)."""

    input: str = ""
    frame: int = 0
    nu: float = 0.01
    cell: int = 20
    camera: CameraOverride = field(default_factory=CameraOverride)
    max_frames: int = 0
    reference: str = ""


#: The domains of the numeric settings, on the command line and in ``--config``.
DOMAINS = {
    "nu": POSITIVE,
    "cell": Domain(integer=True, lo=3, hi=10_000),
    "max_frames": Domain(integer=True, lo=0, note="0 = all"),
    "frame": NON_NEGATIVE_INT,
    "depth_scale": POSITIVE,
}
_CONFIG_KEYS = {"nu": float, "cell": int, "max_frames": int, "frame": int}
NU_OPTION = option(0.01, "--nu", domain=DOMAINS["nu"], help="Texture pixel size (m).")
CELL_OPTION = option(
    20, "--cell", domain=DOMAINS["cell"], help="Patch size of the organised extraction (px)."
)


def _config(path: Path | None) -> dict[str, Any]:
    """Settings from ``--config`` (a TOML file with the keys of :class:`PlanesRunSettings`)."""
    if path is None:
        return {}
    from navkit.errors import ConfigError
    from navkit.io.textfiles import load_toml_file

    data = load_toml_file(path, "a settings TOML file")
    table = data.get("planes", data)
    out: dict[str, Any] = {}
    for key, kind in _CONFIG_KEYS.items():
        if key in table:
            try:
                out[key] = kind(table[key])
            except (TypeError, ValueError, OverflowError):
                raise ConfigError(
                    f"{key} = {table[key]!r}", source=path, field=key, expected=kind.__name__
                ) from None
            DOMAINS[key].check(table[key], key, source=path, error=ConfigError)
    cam = table.get("camera", {})
    if isinstance(cam, dict):
        out["camera"] = {k: float(v) for k, v in cam.items() if float(v) > 0}
    return out


def _opt(conf: dict[str, Any], key: str, value: float, default: float) -> float:
    """An option's value: the command line's when given (not its default), else the config's."""
    return float(conf.get(key, value)) if value == default else value


def _intrinsics(text: str | None, depth_scale: float | None, config: dict) -> CameraOverride:
    """``--intrinsics FX,FY,CX,CY`` (pixels) and ``--depth-scale`` over the config's camera."""
    from navkit.errors import InputError

    vals = dict(config.get("camera", {}))
    if text:
        try:
            fx, fy, cx, cy = (float(v) for v in text.split(","))
        except ValueError:
            raise InputError(
                f"got {text!r}", field="--intrinsics", expected="FX,FY,CX,CY in pixels"
            ) from None
        if min(fx, fy) <= 0:
            raise InputError(f"got {text!r}", field="--intrinsics", expected="FX, FY > 0")
        vals.update(fx=fx, fy=fy, cx=cx, cy=cy)
    if depth_scale is not None:
        vals["depth_scale"] = depth_scale
    return CameraOverride(**{k: float(v) for k, v in vals.items() if k in _CAMERA_KEYS})


_CAMERA_KEYS = ("fx", "fy", "cx", "cy", "depth_scale")
INTRINSICS_HELP = "Camera intrinsics FX,FY,CX,CY (pixels); overrides the folder's."
DEPTH_SCALE_OPTION = option(
    None,
    "--depth-scale",
    domain=DOMAINS["depth_scale"],
    help="Raw depth units per metre (default 1000: millimetres; TUM folders 5000 as the format "
    "says).",
)


@planes_app.command("extract")
def extract_cmd(
    inputs: list[str] = typer.Argument(
        ...,
        help="RGB-D folder (TUM, color/+depth/+camera.yaml, 7-Scenes), CAPE folder, .pcd or .ply "
        "(a path or an fsspec URL such as file:// or s3://). Several inputs: one output folder "
        "each, named after the input.",
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace earlier outputs in --out."),
    config: Path | None = typer.Option(None, "--config", help="Settings from a TOML file."),
    frame: int = option(
        0, "--frame", domain=DOMAINS["frame"], help="Frame index in a sequence folder."
    ),
    nu: float = NU_OPTION,
    cell: int = CELL_OPTION,
    intrinsics: str | None = typer.Option(None, "--intrinsics", help=INTRINSICS_HELP),
    depth_scale: float | None = DEPTH_SCALE_OPTION,
    workers: int | None = WORKERS,
    scheduler: str | None = SCHEDULER,
    resume: bool = RESUME,
) -> None:
    """Extract planes: planes.json, one texture PNG per plane, overlay.png.

    Several inputs (or --workers / --scheduler / --resume) run as a batch: OUT/<input>/ per
    input, batch.jsonl (one row per input) and batch_summary.json; exit code 3 when any failed.

    Example: navkit planes extract "$NAVKIT_DATA"/rgbd/slambook-ch5 --intrinsics 518,519,325.5,253.5 -o out/slambook-planes
    """
    with cli_errors():
        from navkit.batch.planes_extract import extract_planes_to

        conf = _config(config)
        nu, cell = _opt(conf, "nu", nu, 0.01), int(_opt(conf, "cell", cell, 20))
        frame = int(_opt(conf, "frame", frame, 0))
        cam = _intrinsics(intrinsics, depth_scale, conf)
        out = check_out_dir(out, overwrite or resume)
        settings = PlanesRunSettings(
            input=" ".join(inputs), frame=frame, nu=nu, cell=cell, camera=cam
        )
        if len(inputs) > 1 or workers or scheduler or resume:
            summary = _extract_batch(inputs, out, frame, cam, nu, cell, workers, scheduler, resume)
        else:
            summary = extract_planes_to(
                out,
                inputs[0],
                frame=frame,
                camera=cam,
                nu=nu,
                cell=cell,
                iterate=lambda items: progress(items, "textures"),
            )
            typer.echo(f"{summary['planes']} planes ({summary['kind']}) -> {out}")
        write_run_files(out, settings, summary)
    exit_if_failed(summary)


def _extract_batch(
    inputs: list[str],
    out: Path,
    frame: int,
    cam: CameraOverride,
    nu: float,
    cell: int,
    workers: int | None,
    scheduler: str | None,
    resume: bool,
) -> dict[str, Any]:
    """Every input as one task of a batch (``out/<input name>/planes.json``, textures, overlay).

    The settings hash covers the navkit version, the input (a file's size and modification
    time; a folder's own entry, so a frame replaced in place inside a folder is not noticed by
    ``--resume``: use a new --out), the frame, the camera override, nu and cell.
    """
    from navkit import __version__
    from navkit.batch import BatchTask, settings_hash
    from navkit.batch.planes_extract import input_key, planes_extract_job
    from navkit.io.urls import input_identity

    keys = [input_key(s) for s in inputs]
    keys = [k if keys.count(k) == 1 else f"{k}_{i}" for i, k in enumerate(keys)]
    tasks = [
        BatchTask(
            key,
            planes_extract_job,
            {"source": str(s), "frame": frame, "camera": cam, "nu": nu, "cell": cell},
            settings_hash(__version__, input_identity(s), frame, cam, nu, cell),
        )
        for key, s in zip(keys, inputs, strict=True)
    ]
    return run_inputs(
        tasks, out, workers=workers, scheduler=scheduler, resume=resume, description="planes"
    )


def _reference_poses(path: Path, n: int, stamps=None):  # type: ignore[no-untyped-def]
    """Reference poses ``(n, 4, 4)``: a TUM trajectory (8 columns: time, position, quaternion)
    interpolated at the frames' ``stamps`` (NaN where it does not cover a frame:
    :func:`navkit.planes.metrics.poses_at`), or 'tx ty tz qx qy qz qw' lines, one per frame
    (slambook pose.txt)."""
    import numpy as np

    from navkit.errors import FormatError
    from navkit.geometry import se3_from_xyz_quat
    from navkit.planes.metrics import poses_at

    try:
        tab = np.loadtxt(path, comments="#", ndmin=2)
    except ValueError as exc:
        raise FormatError(
            f"not a numeric table ({exc})",
            source=path,
            expected="TUM or 'tx ty tz qx qy qz qw' lines",
        ) from None
    if tab.shape[1] == 8 and stamps is not None and len(tab) >= 2:
        order = np.argsort(tab[:, 0], kind="stable")
        tab = tab[order]
        return poses_at(stamps[:n], tab[:, 0], se3_from_xyz_quat(tab[:, 1:4], tab[:, 4:]))
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


def _reference_folder(path: Path, n: int):
    """``T_world_camera`` from a folder of 7-Scenes ``frame-N.pose.txt`` files."""
    import numpy as np

    from navkit.errors import FormatError
    from navkit.io.rgbd import read_pose_matrix

    files = sorted(path.glob("frame-*.pose.txt"))
    if len(files) < n:
        raise FormatError(
            f"{len(files)} pose files", source=path, field="reference", expected=f">= {n}"
        )
    return np.stack([read_pose_matrix(f) for f in files[:n]])


def _open_sequence(sequence: list[str], cam: CameraOverride, cell: int, max_frames: int):
    """``(n, stamps, observe(i), reference poses or None)`` of an RGB-D folder or .pcd files."""
    import numpy as np

    from navkit.planes import ExtractionSettings, observe_points, observe_rgbd

    es = ExtractionSettings(cell=cell)
    first = Path(sequence[0])
    if len(sequence) == 1 and first.is_dir() and not any(first.glob("*.pcd")):
        seq = open_rgbd(first, cam)
        n = len(seq) if max_frames <= 0 else min(max_frames, len(seq))
        ref = None if seq.reference is None else seq.reference[:n]
        return (
            n,
            np.asarray(seq.timestamps[:n], float),
            lambda i: observe_rgbd(seq.frame(i), es),
            ref,
        )
    from navkit.io.pointcloud import read_pcd

    files = expand_inputs(sequence, (".pcd",))
    n = len(files) if max_frames <= 0 else min(max_frames, len(files))

    def observe(i: int):
        cloud = read_pcd(files[i])
        return observe_points(
            cloud.grid() if cloud.is_organized else cloud.points, organized_settings=es
        )

    return n, np.arange(n, dtype=np.float64), observe, None


def _frame_row(i: int, stamp: float, r, t_extract: float) -> dict[str, Any]:
    """One frame's row: a tracked frame (``FrameMotion``) or a ``MotionFailure``."""
    from navkit.results import Failure

    failed = isinstance(r, Failure)
    motion = r if failed else r.motion
    return {
        "index": i,
        "timestamp": stamp,
        "status": "failed" if failed else "tracked",
        "source": "prediction (not written)" if failed else r.source,
        "reason": r.reason if failed else r.note,
        "case": r.case,
        "planes": r.n_planes,
        "extract_ms": t_extract,
        "motion_ms": r.ms,
        "dof_sources": {} if failed else r.dof_sources,
        "texture_dof": list(getattr(motion, "texture_dof", ())),
        "free_dof": list(getattr(motion, "free_dof", ())),
        "prior_dof": list(getattr(motion, "prior_dof", ())),
        "plane_free_dof": [] if failed else list(r.plane_free_dof),
    }


def _write_frames_csv(path: Path, frames: list[dict[str, Any]]) -> None:
    """``frames.csv``: one row per input frame - index, timestamp, status, source, reason."""
    import csv
    import io

    from navkit.io.atomic import write_text

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["index", "timestamp", "status", "source", "reason"])
    for f in frames:
        w.writerow([f["index"], f"{f['timestamp']:.6f}", f["status"], f["source"], f["reason"]])
    write_text(path, buf.getvalue())


@planes_app.command("odometry")
def odometry_cmd(
    sequence: list[str] = typer.Argument(
        ..., help="RGB-D folder (TUM, color/+depth/, 7-Scenes), or organised .pcd files."
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace earlier outputs in --out."),
    config: Path | None = typer.Option(None, "--config", help="Settings from a TOML file."),
    max_frames: int = option(
        0, "--max-frames", domain=DOMAINS["max_frames"], help="Use at most this many frames."
    ),
    cell: int = CELL_OPTION,
    nu: float = NU_OPTION,
    reference: Path | None = typer.Option(
        None,
        "--reference",
        help="Reference poses for ATE / RPE: TUM, slambook pose.txt, or a folder of 7-Scenes "
        "frame-N.pose.txt (a 7-Scenes input folder is its own reference).",
    ),
    intrinsics: str | None = typer.Option(None, "--intrinsics", help=INTRINSICS_HELP),
    depth_scale: float | None = DEPTH_SCALE_OPTION,
) -> None:
    """Track a sequence: trajectory.tum (tracked frames only), frames.csv (every frame: status,
    source, reason), map.json, map.ply, map.png, summary.json.

    Example: navkit planes odometry "$NAVKIT_DATA"/rgbd/7scenes-tsdf -o out/7scenes
    """
    with cli_errors():
        import numpy as np

        from navkit.planes import OdometrySettings, PlaneOdometry
        from navkit.planes.motion import MotionSettings
        from navkit.planes.solve import SolverSettings

        conf = _config(config)
        nu, cell = _opt(conf, "nu", nu, 0.01), int(_opt(conf, "cell", cell, 20))
        max_frames = int(_opt(conf, "max_frames", max_frames, 0))
        cam = _intrinsics(intrinsics, depth_scale, conf)
        out = check_out_dir(out, overwrite)
        settings = PlanesRunSettings(
            input=" ".join(sequence),
            nu=nu,
            cell=cell,
            camera=cam,
            max_frames=max_frames,
            reference=str(reference or ""),
        )
        n, stamps, observe, ref = _open_sequence(sequence, cam, cell, max_frames)
        if len(np.unique(stamps)) != len(stamps) or np.any(np.diff(stamps) <= 0):
            stamps = np.arange(n, dtype=np.float64)  # repeated files (A -> B -> A): index as time
        odo = PlaneOdometry(OdometrySettings(motion=MotionSettings(solver=SolverSettings(nu=nu))))
        frames = []
        for i in progress(range(n), "frames"):
            t0 = time.perf_counter()
            obs = observe(i)
            t_extract = 1000 * (time.perf_counter() - t0)
            frames.append(_frame_row(i, float(stamps[i]), odo.update(obs), t_extract))
        if reference is None and len(sequence) == 1:  # a TUM folder carries its truth
            gt = Path(sequence[0]) / "groundtruth.txt"
            reference = gt if gt.is_file() else None
        if reference is not None:
            ref = (
                _reference_folder(reference, n)
                if reference.is_dir()
                else _reference_poses(reference, n, stamps)
            )
            settings = replace(settings, reference=str(reference))
        elif ref is not None:
            settings = replace(settings, reference=f"{sequence[0]} (frame-N.pose.txt)")
        summary = _write_odometry(out, odo, stamps, frames, ref)
        write_run_files(out, settings, summary)
        typer.echo(
            f"{n} frames, {summary['tracked']} tracked, {summary['failed']} failed "
            f"(frames.csv), {summary['map_planes']} map planes -> {out}"
        )


def _write_odometry(out: Path, odo, stamps, frames: list[dict[str, Any]], ref) -> dict[str, Any]:
    """Trajectory (tracked frames only), frames.csv, the map files; the summary."""
    import numpy as np

    from navkit.geometry import se3_inverse
    from navkit.io.atomic import write_json
    from navkit.io.pointcloud import write_ply
    from navkit.io.trajectory import Trajectory, write_tum
    from navkit.planes.metrics import ate, rpe
    from navkit.viz.planes import plot_map

    poses, ok = odo.trajectory, odo.tracked
    n = len(frames)
    # a failed frame is never written as a pose: its pose is the prediction, not a measurement
    write_tum(out / "trajectory.tum", Trajectory(stamps[ok], poses[ok]))
    _write_frames_csv(out / "frames.csv", frames)
    mp = odo.map.to_dict()
    write_json(out / "map.json", mp)
    V, C, F = odo.map.mesh()
    write_ply(out / "map.ply", V, colors=C, faces=F if len(F) else None)
    summary: dict[str, Any] = {
        "frames": n,
        "tracked": int(ok.sum()),
        "failed": int(n - ok.sum()),
        "failed_frames": [f["index"] for f in frames if f["status"] == "failed"],
        "sources": {
            s: sum(f["source"] == s for f in frames) for s in sorted({f["source"] for f in frames})
        },
        "cases": {str(c): sum(f["case"] == c for f in frames[1:]) for c in (1, 2, 3)},
        "map_planes": len(mp["planes"]),
        "mean_extract_ms": float(np.mean([f["extract_ms"] for f in frames])),
        "mean_motion_ms": float(np.mean([f["motion_ms"] for f in frames[1:]])) if n > 1 else None,
        "per_frame": frames,
    }
    truth = None
    covered = None if ref is None else np.isfinite(ref).all(axis=(1, 2))
    if ref is not None and covered is not None and (ok & covered).sum() >= 2:
        # the reference relative to the first frame it covers (a motion-capture recording may
        # start after the camera), the estimate likewise; frames it does not cover are left out
        j0 = int(np.flatnonzero(covered)[0])
        truth = se3_inverse(ref[j0]) @ ref
        est = se3_inverse(poses[j0]) @ poses
        m = ok & covered
        t_rmse, r_rmse = rpe(est[m], truth[m])
        summary.update(
            metrics_over="tracked frames the reference covers (RPE between consecutive ones)",
            reference_frames=int(covered.sum()),
            ate_m=ate(est[m], truth[m]),
            rpe_trans_m=t_rmse,
            rpe_rot_deg=r_rmse,
        )
    if truth is None:
        plot_map(out / "map.png", mp["planes"], poses[ok])
    else:  # the map in the first frame's coordinates; the reference where it covers a frame
        plot_map(out / "map.png", mp["planes"], poses[ok], truth=poses[j0] @ truth[ok & covered])
    return summary


def register(app: typer.Typer) -> None:
    app.add_typer(planes_app, name="planes")
