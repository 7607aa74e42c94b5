"""Numba helpers shared by the obstacle kernels: NaN-propagating minima and maxima, exact order
statistics and a union-find.

Each is called from kernels only (no NumPy twin of its own); the order statistics equal
``np.median`` and ``np.sort(v)[k]`` exactly (tested in ``tests/obstacles/test_kernels.py``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__: list[str] = []

TWINS: dict[str, str] = {}
"""No public kernel: the helpers are tested against NumPy through the kernels that call them."""


@njit(cache=True, error_model="numpy", inline="always")
def _min_nan(a, b):  # type: ignore[no-untyped-def]
    """``np.minimum``: NaN if either is NaN."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a <= b else b


@njit(cache=True, error_model="numpy", inline="always")
def _max_nan(a, b):  # type: ignore[no-untyped-def]
    """``np.maximum``: NaN if either is NaN."""
    if a != a:
        return a
    if b != b:
        return b
    return a if a >= b else b


@njit(cache=True)
def _kth(values, k):  # type: ignore[no-untyped-def]
    """The k-th smallest of ``values`` (0-based), by a selection in place (reorders them)."""
    lo, hi = 0, len(values) - 1
    while lo < hi:
        pivot = values[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while values[i] < pivot:
                i += 1
            while values[j] > pivot:
                j -= 1
            if i <= j:
                values[i], values[j] = values[j], values[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            return values[k]
    return values[k]


@njit(cache=True)
def _kth_banded(values, k, work):  # type: ignore[no-untyped-def]
    """The k-th smallest of ``values`` (0-based; no NaN), exactly: a strided sample brackets
    the k-th value, one pass counts what lies below the bracket and copies what lies inside it
    into ``work``, and a selection runs on that copy only (the whole array when the bracket
    misses)."""
    n = len(values)
    s = min(n, 2048)
    stride = max(n // s, 1)
    sample = np.empty(s)
    for q in range(s):
        sample[q] = values[q * stride]
    sample.sort()
    pos = int(s * (k / n))
    lo = sample[max(pos - 64, 0)]
    hi = sample[min(pos + 64, s - 1)]
    below = 0
    m = 0
    for q in range(n):  # branch-free: always write, advance when inside the bracket
        v = values[q]
        below += 1 if v < lo else 0
        work[np.uint64(m)] = v  # m >= 0: no negative-index fix-up
        m += 1 if (v >= lo and v <= hi) else 0
    if below <= k < below + m:
        return _kth(work[:m], k - below)
    for q in range(n):
        work[q] = values[q]
    return _kth(work[:n], k)


@njit(cache=True)
def _median_banded(values, work):  # type: ignore[no-untyped-def]
    """``np.median`` of ``values`` (no NaN, at least one), exactly: the middle order statistic,
    or the mean of the two middle ones from **one** bracket pass (:func:`_kth_banded`): after
    the selection of the lower one in the bracket's copy, every later entry of the copy is at
    least as large, so the upper one is their minimum."""
    n = len(values)
    h = n // 2
    if n % 2:
        return _kth_banded(values, h, work)
    k = h - 1
    s = min(n, 2048)
    stride = max(n // s, 1)
    sample = np.empty(s)
    for q in range(s):
        sample[q] = values[q * stride]
    sample.sort()
    pos = int(s * (k / n))
    lo = sample[max(pos - 64, 0)]
    hi = sample[min(pos + 64, s - 1)]
    below = 0
    m = 0
    for q in range(n):  # branch-free: always write, advance when inside the bracket
        v = values[q]
        below += 1 if v < lo else 0
        work[np.uint64(m)] = v
        m += 1 if (v >= lo and v <= hi) else 0
    if below <= k and k + 1 < below + m:
        a = _kth(work[:m], k - below)
        b = work[k - below + 1]
        for q in range(k - below + 2, m):
            b = work[q] if work[q] < b else b
        return (a + b) / 2
    for q in range(n):
        work[q] = values[q]
    a = _kth(work[:n], k)
    b = work[k + 1]
    for q in range(k + 2, n):
        b = work[q] if work[q] < b else b
    return (a + b) / 2


@njit(cache=True)
def _median(values):  # type: ignore[no-untyped-def]
    """``np.median`` of a 1-D array (reorders a copy)."""
    v = values.copy()
    m = len(v)
    h = m // 2
    if m % 2:
        return _kth(v, h)
    a = _kth(v, h - 1)
    b = _kth(v, h)
    return (a + b) / 2


# union-find over labels (stages 6 and 7)


@njit(cache=True, inline="always")
def _find(parent, a):  # type: ignore[no-untyped-def]
    """Root of ``a`` with path halving."""
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    return a


@njit(cache=True, inline="always")
def _union(parent, a, b):  # type: ignore[no-untyped-def]
    """Join the sets of ``a`` and ``b``; the smaller root stays the root."""
    ra = _find(parent, a)
    rb = _find(parent, b)
    if ra < rb:
        parent[rb] = ra
    elif rb < ra:
        parent[ra] = rb


_OFF_I = (0, 0, 1, -1)
_OFF_J = (1, -1, -1, 1)


@njit(cache=True)
def _renumber_by_min(parent, n):  # type: ignore[no-untyped-def]
    """``lut (n + 1,)``: labels 1..n to their merged component, numbered by smallest member."""
    lut = np.zeros(n + 1, np.int32)
    m = 0
    for a in range(1, n + 1):
        r = _find(parent, a)
        if r == a:
            m += 1
            lut[a] = m
        else:
            lut[a] = lut[r]
    return lut, m
