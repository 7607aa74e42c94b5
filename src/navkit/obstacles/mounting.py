"""Sensor mounting: from the sensor frame to paper 1's level body frame (z up, origin on the ground).

Paper 1 assumes the local vertical is known from other instruments (an IMU). The mounting is
given either as the sensor's height and tilt (roll, pitch) or as a gravity vector measured in the
sensor frame; both give ``R_body_sensor`` and ``T_body_sensor``.

When the height is not known, :func:`estimate_sensor_height` measures it from the scan itself:
a robust plane fit to the lowest returns in a ring around the sensor (the ground the robot
stands on). It is never assumed to be 0.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from navkit.errors import ConfigError
from navkit.geometry import se3_from_rt
from navkit.geometry.rotations import quat_to_matrix, rotation_between

log = logging.getLogger(__name__)

__all__ = [
    "HeightEstimate",
    "Mounting",
    "SensorHeight",
    "choose_sensor_height",
    "estimate_sensor_height",
    "level_rotation_from_gravity",
]


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


@dataclass(frozen=True)
class HeightEstimate:
    """The sensor's height above the ground, measured from one scan.

    Attributes
    ----------
    height_m : float
        Distance from the sensor origin to the fitted ground plane (m); NaN when no plane was
        found.
    normal : (3,) tuple
        Unit normal of the ground plane in the level frame (pointing up).
    tilt_deg : float
        Angle between that normal and the level frame's z axis (deg): the mounting's residual
        tilt, or a sloping ground.
    n_inliers : int
        Returns within ``tolerance_m`` of the plane that the final fit used.
    rms_m : float
        RMS distance of those returns to the plane (m).
    plausible : bool
        A plane was found, the height lies in ``plausible_m`` and the tilt is below
        ``max_tilt_deg`` of :func:`estimate_sensor_height`.
    reason : str
        Why the estimate is not plausible (empty when it is).
    """

    height_m: float
    normal: tuple[float, float, float]
    tilt_deg: float
    n_inliers: int
    rms_m: float
    plausible: bool
    reason: str = ""


def _fit_plane(pts: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
    """Least-squares plane ``n . p + d = 0`` (unit ``n`` with ``n_z >= 0``) through ``(N, 3)``."""
    c = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - c, full_matrices=False)
    n = vt[-1]
    if n[2] < 0:
        n = -n
    return n, -float(n @ c)


def estimate_sensor_height(
    points_sensor: NDArray[np.float64],
    R_body_sensor: NDArray[np.float64] | None = None,
    *,
    ring_m: tuple[float, float] = (3.0, 10.0),
    cell_m: float = 1.0,
    tolerance_m: float = 0.08,
    max_tilt_deg: float = 10.0,
    plausible_m: tuple[float, float] = (0.05, 4.0),
    iterations: int = 200,
    rng: np.random.Generator | None = None,
) -> HeightEstimate:
    """Estimate the sensor's height from the ground around it (a robust plane fit).

    Steps: (1) level the returns with ``R_body_sensor``; (2) keep those whose horizontal range
    lies in ``ring_m`` (near enough to be dense, outside the robot's own body); (3) in every
    ``cell_m`` x ``cell_m`` cell keep the lowest return - the ground where it is seen, the foot of
    an obstacle otherwise; (4) RANSAC a plane through those lowest returns, its normal within
    ``max_tilt_deg`` of vertical, inliers within ``tolerance_m``; (5) refit by least squares on
    *all* ring returns within ``tolerance_m`` of that plane (the per-cell minimum alone is biased
    low by the range noise). The height is the sensor origin's distance to the plane.

    Parameters
    ----------
    points_sensor : (N, 3) float array
        Returns in the sensor frame (m); NaN rows are ignored.
    R_body_sensor : (3, 3) array, optional
        Rotation from the sensor frame to the level frame (default: the identity).
    rng : numpy Generator, optional
        For the RANSAC samples (default: seeded, so the estimate is repeatable).

    Returns
    -------
    HeightEstimate
        Never raises on a scan without ground: ``plausible`` is false and ``reason`` says why.
    """
    pts = np.asarray(points_sensor, dtype=np.float64).reshape(-1, np.shape(points_sensor)[-1])
    pts = pts[:, :3]
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if R_body_sensor is not None:
        pts = pts @ np.asarray(R_body_sensor, dtype=np.float64).T
    r = np.hypot(pts[:, 0], pts[:, 1])
    ring = pts[(r >= ring_m[0]) & (r <= ring_m[1])]
    nan = HeightEstimate(float("nan"), (0.0, 0.0, 1.0), float("nan"), 0, float("nan"), False)

    def failed(reason: str) -> HeightEstimate:
        log.warning("sensor height: no ground plane found (%s)", reason)
        return HeightEstimate(**{**nan.__dict__, "reason": reason})

    if len(ring) < 50:
        return failed(f"{len(ring)} returns between {ring_m[0]} and {ring_m[1]} m")
    # (3) the lowest return of every occupied cell
    ij = np.floor(ring[:, :2] / cell_m).astype(np.int64)
    key = (ij[:, 0] - ij[:, 0].min()) * (ij[:, 1].max() - ij[:, 1].min() + 1) + (
        ij[:, 1] - ij[:, 1].min()
    )
    order = np.lexsort((ring[:, 2], key))
    first = np.ones(len(order), dtype=bool)
    first[1:] = key[order][1:] != key[order][:-1]
    low = ring[order[first]]
    if len(low) < 10:
        return failed(f"only {len(low)} cells with returns")
    # (4) RANSAC over the lowest returns, planes near horizontal only
    rng = np.random.default_rng(0) if rng is None else rng
    cos_max = math.cos(math.radians(max_tilt_deg))
    best_n, best_d, best_count = np.array([0.0, 0.0, 1.0]), 0.0, -1
    for _ in range(iterations):
        a, b, c = low[rng.choice(len(low), 3, replace=False)]
        n = np.cross(b - a, c - a)
        norm = np.linalg.norm(n)
        if norm < 1e-9:
            continue
        n = n / norm
        if n[2] < 0:
            n = -n
        if n[2] < cos_max:
            continue
        d = -float(n @ a)
        count = int(np.count_nonzero(np.abs(low @ n + d) < tolerance_m))
        if count > best_count:
            best_n, best_d, best_count = n, d, count
    if best_count < 3:
        return failed(f"no plane within {max_tilt_deg} deg of level through the lowest returns")
    # (5) least-squares refit on every ring return near the plane (twice, tightening)
    n, d = best_n, best_d
    inl = ring
    for _ in range(2):
        inl = ring[np.abs(ring @ n + d) < tolerance_m]
        if len(inl) < 3:
            return failed("too few returns near the ground plane")
        n, d = _fit_plane(inl)
    dist = inl @ n + d
    height = abs(d)  # distance of the origin (the sensor) to the plane
    tilt = math.degrees(math.acos(min(1.0, float(n[2]))))
    reasons = []
    if not plausible_m[0] <= height <= plausible_m[1]:
        reasons.append(f"height {height:.2f} m outside {plausible_m[0]}..{plausible_m[1]} m")
    if tilt > max_tilt_deg:
        reasons.append(f"ground tilted {tilt:.1f} deg")
    if d < 0:
        reasons.append("the sensor is below the fitted plane")
    est = HeightEstimate(
        height_m=float(height),
        normal=(float(n[0]), float(n[1]), float(n[2])),
        tilt_deg=tilt,
        n_inliers=len(inl),
        rms_m=float(np.sqrt(np.mean(dist**2))),
        plausible=not reasons,
        reason="; ".join(reasons),
    )
    if reasons:
        log.warning("sensor height estimate %.2f m is implausible: %s", height, est.reason)
    return est


@dataclass(frozen=True)
class SensorHeight:
    """The sensor height a run uses, and where it came from.

    Attributes
    ----------
    height_m : float
    source : str
        ``"given"`` (an option or the input file), ``"estimated from the ground"``, or
        ``"sensor preset's typical height (no ground found)"``.
    estimate : HeightEstimate or None
        The measurement from the ground, when one was made.
    warning : str
        Why the height is doubtful (empty when it is not).
    """

    height_m: float
    source: str
    estimate: HeightEstimate | None = None
    warning: str = ""

    def to_dict(self) -> dict[str, object]:
        """Plain-JSON form (``summary.json``'s ``sensor_height``)."""
        out: dict[str, object] = {"m": self.height_m, "source": self.source}
        if self.estimate is not None:
            e = self.estimate
            out["estimate"] = {
                "height_m": e.height_m,
                "tilt_deg": e.tilt_deg,
                "n_inliers": e.n_inliers,
                "rms_m": e.rms_m,
                "plausible": e.plausible,
                "reason": e.reason,
            }
        if self.warning:
            out["warning"] = self.warning
        return out


def choose_sensor_height(
    points_sensor: NDArray[np.float64] | None,
    R_body_sensor: NDArray[np.float64] | None = None,
    *,
    given_m: float | None = None,
    typical_m: float | None = None,
    plausible_m: tuple[float, float] = (0.05, 4.0),
    source: str = "scan",
) -> SensorHeight:
    """The height to use: the given one, else measured from the ground, never a silent 0.

    Order: ``given_m`` (an option or the file's) as is; else :func:`estimate_sensor_height` on
    ``points_sensor``, used when a ground plane was found (with a warning when it lies outside
    ``plausible_m`` - the sensor preset's range - or the ground is tilted); else the preset's
    ``typical_m`` with a warning.

    Raises
    ------
    ConfigError
        No height given, no ground found and no typical height to fall back on; names
        ``source`` and asks for ``--sensor-height`` or ``--sensor``.
    """
    if given_m is not None:
        return SensorHeight(float(given_m), "given")
    if points_sensor is None:
        est = None
    else:
        est = estimate_sensor_height(points_sensor, R_body_sensor, plausible_m=plausible_m)
    if est is not None and math.isfinite(est.height_m):
        warning = "" if est.plausible else f"estimated height is implausible: {est.reason}"
        return SensorHeight(est.height_m, "estimated from the ground", est, warning)
    if typical_m is not None:
        reason = est.reason if est is not None else "no points"
        warning = f"no ground plane found ({reason}); using the preset's typical {typical_m} m"
        log.warning("%s", warning)
        return SensorHeight(
            float(typical_m), "sensor preset's typical height (no ground found)", est, warning
        )
    raise ConfigError(
        "the sensor height is not given and no ground plane was found to measure it"
        + (f" ({est.reason})" if est is not None else ""),
        source=source,
        field="--sensor-height",
        expected="--sensor-height METRES or a --sensor preset",
    )
