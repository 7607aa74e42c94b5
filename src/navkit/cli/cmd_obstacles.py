"""``navkit obstacles``: the eight-stage obstacle detector and the 2D obstacle map (paper 1)."""

from __future__ import annotations

import logging
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import typer

from navkit.batch.obstacle_frames import (
    OUTPUTS,
    PITCH_DOMAIN,
    ROLL_DOMAIN,
    SENSOR_HEIGHT_DOMAIN,
    InputOptions,
    MapOptions,
    RunSettings,
    process_frame,
)
from navkit.cli.batching import (
    RESUME,
    SCHEDULER,
    WORKERS,
    exit_if_failed,
    expand_sources,
    run_inputs,
)
from navkit.cli.common import check_out_dir, cli_errors, option, progress, write_run_files
from navkit.domains import POSITIVE, POSITIVE_INT, Domain

log = logging.getLogger(__name__)

obstacles_app = typer.Typer(
    name="obstacles",
    help="Obstacles from range scans, lidar clouds and depth images, and the 2D obstacle map.",
    no_args_is_help=True,
)

DEFAULT_OUTPUTS = "labels,obstacles"


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


def _names(text: str, allowed: Any, option: str) -> tuple[str, ...]:
    from navkit.errors import ConfigError

    names = tuple(n.strip() for n in text.split(",") if n.strip())
    unknown = [n for n in names if n not in allowed]
    if unknown:
        raise ConfigError(
            f"unknown {unknown}", field=option, expected=f"names from {list(allowed)}"
        )
    return names


def _with_preset(opts: InputOptions) -> tuple[InputOptions, Any]:
    """Fill options the user left at their defaults from the ``--sensor`` preset."""
    if opts.sensor is None:
        return opts, None
    from navkit.sensors.presets import get_preset

    p = get_preset(opts.sensor)
    return (
        replace(
            opts,
            rings=opts.rings if opts.rings is not None else p.rings,
            columns=opts.columns if opts.columns is not None else p.columns,
            ring_method=opts.ring_method if opts.ring_method != "auto" else p.ring_method,
            intrinsics=opts.intrinsics or p.intrinsics,
            depth_scale=p.depth_scale
            if (p.depth_scale and opts.depth_scale == 1000.0)
            else opts.depth_scale,
        ),
        p,
    )


def register(app: typer.Typer) -> None:
    """Add ``navkit obstacles ...`` to the main command."""
    app.add_typer(obstacles_app)


def _load_config(config: Path | None, ctx: typer.Context) -> dict[str, dict[str, Any]]:
    """The ``[detector]``, ``[inputs]`` and ``[map]`` tables of ``--config`` (a ``settings.toml``
    of an earlier run works), without the keys given on the command line."""
    if config is None:
        return {"detector": {}, "inputs": {}, "map": {}}
    from navkit.errors import ConfigError
    from navkit.io.textfiles import load_toml_file

    data = load_toml_file(config, "a settings TOML file")
    tables = {"detector", "inputs", "map"}
    if not tables & set(data):  # a bare table of detector settings
        data = {"detector": data}
    for name in ("inputs", "map"):
        known = {f for f in (InputOptions if name == "inputs" else MapOptions).__dataclass_fields__}
        extra = set(data.get(name, {})) - known
        if extra:
            raise ConfigError(
                f"unknown keys {sorted(extra)}",
                source=config,
                field=name,
                expected=f"keys of {sorted(known)}",
            )
    return {k: dict(data.get(k, {})) for k in tables}


OUTPUTS_OPTION = typer.Option(
    DEFAULT_OUTPUTS,
    "--outputs",
    help="What to write per frame, comma-separated: labels, obstacles, grid (map_server "
    "PGM + YAML), png (figure), geojson (WGS84; needs --origin, which adds it).",
)

SENSOR_OPTION = typer.Option(
    None,
    "--sensor",
    help="Sensor preset: hdl64e-kitti, vlp16, os1-64, os1-128, livox-mid360, kinect-v1-tum, "
    "realsense-d435 (beam layout, intrinsics, plausible height).",
)

SENSOR_HEIGHT_OPTION = option(
    None,
    "--sensor-height",
    domain=SENSOR_HEIGHT_DOMAIN,
    help="Sensor height above the ground (m). Default: the .npz's, else measured from the "
    "ground in the first frame and reported in summary.json.",
)

ORIGIN_OPTION = typer.Option(
    None,
    "--origin",
    help="Georeference LAT,LON[,HEADING] (deg; heading of x, clockwise from north): "
    "writes map.geojson in WGS84.",
)


