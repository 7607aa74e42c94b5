"""``navkit stereo``: dense disparity of a rectified pair, and simulated stereo rooms.

- ``navkit stereo disparity LEFT RIGHT --calib FILE --out DIR`` -> ``disparity.pfm``,
  ``disparity.png`` (coloured), ``points.ply`` (coloured 3D points, left camera frame),
  ``summary.json`` (ms, density, bad-2.0 / bad-4.0 with ``--gt``), ``settings.toml``;
- ``navkit stereo simulate ROOM --out DIR`` -> a folder of rendered stereo frames with poses
  (``calib.yaml``, ``poses.tum``, ``left/``, ``right/``) and ``truth.json`` (the room's true walls
  and corners), ready for ``navkit map build`` / ``navkit map locate``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any

import typer

from navkit.cli.common import check_out_dir, cli_errors, option, progress, write_run_files
from navkit.domains import POSITIVE, SEED, Domain

log = logging.getLogger(__name__)

stereo_app = typer.Typer(help="Stereo disparity and 3D points (paper 3).", no_args_is_help=True)


class MatcherChoice(str, Enum):
    sgbm = "sgbm"
    sgbm3way = "sgbm3way"
    hh = "hh"
    bm = "bm"


class FillChoice(str, Enum):
    none = "none"
    background = "background"


class RoomChoice(str, Enum):
    rectangle = "rectangle"
    lshape = "lshape"
    column = "column"
    doorway = "doorway"


@dataclass(frozen=True)
class DisparityRun:
    left: str
    right: str
    calib: str
    ground_truth: str = ""
    mask: str = ""


@stereo_app.command("disparity")
def disparity_cmd(
    left: Path = typer.Argument(..., help="Left rectified image."),
    right: Path = typer.Argument(..., help="Right rectified image."),
    calib: Path = typer.Option(
        ..., "--calib", help="Middlebury calib.txt, KITTI calib (P2/P3) or YAML (K, baseline)."
    ),
    out: Path = typer.Option(
        ..., "--out", "-o", help="Output folder (refused if it holds files, unless --overwrite)."
    ),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace outputs already in --out."),
    matcher: MatcherChoice = typer.Option(MatcherChoice.sgbm, help="OpenCV matcher."),
    num_disparities: int = option(
        0,
        "--num-disparities",
        domain=Domain(integer=True, lo=0, hi=4096, multiple_of=16),
        help="Search range (pixels); 0 = from the calibration's ndisp, else 128.",
    ),
    block_size: int = option(
        0,
        "--block-size",
        domain=Domain(integer=True, lo=0, hi=51),
        help="Matching window (odd; BM: >= 5); 0 = 3 for SGBM, 9 for BM.",
    ),
    lr_check: bool = typer.Option(True, help="Left-right consistency check."),
    fill: FillChoice = typer.Option(
        FillChoice.background, help="Fill rejected pixels from the background."
    ),
    max_depth: float = option(
        50.0,
        "--max-depth",
        domain=POSITIVE,
        help="Points farther than this (m) are left out of points.ply.",
    ),
    gt: Path | None = typer.Option(
        None, "--gt", help="Ground-truth disparity (PFM) to score bad-2.0 / bad-4.0."
    ),
    mask: Path | None = typer.Option(
        None, "--mask", help="Middlebury mask (255 = scored, e.g. mask0nocc.png)."
    ),
) -> None:
    """Dense disparity (PFM + coloured PNG) and 3D points (PLY) of a rectified stereo pair.

    \b
    Example:
      D="$NAVKIT_DATA/stereo/middlebury2014-motorcycle-q"
      navkit stereo disparity $D/im0.png $D/im1.png --calib $D/calib.txt \\
          --gt $D/disp0GT.pfm --mask $D/mask0nocc.png -o out/motorcycle
    """
    with cli_errors():
        from navkit.io.images import read_image
        from navkit.io.stereo import read_stereo_calib
        from navkit.stereo import DisparitySettings, compute_disparity

        L = read_image(left)
        R = read_image(right)
        rig = read_stereo_calib(calib, image_size=(L.shape[1], L.shape[0]))
        if (rig.camera.height, rig.camera.width) != L.shape[:2]:
            from navkit.errors import InputError

            raise InputError(
                f"image is {L.shape[1]} x {L.shape[0]}, calibration {rig.camera.width} x {rig.camera.height}",
                source=left,
                field="size",
                expected="the calibrated image size",
            )
        nd = num_disparities if num_disparities > 0 else _calib_num_disparities(calib)
        G, M = _read_reference(gt, mask, L.shape[:2])  # every input read before any output
        bs = block_size or (9 if matcher == MatcherChoice.bm else 3)
        settings = DisparitySettings(
            matcher=matcher.value,
            num_disparities=nd,
            block_size=bs,
            lr_check=lr_check,
            fill=fill.value,
        )
        check_out_dir(out, overwrite)
        res = compute_disparity(L, R, settings)
        summary = _write_disparity(out, L, res, rig, max_depth, G, M)
        write_run_files(
            out,
            {
                "input": DisparityRun(
                    str(left), str(right), str(calib), str(gt or ""), str(mask or "")
                ),
                "disparity": settings,
            },
            summary,
        )
        typer.echo(
            f"disparity: {100 * res.density:.1f}% valid, {1e3 * res.seconds:.0f} ms"
            + (f", bad-2.0 {summary['bad_2.0_percent']:.2f}%" if gt is not None else "")
            + f" -> {out}"
        )


def _write_disparity(
    out: Path, L: Any, res: Any, rig: Any, max_depth: float, G: Any, M: Any
) -> dict[str, Any]:
    """Write ``disparity.pfm``, ``disparity.png`` and ``points.ply`` (points nearer than
    ``max_depth``); returns the summary, with bad-2.0 / bad-4.0 against ``G`` when given."""
    import numpy as np

    from navkit.io.images import write_image, write_pfm
    from navkit.io.pointcloud import write_ply
    from navkit.stereo import disparity_to_points
    from navkit.stereo.disparity import bad_pixel_rate
    from navkit.viz.maps import colorize_disparity

    write_pfm(
        out / "disparity.pfm",
        np.where(np.isfinite(res.disparity), res.disparity, np.inf).astype(np.float32),
    )
    write_image(out / "disparity.png", colorize_disparity(res.disparity))
    P = disparity_to_points(res.checked, rig)
    ok = np.all(np.isfinite(P), axis=-1) & (P[..., 2] <= max_depth)
    colors = L[ok] if L.ndim == 3 else np.repeat(L[ok][:, None], 3, axis=1)
    write_ply(out / "points.ply", P[ok], colors=colors)
    summary: dict[str, Any] = {
        "ms": 1e3 * res.seconds,
        "density": res.density,
        "density_before_fill": float(np.isfinite(res.checked).mean()),
        "points": int(ok.sum()),
        "rig": {"fx": rig.camera.fx, "baseline_m": rig.baseline, "doffs": rig.doffs},
    }
    if G is not None:
        for t in (2.0, 4.0):
            bad, bad_valid = bad_pixel_rate(res.disparity, G, t, M)
            summary[f"bad_{t:.1f}_percent"] = bad
            summary[f"bad_{t:.1f}_valid_percent"] = bad_valid
    return summary


def _calib_num_disparities(calib: Path) -> int:
    """The calibration's disparity range (Middlebury ``ndisp``) rounded up to a multiple of 16,
    or 128 when the file does not say."""
    import numpy as np

    from navkit.errors import InputError
    from navkit.io.stereo import read_middlebury_calib

    try:
        ndisp = read_middlebury_calib(calib)[1].get("ndisp", 0.0)
    except InputError:  # not a Middlebury file (a bad one was refused when the rig was read)
        ndisp = 0.0
    return int(16 * np.ceil(ndisp / 16)) if ndisp > 0 else 128


def _read_reference(gt: Path | None, mask: Path | None, shape: tuple[int, ...]) -> tuple[Any, Any]:
    """Ground-truth disparity (NaN where unknown) and the non-occluded mask (255), or None;
    both must have the left image's ``shape`` (rows, columns).

    Raises
    ------
    InputError
        Naming the ground truth or the mask whose size differs from the image's.
    """
    import numpy as np

    from navkit.errors import InputError
    from navkit.io.images import read_image, read_pfm

    if gt is None:
        return None, None
    G = read_pfm(gt).astype(np.float64)
    G[~np.isfinite(G)] = np.nan
    M = None
    if mask is not None:
        m = read_image(mask)
        M = (m if m.ndim == 2 else m[..., 0]) == 255
    for name, path, arr in (("--gt", gt, G), ("--mask", mask, M)):
        if arr is not None and arr.shape[:2] != tuple(shape):
            raise InputError(
                f"is {arr.shape[1]} x {arr.shape[0]} pixels",
                source=path,
                field=name,
                expected=f"the left image's size, {shape[1]} x {shape[0]}",
            )
    return G, M


@stereo_app.command("simulate")
def simulate_cmd(
    room: RoomChoice = typer.Argument(..., help="Which test room."),
    out: Path = typer.Option(
        ..., "--out", "-o", help="Output folder, a stereo frame folder (refused if it holds files)."
    ),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace outputs already in --out."),
    random_poses: int = option(
        0,
        "--random",
        domain=Domain(integer=True, lo=0, hi=10_000, note="0 = the survey"),
        help="Render N random poses instead of the survey.",
    ),
    width: int = option(
        320,
        "--width",
        domain=Domain(integer=True, lo=16, hi=4096),
        help="Image width (pixels); the height is 3/4 of it.",
    ),
    hfov_deg: float = option(
        90.0, "--hfov-deg", domain=Domain(lo=1.0, hi=170.0), help="Horizontal field of view (deg)."
    ),
    baseline: float = option(
        0.2, "--baseline", domain=Domain(lo=1e-3, hi=10.0), help="Stereo baseline (m)."
    ),
    height: float = option(
        1.2, "--height", domain=Domain(lo=0.0, hi=10.0), help="Camera height above the floor (m)."
    ),
    turn: int = option(
        1,
        "--turn",
        domain=Domain(integer=True, lo=1, hi=360),
        help="Frames per place: the camera turns through N headings (use with map locate --group N).",
    ),
    seed: int = option(
        0, "--seed", domain=SEED, help="Seed of the random poses and the image noise."
    ),
    pixel_noise: float = option(
        1.0, "--pixel-noise", domain=Domain(lo=0.0, hi=255.0), help="Image noise (grey levels)."
    ),
) -> None:
    """Render a textured test room with a stereo rig (survey or random poses) into a frame folder.

    \b
    Example:
      navkit stereo simulate lshape --turn 4 -o out/lshape
    """
    with cli_errors():
        import numpy as np

        from navkit.io.atomic import write_json
        from navkit.io.stereo import write_stereo_frames
        from navkit.sensors import PinholeCamera, StereoRig
        from navkit.sim import render_stereo
        from navkit.sim.scene_io import scene_from_dict
        from navkit.stereo.rooms import room as make_room
        from navkit.stereo.rooms import sample_poses
        from navkit.stereo.triangulation import planar_camera_pose

        check_out_dir(out, overwrite)
        truth = make_room(room.value)
        scene = scene_from_dict(truth.scene)
        rig = StereoRig(PinholeCamera.from_fov(width, width * 3 // 4, hfov_deg), baseline)
        rng = np.random.default_rng(seed)
        X = truth.survey if random_poses <= 0 else sample_poses(truth, random_poses, rng)
        if turn > 1:  # each place seen in `turn` headings (the camera turns on its drive)
            X = np.concatenate(
                [X + np.array([0.0, 0.0, 2 * np.pi * k / turn]) for k in range(turn)], axis=1
            )
            X = X.reshape(-1, 3)
        lefts, rights, poses = [], [], []
        for x, y, th in progress(X, "rendering"):
            T = planar_camera_pose(x, y, th, height)
            st = render_stereo(scene, rig, T, rng=rng, pixel_noise=pixel_noise, supersample=1)
            lefts.append(st.pair.left)
            rights.append(st.pair.right)
            poses.append(T)
        write_stereo_frames(out, rig, lefts, rights, np.array(poses))
        write_json(
            out / "truth.json",
            {
                "room": room.value,
                "walls": truth.walls,
                "corners": truth.corners,
                "outline": truth.outline,
                "size": truth.size,
                "poses_xytheta": X,
            },
        )
        typer.echo(f"{len(X)} stereo frames of room '{room.value}' -> {out}")


def register(app: typer.Typer) -> None:
    app.add_typer(stereo_app, name="stereo")
