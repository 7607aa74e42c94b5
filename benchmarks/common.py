"""Timing helpers and the row type shared by the benchmark modules."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass
class Row:
    """One benchmark figure, navkit beside its peer.

    ``ratio`` is ``peer / navkit`` for times (> 1: navkit faster) and whatever the ``note`` says
    for other quantities; ``None`` where no peer does the same work.
    """

    area: str
    benchmark: str
    unit: str
    navkit: float | None
    peer: float | None = None
    peer_name: str = ""
    ratio: float | None = None
    note: str = ""


def median_time(fn: Callable[[], Any], repeats: int = 7, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` in seconds over ``repeats`` runs after ``warmup`` runs."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    times.sort()
    return times[len(times) // 2]


def time_ratio(navkit_s: float | None, peer_s: float | None) -> float | None:
    """``peer / navkit`` (how many times faster navkit is), or None."""
    if navkit_s is None or peer_s is None or navkit_s <= 0:
        return None
    return peer_s / navkit_s