RINGS_OPTION = option(
    None, "--rings", domain=POSITIVE_INT, help="Beams of a lidar cloud (default: recovered)."
)
COLUMNS_OPTION = option(
    None,
    "--columns",
    domain=POSITIVE_INT,
    help="Azimuth columns of a lidar cloud (default: recovered).",
)
C0_DOMAIN = Domain(lo=0.0, hi=90.0, lo_open=True, hi_open=True)


@obstacles_app.command("detect")
def detect(
    ctx: typer.Context,
    inputs: list[str] = typer.Argument(
        ..., help="Files, folders or globs: .npz grids, KITTI .bin, PCD/PLY, .npy, depth images."
    ),
    out: Path = typer.Option(
        ..., "--out", "-o", help="Output folder (one sub-folder per input, named after its stem)."
    ),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace outputs already in --out."),
    outputs: str = OUTPUTS_OPTION,
    config: Path | None = typer.Option(
        None, "--config", help="TOML with [detector], [inputs] and [map] tables (as settings.toml)."
    ),
    sensor: str | None = SENSOR_OPTION,
    sensor_height: float | None = SENSOR_HEIGHT_OPTION,
    roll_deg: float = option(
        0.0, "--roll-deg", domain=ROLL_DOMAIN, help="Sensor roll in the level frame (deg)."
    ),
    pitch_deg: float = option(
        0.0, "--pitch-deg", domain=PITCH_DOMAIN, help="Sensor pitch in the level frame (deg)."
    ),
    gravity: str | None = typer.Option(
        None, "--gravity", help="Gravity in the sensor frame GX,GY,GZ (overrides roll and pitch)."
    ),
    c0_deg: float | None = option(
        None, "--c0-deg", domain=C0_DOMAIN, help="Largest traversable slope (deg)."
    ),
    shapes: str | None = typer.Option(
        None, "--shapes", help="Shapes to compute, comma-separated (A1..A6, MEC, MVEE)."
    ),
    rings: int | None = RINGS_OPTION,
    columns: int | None = COLUMNS_OPTION,
    ring_method: str = typer.Option("auto", "--ring-method", help="auto, order or elevation."),
    intrinsics: str | None = typer.Option(
        None, "--intrinsics", help="Depth images: FX,FY,CX,CY (pixels)."
    ),
    depth_scale: float = option(
        1000.0, "--depth-scale", domain=POSITIVE, help="Depth images: raw units per metre."
    ),
    resolution: float = option(
        0.1, "--resolution", domain=POSITIVE, help="Occupancy grid cell (m)."
    ),
    extent: float = option(
        40.0, "--extent", domain=POSITIVE, help="Half-width of the maps around the sensor (m)."
    ),
    plot_shapes: str = typer.Option(
        "A1,A6", "--plot-shapes", help="Shapes in map.png and map.geojson, comma-separated."
    ),
    origin: str | None = ORIGIN_OPTION,
    workers: int | None = WORKERS,
    scheduler: str | None = SCHEDULER,
    resume: bool = RESUME,
) -> None:
    """Detect obstacles in every input; by default write labels.npy and obstacles.json per frame.

    A frame that fails is reported (log, frames.csv, summary.json) and the others go on.

    \b
    Example:
      navkit obstacles detect "$NAVKIT_DATA/lidar/semantickitti-seq00" \\
          --sensor hdl64e-kitti -o out/kitti
    """
    with cli_errors():
        n_failed = _detect(ctx, inputs, out, overwrite, config, workers, scheduler, resume)
    exit_if_failed({"failed": n_failed})  # 3 with any failed frame, batch or not


def _detect(
    ctx: typer.Context,
    inputs: list[str],
    out: Path,
    overwrite: bool,
    config: Path | None,
    workers: int | None,
    scheduler: str | None,
    resume: bool,
) -> int:
    """``detect``'s run: settings, inputs checked before anything is written, the frames (in
    this process or a batch), the run files and the summary line. Returns the failed count."""
    settings, opts, mopts = _resolve_settings(ctx, config)
    files = expand_sources(inputs, _suffixes())
    check_out_dir(out, overwrite or resume)
    if workers or scheduler or resume:
        frames, failed, height = _run_batch(
            files, out, settings, opts, mopts, workers, scheduler, resume
        )
        first_error = None
    else:
        from navkit.io.scans import check_scan_input
        from navkit.io.urls import local_copy

        for f in files:  # every input's container checked before anything is written
            with local_copy(f) as local:
                check_scan_input(local)
        frames, failed, height, first_error = _run_frames(files, out, settings, opts, mopts)
    if first_error is not None and not frames:
        raise first_error  # nothing worked: the one-line error, exit code 2, no run files
    run = RunSettings(detector=asdict(settings), inputs=opts, map=mopts)
    write_run_files(
        out,
        asdict(run),
        {
            "frames": frames,
            "n_frames": len(frames),
            "failed": failed,
            "sensor_height": height.to_dict() if height is not None else None,
            "outputs": list(mopts.outputs),
        },
        reference="none: the detections are not compared with any ground truth",
    )
    if height is not None and height.source != "given":
        log.info("sensor height %.3f m (%s)", height.height_m, height.source)
    paths = sorted({str(f.get("path", "scan")) for f in frames})
    typer.echo(
        f"{len(frames)} frame(s) ({', '.join(paths) or 'no'} path), "
        f"{sum(f['n_obstacles'] for f in frames)} obstacles"
        + (f", {len(failed)} failed (see frames.csv)" if failed else "")
        + f" -> {out}"
    )
    return len(failed)


