"""A range scan organised on an azimuth x elevation grid (paper 1, stage 1).

The grid is what a tilting 2D scanner (SICK LMS 200 swept in elevation), a spinning 3D lidar
(beams x columns) or a depth camera produce: one range per (azimuth, elevation) pair, NaN where
there was no return.

Frames: the *sensor* frame is x forward, y left, z up with azimuth alpha counter-clockwise from +x
seen from +z and elevation beta up from the horizontal (beta < 0 below the horizon). The *body*
frame is the level frame with z up and its origin on the ground under the sensor (paper 1's
frame), reached from the sensor frame by ``T_body_sensor`` (mounting tilt, and the height
``sensor_height`` on z).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError
from navkit.geometry import se3_from_rt
from navkit.geometry.linalg import rows_matmul

__all__ = ["RangeScan", "grid_directions"]


def grid_directions(azimuth: ArrayLike, elevation: ArrayLike) -> NDArray[np.float64]:
    """Unit ray directions ``(n_az, n_el, 3)`` in the sensor frame (paper 1, stage 1).

    ``(cos b cos a, cos b sin a, sin b)`` for azimuth ``a`` and elevation ``b`` in radians.
    """
    a = np.asarray(azimuth, dtype=np.float64)[:, None]
    b = np.asarray(elevation, dtype=np.float64)[None, :]
    cb = np.cos(b)
    return np.stack(np.broadcast_arrays(cb * np.cos(a), cb * np.sin(a), np.sin(b)), axis=-1)


@dataclass(frozen=True)
class RangeScan:
    """Ranges on an azimuth x elevation grid.

    Attributes
    ----------
    ranges : (n_azimuth, n_elevation) float64 array
        Distances along the rays, metres; NaN = no return.
    azimuth : (n_azimuth,) float64 array
        Azimuth of each row, radians, counter-clockwise from the sensor's +x.
    elevation : (n_elevation,) float64 array
        Elevation of each column, radians, positive up.
    sensor_height : float
        Height of the sensor's origin above the ground under it, metres (``z_D`` of paper 1).
    R_body_sensor : (3, 3) float64 array
        Mounting orientation of the sensor in the level body frame (identity = level mount).
    max_range : float
        Returns at or beyond this distance are treated as missing (``inf`` = no limit).
    timestamp : float
        Seconds (any epoch), NaN if unknown.
    """

    ranges: NDArray[np.float64]
    azimuth: NDArray[np.float64]
    elevation: NDArray[np.float64]
    sensor_height: float = 0.0
    R_body_sensor: NDArray[np.float64] = field(default_factory=lambda: np.eye(3))
    max_range: float = float("inf")
    timestamp: float = float("nan")

    def __post_init__(self) -> None:
        def arr(name: str, value: object, ndim: int) -> NDArray[np.float64]:
            try:
                a = np.asarray(value, dtype=np.float64)
            except (TypeError, ValueError) as exc:
                raise InputError(
                    f"is not numeric: {exc}", field=name, expected="float array"
                ) from exc
            if a.ndim != ndim:
                raise InputError(
                    f"has {a.ndim} dimensions (shape {a.shape})",
                    field=name,
                    expected=f"a {ndim}-D array",
                )
            return a

        ranges = arr("ranges", self.ranges, 2)
        az = arr("azimuth", self.azimuth, 1)
        el = arr("elevation", self.elevation, 1)
        if ranges.shape != (az.size, el.size):
            raise InputError(
                f"has shape {ranges.shape}",
                field="ranges",
                expected=f"shape (n_azimuth, n_elevation) = ({az.size}, {el.size})",
            )
        if ranges.size == 0:
            raise InputError("is empty", field="ranges", expected="at least one range")
        if not (np.all(np.isfinite(az)) and np.all(np.isfinite(el))):
            raise InputError(
                "contains NaN or inf", field="azimuth/elevation", expected="finite angles"
            )
        if np.any(np.abs(el) > np.pi / 2 + 1e-9):
            raise InputError("outside [-pi/2, pi/2]", field="elevation", expected="radians")
        R = arr("R_body_sensor", self.R_body_sensor, 2)
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6):
            raise InputError(
                "is not a rotation matrix", field="R_body_sensor", expected="(3, 3) orthonormal"
            )
        if not np.isfinite(self.sensor_height):
            raise InputError("is not finite", field="sensor_height", expected="metres")
        ranges = ranges.copy()
        ranges[(ranges <= 0) | (ranges >= self.max_range) | ~np.isfinite(ranges)] = np.nan
        object.__setattr__(self, "ranges", ranges)
        object.__setattr__(self, "azimuth", az)
        object.__setattr__(self, "elevation", el)
        object.__setattr__(self, "R_body_sensor", R)
        object.__setattr__(self, "sensor_height", float(self.sensor_height))

    @property
    def shape(self) -> tuple[int, int]:
        """``(n_azimuth, n_elevation)``."""
        return self.ranges.shape  # type: ignore[return-value]

    @property
    def valid(self) -> NDArray[np.bool_]:
        """``(n_az, n_el)`` mask of cells with a return (paper 1's validity code C_d)."""
        return np.isfinite(self.ranges)

    @property
    def T_body_sensor(self) -> NDArray[np.float64]:
        """``(4, 4)`` transform from the sensor frame to the level body frame."""
        return se3_from_rt(self.R_body_sensor, np.array([0.0, 0.0, self.sensor_height]))

    def directions(self, frame: str = "body") -> NDArray[np.float64]:
        """Unit ray directions ``(n_az, n_el, 3)`` in the ``"sensor"`` or ``"body"`` frame."""
        d = grid_directions(self.azimuth, self.elevation)
        if frame == "sensor":
            return d
        if frame == "body":
            return rows_matmul(d, self.R_body_sensor.T)
        raise InputError(f"unknown frame {frame!r}", field="frame", expected="'sensor' or 'body'")

    def points(self, frame: str = "body") -> NDArray[np.float64]:
        """3D points ``(n_az, n_el, 3)``, NaN where there is no return (paper 1, stage 1).

        In the body frame: ``x = d cos b cos a, y = d cos b sin a, z = z_D + d sin b`` for a level
        mount; a tilted mount rotates the rays first.
        """
        p = self.ranges[..., None] * self.directions(frame)
        if frame == "body":
            p[..., 2] += self.sensor_height
        return p
