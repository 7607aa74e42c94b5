"""Settings of the integrated mission: the robot, its sensors and rates, the route, the fusion.

All settings are frozen dataclasses with their defaults here (one place); a run writes the
resolved values to ``settings.toml``. Units are SI (metres, seconds, radians) unless the name
says otherwise (``_deg``, ``_hz``, ``_px``).
"""

from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from navkit.errors import ConfigError, DataNotFoundError, FormatError
from navkit.geometry._validate import check_settings
from navkit.sim.render import (
    CAMERA_HEIGHT,
    CAMERA_HFOV_DEG,
    CAMERA_PITCH_DOWN_DEG,
    DEPTH_MAX,
    DEPTH_RELATIVE_SIGMA,
    STEREO_BASELINE,
    STEREO_PIXEL_NOISE,
)
from navkit.sim.scanners import (
    LIDAR_ABSOLUTE_SIGMA,
    LIDAR_DROPOUT,
    LIDAR_ELEVATION_MAX_DEG,
    LIDAR_ELEVATION_MIN_DEG,
    LIDAR_HEIGHT,
    LIDAR_MAX_RANGE,
    LIDAR_RELATIVE_SIGMA,
)

if TYPE_CHECKING:
    from navkit.localization import LocalizerSettings

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = [
    "BlockSettings",
    "CameraSettings",
    "DemoSettings",
    "FusionSettings",
    "LidarSettings",
    "MissionMapSettings",
    "MissionSettings",
    "RobotSettings",
    "Route",
    "ScannerMount",
    "StereoSettings",
    "VOSettings",
    "builtin_route_path",
    "load_route",
    "read_config",
]


