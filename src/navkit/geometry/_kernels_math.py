"""Compiled scalar ``sin``/``cos``, ``exp``, ``log`` and ``atan2`` with one fixed arithmetic:
the scalar twins of :mod:`navkit.geometry.fixedmath` and :mod:`navkit.geometry.angles` (the same
IEEE operations in the same order, so the same bits on every machine; see those modules for the
algorithms and their errors). The shape kernels (:mod:`navkit.geometry._kernels`) inline the
scalar functions; the array kernels exist for the tests and for the scan grid's azimuths.

The kernels read the constants of those two modules when they compile: Numba's cache is keyed
by this file, so a change to those constants needs this file touched (or the cache cleared).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from navkit.geometry import fixedmath as _fm
from navkit.geometry.angles import ATAN_P, ATAN_Q, MID_FROM, MOREBITS, PI_2, PI_4, TAN_3PI_8

__all__ = ["atan2_kernel", "exp_kernel", "log_kernel", "sincos_kernel"]

TWINS = {
    "atan2_kernel": "navkit.geometry.angles.atan2",
    "exp_kernel": "navkit.geometry.fixedmath.exp",
    "log_kernel": "navkit.geometry.fixedmath.log",
    "sincos_kernel": "navkit.geometry.fixedmath.sincos",
}
"""Each public kernel -> its NumPy twin."""

TEST_ONLY = ("exp_kernel", "log_kernel", "sincos_kernel")
"""Array entry points of the scalar ``_exp``, ``_log`` and ``_sincos`` that the shape kernels
inline: the tests compare them with :mod:`navkit.geometry.fixedmath` bit for bit."""

# ------------------------------------------------------------------------------------------
# sin, cos, exp, log and atan2 with one fixed arithmetic: the scalar twins of
# navkit.geometry.fixedmath and navkit.geometry.angles (the same operations in the same order,
# so the same bits on every machine; see those modules for the algorithms and their errors)

_P0, _P1, _P2, _P3, _P4 = ATAN_P
_Q0, _Q1, _Q2, _Q3, _Q4 = ATAN_Q
_S0, _S1, _S2, _S3, _S4, _S5 = _fm.SIN_C
_C0, _C1, _C2, _C3, _C4, _C5 = _fm.COS_C
_PI4A, _PI4B, _PI4C, _FOUR_OVER_PI, _SINCOS_MAX = (
    _fm.PI4A,
    _fm.PI4B,
    _fm.PI4C,
    _fm.FOUR_OVER_PI,
    _fm.SINCOS_MAX,
)
_EP0, _EP1, _EP2 = _fm.EXP_P
_EQ0, _EQ1, _EQ2, _EQ3 = _fm.EXP_Q
_LN2_HI, _LN2_LO, _LOG2E, _EXP_MAX, _EXP_MIN = (
    _fm.LN2_HI,
    _fm.LN2_LO,
    _fm.LOG2E,
    _fm.EXP_MAX,
    _fm.EXP_MIN,
)
_LP0, _LP1, _LP2, _LP3, _LP4, _LP5 = _fm.LOG_P
_LQ0, _LQ1, _LQ2, _LQ3, _LQ4 = _fm.LOG_Q
_LR0, _LR1, _LR2 = _fm.LOG_R
_LS0, _LS1, _LS2 = _fm.LOG_S
_LOG_HI, _LOG_LO, _SQRTH = _fm.LOG_LN2_HI, _fm.LOG_LN2_LO, _fm.SQRTH


@njit(cache=True, error_model="numpy")
def _sincos(x):  # type: ignore[no-untyped-def]
    """``(sin x, cos x)``: :func:`navkit.geometry.fixedmath.sincos` on one value."""
    ax = abs(x)
    if not ax < _SINCOS_MAX:
        return np.nan, np.nan
    j = np.int64(ax * _FOUR_OVER_PI)
    y = np.float64(j)
    if j & 1:
        j += 1
        y = y + 1.0
    j &= 7
    z = ((ax - y * _PI4A) - y * _PI4B) - y * _PI4C
    zz = z * z
    ps = (((((zz * _S0 + _S1) * zz + _S2) * zz + _S3) * zz + _S4) * zz + _S5) * zz
    s = z + z * ps
    pc = (((((zz * _C0 + _C1) * zz + _C2) * zz + _C3) * zz + _C4) * zz + _C5) * zz
    c = (1.0 - 0.5 * zz) + zz * pc
    upper = j > 3
    if upper:
        j -= 4
    swap = j == 2
    sv = c if swap else s
    cv = s if swap else c
    if upper != (math.copysign(1.0, x) < 0.0):
        sv = -sv
    if upper != swap:
        cv = -cv
    return sv, cv


@njit(cache=True, error_model="numpy")
def _exp(x):  # type: ignore[no-untyped-def]
    """``e^x``: :func:`navkit.geometry.fixedmath.exp` on one value."""
    if x != x:
        return x
    if x > _EXP_MAX:
        return np.inf
    if x < _EXP_MIN:
        return 0.0
    px = np.floor(_LOG2E * x + 0.5)
    n = np.int64(px)
    r = x - px * _LN2_HI
    r = r - px * _LN2_LO
    rr = r * r
    p = r * ((_EP0 * rr + _EP1) * rr + _EP2)
    q = ((_EQ0 * rr + _EQ1) * rr + _EQ2) * rr + _EQ3
    e = p / (q - p)
    e = 1.0 + 2.0 * e
    return math.ldexp(e, n)


@njit(cache=True, error_model="numpy")
def _log(x):  # type: ignore[no-untyped-def]
    """``ln x``: :func:`navkit.geometry.fixedmath.log` on one value."""
    if not (x > 0.0 and x < np.inf):
        if x == np.inf:
            return np.inf
        if x == 0.0:
            return -np.inf
        return np.nan
    f, e = math.frexp(x)
    ef = np.float64(e)
    low = f < _SQRTH
    if low:
        ef = ef - 1.0
    if e > 2 or e < -2:
        zn = f - 0.5
        if low:
            zd = 0.5 * zn + 0.5
        else:
            zn = zn - 0.5
            zd = 0.5 * f + 0.5
        w = zn / zd
        w2 = w * w
        rr = (_LR0 * w2 + _LR1) * w2 + _LR2
        ss = ((w2 + _LS0) * w2 + _LS1) * w2 + _LS2
        z = w * (w2 * rr / ss)
        z = z + ef * _LOG_LO
        z = z + w
        return z + ef * _LOG_HI
    t = (f + f) - 1.0 if low else f - 1.0
    t2 = t * t
    pp = ((((_LP0 * t + _LP1) * t + _LP2) * t + _LP3) * t + _LP4) * t + _LP5
    qq = ((((t + _LQ0) * t + _LQ1) * t + _LQ2) * t + _LQ3) * t + _LQ4
    y = t * (t2 * pp / qq)
    y = y + ef * _LOG_LO
    y = y - 0.5 * t2
    z = t + y
    return z + ef * _LOG_HI


@njit(cache=True, error_model="numpy", inline="always")
def _atan2(yk, xk):  # type: ignore[no-untyped-def]
    """``atan2(y, x)``: :func:`navkit.geometry.angles.atan2` on one pair (the loop body of
    :func:`atan2_kernel`)."""
    t = yk / xk
    a = abs(t)
    big = a > TAN_3PI_8
    mid = a > MID_FROM
    r = -1.0 / a if big else ((a - 1.0) / (a + 1.0) if mid else a)
    z = r * r
    num = ((((z * _P0 + _P1) * z + _P2) * z + _P3) * z + _P4) * z
    den = (((z + _Q0) * z + _Q1) * z + _Q2) * z + _Q3
    den = den * z + _Q4
    v = r * (num / den) + r
    v = v + (MOREBITS if big else (0.5 * MOREBITS if mid else 0.0))
    v = v + (PI_2 if big else (PI_4 if mid else 0.0))
    v = math.copysign(v, t)
    v = v + math.copysign(math.pi, yk) if xk < 0 else v
    on_axis = (math.pi if math.copysign(1.0, xk) < 0 else 0.0) if yk == 0 else PI_2
    return math.copysign(on_axis, yk) if xk == 0 else v


@njit(cache=True, error_model="numpy")
def sincos_kernel(x, s, c):  # type: ignore[no-untyped-def]
    """``s[k], c[k] = sin x[k], cos x[k]`` (:func:`_sincos`)."""
    for k in range(len(x)):
        s[k], c[k] = _sincos(x[k])


@njit(cache=True, error_model="numpy")
def exp_kernel(x, out):  # type: ignore[no-untyped-def]
    """``out[k] = e^x[k]`` (:func:`_exp`)."""
    for k in range(len(x)):
        out[k] = _exp(x[k])
    return out


@njit(cache=True, error_model="numpy")
def log_kernel(x, out):  # type: ignore[no-untyped-def]
    """``out[k] = ln x[k]`` (:func:`_log`)."""
    for k in range(len(x)):
        out[k] = _log(x[k])
    return out


@njit(cache=True, error_model="numpy")
def atan2_kernel(y, x, out):  # type: ignore[no-untyped-def]
    """``out[k] = atan2(y[k], x[k])`` with the arithmetic of :func:`navkit.geometry.angles.atan2`
    (its NumPy twin: the same operations in the same order, so the same bits): :func:`_atan2`
    inlined into one branch-free loop that LLVM vectorises (every candidate computed, then
    selected). Finite inputs."""
    for k in range(len(out)):
        out[k] = _atan2(y[k], x[k])
    return out
