"""``sin``, ``cos``, ``exp`` and ``log`` with one fixed arithmetic: the same bits on every machine.

NumPy's ``sin``, ``cos``, ``exp`` and ``log`` on arrays run NumPy's own SIMD code where the CPU
has it (AVX2, AVX-512: different code paths) and the C library's elsewhere; a Numba kernel calls
the C library (``libm``), whose result also depends on the machine (glibc picks an FMA variant
at load time). The results agree to an ulp, not bit for bit. A compiled kernel and its NumPy
twin that must give the same bits (stage 8's A6 search, ``docs/kernels.md``, "Equivalence
contract") therefore use the functions of this module and their scalar twins in
:mod:`navkit.geometry._kernels` (``_sincos``, ``_exp``, ``_log``): every operation is one
IEEE-754 double operation (``+ - * /``, ``floor``, ``frexp`` / ``ldexp``, conversions between
small integers and doubles: all exact or correctly rounded) in a fixed order, no fused
multiply-add, so both give the same bits on any machine, as :mod:`navkit.geometry.angles`
does for ``atan2``.

The algorithms are S. L. Moshier's Cephes (``sin.c``, ``exp.c``, ``log.c``; the coefficients
Go's ``math`` package also uses for ``Sin`` and ``Cos``):

- :func:`sincos`: ``x`` reduced by the octant ``j = trunc(|x| 4 / pi)`` (rounded up to even)
  with ``pi / 4`` split in three parts (the first two exact in the product for
  ``|x| < 2^29``), then the degree-13 odd (sine) or degree-14 even (cosine) polynomial on
  ``|z| <= pi / 4``;
- :func:`exp`: ``x = n ln 2 + r`` (``ln 2`` in two parts, ``|r| <= ln 2 / 2``), then
  ``e^r = 1 + 2 r P(r^2) / (Q(r^2) - r P(r^2))`` and ``2^n`` by ``ldexp``;
- :func:`log`: ``x = f 2^e`` (``frexp``, ``f`` moved to ``[sqrt(1/2), sqrt(2))``), then
  ``log(1 + t)`` by a rational function of ``t = f - 1`` (``|e| <= 2``) or of
  ``z = 2 (f - 1) / (f + 1)`` (beyond), plus ``e ln 2`` in two parts.

Errors against the correctly rounded values (measured on millions of random arguments:
``tests/geometry/test_fixedmath.py``): at most 1 ulp for ``sin`` and ``cos`` on
``|x| <= 100`` except near their zeros, where the reduction's absolute error (~1e-32 |x|)
counts; ``exp`` and ``log`` at most 1 ulp.

Domains: ``sincos`` for ``|x| < 2^29`` (NaN beyond, and for NaN / infinities); ``exp`` for
every double (0 below -745.14, ``inf`` above 709.79, NaN for NaN); ``log`` for every double
(``-inf`` at 0, NaN below 0 and for NaN, ``inf`` at ``inf``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.geometry.angles import COS_C, FOUR_OVER_PI, PI4A, PI4B, PI4C, SIN_C

__all__ = ["exp", "log", "sincos"]

# Cephes sin.c: sin(z) = z + z^3 S(z^2), cos(z) = 1 - z^2 / 2 + z^4 C(z^2) on |z| <= pi/4; the
# coefficients, pi/4 in three parts (Cody-Waite: PI4A and PI4B have trailing zeros, so y * PI4A
# and y * PI4B are exact for y < 2^29) and fl(4 / pi) are those of navkit.geometry.angles.cos
SINCOS_MAX = float(2**29)
"""``|x|`` from which :func:`sincos` returns NaN (the reduction's products are exact below)."""

# Cephes exp.c: e^r = 1 + 2 r P(r^2) / (Q(r^2) - r P(r^2)) on |r| <= ln 2 / 2
EXP_P = (1.26177193074810590878e-4, 3.02994407707441961300e-2, 9.99999999999999999910e-1)
EXP_Q = (
    3.00198505138664455042e-6,
    2.52448340349684104192e-3,
    2.27265548208155028766e-1,
    2.00000000000000000009e0,
)
LN2_HI = 6.93145751953125e-1  # ln 2 in two parts (exp); LN2_HI has trailing zeros
LN2_LO = 1.42860682030941723212e-6
LOG2E = 1.4426950408889634073599
EXP_MAX = 7.09782712893383996843e2  # ln(max double)
EXP_MIN = -7.451332191019412076235e2  # ln(smallest subnormal)

# Cephes log.c: log(1 + t) = t - t^2 / 2 + t^3 P(t) / Q(t) on sqrt(1/2) - 1 <= t < sqrt(2) - 1
LOG_P = (
    1.01875663804580931796e-4,
    4.97494994976747001425e-1,
    4.70579119878881725854e0,
    1.44989225341610930846e1,
    1.79368678507819816313e1,
    7.70838733755885391666e0,
)
LOG_Q = (  # the leading coefficient 1 is implicit
    1.12873587189167450590e1,
    4.52279145837532221105e1,
    8.29875266912776603211e1,
    7.11544750618563894466e1,
    2.31251620126765340583e1,
)
# log(x) = z + z^3 R(z^2) / S(z^2), z = 2 (x - 1) / (x + 1)
LOG_R = (-7.89580278884799154124e-1, 1.63866645699558079767e1, -6.41409952958715622951e1)
LOG_S = (  # the leading coefficient 1 is implicit
    -3.56722798256324312549e1,
    3.12093766372244180303e2,
    -7.69691943550460008604e2,
)
LOG_LN2_HI = 0.693359375  # ln 2 in two parts (log): 0.693359375 - 2.1219444e-4
LOG_LN2_LO = -2.121944400546905827679e-4
SQRTH = 0.70710678118654752440


def _array(x: ArrayLike) -> NDArray[np.float64]:
    return np.asarray(x, dtype=np.float64)


def sincos(x: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(sin x, cos x)`` elementwise with the fixed arithmetic of this module (the same bits as
    ``navkit.geometry._kernels_math._sincos``). NaN where ``|x| >= 2^29`` or ``x`` is not finite."""
    xv = _array(x)
    ax = np.abs(xv)
    ok = ax < SINCOS_MAX  # False for NaN and infinities
    ax = np.where(ok, ax, 0.0)
    j = (ax * FOUR_OVER_PI).astype(np.int64)  # the octant (truncated: ax >= 0)
    y = j.astype(np.float64)
    odd = (j & 1) == 1
    j = j + odd
    y = y + odd  # + 1.0 where odd: exact
    j &= 7
    z = ((ax - y * PI4A) - y * PI4B) - y * PI4C
    zz = z * z
    ps = zz * SIN_C[0]
    for c in SIN_C[1:]:
        ps += c
        ps *= zz
    s = z + z * ps  # z + z^3 S(zz)
    pc = zz * COS_C[0]
    for c in COS_C[1:]:
        pc += c
        pc *= zz
    # 1 - zz / 2 + zz^2 C(zz): (1 - 0.5 zz) + zz * (zz C(zz))
    c_ = (1.0 - 0.5 * zz) + zz * pc
    upper = j > 3
    j = np.where(upper, j - 4, j)
    swap = j == 2  # octants 2, 6: sin is the cosine polynomial and vice versa
    sin_neg = upper != np.signbit(xv)
    cos_neg = upper != swap
    sv = np.where(swap, c_, s)
    cv = np.where(swap, s, c_)
    sv = np.where(sin_neg, -sv, sv)
    cv = np.where(cos_neg, -cv, cv)
    sv = np.where(ok, sv, np.nan)
    cv = np.where(ok, cv, np.nan)
    return sv, cv


def exp(x: ArrayLike) -> NDArray[np.float64]:
    """``e^x`` elementwise with the fixed arithmetic of this module (the same bits as
    ``navkit.geometry._kernels_math._exp``)."""
    xv = _array(x)
    ok = (xv >= EXP_MIN) & (xv <= EXP_MAX)
    xr = np.where(ok, xv, 0.0)
    px = np.floor(LOG2E * xr + 0.5)
    n = px.astype(np.int64)
    r = xr - px * LN2_HI
    r = r - px * LN2_LO
    rr = r * r
    p = (EXP_P[0] * rr + EXP_P[1]) * rr + EXP_P[2]
    p = r * p
    q = ((EXP_Q[0] * rr + EXP_Q[1]) * rr + EXP_Q[2]) * rr + EXP_Q[3]
    e = p / (q - p)
    e = 1.0 + 2.0 * e
    out = np.ldexp(e, n)
    out = np.where(xv > EXP_MAX, np.inf, out)
    out = np.where(xv < EXP_MIN, 0.0, out)
    return np.where(np.isnan(xv), np.nan, out)


def log(x: ArrayLike) -> NDArray[np.float64]:
    """``ln x`` elementwise with the fixed arithmetic of this module (the same bits as
    ``navkit.geometry._kernels_math._log``)."""
    xv = _array(x)
    ok = (xv > 0) & (xv < np.inf)
    f, e = np.frexp(np.where(ok, xv, 1.0))  # x = f 2^e, 0.5 <= f < 1
    ef = e.astype(np.float64)
    low = f < SQRTH
    ef = np.where(low, ef - 1.0, ef)
    far = (e > 2) | (e < -2)  # tested on frexp's exponent, before the move of f
    # far: z = 2 (f' - 1) / (f' + 1) with f' = 2 f (low) or f
    zn = f - 0.5
    zn = np.where(low, zn, zn - 0.5)
    zd = np.where(low, 0.5 * zn + 0.5, 0.5 * f + 0.5)
    w = zn / zd
    w2 = w * w
    rr = (LOG_R[0] * w2 + LOG_R[1]) * w2 + LOG_R[2]
    ss = ((w2 + LOG_S[0]) * w2 + LOG_S[1]) * w2 + LOG_S[2]
    zf = w * (w2 * rr / ss)
    zf = zf + ef * LOG_LN2_LO
    zf = zf + w
    zf = zf + ef * LOG_LN2_HI
    # near: t = 2 f - 1 (low) or f - 1, log(1 + t) = t - t^2 / 2 + t^3 P(t) / Q(t)
    t = np.where(low, (f + f) - 1.0, f - 1.0)
    t2 = t * t
    pp = LOG_P[0] * t
    for c in LOG_P[1:-1]:
        pp += c
        pp *= t
    pp += LOG_P[-1]
    qq = t + LOG_Q[0]
    for c in LOG_Q[1:]:
        qq *= t
        qq += c
    yn = t * (t2 * pp / qq)
    yn = yn + ef * LOG_LN2_LO
    yn = yn - 0.5 * t2
    zn_ = t + yn
    zn_ = zn_ + ef * LOG_LN2_HI
    out = np.where(far, zf, zn_)
    out = np.where(xv == np.inf, np.inf, out)
    out = np.where(xv == 0.0, -np.inf, out)
    return np.where((xv < 0) | np.isnan(xv), np.nan, out)