def _resolve_settings(ctx: typer.Context, config: Path | None) -> tuple[Any, Any, Any]:
    """The detector settings, input options and map options of a run: the ``--config`` tables,
    with the options given on the command line on top (read from click's context)."""
    from navkit.geometry.shapes import SHAPES
    from navkit.obstacles import ObstacleSettings

    o = ctx.params
    cfg = _load_config(config, ctx)
    given = {k for k in o if _given(ctx, k)}
    if o["c0_deg"] is not None:
        cfg["detector"]["c0_deg"] = o["c0_deg"]
    if o["shapes"] is not None:
        cfg["detector"]["shapes"] = _names(o["shapes"], SHAPES, "--shapes")
    settings = ObstacleSettings.from_dict(cfg["detector"], source=str(config or "options"))
    cli_inputs = {
        "sensor": o["sensor"], "sensor_height_m": o["sensor_height"], "roll_deg": o["roll_deg"],
        "pitch_deg": o["pitch_deg"], "gravity": _parse_floats(o["gravity"], 3, "--gravity"),
        "rings": o["rings"], "columns": o["columns"], "ring_method": o["ring_method"],
        "intrinsics": _parse_floats(o["intrinsics"], 4, "--intrinsics"),
        "depth_scale": o["depth_scale"],
    }  # fmt: skip
    option_of = {"sensor_height_m": "sensor_height", "intrinsics": "intrinsics"}
    merged = {**cfg["inputs"]}
    for key, val in cli_inputs.items():
        if option_of.get(key, key) in given or key not in merged:
            merged[key] = val
    opts, _ = _with_preset(_in_table(config, "inputs", InputOptions, merged))
    origin = o["origin"]
    geo = _parse_floats(origin, 3 if origin.count(",") == 2 else 2, "--origin") if origin else None
    cli_map: dict[str, Any] = {
        "outputs": _names(o["outputs"], OUTPUTS, "--outputs"), "resolution_m": o["resolution"],
        "extent_m": o["extent"], "png_shapes": _names(o["plot_shapes"], SHAPES, "--plot-shapes"),
        "origin": geo,
    }  # fmt: skip
    map_option = {"resolution_m": "resolution", "extent_m": "extent", "png_shapes": "plot_shapes"}
    mcfg: dict[str, Any] = dict(cfg["map"])
    for key, val in cli_map.items():
        if map_option.get(key, key) in given or key not in mcfg:
            mcfg[key] = val
    mcfg = {k: tuple(v) if isinstance(v, list) else v for k, v in mcfg.items()}
    mcfg["outputs"] = _check_geo(
        _names(",".join(mcfg["outputs"]), OUTPUTS, "outputs"),
        mcfg.get("origin"),
        "outputs" in given or "outputs" in cfg["map"],
    )
    return settings, opts, _in_table(config, "map", MapOptions, mcfg)


def _in_table(config: Path | None, table: str, cls: Any, values: dict[str, Any]) -> Any:
    """``cls(**values)``; an error names ``--config``'s file and table when one is given."""
    from navkit.errors import ConfigError

    try:
        return cls(**values)
    except ConfigError as exc:
        if config is None:
            raise
        raise ConfigError(
            exc.message, source=config, field=f"[{table}] {exc.field}", expected=exc.expected
        ) from None


