"""Array buffers for the compiled kernels: one allocation per call (outputs), one per grid shape
and thread (work arrays).

The machine cost that dominates a kernel call which allocates its arrays itself is not the
arithmetic but the first touch of fresh memory: Numba allocates with ``malloc``, each large
array comes from a new ``mmap``, and every 4 KiB page faults on first write (~2 us each on the
benchmark VM: 2,700 faults, ~6 ms, per stage 2-5 call on a KITTI grid - twice the work).
NumPy asks the kernel for transparent huge pages (``madvise``) for allocations of 4 MiB and
more, so the outputs of a call are carved out of one NumPy allocation of at least that size,
and the work arrays, which no caller sees, are kept between calls (per grid shape, per thread,
the last four shapes).
"""

from __future__ import annotations

import math
import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable, Sequence
from typing import Any

import numpy as np
from numpy.typing import DTypeLike, NDArray

__all__ = ["arena", "cached_work"]

_ALIGN = 64  # bytes: every array starts on a cache line
_HUGE = 1 << 22  # NumPy madvises huge pages from 4 MiB on
_PAGE = 1 << 21  # a huge page
_LOCAL = threading.local()
_KEEP = 4


def arena(specs: Sequence[tuple[tuple[int, ...], DTypeLike]]) -> list[NDArray[Any]]:
    """Uninitialised C-contiguous arrays ``(shape, dtype)``, all views of one allocation.

    Allocations from 1 MiB on are rounded up to whole 2 MiB pages (at least 4 MiB, from a 2 MiB
    boundary), so that NumPy backs them with huge pages (a few page faults instead of one per
    4 KiB); the untouched rest costs no memory.
    """
    # plain Python integers (``math.prod``): ``np.prod`` per spec cost ~0.1 ms per call here
    dts = [np.dtype(dtype) for _, dtype in specs]
    counts = [math.prod(shape) for shape, _ in specs]
    offsets = []
    total = 0
    for dt, n in zip(dts, counts, strict=True):
        offsets.append(total)
        total += -(-n * dt.itemsize // _ALIGN) * _ALIGN
    if total >= (1 << 20):
        # whole 2 MiB pages, from a 2 MiB boundary: the kernel backs every page of them with a
        # huge page (the ends of an unaligned region would fault 4 KiB at a time)
        size = max(-(-total // _PAGE) * _PAGE, _HUGE)
        raw = np.empty(size + _PAGE, dtype=np.uint8)
        skip = -raw.ctypes.data % _PAGE
    else:
        raw = np.empty(total + _ALIGN, dtype=np.uint8)
        skip = -raw.ctypes.data % _ALIGN
    out = []
    for (shape, _), dt, n, off in zip(specs, dts, counts, offsets, strict=True):
        start = skip + off
        out.append(raw[start : start + n * dt.itemsize].view(dt).reshape(shape))
    return out


def cached_work(key: Hashable, make: Callable[[], list[NDArray[Any]]]) -> list[NDArray[Any]]:
    """The work arrays ``make()`` builds for ``key`` (a grid shape), kept for the next call of
    this thread with the same key (the last four keys)."""
    cache: OrderedDict[Hashable, list[NDArray[Any]]] | None = getattr(_LOCAL, "cache", None)
    if cache is None:
        cache = _LOCAL.cache = OrderedDict()
    got = cache.get(key)
    if got is None:
        got = cache[key] = make()
        while len(cache) > _KEEP:
            cache.popitem(last=False)
    else:
        cache.move_to_end(key)
    return got