@dataclass(frozen=True)
class RobotSettings:
    """The unicycle robot and its operator-side driver.

    Attributes
    ----------
    width, length : float
        Footprint of the robot, metres ("an obstacle larger than the robot": either horizontal
        extent at least ``width``).
    v_max : float
        Cruise speed, m/s.
    omega_max : float
        Turn-rate limit, rad/s.
    lookahead : float
        Pure-pursuit look-ahead distance of the scripted operator, metres.
    goal_tolerance : float
        The operator's route is done when the robot is this close to the last waypoint, metres.
    dt : float
        Control and visual-odometry period, seconds (paper 4: VO at 10 Hz).
    """

    width: float = 0.5
    length: float = 0.6
    v_max: float = 0.6
    omega_max: float = 0.8
    lookahead: float = 1.0
    goal_tolerance: float = 0.3
    dt: float = 0.1

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class VOSettings:
    """Visual-odometry errors (see :class:`navkit.sensors.VisualOdometryNoise`).

    Defaults: a VO that reads 2 % long with 5 % per-step scale noise and drifts in heading by
    0.6 deg per metre plus 0.3 deg per step - a few percent of the distance travelled, the
    magnitude paper 4 reports for its VO.
    """

    scale_bias: float = 0.02
    scale_sigma: float = 0.05
    heading_bias_deg_per_m: float = 0.6
    heading_sigma_deg: float = 0.3

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class LidarSettings:
    """The spinning 3D lidar (reduced resolution so the demo runs in about a minute; the
    defaults of the simulated sensor are :mod:`navkit.sim.scanners`' ``LIDAR_*``)."""

    rate_hz: float = 2.0
    height: float = LIDAR_HEIGHT
    n_beams: int = 32
    n_columns: int = 512
    elevation_min_deg: float = LIDAR_ELEVATION_MIN_DEG
    elevation_max_deg: float = LIDAR_ELEVATION_MAX_DEG
    max_range: float = LIDAR_MAX_RANGE
    relative_sigma: float = LIDAR_RELATIVE_SIGMA
    absolute_sigma: float = LIDAR_ABSOLUTE_SIGMA
    dropout: float = LIDAR_DROPOUT

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class CameraSettings:
    """The forward RGB-D camera (plane-based motion, paper 2).

    ``max_depth`` is the sensor's range: structured-light and active-stereo RGB-D cameras
    return no depth beyond about 4-10 m (Kinect v2 4.5 m, RealSense D435 about 10 m). Without
    it the simulated camera would see the ground out to the horizon, a "plane" whose gentle
    hills fit only to tens of centimetres. Defaults: :mod:`navkit.sim.render`'s ``CAMERA_*``,
    ``DEPTH_*``.
    """

    rate_hz: float = 1.0
    height: float = CAMERA_HEIGHT
    pitch_down_deg: float = CAMERA_PITCH_DOWN_DEG
    width_px: int = 200
    height_px: int = 150
    hfov_deg: float = CAMERA_HFOV_DEG
    depth_relative_sigma: float = DEPTH_RELATIVE_SIGMA
    max_depth: float = DEPTH_MAX

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class StereoSettings:
    """The level stereo camera that maps the room (paper 3), used at the camera rate in the room.

    A 0.3 m baseline keeps the predicted depth error ``z^2 sigma_d / (b f)`` within the
    floor-plan front end's 0.25 m budget out to about 7 m (the room's size); ``supersample = 1``
    renders one ray per pixel (4x cheaper; the matcher does not need anti-aliasing). The rig
    sits on a pan drive (paper 3: "the camera's heading is known from the camera drive's angle
    sensor") that steps through ``pan_deg`` (degrees from the robot's forward axis), one angle
    per frame, so a few frames survey the whole room.
    """

    height: float = CAMERA_HEIGHT
    width_px: int = 320
    height_px: int = 240
    hfov_deg: float = CAMERA_HFOV_DEG
    baseline: float = STEREO_BASELINE
    pixel_noise: float = STEREO_PIXEL_NOISE
    supersample: int = 1
    pan_deg: tuple[float, ...] = (0.0, 90.0, 180.0, -90.0)

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class FusionSettings:
    """How the plane motions and the room fixes correct the VO (a complementary filter).

    Attributes
    ----------
    weight_xy_geometry, weight_heading_geometry : float
        Weights of a plane-based increment's translation and heading against the VO increment
        over the same interval, when three or more plane directions fixed it geometrically.
    weight_xy_texture, weight_heading_texture : float
        The same when the texture fixed part of it (one or two plane directions).
        The defaults are inverse-variance weights ``w = var_vo / (var_vo + var_plane)`` from the
        increment errors measured per case on the default mission (seed 0, 1 s intervals at
        0.5 m/s): geometry 2.6 mm / 0.06 deg, texture 5 cm / 0.45 deg, VO 1.2 cm / 1.0 deg -
        the texture search is coarser than the VO in translation but much better in heading.
    gate_m, gate_deg : float
        A plane increment further than this from the VO increment is an outlier and dropped.
    fix_weight : float
        Weight of a room-map localization fix against the current estimate.
    fix_gate_m : float
        Fixes further than this from the estimate are not trusted.
    room_sensor : {"stereo", "lidar"}
        What sees the room's walls: the stereo pair (paper 3) or the lidar's rings.
    room_map_views : int
        Views of the room on the first visit that build the room map (fewer if the robot leaves
        the room or the link is lost first); later views are localized against it.
    wall_z_min, wall_z_max : float
        Heights (above the ground under the robot) of the points used as wall points: above
        furniture, below the ceiling.
    room_view_range : float
        Wall points farther than this from the robot are not used, metres.
    fragment_views : int
        Views (this one and the previous ones) that make the fragment localized in the room map.
    map_fix_weight : float
        On the way back, each lidar scan's obstacles (at the camera rate) are located by
        correlation in the obstacle map of the way out - the map the stored path was recorded
        with - and the fix pulls the estimate with this weight (0 = off). This keeps the
        estimate consistent with the path, which is what the return needs.
    map_fix_gate_m : float
        Search window and gate of those fixes, metres.
    map_fix_min_points : int
        Fewest obstacle points a scan needs for such a fix.
    """

    weight_xy_geometry: float = 0.9
    weight_heading_geometry: float = 0.95
    weight_xy_texture: float = 0.1
    weight_heading_texture: float = 0.8
    gate_m: float = 0.25
    gate_deg: float = 8.0
    fix_weight: float = 0.7
    fix_gate_m: float = 0.4
    room_sensor: str = "stereo"
    room_map_views: int = 12
    wall_z_min: float = 1.05
    wall_z_max: float = 2.8
    room_view_range: float = 6.0
    fragment_views: int = 4
    map_fix_weight: float = 0.5
    map_fix_gate_m: float = 0.8
    map_fix_min_points: int = 40

    def __post_init__(self) -> None:
        check_settings(self)

    def room_localizer(self) -> LocalizerSettings | None:
        """:class:`~navkit.localization.LocalizerSettings` of the room fixes: a 5 cm field of
        width 0.1 m (stereo wall points), a +-``fix_gate_m``, +-10 deg window around the
        estimate, blended by ``fix_weight`` within ``fix_gate_m``; a rejected fix leaves the
        estimate. None when ``fix_weight`` is 0 (room fixes off)."""
        from navkit.localization import LocalizerSettings, MatcherSettings

        if self.fix_weight == 0:
            return None
        return LocalizerSettings(
            sigma=0.1,
            resolution=0.05,
            matcher=MatcherSettings(linear_window=self.fix_gate_m, angular_window_deg=10.0),
            fix_weight=self.fix_weight,
            gate_m=self.fix_gate_m,
            recentre_on_rejected=False,
        )

    def map_localizer(self, resolution: float) -> LocalizerSettings | None:
        """:class:`~navkit.localization.LocalizerSettings` of the way back's fixes in the
        outbound obstacle map (cells of ``resolution`` metres, field width 0.15 m, a
        +-``map_fix_gate_m``, +-8 deg window, points every 0.2 m). None when
        ``map_fix_weight`` is 0 (off)."""
        from navkit.localization import LocalizerSettings, MatcherSettings

        if self.map_fix_weight == 0:
            return None
        window = MatcherSettings(
            linear_window=self.map_fix_gate_m, angular_window_deg=8.0, point_spacing=0.2
        )
        return LocalizerSettings(
            sigma=0.15,
            resolution=resolution,
            matcher=window,
            fix_weight=self.map_fix_weight,
            gate_m=self.map_fix_gate_m,
            recentre_on_rejected=False,
        )


