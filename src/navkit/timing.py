"""Wall-clock timings of named stages: a dict of lists and a context manager that appends to it."""

from __future__ import annotations

import time
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["Timings", "new_timings", "timed"]

Timings = defaultdict[str, list[float]]
"""Seconds per call, by stage name."""


def new_timings() -> Timings:
    """An empty store."""
    return defaultdict(list)


@contextmanager
def timed(store: Timings | None, key: str) -> Iterator[None]:
    """Append the seconds the ``with`` block took to ``store[key]`` (nothing when ``store`` is
    None)."""
    t0 = time.perf_counter()
    try:
        yield
    finally:
        if store is not None:
            store[key].append(time.perf_counter() - t0)
