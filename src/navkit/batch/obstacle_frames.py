"""One frame of ``navkit obstacles detect``: read, detect, write the chosen outputs.

The per-input function of the command's in-process loop and of its batch runs
(``--workers`` / ``--scheduler`` / ``--resume``, :mod:`navkit.batch`): the same code writes the
same files either way.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from navkit.domains import POSITIVE, POSITIVE_INT, Domain, domain_field

__all__ = [
    "OUTPUTS",
    "PITCH_DOMAIN",
    "ROLL_DOMAIN",
    "SENSOR_HEIGHT_DOMAIN",
    "InputOptions",
    "MapOptions",
    "RunSettings",
    "obstacles_frame_job",
    "process_frame",
    "read_mounted",
    "resolve_height",
]

OUTPUTS = ("labels", "obstacles", "grid", "png", "geojson")
"""What ``--outputs`` may choose, per frame: ``labels.npy``, ``obstacles.json``, the map_server
occupancy grid ``map.pgm`` + ``map.yaml``, the figure ``map.png``, ``map.geojson`` (WGS84,
needs ``--origin``)."""


SENSOR_HEIGHT_DOMAIN = Domain(lo=0.0, lo_open=True)
"""``--sensor-height`` / ``[inputs] sensor_height_m`` (m): the sensor is above the ground it
classifies (the detector levels the cloud and puts the ground plane ``h`` below the sensor); a
height <= 0 would put that plane at or above the sensor, where no ray meets it from above, so it
is refused rather than read as a sensor looking up at a ceiling."""
ROLL_DOMAIN = Domain(lo=-180.0, hi=180.0, note="signed: either side")
PITCH_DOMAIN = Domain(lo=-90.0, hi=90.0, note="signed: positive looking down")


@dataclass(frozen=True)
class InputOptions:
    """How inputs are read and mounted (the ``[inputs]`` table of ``settings.toml``); each
    number is checked against its declared domain (the same as the CLI option's)."""

    sensor: str | None = None
    sensor_height_m: float | None = domain_field(None, SENSOR_HEIGHT_DOMAIN)
    roll_deg: float = domain_field(0.0, ROLL_DOMAIN)
    pitch_deg: float = domain_field(0.0, PITCH_DOMAIN)
    gravity: tuple[float, float, float] | None = None
    rings: int | None = domain_field(None, POSITIVE_INT)
    columns: int | None = domain_field(None, POSITIVE_INT)
    ring_method: str = "auto"
    intrinsics: tuple[float, float, float, float] | None = None
    depth_scale: float = domain_field(1000.0, POSITIVE)

    def __post_init__(self) -> None:
        from navkit.errors import ConfigError
        from navkit.geometry._validate import check_settings

        check_settings(self)
        for name, n in (("gravity", 3), ("intrinsics", 4)):
            _check_numbers(getattr(self, name), n, name, ConfigError)
        if self.intrinsics is not None:
            for k, v in zip(("fx", "fy"), self.intrinsics[:2], strict=True):
                POSITIVE.check(v, f"intrinsics {k}", source="InputOptions", error=ConfigError)


@dataclass(frozen=True)
class MapOptions:
    """What is written per frame (the ``[map]`` table of ``settings.toml``)."""

    outputs: tuple[str, ...] = ("labels", "obstacles")
    resolution_m: float = domain_field(0.1, POSITIVE)
    extent_m: float | None = domain_field(40.0, POSITIVE)
    png_shapes: tuple[str, ...] = ("A1", "A6")
    origin: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        from navkit.geometry._validate import check_settings

        check_settings(self)


def _check_numbers(values: Any, n: int, name: str, error: Any) -> None:
    """``values`` None or ``n`` finite numbers, else ``error`` naming ``name``."""
    import math

    if values is None:
        return
    try:
        ok = len(values) == n and all(math.isfinite(float(v)) for v in values)
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise error(
            f"is {values!r}", source="InputOptions", field=name, expected=f"{n} finite numbers"
        )


@dataclass(frozen=True)
class RunSettings:
    """Everything a ``navkit obstacles detect`` run used."""

    detector: Any
    inputs: InputOptions = field(default_factory=InputOptions)
    map: MapOptions = field(default_factory=MapOptions)


def read_mounted(path: Path | str, opts: InputOptions) -> tuple[Any, Any]:
    """Read one input (a path or an fsspec URL) as a scan grid and its mounting (height still
    0: see :func:`resolve_height`)."""
    from navkit.io.scans import read_scan_grid
    from navkit.io.urls import local_copy
    from navkit.obstacles import Mounting

    with local_copy(path) as local:  # a path as it is; an fsspec URL through a private copy
        scan = read_scan_grid(
            local,
            rings=opts.rings,
            columns=opts.columns,
            ring_method=opts.ring_method,
            intrinsics=opts.intrinsics,
            depth_scale=opts.depth_scale,
        )
    use_file_R = scan.R_body_sensor is not None and opts.gravity is None
    use_file_R = use_file_R and opts.roll_deg == 0 and opts.pitch_deg == 0
    R_file = scan.R_body_sensor if use_file_R else None
    mounting = Mounting(0.0, opts.roll_deg, opts.pitch_deg, opts.gravity, R_file)  # type: ignore[arg-type]
    return scan, mounting


def resolve_height(scan: Any, mounting: Any, opts: InputOptions, path: Path | str) -> Any:
    """The sensor height of a run: given, from the file, or measured on this frame's ground
    (:func:`~navkit.obstacles.mounting.choose_sensor_height`)."""
    from navkit.obstacles.mounting import choose_sensor_height
    from navkit.sensors.presets import get_preset

    preset = get_preset(opts.sensor) if opts.sensor else None
    given = opts.sensor_height_m if opts.sensor_height_m is not None else scan.sensor_height_m
    return choose_sensor_height(
        scan.grid.points,
        mounting.R_body_sensor,
        given_m=given,
        typical_m=preset.typical_height_m if preset else None,
        plausible_m=preset.height_range_m if preset else (0.05, 4.0),
        source=str(path),
    )


def process_frame(
    path: Path | str, out: Path, settings: Any, opts: InputOptions, mopts: MapOptions, height: Any
) -> tuple[dict[str, Any], Any]:
    """Read one input, detect its obstacles and write the chosen outputs into ``out``.

    ``height`` is the run's :class:`~navkit.obstacles.mounting.SensorHeight` (None: resolve it
    on this frame). Returns the frame's summary and the height used.
    """
    from navkit.io.maps import GeoOrigin, write_occupancy_grid
    from navkit.io.obstacles import write_labels, write_obstacle_geojson, write_obstacles_json
    from navkit.io.urls import url_name
    from navkit.obstacles import detect_obstacles_in_grid
    from navkit.obstacles.occupancy import occupancy_grid

    t0 = time.perf_counter()
    cloud = read_unorganised(path, opts)
    if cloud is not None:
        return _process_unorganised(path, out, cloud, mopts, t0), height
    scan, mounting = read_mounted(path, opts)
    t1 = time.perf_counter()
    if height is None or (scan.sensor_height_m is not None and opts.sensor_height_m is None):
        height = resolve_height(scan, mounting, opts, path)
    mounting = replace(mounting, height_m=height.height_m)
    t2 = time.perf_counter()
    det = detect_obstacles_in_grid(scan.grid, mounting, settings, source=str(path))
    t3 = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    chosen = set(mopts.outputs)
    if "labels" in chosen:
        labels = scan.grid.per_point(det.vertex_labels)
        write_labels(
            out / "labels.npy",
            labels.reshape(det.vertex_labels.shape) if scan.kind == "grid" else labels,
        )
    if "obstacles" in chosen:
        write_obstacles_json(
            out / "obstacles.json", det, source=str(path), extra={"sensor_height": height.to_dict()}
        )
    if "grid" in chosen:
        occ = occupancy_grid(det, mopts.resolution_m, mopts.extent_m)
        write_occupancy_grid(out / "map", occ.occupancy, occ.resolution, occ.origin_xy)
    if "geojson" in chosen and mopts.origin is not None:
        origin = GeoOrigin(*mopts.origin)
        write_obstacle_geojson(
            out / "map.geojson", det, origin, shapes=mopts.png_shapes, source=str(path)
        )
    if "png" in chosen:
        from navkit.viz.obstacles import save_obstacle_map

        save_obstacle_map(
            out / "map.png",
            det,
            shapes=mopts.png_shapes,
            extent_m=min(mopts.extent_m or 40.0, 40.0),
            title=f"{url_name(path)}: {len(det.obstacles)} obstacles",
        )
    t4 = time.perf_counter()
    frame = {
        "input": str(path),
        "output": str(out),
        "kind": scan.kind,
        "path": "scan",
        "grid_method": scan.grid.method,
        "grid_shape": list(det.vertex_labels.shape),
        "n_points": int(scan.grid.cell_of_point.size),
        "n_obstacles": len(det.obstacles),
        "sensor_height_m": height.height_m,
        "triangles": det.counts,
        "bytes_written": sum(f.stat().st_size for f in out.iterdir() if f.is_file()),
        "timings_s": {
            "read_and_grid": t1 - t0,
            "sensor_height": t2 - t1,
            **det.timings,
            "detect_total": t3 - t2,
            "write_outputs": t4 - t3,
            "frame_total": t4 - t0,
        },
    }
    return frame, height


UNORGANISED_OUTPUTS = ("labels", "obstacles")
"""What the unorganised path writes: per-point labels and the obstacles (no sensor, so no
sensor-centred grid, figure or GeoJSON)."""


def read_unorganised(path: Path | str, opts: InputOptions) -> tuple[Any, Any] | None:
    """``(points, CloudKind)`` when the input is a point-by-point cloud without a recoverable
    ring structure (:func:`navkit.obstacles.unorganised.recognise_cloud`); ``None`` for scans,
    organised clouds, depth images and clouds whose rings can be recovered (the scan path).
    ``--rings`` / ``--columns`` / ``--ring-method`` other than ``auto`` force the scan path."""
    from navkit.io.urls import local_copy, url_name

    suffix = Path(url_name(path)).suffix.lower()
    if suffix not in (".pcd", ".ply", ".npy"):
        return None
    if opts.rings is not None or opts.columns is not None or opts.ring_method != "auto":
        return None
    import numpy as np

    from navkit.errors import FormatError
    from navkit.obstacles.unorganised import recognise_cloud

    with local_copy(path) as local:
        if suffix == ".npy":
            try:
                arr = np.load(local, mmap_mode="r", allow_pickle=False)
            except (OSError, ValueError) as exc:
                raise FormatError(f"cannot be read as .npy: {exc}", source=path) from exc
            if arr.ndim != 2:
                return None
            points = np.asarray(arr)
        else:
            from navkit.io.pointcloud import read_pcd, read_ply

            cloud = read_pcd(local) if suffix == ".pcd" else read_ply(local)
            if cloud.height > 1:
                return None
            points = cloud.points
    kind = recognise_cloud(points, source=str(path))
    return (points, kind) if kind.path == "unorganised" else None


def _process_unorganised(
    path: Path | str, out: Path, cloud: tuple[Any, Any], mopts: MapOptions, t0: float
) -> dict[str, Any]:
    """The unorganised path of one frame: detection, per-point labels, obstacles.json."""
    from navkit.errors import ConfigError
    from navkit.io.obstacles import write_labels, write_obstacles_json
    from navkit.obstacles.unorganised import detect_unorganised

    points, kind = cloud
    unsupported = sorted(set(mopts.outputs) - set(UNORGANISED_OUTPUTS))
    if unsupported:
        raise ConfigError(
            f"{unsupported} need a sensor position and {path} is an unorganised cloud "
            f"({kind.reason})",
            field="--outputs",
            expected=f"outputs among {list(UNORGANISED_OUTPUTS)} for unorganised clouds",
        )
    t1 = time.perf_counter()
    det = detect_unorganised(points, source=str(path))
    t2 = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    if "labels" in mopts.outputs:
        write_labels(out / "labels.npy", det.point_labels)
    if "obstacles" in mopts.outputs:
        write_obstacles_json(
            out / "obstacles.json",
            det,
            source=str(path),
            extra={"path": "unorganised", "ground_band_m": det.band_m},
        )
    t3 = time.perf_counter()
    return {
        "input": str(path),
        "output": str(out),
        "kind": "cloud",
        "path": "unorganised",
        "path_reason": kind.reason,
        "n_points": int(det.point_labels.size),
        "n_ground_points": int(det.ground.sum()),
        "n_obstacles": len(det.obstacles),
        "spacing_m": det.spacing_m,
        "noise_m": det.noise_m,
        "ground_band_m": det.band_m,
        "n_tiles": len(det.tiles),
        "triangles": det.counts,
        "bytes_written": sum(f.stat().st_size for f in out.iterdir() if f.is_file()),
        "timings_s": {
            "read_and_recognise": t1 - t0,
            **det.timings,
            "detect_total": t2 - t1,
            "write_outputs": t3 - t2,
            "frame_total": t3 - t0,
        },
    }


def obstacles_frame_job(
    out_dir: Path,
    *,
    path: str,
    settings: Any,
    opts: InputOptions,
    mopts: MapOptions,
    height: Any,
) -> dict[str, Any]:
    """:func:`process_frame` as a batch task: the frame's figures without its timings."""
    from navkit.io.urls import is_url

    source = path if is_url(path) else Path(path)
    frame, _ = process_frame(source, out_dir, settings, opts, mopts, height)
    return {k: v for k, v in frame.items() if k not in ("timings_s", "output")}