@dataclass(frozen=True)
class MissionMapSettings:
    """The global 2D obstacle map fused from every scan (estimate frame).

    Attributes
    ----------
    resolution : float
        Cell size, metres.
    margin : float
        Border around the scene's bounds, metres.
    min_hits : int
        Scans that must have seen an obstacle in a cell for it to count.
    min_ratio : float
        ... and the share of the scans that observed the cell (obstacle or ground) that saw an
        obstacle there.
    match_tolerance : float
        A found obstacle matches a true one when it comes this close to its footprint, metres
        (about the pose error along the route plus one cell).
    max_range : float
        Obstacles found farther than this from the robot are not fused (the far field is sparse
        and most affected by heading error), metres.
    recent_scans : int
        Scans in the short memory that the return's check of the way ahead uses.
    """

    resolution: float = 0.1
    margin: float = 2.0
    min_hits: int = 2
    min_ratio: float = 0.3
    match_tolerance: float = 0.6
    max_range: float = 15.0
    recent_scans: int = 4

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class BlockSettings:
    """The return's check of the obstacle map ahead of the robot.

    Attributes
    ----------
    lookahead : float
        Length of stored path ahead of the robot that is checked, metres.
    clearance : float
        Extra distance to the robot's half-width; the corridor's half-width is
        ``width / 2 + clearance``, metres.
    wait : float
        How long the robot waits stopped before giving up, seconds.
    known_margin : float
        Obstacle cells within this of an obstacle mapped on the way out do not block the return
        (the robot drove past them; seen again with a drifted estimate they may land on the
        path): about the corrected estimate's largest error along the default mission, metres.
    detour : bool
        Go round a blocked stretch (:func:`navkit.path.detour.plan_detour` on the obstacle
        map) instead of stopping; the robot stops only when no detour exists.
    detour_margin : float
        Clearance the detour keeps beyond the corridor half-width ``width / 2 + clearance``
        (cell placement, half a cell diagonal, and the controller's corner cutting), metres.
    detour_search : float
        Length of stored path ahead searched for the rejoin point, metres.
    """

    lookahead: float = 2.0
    clearance: float = 0.05
    wait: float = 3.0
    known_margin: float = 0.6
    detour: bool = True
    detour_margin: float = 0.2
    detour_search: float = 8.0

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class Route:
    """The scripted operator's route and the places the mission needs to know.

    Attributes
    ----------
    waypoints : tuple of (x, y)
        The operator drives the robot through these, metres (world frame).
    room : (xmin, ymin, xmax, ymax) or None
        The indoor room (stereo/laser map on the first visit, localization later).
    block_at : float or None
        If set, an obstacle is dropped on the way back at this arc length along the outbound
        route (metres from the start) when the link is lost: the blocked-return scenario.
    block_size : (x, y, z)
        Extents of the dropped box, metres.
    """

    waypoints: tuple[tuple[float, float], ...]
    room: tuple[float, float, float, float] | None = None
    block_at: float | None = None
    block_size: tuple[float, float, float] = (0.8, 0.8, 1.0)

    def __post_init__(self) -> None:
        try:
            self._check()
        except (TypeError, ValueError) as exc:  # ragged lists, strings where numbers belong
            if isinstance(exc, ConfigError):
                raise
            raise ConfigError(
                f"has a value of the wrong type or shape ({exc})",
                field="route",
                expected="waypoints = [[x, y], ...], room = [xmin, ymin, xmax, ymax], "
                "block_at = metres, block_size = [x, y, z]",
            ) from None

    def _check(self) -> None:
        w = np.asarray(self.waypoints, dtype=np.float64)
        if w.ndim != 2 or w.shape[1] != 2 or len(w) < 1 or not np.all(np.isfinite(w)):
            raise ConfigError(
                f"is {self.waypoints!r}",
                field="route.waypoints",
                expected="a list of at least one finite [x, y] pair (metres)",
            )
        object.__setattr__(self, "waypoints", tuple((float(a), float(b)) for a, b in w))
        if self.room is not None:
            r = tuple(float(v) for v in self.room)
            if len(r) != 4 or not (r[0] < r[2] and r[1] < r[3]):
                raise ConfigError(
                    f"is {self.room!r}",
                    field="route.room",
                    expected="[xmin, ymin, xmax, ymax] with min < max",
                )
            object.__setattr__(self, "room", r)
        if self.block_at is not None and not (math.isfinite(self.block_at) and self.block_at > 0):
            raise ConfigError(
                f"is {self.block_at}", field="route.block_at", expected="a positive arc length"
            )
        bs = tuple(float(v) for v in self.block_size)
        if len(bs) != 3 or min(bs) <= 0:
            raise ConfigError(
                f"is {self.block_size!r}",
                field="route.block_size",
                expected="three positive extents",
            )
        object.__setattr__(self, "block_size", bs)

    def in_room(self, xy: np.ndarray) -> bool:
        """Whether the point ``(2,)`` is inside the room's rectangle."""
        if self.room is None:
            return False
        x0, y0, x1, y1 = self.room
        return bool(x0 <= xy[0] <= x1 and y0 <= xy[1] <= y1)


