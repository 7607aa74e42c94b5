"""Planar pose algebra of the mission on ``(x, y, theta)`` rows, over :mod:`navkit.geometry`'s SE(2).

The heading is kept continuous (no wrap) when increments are composed, so a dead-reckoned heading
can be compared with the truth's without unwrapping.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from navkit.geometry import (
    R_BODY_FROM_OPTICAL,
    se2_from_xytheta,
    se2_to_xytheta,
    se3_from_rt,
    wrap_angle,
)

__all__ = ["T_body_camera", "blend", "compose", "pose3", "relative"]


def relative(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """Body-frame increment ``a^-1 b`` of two poses ``(3,)``.

    Decision: the general inverse (LU), not :func:`navkit.geometry.se2_inverse`'s exact one: they
    differ in the last bits, and a whole mission (a chaotic loop of gates and thresholds) amplifies
    that into different figures; this keeps the published runs bit-identical."""
    return se2_to_xytheta(np.linalg.inv(se2_from_xytheta(*a)) @ se2_from_xytheta(*b))


def compose(a: NDArray[np.float64], inc: NDArray[np.float64]) -> NDArray[np.float64]:
    """The pose ``a`` moved by the body-frame increment ``inc``."""
    out = se2_to_xytheta(se2_from_xytheta(*a) @ se2_from_xytheta(*inc))
    out[2] = a[2] + inc[2]  # keep the heading continuous (no wrap)
    return out


def blend(a: NDArray[np.float64], b: NDArray[np.float64], w: float) -> NDArray[np.float64]:
    """``(1 - w) a + w b`` for poses, the heading difference wrapped."""
    out = a + w * (b - a)
    out[2] = a[2] + w * float(wrap_angle(b[2] - a[2]))
    return out


def pose3(p: NDArray[np.float64], z: float) -> NDArray[np.float64]:
    """The ``(4, 4)`` pose of a planar pose ``(x, y, theta)`` at height ``z``."""
    c, s = np.cos(p[2]), np.sin(p[2])
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return se3_from_rt(R, np.array([p[0], p[1], z]))


def T_body_camera(height: float, pitch_down_deg: float) -> NDArray[np.float64]:
    """``T_body_camera`` of a forward camera (optical frame) ``height`` metres up, pitched down."""
    p = np.radians(pitch_down_deg)
    cp, sp = np.cos(p), np.sin(p)
    Ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])  # +pitch about y tips x down
    return se3_from_rt(Ry @ R_BODY_FROM_OPTICAL, np.array([0.0, 0.0, height]))
