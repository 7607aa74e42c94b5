"""``navkit obstacles``: the eight-stage obstacle detector and the 2D obstacle map (paper 1)."""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import typer

from navkit.cli.common import cli_errors, expand_inputs, progress, write_run_files

log = logging.getLogger(__name__)

obstacles_app = typer.Typer(
    name="obstacles",
    help="Obstacles from range scans, lidar clouds and depth images, and the 2D obstacle map.",
    no_args_is_help=True,
)

SUFFIXES = (".npz", ".bin", ".pcd", ".ply", ".npy", ".png", ".pgm", ".tif", ".tiff")


@dataclass(frozen=True)
class InputOptions:
    """How inputs are read and mounted (written to ``settings.toml``)."""

    sensor_height_m: float | None = None
    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    gravity: tuple[float, float, float] | None = None
    rings: int | None = None
    columns: int | None = None
    ring_method: str = "auto"
    camera: tuple[float, float, float, float] | None = None
    depth_scale: float = 1000.0


@dataclass(frozen=True)
class MapOptions:
    """The 2D map exports."""

    resolution_m: float = 0.1
    extent_m: float | None = 40.0
    png_shapes: tuple[str, ...] = ("A1", "A6")


@dataclass(frozen=True)
class RunSettings:
    """Everything a ``navkit obstacles detect`` run used."""

    detector: Any
    inputs: InputOptions = field(default_factory=InputOptions)
    map: MapOptions = field(default_factory=MapOptions)


def _parse_floats(text: str | None, n: int, name: str) -> tuple[float, ...] | None:
    from navkit.errors import ConfigError

    if text is None:
        return None
    try:
        vals = tuple(float(v) for v in text.replace(" ", "").split(","))
    except ValueError as exc:
        raise ConfigError(
            f"= {text!r}", field=name, expected=f"{n} comma-separated numbers"
        ) from exc
    if len(vals) != n:
        raise ConfigError(f"= {text!r}", field=name, expected=f"{n} comma-separated numbers")
    return vals


