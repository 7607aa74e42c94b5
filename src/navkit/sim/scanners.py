"""Simulated range sensors: a tilting 2D scanner, a spinning lidar, and their range noise."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import ConfigError

__all__ = ["RangeNoise", "SpinningLidar", "TiltingScanner"]


def _grid_deg(lo: float, hi: float, step: float, field: str) -> NDArray[np.float64]:
    """Inclusive angle grid ``lo, lo + step, ..., hi`` (degrees in, radians out)."""
    if not (np.isfinite(step) and step > 0):
        raise ConfigError(
            f"is {step}", field=f"{field}_step_deg", expected="a positive step in degrees"
        )
    if not hi >= lo:
        raise ConfigError(f"max {hi} < min {lo}", field=f"{field}_max_deg", expected="max >= min")
    n = int(np.floor((hi - lo) / step + 1e-9)) + 1
    return np.radians(lo + step * np.arange(n))


@dataclass(frozen=True)
class TiltingScanner:
    """A SICK LMS 200-like 2D scanner swept in elevation (paper 1's sensor).

    Each sweep step is one elevation; each scan line covers the azimuths. Angles in degrees,
    inclusive ranges. ``azimuth`` / ``elevation`` give the grid in radians (azimuth rows,
    elevation columns of the :class:`~navkit.sensors.RangeScan`).
    """

    azimuth_min_deg: float = -90.0
    azimuth_max_deg: float = 90.0
    azimuth_step_deg: float = 1.0
    elevation_min_deg: float = -30.0
    elevation_max_deg: float = 0.0
    elevation_step_deg: float = 1.0

    def __post_init__(self) -> None:
        _ = self.azimuth, self.elevation  # validate now
        if not (-90 <= self.elevation_min_deg and self.elevation_max_deg <= 90):
            raise ConfigError(
                "outside [-90, 90]",
                field="elevation_min_deg/elevation_max_deg",
                expected="elevations in degrees within [-90, 90]",
            )

    @property
    def azimuth(self) -> NDArray[np.float64]:
        """``(n_az,)`` radians."""
        return _grid_deg(
            self.azimuth_min_deg, self.azimuth_max_deg, self.azimuth_step_deg, "azimuth"
        )

    @property
    def elevation(self) -> NDArray[np.float64]:
        """``(n_el,)`` radians."""
        return _grid_deg(
            self.elevation_min_deg, self.elevation_max_deg, self.elevation_step_deg, "elevation"
        )


LIDAR_ELEVATION_MIN_DEG = -24.8
"""Lowest beam of the simulated spinning lidar (Velodyne HDL-64E-like), degrees."""
LIDAR_ELEVATION_MAX_DEG = 2.0
"""Highest beam, degrees."""
LIDAR_HEIGHT = 1.2
"""Mounting height of the lidar on the simulated robot, metres."""
LIDAR_RELATIVE_SIGMA = 0.002
"""Range noise proportional to the range (:class:`RangeNoise`)."""
LIDAR_ABSOLUTE_SIGMA = 0.01
"""Constant range noise, metres."""
LIDAR_MAX_RANGE = 40.0
"""Range beyond which the simulated lidar reports no return, metres."""
LIDAR_DROPOUT = 0.01
"""Probability that a return is missing (:class:`RangeNoise`)."""
# the one home of the simulated lidar's defaults: navkit.mission.settings.LidarSettings (the
# mission's and the demo's lidar) takes these; each use picks only its resolution


@dataclass(frozen=True)
class SpinningLidar:
    """A spinning multi-beam lidar (Velodyne HDL-64E-like by default).

    ``n_columns`` azimuths evenly over a full turn starting at -180 deg (no duplicate at +180);
    ``n_beams`` elevations evenly from ``elevation_min_deg`` to ``elevation_max_deg`` inclusive.
    """

    n_beams: int = 64
    n_columns: int = 2048
    elevation_min_deg: float = LIDAR_ELEVATION_MIN_DEG
    elevation_max_deg: float = LIDAR_ELEVATION_MAX_DEG

    def __post_init__(self) -> None:
        if int(self.n_beams) < 1 or int(self.n_columns) < 1:
            raise ConfigError(
                f"n_beams={self.n_beams}, n_columns={self.n_columns}",
                field="n_beams/n_columns",
                expected="positive counts",
            )
        if not (-90 <= self.elevation_min_deg <= self.elevation_max_deg <= 90):
            raise ConfigError(
                f"[{self.elevation_min_deg}, {self.elevation_max_deg}]",
                field="elevation_min_deg/elevation_max_deg",
                expected="min <= max within [-90, 90] degrees",
            )

    @property
    def azimuth(self) -> NDArray[np.float64]:
        """``(n_columns,)`` radians in ``[-pi, pi)``."""
        return -np.pi + 2.0 * np.pi * np.arange(int(self.n_columns)) / int(self.n_columns)

    @property
    def elevation(self) -> NDArray[np.float64]:
        """``(n_beams,)`` radians, increasing."""
        return np.radians(
            np.linspace(self.elevation_min_deg, self.elevation_max_deg, int(self.n_beams))
        )


@dataclass(frozen=True)
class RangeNoise:
    """Range noise: Gaussian, ``sigma^2 = (relative_sigma r)^2 + absolute_sigma^2 + (quadratic_sigma r^2)^2``.

    The relative part models noise proportional to range (the issue's "noise proportional to
    range"), the absolute part a constant floor, the quadratic part the depth noise of
    structured-light / stereo depth cameras (Kinect v1: about ``0.0019`` m/m^2, Nguyen et al.
    2012); the sources are independent, so their variances add. Each return is dropped (NaN)
    with probability ``dropout``.
    """

    relative_sigma: float = 0.0
    absolute_sigma: float = 0.0
    dropout: float = 0.0
    quadratic_sigma: float = 0.0

    def __post_init__(self) -> None:
        for f in ("relative_sigma", "absolute_sigma", "quadratic_sigma"):
            v = getattr(self, f)
            if not (np.isfinite(v) and v >= 0):
                raise ConfigError(f"is {v}", field=f, expected="a number >= 0")
        if not (0.0 <= self.dropout <= 1.0):
            raise ConfigError(
                f"is {self.dropout}", field="dropout", expected="a probability in [0, 1]"
            )

    def sigma(self, ranges: ArrayLike) -> NDArray[np.float64]:
        """Standard deviation (metres) of the noise at the given ranges."""
        r = np.asarray(ranges, dtype=np.float64)
        return np.sqrt(
            (self.relative_sigma * r) ** 2
            + self.absolute_sigma**2
            + (self.quadratic_sigma * r * r) ** 2
        )

    @property
    def is_zero(self) -> bool:
        return (
            self.relative_sigma == 0
            and self.absolute_sigma == 0
            and self.quadratic_sigma == 0
            and self.dropout == 0
        )

    def apply(self, ranges: ArrayLike, rng: np.random.Generator) -> NDArray[np.float64]:
        """Noisy copy of ``ranges`` (any shape, NaN kept); dropped returns become NaN."""
        r = np.array(ranges, dtype=np.float64, copy=True)
        if self.is_zero:
            return r
        sigma = self.sigma(r)
        noise = rng.standard_normal(r.shape)
        r = r + np.where(np.isfinite(r), sigma * noise, 0.0)
        if self.dropout > 0:
            r[rng.random(r.shape) < self.dropout] = np.nan
        return r