@dataclass(frozen=True)
class MissionSettings:
    """Everything a mission run used (written to ``settings.toml``).

    Attributes
    ----------
    seed : int
        Seed of every random draw (sensor noise, VO errors).
    max_time : float
        Safety limit of the simulated time of each phase, seconds.
    path_tolerance : float
        Tolerance of the path memory's spline (paper 4's eps), metres.
    return_delta, return_v_max, return_stop_radius : float
        Return controller (paper 4, mode 2): look-ahead along the path, speed, stop radius.
    obstacle_shapes, obstacle_guaranteed_shapes : tuple of str
        Bounding shapes (paper 1, stage 8) of each obstacle a lidar scan shows, and its A7
        shapes over the obstacle with its shadows (:class:`navkit.obstacles.ObstacleSettings`'s
        ``shapes`` / ``guaranteed_shapes``). Decision: by default the ones the mission's
        outputs use - ``results.mcap`` publishes A1, A6 and A7; the obstacle map, the fixes and
        the return use none - because each shape costs CPU on every scan (MVEE the most).
    """

    seed: int = 0
    max_time: float = 240.0
    path_tolerance: float = 0.1
    return_delta: float = 0.8
    return_v_max: float = 0.6
    return_stop_radius: float = 0.25
    obstacle_shapes: tuple[str, ...] = ("A1", "A6")
    obstacle_guaranteed_shapes: tuple[str, ...] = ("A1", "MEC")
    robot: RobotSettings = field(default_factory=RobotSettings)
    vo: VOSettings = field(default_factory=VOSettings)
    lidar: LidarSettings = field(default_factory=LidarSettings)
    camera: CameraSettings = field(default_factory=CameraSettings)
    stereo: StereoSettings = field(default_factory=StereoSettings)
    fusion: FusionSettings = field(default_factory=FusionSettings)
    obstacle_map: MissionMapSettings = field(default_factory=MissionMapSettings)
    block: BlockSettings = field(default_factory=BlockSettings)

    def __post_init__(self) -> None:
        check_settings(self)
        for name, v in (
            ("robot.dt", self.robot.dt),
            ("lidar.rate_hz", self.lidar.rate_hz),
            ("camera.rate_hz", self.camera.rate_hz),
            ("max_time", self.max_time),
        ):
            if not (math.isfinite(v) and v > 0):
                raise ConfigError(f"is {v}", field=name, expected="a positive number")
        for name, rate in (
            ("lidar.rate_hz", self.lidar.rate_hz),
            ("camera.rate_hz", self.camera.rate_hz),
        ):
            k = 1.0 / (rate * self.robot.dt)
            if abs(k - round(k)) > 1e-6 or round(k) < 1:
                raise ConfigError(
                    f"is {rate} with a {self.robot.dt} s control period",
                    field=name,
                    expected="a rate that divides the VO rate (1 / robot.dt)",
                )

    def every(self, rate_hz: float) -> int:
        """Number of control steps between two readings of a sensor at ``rate_hz``."""
        return round(1.0 / (rate_hz * self.robot.dt))

    @classmethod
    def small(cls, seed: int = 0) -> MissionSettings:
        """Reduced sensor resolutions for quick runs (tests)."""
        return cls(
            seed=seed,
            lidar=LidarSettings(n_beams=24, n_columns=480),
            camera=CameraSettings(width_px=160, height_px=120),
        )

    def with_overrides(self, data: dict[str, Any], source: str = "settings") -> MissionSettings:
        """A copy with values from a nested dict (e.g. a ``[settings]`` table of a mission file)."""
        return _replace(self, data, source, "")