def _run_frames(
    files: list[Path], out: Path, settings: Any, opts: InputOptions, mopts: MapOptions
) -> tuple[list[dict[str, Any]], list[dict[str, Any]], Any, Exception | None]:
    """Every frame in turn; a frame that fails is reported (log, ``frames.csv``, the summary's
    ``failed``) and gets no outputs, and the others go on. ``frames.csv``: one row per input,
    ``frame,input,status,n_obstacles,reason``."""
    from navkit.errors import DegenerateGeometryError, InputError
    from navkit.io.obstacles import write_frame_status

    frames: list[dict[str, Any]] = []
    failed: list[dict[str, Any]] = []
    rows: list[tuple[str, str, str, int | None, str]] = []
    height, first_error = None, None
    for path, name in progress(_frame_names(files), "obstacles"):
        try:
            frame, height = process_frame(path, out / name, settings, opts, mopts, height)
        except (InputError, DegenerateGeometryError) as exc:
            log.error("frame failed, no outputs written: %s", exc)  # exc names the file
            first_error = first_error or exc
            failed.append({"input": str(path), "reason": str(exc)})
            rows.append((name, str(path), "failed", None, str(exc)))
            continue
        frames.append(frame)
        rows.append((name, str(path), "ok", frame["n_obstacles"], ""))
    if frames:
        write_frame_status(out / "frames.csv", rows)
    return frames, failed, height, first_error


def _run_batch(
    files: list[Path],
    out: Path,
    settings: Any,
    opts: InputOptions,
    mopts: MapOptions,
    workers: int | None,
    scheduler: str | None,
    resume: bool,
) -> tuple[list[dict[str, Any]], list[dict[str, Any]], Any]:
    """The frames as a batch (``navkit.batch``): the sensor height is resolved once, on the first
    readable frame, here; then every frame is one task with that height, on Dask or in process."""
    import json

    from navkit.batch import BatchTask, settings_hash
    from navkit.batch.obstacle_frames import obstacles_frame_job, read_mounted, resolve_height
    from navkit.errors import DegenerateGeometryError, InputError
    from navkit.io.urls import input_identity

    named = _frame_names(files)
    height, first_error = None, None
    for path, _ in named:  # the first frame that reads; the unreadable ones fail as tasks
        try:
            scan, mounting = read_mounted(path, opts)
            height = resolve_height(scan, mounting, opts, path)
            break
        except (InputError, DegenerateGeometryError) as exc:
            first_error = first_error or exc
    if height is None:
        assert first_error is not None
        raise first_error
    tasks = [
        BatchTask(
            name,
            obstacles_frame_job,
            {"path": str(p), "settings": settings, "opts": opts, "mopts": mopts, "height": height},
            settings_hash(input_identity(p), settings, opts, mopts, height.height_m),
        )
        for p, name in named
    ]
    run_inputs(
        tasks, out, workers=workers, scheduler=scheduler, resume=resume, description="obstacles"
    )
    rows = [json.loads(line) for line in (out / "batch.jsonl").read_text().splitlines()]
    frames = [
        {**r["figures"], "output": str(out / r["key"])} for r in rows if r["status"] != "failed"
    ]
    failed = [{"input": r["key"], "reason": r["error"]} for r in rows if r["status"] == "failed"]
    return frames, failed, height


def _given(ctx: typer.Context, name: str) -> bool:
    """Whether option ``name`` was written on the command line (or in the environment)."""
    source = ctx.get_parameter_source(name)
    return source is not None and source.name in ("COMMANDLINE", "ENVIRONMENT", "PROMPT")


def _suffixes() -> tuple[str, ...]:
    from navkit.io.scans import SCAN_SUFFIXES

    return SCAN_SUFFIXES


def _frame_names(files: list[Any]) -> list[tuple[Any, str]]:
    """One output sub-folder per input (a path or a URL), named after its stem (``_2``, ... for
    repeated stems)."""
    from navkit.io.urls import url_name

    used: dict[str, int] = {}
    named = []
    for path in files:
        stem = Path(url_name(path)).stem
        used[stem] = used.get(stem, 0) + 1
        k = used[stem]
        named.append((path, stem if k == 1 else f"{stem}_{k}"))
    return named


def _check_geo(chosen: tuple[str, ...], origin: Any, explicit: bool) -> tuple[str, ...]:
    """GeoJSON only when georeferenced: refuse ``geojson`` without ``--origin``; ``--origin``
    adds it to the default outputs."""
    from navkit.errors import ConfigError
    from navkit.io.maps import GeoOrigin

    if origin is not None:
        GeoOrigin(*origin)  # validates the ranges
        if "geojson" not in chosen and not explicit:
            chosen = (*chosen, "geojson")
    elif "geojson" in chosen:
        raise ConfigError(
            "GeoJSON (RFC 7946) is WGS84 longitude / latitude and this map is in local metres",
            field="--outputs geojson",
            expected="--origin LAT,LON[,HEADING] to georeference it, or the map_server grid "
            "(--outputs grid) and obstacles.json",
        )
    return chosen
