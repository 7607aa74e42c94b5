"""Per-frame outputs of the obstacle detector: labels, ``obstacles.json``, GeoJSON features.

Formats (see ``docs/formats.md``):

- ``labels.npy``: int8, one class per input point (the input's order; ``(n_az, n_el)`` for a
  ``.npz`` range scan): 0 ground, -1 unreliable, -2 obstacle, -3 side shadow, -4 shadow behind.
- ``obstacles.json``: the input, the frame, the sensor position and, per obstacle, its boundary
  polygon and the parameters of every bounding shape (A1-A7, MEC, MVEE), compact JSON with
  lengths rounded to 1 mm.
- ``map.geojson`` (georeferenced runs only): every obstacle's boundary polygon and its chosen
  shapes (circles and ellipses as 36-gons) in WGS84 (:func:`navkit.io.maps.write_geojson`).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from navkit.io.atomic import atomic_path, atomic_write, to_jsonable
from navkit.io.maps import GeoOrigin, point_geometry, polygon_geometry, write_geojson

__all__ = [
    "BODY_FRAME",
    "CLASS_NAMES",
    "obstacle_features",
    "write_frame_status",
    "write_labels",
    "write_obstacle_geojson",
    "write_obstacles_json",
]

CLASS_NAMES = {
    "0": "ground",
    "-1": "unreliable",
    "-2": "obstacle",
    "-3": "side shadow",
    "-4": "shadow behind",
}
"""Label value -> class name (``labels.npy`` and the map figure)."""

BODY_FRAME = "body (x forward, y left, z up, origin on the ground under the sensor)"


def _rounded(value: Any, decimals: int) -> Any:
    """Plain JSON of ``value`` with every float rounded to ``decimals`` and NaN / inf -> None
    (like :func:`~navkit.io.atomic.to_jsonable`, in one pass; float arrays rounded by NumPy)."""
    if isinstance(value, float):
        return round(value, decimals) if math.isfinite(value) else None
    if value is None or isinstance(value, (bool, int, str)):
        return value
    if isinstance(value, dict):
        return {str(k): _rounded(v, decimals) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        if value and isinstance(value[0], (list, tuple)) and value[0]:
            try:  # a polygon / point list: round all at once
                arr = np.asarray(value, dtype=np.float64)
            except (TypeError, ValueError):  # ragged, or not numbers
                arr = None
            if arr is not None and arr.ndim == 2 and isinstance(value[0][0], float):
                return _rounded(arr, decimals)
        return [_rounded(v, decimals) for v in value]
    if isinstance(value, np.ndarray):
        if value.dtype.kind == "f":
            r = np.round(value.astype(np.float64), decimals)
            if np.all(np.isfinite(r)):
                return r.tolist()
            return [_rounded(v, decimals) for v in r.tolist()]
        return _rounded(value.tolist(), decimals)
    if isinstance(value, np.generic):
        return _rounded(value.item(), decimals)
    return _rounded(to_jsonable(value), decimals)


def write_frame_status(path: str | Path, rows: list[tuple[str, str, str, int | None, str]]) -> None:
    """Write the per-frame status CSV ``frame,input,status,n_obstacles,reason`` (atomically);
    ``status`` is ``ok`` or ``failed`` (then ``n_obstacles`` is empty and ``reason`` says why)."""
    import csv
    import io

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["frame", "input", "status", "n_obstacles", "reason"])
    for frame, source, status, n, reason in rows:
        w.writerow([frame, source, status, "" if n is None else n, reason])
    with atomic_write(path) as fh:
        fh.write(buf.getvalue())


def write_labels(path: str | Path, labels: NDArray[Any]) -> None:
    """Write per-point labels as an int8 ``.npy`` (atomically)."""
    with atomic_path(path) as tmp:
        np.save(tmp, np.asarray(labels, dtype=np.int8))


def write_obstacles_json(
    path: str | Path,
    detection: Any,
    *,
    source: str,
    extra: dict[str, Any] | None = None,
    decimals: int = 3,
) -> None:
    """Write ``obstacles.json`` for one detection (compact, lengths rounded to ``decimals``).

    Parameters
    ----------
    detection : ObstacleDetection
    source : str
        The input file, recorded in the file.
    extra : dict, optional
        More top-level members (e.g. the sensor height used and where it came from).
    """
    data = {
        "input": source,
        "frame": BODY_FRAME,
        "sensor": detection.sensor_origin,
        "classes": CLASS_NAMES,
        **(extra or {}),
        "obstacles": [ob.to_dict() for ob in detection.obstacles],
    }
    text = json.dumps(_rounded(data, decimals), separators=(",", ":"), allow_nan=False)
    with atomic_write(path) as fh:  # dumps (C encoder) then one write: dump() is pure Python
        fh.write(text + "\n")


def obstacle_features(
    detection: Any, shapes: tuple[str, ...] = ("A1", "A6"), vertices: int = 36
) -> list[tuple[dict[str, Any], dict[str, Any]]]:
    """GeoJSON ``(geometry, properties)`` pairs in local metres: the sensor, each obstacle's
    boundary polygon, and its ``shapes`` (circles and ellipses as ``vertices``-gons, with the
    shape parameters as properties)."""
    feats: list[tuple[dict[str, Any], dict[str, Any]]] = [
        (point_geometry(detection.sensor_origin[:2]), {"kind": "sensor"})
    ]
    for ob in detection.obstacles:
        feats.append(
            (
                polygon_geometry(ob.polygon_xy),
                {
                    "kind": "boundary",
                    "obstacle": ob.id,
                    "height": ob.height,
                    "n_points": ob.n_points,
                    "shadow_area": ob.shadow_area,
                },
            )
        )
        for name in shapes:
            if name in ob.shapes:
                shp = ob.shapes[name]
                feats.append(
                    (
                        polygon_geometry(shp.outline(vertices)),
                        {"kind": "shape", "shape": name, "obstacle": ob.id, **shp.params()},
                    )
                )
    return feats


def write_obstacle_geojson(
    path: str | Path,
    detection: Any,
    origin: GeoOrigin,
    *,
    shapes: tuple[str, ...] = ("A1", "A6"),
    source: str = "",
) -> None:
    """Write one detection's obstacles as WGS84 GeoJSON, the body frame placed at ``origin``."""
    write_geojson(
        path,
        obstacle_features(detection, shapes),
        properties={"frame": BODY_FRAME, "input": source},
        origin=origin,
    )