def _replace(obj: Any, data: dict[str, Any], source: str, prefix: str) -> Any:
    if not isinstance(data, dict):
        raise ConfigError(
            f"is {data!r}", source=source, field=prefix or "settings", expected="a table"
        )
    names = {f.name: f for f in dataclasses.fields(obj)}
    changes: dict[str, Any] = {}
    for key, value in data.items():
        if key not in names:
            raise ConfigError(
                f"unknown key {key!r}",
                source=source,
                field=f"{prefix}{key}",
                expected=f"one of {sorted(names)}",
            )
        cur = getattr(obj, key)
        if dataclasses.is_dataclass(cur):
            changes[key] = _replace(cur, value, source, f"{prefix}{key}.")
        else:
            try:
                changes[key] = type(cur)(value)
            except (TypeError, ValueError):
                raise ConfigError(
                    f"is {value!r}",
                    source=source,
                    field=f"{prefix}{key}",
                    expected=f"a {type(cur).__name__}",
                ) from None
    return dataclasses.replace(obj, **changes)


def read_config(path: str | Path) -> dict[str, Any]:
    """The ``[mission]`` table of a settings TOML (``--config``; the table a run writes into its
    ``settings.toml``), as overrides for :meth:`MissionSettings.with_overrides`. Other tables
    (``route``, ``scene``, the demo's sensors) are ignored: the route comes from the mission file.
    """
    p = Path(path)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: no such settings file (--config)")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise FormatError(f"not valid TOML ({exc})", source=p, expected="a settings TOML") from None
    table = data.get("mission", {})
    if not isinstance(table, dict):
        raise ConfigError(f"is {table!r}", source=str(p), field="mission", expected="a table")
    return table


