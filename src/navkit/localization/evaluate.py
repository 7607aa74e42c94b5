"""A built wall map against the true walls (the figures of ``docs/localization.md``)."""

from __future__ import annotations

import logging

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.localization.mapping import WallMap

log = logging.getLogger(__name__)


def evaluate_map(
    wall_map: WallMap,
    true_walls: ArrayLike,
    true_corners: ArrayLike,
    *,
    max_distance: float = 0.5,
    max_angle_deg: float = 10.0,
) -> dict[str, object]:
    """Map accuracy against a known floor plan.

    Each true wall is matched to the map wall of nearly the same direction (within
    ``max_angle_deg``) whose line passes nearest the true wall's midpoint (within
    ``max_distance``), preferring the longest overlap; each true corner to the nearest map corner
    within ``max_distance``.

    Returns
    -------
    dict
        ``walls_found`` / ``walls_true``, ``wall_angle_error_deg`` (list; NaN = not found),
        ``wall_offset_error`` (metres, mean distance of the true end points' projections... the
        true midpoint to the map line), ``corners_found`` / ``corners_true``,
        ``corner_error`` (metres, list; NaN = not found), and their medians / maxima.
    """
    TW = np.asarray(true_walls, dtype=np.float64).reshape(-1, 2, 2)
    TC = np.asarray(true_corners, dtype=np.float64).reshape(-1, 2)
    ang_err, off_err = [], []
    for a, b in TW:
        d = (b - a) / np.linalg.norm(b - a)
        mid = 0.5 * (a + b)
        best, best_key = None, None
        for w in wall_map.walls:
            ang = np.degrees(np.arccos(min(1.0, abs(float(d @ w.direction)))))
            off = abs(float(w.distance(mid)[0]))
            if ang > max_angle_deg or off > max_distance:
                continue
            ts = sorted(float((p - a) @ d) for p in (w.start, w.end))
            overlap = min(ts[1], float(np.linalg.norm(b - a))) - max(ts[0], 0.0)
            if overlap <= 0:
                continue
            key = -overlap
            if best_key is None or key < best_key:
                best, best_key = (ang, off), key
        ang_err.append(np.nan if best is None else best[0])
        off_err.append(np.nan if best is None else best[1])
    C = np.array([c.point for c in wall_map.corners]).reshape(-1, 2)
    corner_err = []
    for c in TC:
        dist = np.linalg.norm(C - c, axis=1) if len(C) else np.array([np.inf])
        corner_err.append(float(dist.min()) if dist.min() <= max_distance else np.nan)
    ae, oe, ce = np.array(ang_err), np.array(off_err), np.array(corner_err)

    def stat(x: NDArray[np.float64], f) -> float:  # type: ignore[no-untyped-def]
        x = x[np.isfinite(x)]
        return float(f(x)) if len(x) else float("nan")

    return {
        "walls_true": len(TW),
        "walls_found": int(np.isfinite(ae).sum()),
        "walls_in_map": len(wall_map.walls),
        "wall_angle_error_deg": ae.tolist(),
        "wall_offset_error_m": oe.tolist(),
        "wall_angle_error_deg_median": stat(ae, np.median),
        "wall_angle_error_deg_max": stat(ae, np.max),
        "wall_offset_error_m_median": stat(oe, np.median),
        "corners_true": len(TC),
        "corners_found": int(np.isfinite(ce).sum()),
        "corners_in_map": len(wall_map.corners),
        "corner_error_m": ce.tolist(),
        "corner_error_m_median": stat(ce, np.median),
        "corner_error_m_max": stat(ce, np.max),
        "outline_found": wall_map.outline is not None,
    }
