"""The sensor's own noise: the unit every accept / reject threshold of the plane odometry is in.

Two noises are modelled:

- **depth**: a Kinect-type (structured light or active stereo, triangulating) camera measures
  disparity with a roughly constant error, so its depth error grows with the square of the
  distance, ``sigma_z(z) = k z^2`` (differentiate ``z = b f / d``: ``sigma_z = z^2 sigma_d /
  (b f)``). ``k`` is a property of the sensor, in 1/m. Default: Kinect v1, Khoshelham and
  Elberink, "Accuracy and Resolution of Kinect Depth Data for Indoor Mapping Applications",
  Sensors 12(2), 2012: the random error "increases quadratically with increasing distance from
  the sensor and reaches 4 cm at the maximum range of 5 m", ``k = 0.04 / 5^2 = 1.6e-3`` 1/m
  (1.6 mm at 1 m, 6.4 mm at 2 m);
- **brightness**: estimated from each image itself (:func:`brightness_sigma`, Immerkaer 1996),
  so a dark, a bright, a compressed or a rendered image each give their own unit.

A point-to-plane residual between two depth images combines two depth errors, both seen along
the surface normal; :meth:`DepthNoise.point_to_plane` uses ``sqrt(2) sigma_z`` (the normal
within a few tens of degrees of the ray, where the planes that carry the motion are seen).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.domains import POSITIVE, domain_field
from navkit.geometry._validate import check_settings

__all__ = ["KINECT_V1_K", "DepthNoise", "brightness_sigma"]

KINECT_V1_K = 1.6e-3
"""``k`` of ``sigma_z = k z^2`` for a Kinect v1, 1/m (Khoshelham and Elberink 2012: 4 cm at
5 m)."""


@dataclass(frozen=True)
class DepthNoise:
    """Depth noise model ``sigma_z(z) = k z^2`` (module docstring).

    Attributes
    ----------
    k : float
        1/m. :data:`KINECT_V1_K` for Kinect v1 / Xtion-type structured light; a stereo camera's
        is ``sigma_disparity / (baseline f)``.
    """

    k: float = domain_field(KINECT_V1_K, POSITIVE)

    def __post_init__(self) -> None:
        check_settings(self)

    def sigma(self, z: ArrayLike) -> NDArray[np.float64]:
        """``sigma_z`` (metres) of depths ``z`` (metres)."""
        z = np.asarray(z, dtype=np.float64)
        return self.k * z * z

    def point_to_plane(self, z: ArrayLike) -> NDArray[np.float64]:
        """Standard deviation (metres) of a point-to-plane residual between two depth images
        at depth ``z``: two independent depth errors, ``sqrt(2) sigma_z(z)``."""
        return np.sqrt(2.0) * self.sigma(z)


_LAPLACE2 = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], dtype=np.float32)


def brightness_sigma(gray: ArrayLike, floor: float = 1.0 / 255.0) -> float:
    """Standard deviation of the brightness noise of an image (values in [0, 1]).

    Immerkaer, "Fast Noise Variance Estimation", CVIU 64(2), 1996: the image is filtered with
    the difference of two Laplacians (which cancels brightness that varies linearly, i.e. most
    of the scene), ``sigma = sqrt(pi / 2) / (6 (W - 2) (H - 2)) sum |I * N|``. Textured images
    leak some structure into the estimate (it errs high, the safe side for a threshold). At
    least ``floor`` (one 8-bit step: below it the quantisation dominates)."""
    g = np.asarray(gray, dtype=np.float32)
    if g.ndim != 2 or min(g.shape) < 3:
        return float(floor)
    r = cv2.filter2D(g, cv2.CV_32F, _LAPLACE2, borderType=cv2.BORDER_REFLECT)[1:-1, 1:-1]
    r = r[np.isfinite(r)]
    if r.size == 0:
        return float(floor)
    s = float(np.sqrt(np.pi / 2.0) / 6.0 * np.mean(np.abs(r)))
    return max(s, float(floor))
