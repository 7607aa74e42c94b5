"""One input of ``navkit planes extract``: read, extract planes, write ``planes.json``, one
texture PNG per plane and ``overlay.png``.

The per-input function of the command, alone or in a batch (``--workers`` / ``--scheduler`` /
``--resume``, :mod:`navkit.batch`): the same code writes the same files either way. Inputs are
an RGB-D folder (TUM, ``color/`` + ``depth/`` + ``camera.yaml``, 7-Scenes; one frame of it), a
CAPE folder, or a ``.pcd`` / ``.ply`` file (a local path or an fsspec URL, read through
:func:`navkit.io.urls.local_copy`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = [
    "DEFAULT_DEPTH_SCALE",
    "CameraOverride",
    "extract_planes_to",
    "input_key",
    "load_observation",
    "open_rgbd",
    "planes_extract_job",
]

DEFAULT_DEPTH_SCALE = 1000.0
"""Raw depth units per metre when neither ``--depth-scale`` nor the folder says (millimetres;
a TUM folder keeps its format's 5000)."""

DETERMINISTIC = ("kind", "planes", "textures", "inliers", "area_m2")
"""The summary's figures that depend on the input and the settings only (not on timing)."""


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


def open_rgbd(path: Path, cam: CameraOverride) -> Any:
    """An RGB-D folder; a simple layout without ``camera.yaml`` needs ``--intrinsics``."""
    from navkit.errors import DataNotFoundError
    from navkit.io.rgbd import open_rgbd_sequence, read_camera_yaml

    given = cam.as_dict()
    if (
        (path / "color").is_dir()
        and not (path / "camera.yaml").is_file()
        and not all(k in given for k in ("fx", "fy", "cx", "cy"))
    ):
        raise DataNotFoundError(
            f"{path / 'camera.yaml'}: not found, and no --intrinsics given; give the camera as "
            "--intrinsics FX,FY,CX,CY (pixels; and --depth-scale when not 1000) or write "
            "camera.yaml with fx, fy, cx, cy, depth_scale"
        )
    yaml = path / "camera.yaml"
    if (
        not (path / "rgb.txt").is_file()
        and "depth_scale" not in given
        and not (yaml.is_file() and "depth_scale" in read_camera_yaml(yaml))
    ):  # the default only where neither the command line nor the folder's camera.yaml says
        given["depth_scale"] = DEFAULT_DEPTH_SCALE
    return open_rgbd_sequence(path, given)


def _is_cloud_file(source: str | Path) -> bool:
    return str(source).lower().endswith((".pcd", ".ply"))


def load_observation(
    source: str | Path, frame: int, cam: CameraOverride, cell: int
) -> tuple[Any, Any, str, Any]:
    """``(observation, picture to draw on or None, input kind, grey base or None)`` of an input.

    ``source`` is a folder, a ``.pcd`` / ``.ply`` path or an fsspec URL of such a file.
    """
    from navkit.errors import InputError
    from navkit.io.urls import is_url, local_copy
    from navkit.planes import (
        CloudExtractionSettings,
        ExtractionSettings,
        observe_points,
        observe_rgbd,
    )

    es = ExtractionSettings(cell=cell)
    if _is_cloud_file(source):
        from navkit.io.pointcloud import read_pcd, read_ply

        with local_copy(source) as path:
            cloud = read_pcd(path) if path.suffix.lower() == ".pcd" else read_ply(path)
        if cloud.is_organized:
            obs = observe_points(cloud.grid(), organized_settings=es)
            return obs, None, "organised cloud", None
        obs = observe_points(cloud.points, cloud_settings=CloudExtractionSettings())
        return obs, None, "unorganised cloud", None
    if is_url(source):
        raise InputError(
            "a URL of a folder",
            source=str(source),
            expected="a .pcd or .ply URL (RGB-D and CAPE folders are read from local paths)",
        )
    path = Path(source)
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
        kind = "CAPE frame (depth camera + separately calibrated RGB camera)"
        return obs, f.color_registered, kind, None
    if path.is_dir():
        seq = open_rgbd(path, cam)
        if not 0 <= frame < len(seq):
            raise InputError(
                f"frame {frame} of {len(seq)}",
                source=path,
                field="--frame",
                expected=f"0 <= frame < {len(seq)}",
            )
        rgbd = seq.frame(frame)
        return observe_rgbd(rgbd, es), rgbd.color, "RGB-D frame", None
    raise InputError(
        "unsupported input",
        source=path,
        expected="an RGB-D folder (TUM or color/ + depth/), a CAPE folder, a .pcd or .ply file",
    )


def extract_planes_to(
    out_dir: Path,
    source: str | Path,
    *,
    frame: int = 0,
    camera: CameraOverride | None = None,
    nu: float = 0.01,
    cell: int = 20,
    iterate: Callable[[Iterable[Any]], Iterator[Any]] | None = None,
) -> dict[str, Any]:
    """Extract the planes of one input and write its outputs into ``out_dir``; its summary.

    Writes ``planes.json`` (every plane in the sensor frame: normal, rho, rms, inliers, area,
    centroid, its texture frame and outline), ``texture_NN.png`` per plane when the input has
    intensities, and ``overlay.png`` (the extraction's labels over the picture). Every file is
    written atomically.

    Parameters
    ----------
    out_dir : Path
        Output folder (created).
    source : str or Path
        An RGB-D folder, a CAPE folder, a ``.pcd`` / ``.ply`` file or an fsspec URL of one.
    frame : int
        Frame index in a sequence folder.
    camera : CameraOverride, optional
        Intrinsics and depth scale given on the command line.
    nu : float
        Texture pixel size (m).
    cell : int
        Patch size of the organised extraction (px).
    iterate : callable, optional
        Wraps the loop over the planes (a progress bar).
    """
    import time

    import numpy as np

    from navkit.io.atomic import write_json
    from navkit.io.images import write_image
    from navkit.planes.segments import plane_frame
    from navkit.viz.planes import extraction_overlay, texture_to_uint8

    cam = camera or CameraOverride()
    out_dir.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    obs, color, kind, gray = load_observation(source, frame, cam, cell)
    ms = 1000 * (time.perf_counter() - t0)
    planes: list[dict[str, Any]] = []
    segments = obs.segments if iterate is None else iterate(obs.segments)
    for k, seg in enumerate(segments):
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
            write_image(out_dir / name, texture_to_uint8(tex.image))
            entry.update(
                texture=name,
                texture_nu=nu,
                texture_index0=tex.index0,
                texture_valid=tex.valid_count,
                texture_contrast=tex.contrast(),
            )
        planes.append(entry)
    write_json(
        out_dir / "planes.json",
        {
            "input": str(source),
            "kind": kind,
            "frame": "sensor (camera: OpenCV x right, y down, z forward)",
            "planes": planes,
        },
    )
    labels = obs.extraction.labels
    if color is not None:
        write_image(out_dir / "overlay.png", extraction_overlay(color, labels))
    elif labels.ndim == 2:
        base = gray if gray is not None else np.full(labels.shape, 128, np.uint8)
        if base.shape != labels.shape:
            base = np.full(labels.shape, 128, np.uint8)
        write_image(out_dir / "overlay.png", extraction_overlay(base, labels))
    return {
        "input": str(source),
        "kind": kind,
        "planes": len(planes),
        "extract_and_load_ms": ms,
        "textured": bool(obs.has_texture),
        "textures": sum("texture" in p for p in planes),
        "inliers": int(sum(p["inliers"] for p in planes)),
        "area_m2": float(sum(p["area_m2"] for p in planes)),
    }


def planes_extract_job(
    out_dir: Path,
    *,
    source: str,
    frame: int = 0,
    camera: CameraOverride | None = None,
    nu: float = 0.01,
    cell: int = 20,
) -> dict[str, Any]:
    """:func:`extract_planes_to` as a batch task: its deterministic figures (no timings)."""
    s = extract_planes_to(out_dir, source, frame=frame, camera=camera, nu=nu, cell=cell)
    return {k: s[k] for k in DETERMINISTIC}


def input_key(source: str | Path) -> str:
    """The output folder name of an input: a file's stem, a folder's name (URL or path)."""
    name = str(source).rstrip("/").rsplit("/", 1)[-1]
    stem = name.rsplit(".", 1)[0] if _is_cloud_file(name) else name
    keep = "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-"
    return "".join(c if c in keep else "_" for c in stem) or "input"
