"""Visual-odometry error model (paper 4: VO at about 10 Hz with scale and heading errors).

The model corrupts the *increments* of a true planar trajectory, in the body frame of each step:
the travelled distance is scaled by ``1 + scale_bias + N(0, scale_sigma)`` and the heading change
gets ``heading_bias_per_m * distance + N(0, heading_sigma)`` added, then the corrupted increments
are re-integrated. This reproduces how VO drifts: errors grow with distance, and a heading error
bends the rest of the path.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError
from navkit.geometry import se2_compose, se2_from_xytheta, se2_inverse, se2_to_xytheta

__all__ = ["MAX_VO_RATE_HZ", "VisualOdometryNoise"]

#: Highest VO rate accepted: a camera-based VO runs at tens of Hz; 1 kHz leaves a wide margin
#: while keeping a simulated return's step count bounded (``path return --vo-rate-hz 1e9``).
MAX_VO_RATE_HZ = 1000.0


@dataclass(frozen=True)
class VisualOdometryNoise:
    """Per-step VO errors for a planar robot.

    Attributes
    ----------
    rate_hz : float
        VO output rate (paper 4: 10 Hz).
    scale_bias : float
        Relative scale error common to the run (0.02 = 2 % long).
    scale_sigma : float
        Relative per-step scale noise (standard deviation).
    heading_bias_per_m : float
        Systematic heading drift, radians per metre travelled.
    heading_sigma : float
        Per-step heading noise, radians (standard deviation).
    """

    rate_hz: float = 10.0
    scale_bias: float = 0.0
    scale_sigma: float = 0.02
    heading_bias_per_m: float = 0.0
    heading_sigma: float = np.radians(0.2)

    def __post_init__(self) -> None:
        for name in ("rate_hz", "scale_bias", "scale_sigma", "heading_bias_per_m", "heading_sigma"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
                raise InputError(f"is {value!r}", field=name, expected="a number")
            if not np.isfinite(value):
                raise InputError(f"is {value}", field=name, expected="a finite number")
        if not 0 < self.rate_hz <= MAX_VO_RATE_HZ:
            raise InputError(
                f"is {self.rate_hz}",
                field="rate_hz",
                expected=f"Hz in (0, {MAX_VO_RATE_HZ:g}] (a camera's frame rate)",
            )
        if not self.scale_bias > -1:
            raise InputError(f"is {self.scale_bias}", field="scale_bias", expected="> -1")
        for name in ("scale_sigma", "heading_sigma"):
            if getattr(self, name) < 0:
                raise InputError(f"is {getattr(self, name)}", field=name, expected=">= 0")

    def increment_sigma(self, distance_m: float, steps: int) -> tuple[float, float]:
        """Standard deviations of the VO's increment over ``steps`` steps covering
        ``distance_m`` metres (translation in metres, heading in radians), from this model.

        Root mean square errors, each part in quadrature. Heading: ``sqrt(steps)
        heading_sigma`` (independent per step) and the drift ``heading_bias_per_m d``.
        Translation: the scale bias ``scale_bias d``, the per-step scale noise ``scale_sigma d
        / sqrt(steps)`` (equal steps) and the heading error's sideways displacement on the
        way, ``d sigma_heading / sqrt(3)`` (a heading error growing along the path). Checked
        against :meth:`corrupt` by Monte Carlo (``tests/sensors``)."""
        n = max(int(steps), 1)
        d = abs(float(distance_m))
        sig_h = np.hypot(np.sqrt(n) * self.heading_sigma, self.heading_bias_per_m * d)
        sig_t = np.sqrt(
            (self.scale_bias * d) ** 2 + (self.scale_sigma * d) ** 2 / n + (d * sig_h) ** 2 / 3
        )
        return float(sig_t), float(sig_h)

    def corrupt(
        self, poses_xytheta: ArrayLike, rng: np.random.Generator | None = None
    ) -> NDArray[np.float64]:
        """Noisy VO poses ``(N, 3)`` from true poses ``(N, 3)`` sampled at the VO rate.

        The first pose is kept exactly (VO is relative: it starts where the robot starts).
        """
        rng = np.random.default_rng() if rng is None else rng
        P = np.asarray(poses_xytheta, dtype=np.float64)
        if P.ndim != 2 or P.shape[1] != 3 or len(P) == 0:
            raise InputError(
                f"has shape {P.shape}", field="poses_xytheta", expected="(N, 3) rows x, y, theta"
            )
        T = se2_from_xytheta(P[:, 0], P[:, 1], P[:, 2])
        steps = se2_to_xytheta(se2_inverse(T[:-1]) @ T[1:])  # body-frame increments
        n = len(steps)
        dist = np.hypot(steps[:, 0], steps[:, 1])
        scale = 1.0 + self.scale_bias + self.scale_sigma * rng.standard_normal(n)
        dtheta = (
            steps[:, 2]
            + self.heading_bias_per_m * dist
            + self.heading_sigma * rng.standard_normal(n)
        )
        noisy = se2_from_xytheta(steps[:, 0] * scale, steps[:, 1] * scale, dtheta)
        out = np.empty_like(T)
        out[0] = T[0]
        for k in range(n):  # sequential integration; n is the number of VO steps (small)
            out[k + 1] = se2_compose(out[k], noisy[k])
        return se2_to_xytheta(out)