def load_grid(path: Path, opts: InputOptions) -> tuple[Any, Any, str]:
    """Read one input as a :class:`~navkit.obstacles.ScanGrid`, its mounting and a kind string.

    ``.npz``: ``ranges (n_az, n_el)``, ``azimuth``, ``elevation`` (rad), ``sensor_height`` (m),
    optionally ``R_body_sensor (3, 3)`` and ``max_range``; ``.bin``: KITTI float32 x4;
    ``.pcd`` / ``.ply``: organised clouds keep their grid, others are spinning-lidar clouds;
    ``.npy``: an organised ``(H, W, >=3)`` cloud or an ``(N, >=3)`` cloud; images: depth with
    ``--camera fx,fy,cx,cy`` and ``--depth-scale``.
    """
    import numpy as np

    from navkit.errors import ConfigError, FormatError, InputError
    from navkit.obstacles import Mounting, cloud_to_grid, depth_to_grid, organized_to_grid
    from navkit.obstacles.grids import ScanGrid

    suffix = path.suffix.lower()
    height = opts.sensor_height_m
    R_file = None
    if suffix == ".npz":
        from navkit.sensors import RangeScan

        try:
            with np.load(path, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except (OSError, ValueError) as exc:
            raise FormatError(f"cannot be read as .npz: {exc}", source=path) from exc
        for key in ("ranges", "azimuth", "elevation"):
            if key not in data:
                raise FormatError(
                    f"has no array {key!r} (it has {sorted(data)})",
                    source=path,
                    field=key,
                    expected="ranges (n_azimuth, n_elevation), azimuth, elevation (rad), sensor_height (m)",
                )
        for key in ("ranges", "azimuth", "elevation"):
            if data[key].dtype.kind not in "fiu":
                raise FormatError(
                    f"has dtype {data[key].dtype}", source=path, field=key, expected="numbers"
                )
        try:
            scan = RangeScan(
                data["ranges"],
                data["azimuth"],
                data["elevation"],
                sensor_height=float(data.get("sensor_height", 0.0)),
                R_body_sensor=data.get("R_body_sensor", np.eye(3)),
                max_range=float(data.get("max_range", np.inf)),
            )
        except InputError as exc:
            raise FormatError(
                exc.message, source=path, field=exc.field, expected=exc.expected
            ) from exc
        if height is None:
            height = scan.sensor_height
        R_file = scan.R_body_sensor
        ia = np.argsort(scan.azimuth, kind="stable")
        ie = np.argsort(scan.elevation, kind="stable")
        pts = scan.points("sensor")[ia][:, ie]
        n_az, n_el = scan.shape
        cell = np.empty((n_az, n_el), dtype=np.int64)
        cell[np.ix_(ia, ie)] = np.arange(n_az * n_el).reshape(
            n_az, n_el
        )  # input (a, e) -> grid cell
        cell_of_point = cell.ravel().copy()
        cell_of_point[~scan.valid.ravel()] = -1
        az = scan.azimuth[ia]
        step = float(np.median(np.diff(az))) if len(az) > 2 else 0.0
        wraps = bool(len(az) > 2 and np.ptp(az) + 1.5 * step >= 2 * np.pi)
        grid = ScanGrid(pts, cell_of_point, az, wraps, "npz")
        kind = "grid"
    elif suffix == ".bin":
        from navkit.io.pointcloud import read_kitti_bin

        grid = cloud_to_grid(
            read_kitti_bin(path),
            n_rings=opts.rings,
            n_columns=opts.columns,
            ring_method=opts.ring_method,
            source=str(path),
        )
        kind = "cloud"
    elif suffix in (".pcd", ".ply"):
        from navkit.io.pointcloud import read_pcd, read_ply

        cloud = read_pcd(path) if suffix == ".pcd" else read_ply(path)
        if cloud.height > 1:
            grid = organized_to_grid(cloud.grid(), source=str(path))
            kind = "organized"
        else:
            grid = cloud_to_grid(
                cloud.points,
                n_rings=opts.rings,
                n_columns=opts.columns,
                ring_method=opts.ring_method,
                source=str(path),
            )
            kind = "cloud"
    elif suffix == ".npy":
        try:
            arr = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise FormatError(f"cannot be read as .npy: {exc}", source=path) from exc
        if arr.ndim == 3:
            grid = organized_to_grid(arr[..., :3], source=str(path))
            kind = "organized"
        elif arr.ndim == 2:
            grid = cloud_to_grid(
                arr,
                n_rings=opts.rings,
                n_columns=opts.columns,
                ring_method=opts.ring_method,
                source=str(path),
            )
            kind = "cloud"
        else:
            raise FormatError(
                f"has shape {arr.shape}",
                source=path,
                expected="(H, W, >=3) organised or (N, >=3) cloud",
            )
    else:
        from navkit.io.images import read_depth
        from navkit.sensors import PinholeCamera

        if opts.camera is None:
            raise ConfigError(
                "a depth image needs the camera intrinsics",
                source=path,
                field="--camera",
                expected="--camera fx,fy,cx,cy",
            )
        depth = read_depth(path, opts.depth_scale)
        fx, fy, cx, cy = opts.camera
        cam = PinholeCamera(fx, fy, cx, cy, depth.shape[1], depth.shape[0])
        grid = depth_to_grid(depth, cam, source=str(path))
        kind = "depth"
    use_file_R = (
        R_file is not None and opts.gravity is None and opts.roll_deg == 0 and opts.pitch_deg == 0
    )
    mounting = Mounting(
        height_m=float(height or 0.0),
        roll_deg=opts.roll_deg,
        pitch_deg=opts.pitch_deg,
        gravity=opts.gravity,
        rotation=tuple(tuple(float(v) for v in row) for row in R_file)  # type: ignore[misc]
        if use_file_R and R_file is not None
        else None,
    )
    return grid, mounting, kind


def geojson_features(detection: Any) -> list[tuple[dict[str, Any], dict[str, Any]]]:
    """GeoJSON features: every obstacle's boundary polygon and every shape (circles and ellipses
    as 72-gons), with the shape parameters as properties."""
    from navkit.io.maps import point_geometry, polygon_geometry

    feats: list[tuple[dict[str, Any], dict[str, Any]]] = []
    s = detection.sensor_origin
    feats.append((point_geometry(s[:2]), {"kind": "sensor"}))
    for ob in detection.obstacles:
        feats.append(
            (
                polygon_geometry(ob.polygon_xy),
                {
                    "kind": "boundary",
                    "obstacle": ob.id,
                    "height": ob.height,
                    "n_points": ob.n_points,
                    "shadow_area": ob.shadow_area,
                },
            )
        )
        for name, shp in ob.shapes.items():
            feats.append(
                (
                    polygon_geometry(shp.outline(72)),
                    {"kind": "shape", "shape": name, "obstacle": ob.id, **shp.params()},
                )
            )
        for name, shp in ob.guaranteed.items():
            feats.append(
                (
                    polygon_geometry(shp.outline(72)),
                    {"kind": "shape", "shape": f"A7:{name}", "obstacle": ob.id, **shp.params()},
                )
            )
    return feats


def process_frame(
    path: Path, out: Path, settings: Any, opts: InputOptions, mopts: MapOptions
) -> dict[str, Any]:
    """Detect obstacles in one input and write every per-frame output into ``out``."""
    import numpy as np

    from navkit.io.atomic import atomic_path, write_json
    from navkit.io.maps import write_geojson, write_occupancy_grid
    from navkit.obstacles import detect_obstacles_in_grid
    from navkit.obstacles.occupancy import occupancy_grid
    from navkit.viz.obstacles import save_obstacle_map

    t0 = time.perf_counter()
    grid, mounting, kind = load_grid(path, opts)
    t1 = time.perf_counter()
    det = detect_obstacles_in_grid(grid, mounting, settings, source=str(path))
    t2 = time.perf_counter()
    labels = grid.per_point(det.vertex_labels).astype(np.int8)
    if kind == "grid":
        n_az, n_el = det.vertex_labels.shape
        labels = labels.reshape(n_az, n_el)
    out.mkdir(parents=True, exist_ok=True)
    with atomic_path(out / "labels.npy") as tmp:
        np.save(tmp, labels)
    write_json(
        out / "obstacles.json",
        {
            "input": str(path),
            "frame": "body (x forward, y left, z up, origin on the ground under the sensor)",
            "sensor": det.sensor_origin,
            "classes": {
                "0": "ground",
                "-1": "unreliable",
                "-2": "obstacle",
                "-3": "side shadow",
                "-4": "shadow behind",
            },
            "obstacles": [ob.to_dict() for ob in det.obstacles],
        },
    )
    occ = occupancy_grid(det, mopts.resolution_m, mopts.extent_m)
    write_occupancy_grid(out / "map", occ.occupancy, occ.resolution, occ.origin_xy)
    write_geojson(
        out / "map.geojson",
        geojson_features(det),
        properties={"frame": "body", "units": "m", "input": str(path)},
    )
    save_obstacle_map(
        out / "map.png",
        det,
        shapes=mopts.png_shapes,
        extent_m=min(mopts.extent_m or 40.0, 40.0),
        title=f"{path.name}: {len(det.obstacles)} obstacles",
    )
    t3 = time.perf_counter()
    return {
        "input": str(path),
        "output": str(out),
        "kind": kind,
        "grid_method": grid.method,
        "grid_shape": list(det.vertex_labels.shape),
        "n_points": int(labels.size),
        "n_obstacles": len(det.obstacles),
        "triangles": det.counts,
        "timings_s": {
            "read_and_grid": t1 - t0,
            **det.timings,
            "detect_total": t2 - t1,
            "write_outputs": t3 - t2,
        },
    }


def register(app: typer.Typer) -> None:
    """Add ``navkit obstacles ...`` to the main command."""
    app.add_typer(obstacles_app)


@obstacles_app.command("detect")
def detect(
    inputs: list[str] = typer.Argument(
        ..., help="Files, folders or globs: .npz grids, KITTI .bin, PCD/PLY, .npy, depth images."
    ),
    out: Path = typer.Option(
        ..., "--out", "-o", help="Output folder (one sub-folder per input, named after its stem)."
    ),
    config: Path | None = typer.Option(
        None, "--config", help="TOML with detector settings (keys of ObstacleSettings)."
    ),
    sensor_height: float | None = typer.Option(
        None,
        "--sensor-height",
        help="Sensor height above the ground, m (default: the .npz's, else 0).",
    ),
    roll_deg: float = typer.Option(0.0, "--roll-deg", help="Sensor roll in the level frame, deg."),
    pitch_deg: float = typer.Option(
        0.0, "--pitch-deg", help="Sensor pitch (positive = looking down), deg."
    ),
    gravity: str | None = typer.Option(
        None, "--gravity", help="Gravity in the sensor frame 'gx,gy,gz' (overrides roll/pitch)."
    ),
    c0_deg: float | None = typer.Option(
        None, "--c0-deg", help="Largest traversable slope c0, deg."
    ),
    shapes: str | None = typer.Option(
        None, "--shapes", help="Comma-separated shapes (A1..A6, MEC, MVEE)."
    ),
    rings: int | None = typer.Option(
        None, "--rings", help="Beam count of a lidar cloud (default: recovered)."
    ),
    columns: int | None = typer.Option(
        None, "--columns", help="Azimuth columns of a lidar cloud (default: recovered)."
    ),
    ring_method: str = typer.Option("auto", "--ring-method", help="auto | order | elevation."),
    camera: str | None = typer.Option(
        None, "--camera", help="Depth images: 'fx,fy,cx,cy' in pixels."
    ),
    depth_scale: float = typer.Option(
        1000.0, "--depth-scale", help="Depth images: raw units per metre."
    ),
    resolution: float = typer.Option(0.1, "--resolution", help="Occupancy grid cell, m."),
    extent: float = typer.Option(
        40.0, "--extent", help="Half-width of the maps around the sensor, m."
    ),
    plot_shapes: str = typer.Option(
        "A1,A6",
        "--plot-shapes",
        help="Shapes drawn in map.png, comma-separated (A1..A6, MEC, MVEE); all are in obstacles.json.",
    ),
) -> None:
    """Detect obstacles in every input; write labels, obstacles, occupancy map, GeoJSON and PNG."""
    with cli_errors():
        import dataclasses

        try:
            import tomllib
        except ModuleNotFoundError:  # Python 3.10
            import tomli as tomllib  # type: ignore[no-redef]

        from navkit.errors import ConfigError
        from navkit.obstacles import ObstacleSettings

        data: dict[str, Any] = {}
        if config is not None:
            try:
                data = tomllib.loads(config.read_text(encoding="utf-8"))
            except tomllib.TOMLDecodeError as exc:
                raise ConfigError(f"is not valid TOML: {exc}", source=config) from exc
            data = data.get("detector", data)
        if c0_deg is not None:
            data["c0_deg"] = c0_deg
        if shapes is not None:
            data["shapes"] = tuple(s.strip() for s in shapes.split(",") if s.strip())
        settings = ObstacleSettings.from_dict(data, source=str(config or "options"))
        g = _parse_floats(gravity, 3, "--gravity")
        cam = _parse_floats(camera, 4, "--camera")
        opts = InputOptions(
            sensor_height,
            roll_deg,
            pitch_deg,
            g,  # type: ignore[arg-type]
            rings,
            columns,
            ring_method,
            cam,  # type: ignore[arg-type]
            depth_scale,
        )
        drawn = tuple(n.strip() for n in plot_shapes.split(",") if n.strip())
        from navkit.errors import ConfigError
        from navkit.geometry.shapes import SHAPES

        unknown = [n for n in drawn if n not in SHAPES]
        if unknown:
            raise ConfigError(
                f"unknown shapes {unknown}",
                field="--plot-shapes",
                expected=f"names from {sorted(SHAPES)}",
            )
        mopts = MapOptions(resolution_m=resolution, extent_m=extent, png_shapes=drawn)
        files = expand_inputs(inputs, SUFFIXES)
        frames = []
        used: dict[str, int] = {}
        for path in progress(files, "obstacles"):
            stem = path.stem
            used[stem] = used.get(stem, 0) + 1
            name = stem if used[stem] == 1 else f"{stem}_{used[stem]}"
            frames.append(process_frame(path, out / name, settings, opts, mopts))
        run = RunSettings(detector=dataclasses.asdict(settings), inputs=opts, map=mopts)
        write_run_files(out, asdict(run), {"frames": frames, "n_frames": len(frames)})
        typer.echo(
            f"{len(frames)} frame(s), {sum(f['n_obstacles'] for f in frames)} obstacles -> {out}"
        )
