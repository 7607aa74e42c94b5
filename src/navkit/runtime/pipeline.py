"""Which topic goes to which capability, and every setting of a run (``--config PIPELINE.toml``).

The TOML has one table per part, the same tables the resolved ``settings.toml`` holds::

    [topics]            # explicit topic choice (default: by message kind, see resolve_pipeline)
    clouds = ["/velodyne_points"]
    scans = ["/scan"]
    pose = "/ground_truth"      # the sensor's pose in the world: obstacle map, wall map, path
    odometry = "/odom"          # prior of localization
    reference = "/ground_truth" # scoring only (errors in summary.json), never used to estimate
    [obstacles]  sensor_height_m, roll_deg, pitch_deg, rings, columns, ring_method, map_*
    [obstacles.detector]        # keys of navkit.obstacles.ObstacleSettings
    [laser]      max_range_m, map_resolution_m, keyframe_*, sigma_m, prior, success_*
    [planes]     cell, nu, max_time_offset_s, max_keyframes, max_history, max_map_planes,
                 textures
    [path]       tolerance_m, publish_every
    [run]        capabilities, checkpoint_every, write_frames

Decisions (also in ``docs/runtime.md``):

- Without ``[topics]``, every ``cloud`` topic goes to obstacle detection and every ``scan`` topic
  to the laser stage; the first depth / colour / camera-info topics to plane odometry. Among the
  pose topics, one whose name says ground truth (``truth``, ``gt``, ``ground``, ``corrected``,
  ``reference``) is the *reference* and the *pose*; one whose name says ``odom`` is the
  *odometry*; a single pose topic is both pose and odometry.
- A pose topic gives ``T_world_<child frame>``; the recording's TF tree (``/tf``, ``/tf_static``,
  :mod:`navkit.runtime.tf`) carries it to the frame of each cloud or scan; without a connecting
  TF (or a child frame) the pose topic is taken as the sensor's pose.
- ``LaserScan`` with ``--map`` is localized; without, with a pose topic, it builds a wall map.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass, field
from typing import Any

from navkit.errors import ConfigError

__all__ = [
    "CAPABILITIES",
    "LaserConfig",
    "ObstaclesConfig",
    "PathConfig",
    "Pipeline",
    "PlanesConfig",
    "RunConfig",
    "TopicsConfig",
    "resolve_pipeline",
]

CAPABILITIES = ("obstacles", "obstacle_map", "wall_map", "localization", "planes", "path")

_REFERENCE = re.compile(r"truth|(^|[/_])gt($|[/_])|ground|corrected|reference", re.IGNORECASE)
_ODOM = re.compile(r"odom", re.IGNORECASE)


@dataclass(frozen=True)
class TopicsConfig:
    """Topic of each role (empty = none)."""

    clouds: tuple[str, ...] = ()
    scans: tuple[str, ...] = ()
    depth: str = ""
    color: str = ""
    camera_info: str = ""
    pose: str = ""
    odometry: str = ""
    reference: str = ""


@dataclass(frozen=True)
class ObstaclesConfig:
    """Obstacle detection on point clouds and the 2D obstacle map fused with the poses.

    ``sensor_height_m`` etc. are the mounting (as ``navkit obstacles detect``; no height given:
    measured once on the first cloud's ground, never a silent 0); the map is a
    fixed window of ``2 map_half_extent_m`` around the first pose (memory does not grow with the
    drive); a cell is an obstacle when ``map_min_hits`` scans saw one there and at least
    ``map_min_ratio`` of the scans that saw the cell. Obstacles farther than ``map_max_range_m``
    from the sensor are not fused. The grid is published every ``map_every`` clouds.
    ``shapes``: the bounding shapes published per obstacle on ``/navkit/obstacles/shapes``
    (names among A1-A6, MEC, MVEE; ``"A7"``: the guaranteed outlines). Decision: A1 and A6 by
    default, as the mission publishes them: all of them are ten outlines per obstacle (~650 a
    KITTI frame), whose outlines alone cost a third of the detector; every shape is in
    ``obstacles.json``.
    """

    sensor_height_m: float | None = None
    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    rings: int | None = None
    columns: int | None = None
    ring_method: str = "auto"
    detector: dict[str, Any] = field(default_factory=dict)
    map_resolution_m: float = 0.2
    map_half_extent_m: float = 100.0
    map_min_hits: int = 2
    map_min_ratio: float = 0.3
    map_max_range_m: float = 30.0
    map_every: int = 10
    shapes: tuple[str, ...] = ("A1", "A6")


@dataclass(frozen=True)
class LaserConfig:
    """Planar laser: wall map building (with poses) or localization (with ``--map``).

    Mapping keeps *keyframes*: a scan whose pose moved ``keyframe_distance_m`` or turned
    ``keyframe_angle_deg`` since the last keyframe (0 and 0: every scan). At most
    ``max_keyframes`` are kept: when full, every second one is dropped and the thresholds
    double, so memory is bounded; the map is built from them at the end (``build_map_from_scans``,
    as ``navkit map build``). Localization matches each scan like ``navkit map locate``
    (``prior = "odometry"``: the last fix moved by the odometry increment; ``"none"``: global).
    """

    max_range_m: float = 30.0
    map_resolution_m: float = 0.05
    keyframe_distance_m: float = 0.0
    keyframe_angle_deg: float = 0.0
    max_keyframes: int = 20000
    sigma_m: float = 0.1
    prior: str = "odometry"
    success_m: float = 0.3
    success_deg: float = 5.0


@dataclass(frozen=True)
class PlanesConfig:
    """Plane odometry on depth (+ colour) frames: extraction patch ``cell`` (px), texture pixel
    ``nu`` (m); colour and depth are paired when their stamps differ by at most
    ``max_time_offset_s`` (a depth frame without colour is used alone).

    Memory bounds (``navkit.planes.OdometrySettings``; a run of any length stays flat):
    ``max_keyframes`` dense keyframes kept for revisits (an image pyramid each, ~4 MB at
    640 x 480), ``max_history`` poses / results / per-plane observation numbers kept by the
    odometry object (the trajectory is streamed to ``planes/trajectory.tum`` instead), and
    ``max_map_planes`` planes in the merged map (beyond, the least recently observed is dropped).
    ``textures``: each frame's planes as meshes textured with their colour pixels for the viewer
    (``--rerun``; not in ``results.mcap``).
    """

    cell: int = 20
    nu: float = 0.01
    max_time_offset_s: float = 0.02
    max_keyframes: int = 20
    max_history: int = 100
    max_map_planes: int = 40
    textures: bool = True


@dataclass(frozen=True)
class PathConfig:
    """Path memory of the pose topic: tolerance (m); the path is published every N accepted poses."""

    tolerance_m: float = 0.05
    publish_every: int = 50


@dataclass(frozen=True)
class RunConfig:
    """``capabilities``: which to run (default all that the topics allow); a checkpoint every
    ``checkpoint_every`` source items; ``write_frames``: per-frame files of today's commands
    (obstacles ``labels.npy`` + ``obstacles.json``); ``max_items``: stop after this many source
    items (0 = all); ``max_pending``: messages waiting for a pose before they are processed with
    the latest pose."""

    capabilities: tuple[str, ...] = ()
    max_items: int = 0
    checkpoint_every: int = 50
    write_frames: bool = True
    max_pending: int = 200


@dataclass(frozen=True)
class Pipeline:
    """The resolved pipeline of a run (written to ``settings.toml``)."""

    recording: str
    capabilities: tuple[str, ...]
    topics: TopicsConfig
    obstacles: ObstaclesConfig = field(default_factory=ObstaclesConfig)
    laser: LaserConfig = field(default_factory=LaserConfig)
    planes: PlanesConfig = field(default_factory=PlanesConfig)
    path: PathConfig = field(default_factory=PathConfig)
    run: RunConfig = field(default_factory=RunConfig)
    map: str = ""


def _from_table(cls: Any, table: Any, source: str, section: str) -> Any:
    if not isinstance(table, dict):
        raise ConfigError(
            f"[{section}] is {type(table).__name__}",
            source=source,
            field=section,
            expected="a table",
        )
    names = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(table) - set(names))
    if unknown:
        raise ConfigError(
            f"unknown keys {unknown}",
            source=source,
            field=section,
            expected=f"keys among {sorted(names)}",
        )
    values: dict[str, Any] = {}
    defaults = cls()
    for key, val in table.items():
        default = getattr(defaults, key)
        if isinstance(default, tuple):
            if isinstance(val, str):
                val = (val,)
            if not isinstance(val, list | tuple) or not all(isinstance(v, str) for v in val):
                raise ConfigError(
                    f"= {val!r}",
                    source=source,
                    field=f"{section}.{key}",
                    expected="a list of strings",
                )
            val = tuple(val)
        elif isinstance(default, bool):
            if not isinstance(val, bool):
                raise ConfigError(
                    f"= {val!r}", source=source, field=f"{section}.{key}", expected="true or false"
                )
        elif isinstance(default, float) or (default is None and key == "sensor_height_m"):
            if isinstance(val, bool) or not isinstance(val, int | float):
                raise ConfigError(
                    f"= {val!r}", source=source, field=f"{section}.{key}", expected="a number"
                )
            val = float(val)
        elif isinstance(default, int) or (default is None and key in ("rings", "columns")):
            if isinstance(val, bool) or not isinstance(val, int):
                raise ConfigError(
                    f"= {val!r}", source=source, field=f"{section}.{key}", expected="an integer"
                )
        elif isinstance(default, str):
            if not isinstance(val, str):
                raise ConfigError(
                    f"= {val!r}", source=source, field=f"{section}.{key}", expected="a string"
                )
        elif isinstance(default, dict) and not isinstance(val, dict):
            raise ConfigError(
                f"= {val!r}", source=source, field=f"{section}.{key}", expected="a table"
            )
        values[key] = val
    return cls(**values)


def _auto_topics(topics: dict[str, str]) -> TopicsConfig:
    by_kind: dict[str, list[str]] = {}
    for t, kind in sorted(topics.items()):
        by_kind.setdefault(kind, []).append(t)
    poses = by_kind.get("pose", [])
    reference = next((t for t in poses if _REFERENCE.search(t)), "")
    odometry = next((t for t in poses if _ODOM.search(t) and t != reference), "")
    if len(poses) == 1:
        odometry = odometry or poses[0]
    pose = reference or odometry or (poses[0] if poses else "")
    return TopicsConfig(
        clouds=tuple(by_kind.get("cloud", [])),
        scans=tuple(by_kind.get("scan", [])),
        depth=(by_kind.get("depth") or [""])[0],
        color=(by_kind.get("color") or [""])[0],
        camera_info=(by_kind.get("camera_info") or [""])[0],
        pose=pose,
        odometry=odometry,
        reference=reference,
    )


def resolve_pipeline(
    recording: str,
    topics: dict[str, str],
    config: dict[str, Any] | None = None,
    *,
    config_source: str = "--config",
    map_path: str = "",
) -> Pipeline:
    """The pipeline for a recording's ``{topic: kind}`` and a ``--config`` table.

    Raises
    ------
    ConfigError
        Unknown tables or keys, values of the wrong type, a topic the recording does not have
        or of the wrong kind, a capability that is unknown or has no input.
    """
    cfg = dict(config or {})
    parts = {
        "topics": TopicsConfig,
        "obstacles": ObstaclesConfig,
        "laser": LaserConfig,
        "planes": PlanesConfig,
        "path": PathConfig,
        "run": RunConfig,
    }
    unknown = sorted(set(cfg) - set(parts) - {"recording", "capabilities", "map"})
    if unknown:
        raise ConfigError(
            f"unknown tables {unknown}",
            source=config_source,
            expected=f"tables among {sorted(parts)}",
        )
    built = {
        name: _from_table(cls, cfg.get(name, {}), config_source, name)
        for name, cls in parts.items()
    }
    auto = _auto_topics(topics)
    given = cfg.get("topics", {})
    chosen = dataclasses.replace(auto, **{k: getattr(built["topics"], k) for k in given})
    want = {
        "clouds": "cloud",
        "scans": "scan",
        "depth": "depth",
        "color": "color",
        "camera_info": "camera_info",
        "pose": "pose",
        "odometry": "pose",
        "reference": "pose",
    }
    for role, kind in want.items():
        value = getattr(chosen, role)
        for t in value if isinstance(value, tuple) else ((value,) if value else ()):
            if topics.get(t) != kind:
                have = ", ".join(f"{k} ({v})" for k, v in sorted(topics.items()))
                raise ConfigError(
                    f"topic {t!r} is {topics.get(t, 'not in the recording')}",
                    source=config_source,
                    field=f"topics.{role}",
                    expected=f"a {kind} topic of the recording: {have}",
                )
    if map_path and not chosen.scans:
        have = ", ".join(f"{k} ({v})" for k, v in sorted(topics.items())) or "no topics"
        raise ConfigError(
            f"the recording has no laser scans to localize in {map_path} (topics: {have})",
            source=recording,
            field="--map",
            expected="a recording with a LaserScan topic, or no --map",
        )
    possible = []
    if chosen.clouds:
        possible.append("obstacles")
        if chosen.pose:
            possible.append("obstacle_map")
    if chosen.scans and map_path:
        possible.append("localization")
    elif chosen.scans and chosen.pose:
        possible.append("wall_map")
    if chosen.depth and chosen.camera_info:
        possible.append("planes")
    if chosen.pose:
        possible.append("path")
    caps = built["run"].capabilities or tuple(possible)
    for c in caps:
        if c not in CAPABILITIES:
            raise ConfigError(
                f"unknown capability {c!r}",
                source=config_source,
                field="run.capabilities",
                expected=f"names among {CAPABILITIES}",
            )
        if c not in possible:
            raise ConfigError(
                f"capability {c!r} has no input in this recording",
                source=config_source,
                field="run.capabilities",
                expected=f"one of {possible} (topics: {sorted(topics)})",
            )
    if not caps:
        raise ConfigError(
            "no capability can run on this recording",
            source=recording,
            field="topics",
            expected="PointCloud2, LaserScan (+ poses or --map), depth Image + CameraInfo, or poses",
        )
    return Pipeline(
        recording=recording,
        capabilities=tuple(caps),
        topics=chosen,
        obstacles=built["obstacles"],
        laser=built["laser"],
        planes=built["planes"],
        path=built["path"],
        run=built["run"],
        map=map_path,
    )
