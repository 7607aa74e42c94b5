"""``atan2``, ``acos`` and ``cos`` with one fixed arithmetic: the same bits on every machine,
and compiled twins.

NumPy's ``arctan2`` is not one function across machines: with AVX-512 it runs its own SIMD
(SVML) code, elsewhere it calls the C library's ``atan2`` point by point, and the two differ in
the last bit. Per point it is also the largest single cost of recovering a lidar scan grid on a
machine without AVX-512 (about 2.5 ms of a 124k-point SemanticKITTI frame on a Zen 3 core, ~20
ns a call; ``docs/kernels.md``, "Decisions").

:func:`atan2` here is Cephes' ``atan`` (S. L. Moshier; the same coefficients as Go's
``math.Atan``): the argument reduced to ``|t| <= tan(pi/8)`` by ``t -> (t - 1) / (t + 1)``
(``0.66 < |t| <= tan(3 pi/8)``) or ``t -> -1 / t`` (beyond), then ``t + t^3 P(t^2) / Q(t^2)``
with ``P`` of degree 4 and ``Q`` of degree 5, and ``pi/2``'s low bits added back. Applied to
``t = y / x`` and moved to the quadrant of ``(x, y)``. Its error against a correctly rounded
``atan2`` is at most 2 ulp (measured on 2 million random pairs over twelve decades:
``tests/geometry/test_angles.py``); ``arctan2`` of libm is within 1 ulp.

Every operation is one IEEE-754 double operation in a fixed order (no fused multiply-add, no
reassociation), so the NumPy version and :func:`navkit.geometry._kernels_math.atan2_kernel` (one
vectorised loop: about 0.5 ms for 124k points on the same core) give the same bits, on any
machine: a compiled path and its NumPy oracle can use it and agree exactly.

Domain of :func:`atan2`: finite ``y`` and ``x`` (as every valid sensor point is). The signed zeros follow C's
``atan2`` (``atan2(+-0, -0) = +-pi``, ``atan2(+-0, +0) = +-0``, ``atan2(y != 0, +-0) = +-pi/2``);
an infinite argument gives NaN where C's would give a multiple of ``pi/4``.

:func:`acos` and :func:`cos` are Cephes' ``acos`` (through its ``asin``: a rational
approximation on ``|x| <= 0.625``, the identity ``asin(1 - z) = pi/2 - sqrt(2 z)(1 + R(z))``
beyond; ``acos(x) = 2 asin(sqrt((1 - x) / 2))`` for ``x > 0.5``) and ``cos`` (the argument
reduced by multiples of ``pi/4`` in three parts - Cody and Waite - then a degree-6 polynomial in
``z^2`` for the sine or the cosine of the remainder; Go's ``math.Cos``). NumPy's ``arccos`` and
``cos`` run SIMD code on some machines and libm's elsewhere, which differ in the last bit;
these are the same operations in the same order as their compiled twins
(:func:`navkit.planes._kernels.acos_scalar`, :func:`navkit.planes._kernels.cos_scalar`), so the
closed-form eigenvalues of :func:`navkit.planes.extract.smallest_eigenpairs` and of the compiled
``plane_rows`` agree bit for bit. Both are within a few ulp of libm's (``tests/planes/
test_kernels.py``). Domains: ``acos`` on ``[-1, 1]`` (NaN beyond), ``cos`` on ``|x| < 2^29``
(finite; beyond, the three-part reduction loses bits).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["acos", "atan2", "cos"]

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
    module (the same bits as :func:`navkit.geometry._kernels_math.atan2_kernel`); within 2 ulp of
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


# Cephes asin.c (double): asin(x) = x + x^3 P(x^2) / Q(x^2) on |x| <= 0.625
ASIN_P = (
    4.253011369004428248960e-3,
    -6.019598008014123785661e-1,
    5.444622390564711410273e00,
    -1.626247967210700244449e01,
    1.956261983317594739197e01,
    -8.198089802484824371615e00,
)
ASIN_Q = (  # the leading coefficient 1 is implicit
    -1.474091372988853791896e01,
    7.049610280856842141659e01,
    -1.471791292232726029859e02,
    1.395105614657485689735e02,
    -4.918853881490881290097e01,
)
# asin(1 - z) = pi/2 - sqrt(2 z) (1 + z R(z) / S(z)) on 0 <= z <= 0.375
ASIN_R = (
    2.967721961301243206100e-3,
    -5.634242780008963776856e-1,
    6.968710824104713396794e00,
    -2.556901049652824852289e01,
    2.853665548261061424989e01,
)
ASIN_S = (  # the leading coefficient 1 is implicit
    -2.194779531642920639778e01,
    1.470656354026814941758e02,
    -3.838770957603691357202e02,
    3.424398657913078477438e02,
)
ASIN_SPLIT = 0.625
ASIN_TINY = 1.0e-8  # below: asin(x) = x
# Cephes sin.c (double): sin(z) = z + z^3 SIN(z^2), cos(z) = 1 - z^2 / 2 + z^4 COS(z^2) on
# |z| <= pi/4
SIN_C = (
    1.58962301576546568060e-10,
    -2.50507477628578072866e-8,
    2.75573136213857245213e-6,
    -1.98412698295895385996e-4,
    8.33333333332211858878e-3,
    -1.66666666666666307295e-1,
)
COS_C = (
    -1.13585365213876817300e-11,
    2.08757008419747316778e-9,
    -2.75573141792967388112e-7,
    2.48015872888517045348e-5,
    -1.38888888888730564116e-3,
    4.16666666666665929218e-2,
)
PI4A = 7.85398125648498535156e-1  # pi/4 in three parts (Cody-Waite)
PI4B = 3.77489470793079817668e-8
PI4C = 2.69515142907905952645e-15
FOUR_OVER_PI = 4.0 / math.pi


def _poly(z: NDArray[np.float64], coef: tuple[float, ...], monic: bool) -> NDArray[np.float64]:
    """Horner: ``((c0 z + c1) z + c2) ...`` (Cephes' ``polevl``), or with an implicit leading 1
    ``((z + c0) z + c1) ...`` (``p1evl``); one product and one sum per step."""
    out = z + coef[0] if monic else z * coef[0] + coef[1]
    for c in coef[1:] if monic else coef[2:]:
        out = out * z + c
    return out


def _asin(x: NDArray[np.float64]) -> NDArray[np.float64]:
    """Cephes' ``asin`` on ``[-1, 1]`` (both branches computed, then selected)."""
    a = np.abs(x)
    with np.errstate(invalid="ignore"):
        # |x| > 0.625: pi/4 - ((sqrt(2 z) R - MOREBITS) - ... ), z = 1 - |x|
        zz = 1.0 - a
        p = zz * _poly(zz, ASIN_R, False) / _poly(zz, ASIN_S, True)
        zz = np.sqrt(zz + zz)
        hi = PI_4 - zz
        zz = zz * p - MOREBITS
        hi = (hi - zz) + PI_4
        # |x| <= 0.625: |x| + |x|^3 P / Q
        z2 = a * a
        lo = z2 * _poly(z2, ASIN_P, False) / _poly(z2, ASIN_Q, True)
        lo = a * lo + a
    out = np.where(a > ASIN_SPLIT, hi, np.where(a < ASIN_TINY, a, lo))
    return np.where(x < 0, -out, out)


def acos(x: ArrayLike) -> NDArray[np.float64]:
    """``arccos`` elementwise with Cephes' arithmetic (the same bits as the compiled
    :func:`navkit.planes._kernels.acos_scalar`); ``x`` in ``[-1, 1]``, NaN beyond."""
    xv = np.asarray(x, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        half = np.sqrt(0.5 - 0.5 * xv)  # x > 0.5: 2 asin(sqrt((1 - x) / 2))
        big = xv > 0.5
        a = _asin(np.where(big, half, xv))
        out = np.where(big, 2.0 * a, ((PI_4 - a) + MOREBITS) + PI_4)
    return np.where(np.abs(xv) <= 1.0, out, np.nan)


def cos(x: ArrayLike) -> NDArray[np.float64]:
    """``cos`` elementwise with Cephes' arithmetic (the same bits as the compiled
    :func:`navkit.planes._kernels.cos_scalar`); finite ``|x| < 2^29``."""
    xv = np.abs(np.asarray(x, dtype=np.float64))
    y = np.floor(xv * FOUR_OVER_PI)  # the octant
    odd = np.fmod(y, 2.0) == 1.0
    y = np.where(odd, y + 1.0, y)  # map zeros to the origin
    j = np.fmod(y, 8.0)
    z = ((xv - y * PI4A) - y * PI4B) - y * PI4C
    zz = z * z
    s = z + z * zz * _poly(zz, SIN_C, False)
    c = 1.0 - 0.5 * zz + zz * zz * _poly(zz, COS_C, False)
    jj = np.where(j > 3.0, j - 4.0, j)
    out = np.where((jj == 1.0) | (jj == 2.0), s, c)
    flip = (j > 3.0) != (jj > 1.0)
    return np.where(flip, -out, out)
