"""Presets for common range sensors: beam layout, frame convention and typical mounting.

A preset fills in what a user would otherwise look up in a data sheet: the number of beams and
azimuth columns of a spinning lidar (so its cloud's scan grid is recovered without guessing), the
frame its points are in, the intrinsics and depth scale of a depth camera, and the height it is
usually mounted at. The typical height is **not** used as the sensor height: when no height is
given, navkit measures it from the ground (:func:`navkit.obstacles.mounting.estimate_sensor_height`) and
uses ``height_range_m`` to tell whether that measurement is plausible; only when the ground
cannot be found does it fall back to ``typical_height_m``, with a warning.

Figures are from the manufacturers' data sheets (vertical field of view, beams, range) and, for
``hdl64e-kitti``, from the KITTI set-up (Geiger et al., IJRR 2013: Velodyne 1.73 m above the
ground, 10 Hz, about 2083 points per ring per revolution). Depth-camera intrinsics are given only
where a data set fixes them (the TUM RGB-D defaults for a Kinect v1); otherwise pass
``--intrinsics``.
"""

from __future__ import annotations

from dataclasses import dataclass

from navkit.errors import ConfigError

__all__ = ["FRAME_FLU", "FRAME_OPTICAL", "PRESETS", "SensorPreset", "get_preset"]

FRAME_FLU = "x forward, y left, z up (ROS REP 103 body frame)"
FRAME_OPTICAL = "x right, y down, z forward (camera optical frame, REP 103 '_optical')"


@dataclass(frozen=True)
class SensorPreset:
    """One sensor model.

    Attributes
    ----------
    name : str
        The ``--sensor`` value.
    description : str
    kind : {"spinning lidar", "solid-state lidar", "depth camera"}
    frame : str
        The convention of the sensor frame its points are in.
    rings : int or None
        Beams of a spinning lidar (rows of the scan grid); for a non-repetitive lidar the number
        of elevation bins the cloud is gridded into.
    columns : int or None
        Azimuth columns per revolution (None: recovered from the data).
    ring_method : str
        How :func:`~navkit.obstacles.grids.cloud_to_grid` recovers the rings.
    elevation_deg : (lowest, highest)
        Vertical field of view (deg).
    max_range_m : float
        Data-sheet range (m).
    typical_height_m : float
        Usual mounting height above the ground (m): the fallback when it cannot be measured.
    height_range_m : (low, high)
        Heights (m) at which a measured height is plausible for this sensor on a ground robot or
        a car; outside, navkit warns.
    intrinsics : (fx, fy, cx, cy) or None
        Depth cameras: pinhole intrinsics (pixels) of the default stream, when fixed.
    depth_scale : float or None
        Depth cameras: raw units per metre of its 16-bit depth images.
    """

    name: str
    description: str
    kind: str
    frame: str
    rings: int | None
    columns: int | None
    ring_method: str
    elevation_deg: tuple[float, float]
    max_range_m: float
    typical_height_m: float
    height_range_m: tuple[float, float]
    intrinsics: tuple[float, float, float, float] | None = None
    depth_scale: float | None = None


def _lidar(
    name: str,
    description: str,
    rings: int | None,
    columns: int | None,
    elevation_deg: tuple[float, float],
    max_range_m: float,
    typical_height_m: float,
    height_range_m: tuple[float, float],
    *,
    kind: str = "spinning lidar",
    ring_method: str = "auto",
) -> SensorPreset:
    return SensorPreset(
        name,
        description,
        kind,
        FRAME_FLU,
        rings,
        columns,
        ring_method,
        elevation_deg,
        max_range_m,
        typical_height_m,
        height_range_m,
    )


PRESETS: dict[str, SensorPreset] = {
    p.name: p
    for p in (
        _lidar(
            "hdl64e-kitti",
            "Velodyne HDL-64E as mounted on the KITTI car (storage order = rings)",
            64,
            None,
            (-24.9, 2.0),
            120.0,
            1.73,
            (1.5, 2.1),
            ring_method="order",
        ),
        _lidar("vlp16", "Velodyne VLP-16 (Puck)", 16, 1800, (-15.0, 15.0), 100.0, 0.7, (0.1, 2.5)),
        _lidar("os1-64", "Ouster OS1-64", 64, 1024, (-22.5, 22.5), 120.0, 0.7, (0.1, 2.5)),
        _lidar("os1-128", "Ouster OS1-128", 128, 1024, (-22.5, 22.5), 120.0, 0.7, (0.1, 2.5)),
        _lidar(
            "livox-mid360",
            "Livox Mid-360 (non-repetitive pattern, gridded into 40 elevation bins)",
            40,
            None,
            (-7.0, 52.0),
            70.0,
            0.5,
            (0.1, 2.5),
            kind="solid-state lidar",
            ring_method="elevation",
        ),
        SensorPreset(
            "kinect-v1-tum",
            "Microsoft Kinect v1 as in the TUM RGB-D benchmark (default intrinsics, depth x5000)",
            "depth camera",
            FRAME_OPTICAL,
            None,
            None,
            "organized",
            (-21.5, 21.5),
            4.0,
            0.6,
            (0.1, 2.0),
            intrinsics=(525.0, 525.0, 319.5, 239.5),
            depth_scale=5000.0,
        ),
        SensorPreset(
            "realsense-d435",
            "Intel RealSense D435 (depth in mm; intrinsics differ per unit: pass --intrinsics)",
            "depth camera",
            FRAME_OPTICAL,
            None,
            None,
            "organized",
            (-29.0, 29.0),
            10.0,
            0.5,
            (0.1, 2.0),
            depth_scale=1000.0,
        ),
    )
}
"""Every preset by name."""


def get_preset(name: str) -> SensorPreset:
    """The preset called ``name`` (case-insensitive).

    Raises
    ------
    ConfigError
        Naming the known presets.
    """
    key = name.strip().lower()
    if key not in PRESETS:
        raise ConfigError(f"unknown sensor {name!r}", field="--sensor", expected=", ".join(PRESETS))
    return PRESETS[key]
