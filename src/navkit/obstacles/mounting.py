"""Sensor mounting: from the sensor frame to paper 1's level body frame (z up, origin on the ground).

Paper 1 assumes the local vertical is known from other instruments (an IMU). The mounting is
given either as the sensor's height and tilt (roll, pitch) or as a gravity vector measured in the
sensor frame; both give ``R_body_sensor`` and ``T_body_sensor``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from navkit.errors import ConfigError
from navkit.geometry import quat_to_matrix, rotation_between, se3_from_rt

__all__ = ["Mounting", "level_rotation_from_gravity"]


def level_rotation_from_gravity(
    gravity_sensor: NDArray[np.float64] | tuple[float, float, float],
) -> NDArray[np.float64]:
    """``R_body_sensor (3, 3)`` that turns the measured gravity direction onto the body's -z.

    Parameters
    ----------
    gravity_sensor : (3,) array
        Gravity (pointing *down*, any length, e.g. ``(0, 0, -9.81)`` for a level sensor) in the
        sensor frame. The shortest-arc rotation is used, so the body keeps the sensor's heading.
    """
    g = np.asarray(gravity_sensor, dtype=np.float64).reshape(-1)
    if g.shape != (3,) or not np.all(np.isfinite(g)) or np.linalg.norm(g) < 1e-9:
        raise ConfigError(
            f"= {gravity_sensor!r}",
            field="gravity",
            expected="a finite non-zero (3,) vector pointing down",
        )
    return quat_to_matrix(rotation_between(g, np.array([0.0, 0.0, -1.0])))


@dataclass(frozen=True)
class Mounting:
    """Where the range sensor sits on the robot.

    Attributes
    ----------
    height_m : float
        Height of the sensor origin above the ground under it (``z_D`` of paper 1), metres.
    roll_deg, pitch_deg : float
        Tilt of the sensor in the level frame (deg): ``R_body_sensor = R_x(roll) R_y(pitch)``;
        a positive pitch turns the sensor's x axis (forward) down.
    gravity : (3,) tuple or None
        Gravity measured in the sensor frame (pointing down); when given it overrides roll and
        pitch (:func:`level_rotation_from_gravity`).
    rotation : (3, 3) nested tuple or None
        An explicit ``R_body_sensor``; overrides everything else.
    """

    height_m: float = 0.0
    roll_deg: float = 0.0
    pitch_deg: float = 0.0
    gravity: tuple[float, float, float] | None = None
    rotation: tuple[tuple[float, float, float], ...] | None = None

    def __post_init__(self) -> None:
        if not math.isfinite(self.height_m):
            raise ConfigError(f"= {self.height_m!r}", field="height_m", expected="finite metres")
        for name in ("roll_deg", "pitch_deg"):
            if not math.isfinite(getattr(self, name)):
                raise ConfigError(
                    f"= {getattr(self, name)!r}", field=name, expected="finite degrees"
                )
        if self.gravity is not None:
            object.__setattr__(
                self, "gravity", tuple(float(v) for v in np.asarray(self.gravity).reshape(-1))
            )
            level_rotation_from_gravity(self.gravity)  # validates
        if self.rotation is not None:
            R = np.asarray(self.rotation, dtype=np.float64)
            if (
                R.shape != (3, 3)
                or not np.allclose(R @ R.T, np.eye(3), atol=1e-6)
                or np.linalg.det(R) < 0
            ):
                raise ConfigError(
                    "is not a rotation matrix",
                    field="rotation",
                    expected="(3, 3) orthonormal, det +1",
                )
            object.__setattr__(self, "rotation", tuple(tuple(float(v) for v in row) for row in R))

    @property
    def R_body_sensor(self) -> NDArray[np.float64]:
        """``(3, 3)`` rotation from the sensor frame to the level body frame."""
        if self.rotation is not None:
            return np.asarray(self.rotation, dtype=np.float64)
        if self.gravity is not None:
            return level_rotation_from_gravity(self.gravity)
        r, p = math.radians(self.roll_deg), math.radians(self.pitch_deg)
        Rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
        Ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
        return Rx @ Ry

    @property
    def T_body_sensor(self) -> NDArray[np.float64]:
        """``(4, 4)`` transform from the sensor frame to the body frame."""
        return se3_from_rt(self.R_body_sensor, np.array([0.0, 0.0, self.height_m]))

    def to_body(self, points_sensor: NDArray[np.float64]) -> NDArray[np.float64]:
        """Points ``(..., 3)`` from the sensor frame to the body frame (NaN stays NaN)."""
        out = points_sensor @ self.R_body_sensor.T
        out[..., 2] += self.height_m
        return out