def builtin_route_path(scene_name: str) -> Path:
    """The route file shipped for a built-in scene (``navkit/data/mission_<name>.toml``)."""
    return Path(__file__).resolve().parent.parent / "data" / f"mission_{scene_name}.toml"


def load_route(path: str | Path) -> tuple[Route, dict[str, Any]]:
    """Read a mission file: ``[route]`` (waypoints, room, block_at, block_size) and optional
    ``[settings]`` overrides of :class:`MissionSettings`.

    Returns
    -------
    route : Route
    overrides : dict
        The ``[settings]`` table (empty if absent); apply with :meth:`MissionSettings.with_overrides`.
    """
    p = Path(path)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: no such mission file")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError, RecursionError) as exc:
        raise FormatError(
            f"not valid TOML: {str(exc) or type(exc).__name__}",
            source=p,
            expected="a UTF-8 TOML mission file",
        ) from None
    unknown = sorted(set(data) - {"route", "settings"})
    if unknown:
        raise ConfigError(
            f"unknown tables {unknown}",
            source=p,
            field="mission",
            expected="[route] and optionally [settings]",
        )
    r = data.get("route")
    if not isinstance(r, dict) or "waypoints" not in r:
        raise ConfigError(
            "missing [route] with waypoints",
            source=p,
            field="route.waypoints",
            expected="waypoints = [[x, y], ...]",
        )
    bad = sorted(set(r) - {"waypoints", "room", "block_at", "block_size"})
    if bad:
        raise ConfigError(
            f"unknown keys {bad}",
            source=p,
            field="route",
            expected="waypoints, room, block_at, block_size",
        )
    try:
        route = Route(**r)
    except ConfigError as exc:
        raise ConfigError(exc.message, source=p, field=exc.field, expected=exc.expected) from None
    return route, data.get("settings", {}) or {}


# --- the demo's sensor pictures (navkit demo) --------------------------------------------------
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
class DemoSettings:
    """What ``navkit demo`` renders at the start pose besides the mission: one picture per
    simulated sensor (written to ``settings.toml`` with the mission's settings).

    The lidar, the RGB-D camera and the stereo pair are the mission's (:class:`LidarSettings`,
    :class:`CameraSettings`, :class:`StereoSettings`: one set of sensor defaults) at a finer
    resolution; the tilting scanner is the demo's own."""

    scene: str = "yard"
    seed: int = 0
    small: bool = False
    robot_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    lidar: LidarSettings = field(default_factory=lambda: LidarSettings(n_beams=64, n_columns=2048))
    scanner: ScannerMount = field(default_factory=ScannerMount)
    camera: CameraSettings = field(
        default_factory=lambda: CameraSettings(width_px=640, height_px=480)
    )
    stereo: StereoSettings = field(
        default_factory=lambda: StereoSettings(width_px=640, height_px=480)
    )

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
            lidar=LidarSettings(n_beams=16, n_columns=512),
            scanner=ScannerMount(azimuth_step_deg=2.0, elevation_step_deg=2.0),
            camera=CameraSettings(width_px=160, height_px=120),
            stereo=StereoSettings(width_px=160, height_px=120),
        )
