"""``atan2`` with one fixed arithmetic: the same bits on every machine, and a compiled twin.

NumPy's ``arctan2`` is not one function across machines: with AVX-512 it runs its own SIMD
(SVML) code, elsewhere it calls the C library's ``atan2`` point by point, and the two differ in
the last bit. Per point it is also the largest single cost of recovering a lidar scan grid on a
machine without AVX-512 (about 2.5 ms of a 124k-point SemanticKITTI frame on a Zen 3 core, ~20
ns a call; ``docs/kernels.md``, "Obstacles on AVX2").

:func:`atan2` here is Cephes' ``atan`` (S. L. Moshier; the same coefficients as Go's
``math.Atan``): the argument reduced to ``|t| <= tan(pi/8)`` by ``t -> (t - 1) / (t + 1)``
(``0.66 < |t| <= tan(3 pi/8)``) or ``t -> -1 / t`` (beyond), then ``t + t^3 P(t^2) / Q(t^2)``
with ``P`` of degree 4 and ``Q`` of degree 5, and ``pi/2``'s low bits added back. Applied to
``t = y / x`` and moved to the quadrant of ``(x, y)``. Its error against a correctly rounded
``atan2`` is at most 2 ulp (measured on 2 million random pairs over twelve decades:
``tests/geometry/test_angles.py``); ``arctan2`` of libm is within 1 ulp.

Every operation is one IEEE-754 double operation in a fixed order (no fused multiply-add, no
reassociation), so the NumPy version and :func:`navkit.geometry._kernels.atan2_kernel` (one
vectorised loop: about 0.5 ms for 124k points on the same core) give the same bits, on any
machine: a compiled path and its NumPy oracle can use it and agree exactly.

Domain: finite ``y`` and ``x`` (as every valid sensor point is). The signed zeros follow C's
``atan2`` (``atan2(+-0, -0) = +-pi``, ``atan2(+-0, +0) = +-0``, ``atan2(y != 0, +-0) = +-pi/2``);
an infinite argument gives NaN where C's would give a multiple of ``pi/4``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["atan2"]

# Cephes atan.c (double): atan(t) = t + t^3 P(t^2) / Q(t^2) on |t| <= tan(pi/8) = 0.4142...
ATAN_P = (
    -8.750608600031904122785e-01,
    -1.615753718733365076637e01,
    -7.500855792314704667340e01,
    -1.228866684490136173410e02,
    -6.485021904942025371773e01,
)
ATAN_Q = (  # the leading coefficient 1 is implicit
    2.485846490142306297962e01,
    1.650270098316988542046e02,
    4.328810604912902668951e02,
    4.853903996359136964868e02,
    1.945506571482613964425e02,
)
TAN_3PI_8 = 2.41421356237309504880
MID_FROM = 0.66  # Cephes' switch to the pi/4 reduction
MOREBITS = 6.123233995736765886130e-17  # pi/2 - fl(pi/2)
PI_2 = math.pi / 2
PI_4 = math.pi / 4


def atan2(y: ArrayLike, x: ArrayLike) -> NDArray[np.float64]:
    """The angle of ``(x, y)`` in ``[-pi, pi]``, elementwise, with the fixed arithmetic of this
    module (the same bits as :func:`navkit.geometry._kernels.atan2_kernel`); within 2 ulp of
    ``numpy.arctan2``. Finite inputs; broadcasting as NumPy's."""
    yv, xv = np.broadcast_arrays(np.asarray(y, dtype=np.float64), np.asarray(x, dtype=np.float64))
    shape = yv.shape
    yv, xv = yv.reshape(-1), xv.reshape(-1)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = yv / xv
        a = np.abs(t)
        big = a > TAN_3PI_8
        mid = (a > MID_FROM) & ~big
        r = a.copy()
        np.divide(a - 1.0, a + 1.0, out=r, where=mid)
        np.divide(-1.0, a, out=r, where=big)
        z = r * r
        num = z * ATAN_P[0]
        for c in ATAN_P[1:]:
            num += c
            num *= z
        den = z + ATAN_Q[0]
        for c in ATAN_Q[1:]:
            den *= z
            den += c
        num /= den  # z P(z) / Q(z)
        num *= r
        num += r  # r + r z P(z) / Q(z)
        num += np.where(big, MOREBITS, np.where(mid, 0.5 * MOREBITS, 0.0))
        num += np.where(big, PI_2, np.where(mid, PI_4, 0.0))
        out = np.copysign(num, t, out=num)
        np.add(out, np.copysign(np.pi, yv), out=out, where=xv < 0)
        axis = xv == 0
        if axis.any():  # on the y axis (or the origin): C's atan2
            on_axis = np.where(yv == 0, np.where(np.signbit(xv), np.pi, 0.0), PI_2)
            out = np.where(axis, np.copysign(on_axis, yv), out)
    return out.reshape(shape)
