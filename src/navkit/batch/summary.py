"""Aggregate figures of a batch: counts, per-figure statistics, and rates with 95 % intervals.

Rates use the Wilson score interval (Wilson 1927), which stays inside [0, 1] and keeps close to
its nominal 95 % coverage for small batches and rates near 0 or 1, where the normal
approximation does not (Brown, Cai and DasGupta 2001, "Interval estimation for a binomial
proportion").
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["Rate", "summarize", "wilson_interval"]

_Z95 = 1.959963984540054  # two-sided 95 % quantile of the standard normal


@dataclass(frozen=True)
class Rate:
    """``successes`` of ``trials``, the rate and its 95 % Wilson interval."""

    successes: int
    trials: int
    rate: float
    low: float
    high: float

    def __str__(self) -> str:
        return (
            f"{100 * self.rate:.1f} % [{100 * self.low:.1f}, {100 * self.high:.1f}] "
            f"({self.successes}/{self.trials})"
        )


def wilson_interval(successes: int, trials: int, z: float = _Z95) -> Rate:
    """The Wilson score interval of a binomial proportion.

    >>> r = wilson_interval(97, 100)
    >>> round(r.low, 4), round(r.high, 4)
    (0.9154, 0.9897)
    """
    if trials <= 0:
        return Rate(0, 0, math.nan, math.nan, math.nan)
    if not 0 <= successes <= trials:
        raise ValueError(f"{successes} successes of {trials} trials")
    p = successes / trials
    z2 = z * z
    centre = (p + z2 / (2 * trials)) / (1 + z2 / trials)
    half = z * math.sqrt(p * (1 - p) / trials + z2 / (4 * trials * trials)) / (1 + z2 / trials)
    return Rate(successes, trials, p, max(0.0, centre - half), min(1.0, centre + half))


def summarize(rows: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """Counts by status, then, over the inputs that have figures (ok or skipped):

    - a boolean figure -> a rate with its 95 % interval (``rates``);
    - a numeric figure -> count, mean, median, min, max, p95 (``figures``).

    A figure whose value is a list holds one value per trial of its task (a task that simulates
    a chunk of runs): every element counts as one trial.
    """
    status = {s: sum(r.get("status") == s for r in rows) for s in ("ok", "skipped", "failed")}
    done = [r for r in rows if r.get("status") in ("ok", "skipped")]
    names: list[str] = []
    for r in done:
        for k in r.get("figures") or {}:
            if k not in names:
                names.append(k)
    rates: dict[str, Any] = {}
    figures: dict[str, Any] = {}
    for name in names:
        vals: list[Any] = []
        for r in done:
            v = (r.get("figures") or {}).get(name)
            # a list is one value per trial of a task (e.g. a chunk of simulated runs)
            vals.extend(v if isinstance(v, list) else [v])
        vals = [v for v in vals if v is not None]
        if vals and all(isinstance(v, bool) for v in vals):
            rate = wilson_interval(sum(bool(v) for v in vals), len(vals))
            rates[name] = {
                "successes": rate.successes,
                "trials": rate.trials,
                "rate": rate.rate,
                "ci95": [rate.low, rate.high],
                "text": str(rate),
            }
        elif vals and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals):
            a = np.asarray(vals, dtype=float)
            a = a[np.isfinite(a)]
            if a.size:
                figures[name] = {
                    "n": int(a.size),
                    "mean": float(a.mean()),
                    "median": float(np.median(a)),
                    "min": float(a.min()),
                    "max": float(a.max()),
                    "p95": float(np.percentile(a, 95)),
                }
    seconds = [r["seconds"] for r in rows if r.get("status") == "ok" and r.get("seconds")]
    return {
        "inputs": len(rows),
        **status,
        "task_seconds_total": float(sum(seconds)),
        "task_seconds_median": float(np.median(seconds)) if seconds else None,
        "workers": sorted({str(r["worker"]) for r in rows if r.get("worker")}),
        "rates": rates,
        "figures": figures,
        "failures": [
            {"key": r["key"], "error": r.get("error")} for r in rows if r.get("status") == "failed"
        ],
    }
