"""Wall maps on disk: ``map.json`` (walls with extents and uncertainty, corners, outline) with
its occupancy grid as a ROS map_server ``map.pgm`` + ``map.yaml`` named by the JSON's ``grid``
key."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

from navkit.errors import FormatError
from navkit.io.atomic import read_json, write_json
from navkit.localization.mapping import WallMap

__all__ = ["read_map_truth", "read_wall_map", "write_wall_map"]


def read_wall_map(path: str | os.PathLike[str]) -> WallMap:
    """A :class:`WallMap` from ``map.json`` (with its occupancy grid when the file names one).

    Raises
    ------
    DataNotFoundError
        If the file is missing.
    FormatError
        If it is not JSON or not a wall map.
    """
    from navkit.io.maps import read_occupancy_grid

    p = Path(path)
    data = read_json(p, what="a map.json written by navkit map build")
    wall_map = WallMap.from_dict(data, source=str(p))
    grid = data.get("grid") if isinstance(data, dict) else None
    if grid and (p.parent / grid).is_file():
        g = read_occupancy_grid(p.parent / grid)
        wall_map = dataclasses.replace(
            wall_map, occupancy=g.occupancy, resolution=g.resolution, origin=g.origin_xy
        )
    return wall_map


def write_wall_map(folder: str | os.PathLike[str], wall_map: WallMap, source: str = "") -> None:
    """Write ``map.json`` and, when the map has a grid, ``map.pgm`` + ``map.yaml`` into
    ``folder`` (atomically)."""
    from navkit.io.maps import write_occupancy_grid

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    extra: dict[str, str] = {"source": source}
    if wall_map.occupancy is not None:
        write_occupancy_grid(out / "map", wall_map.occupancy, wall_map.resolution, wall_map.origin)
        extra["grid"] = "map.yaml"
    write_json(out / "map.json", {**wall_map.to_dict(), **extra})


def read_map_truth(folder: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The ``truth.json`` of a simulated frame folder (``walls``, ``corners``, ``size``), or None
    when the input is not a folder or has none."""
    p = Path(folder) / "truth.json"
    if not p.is_file():
        return None
    data = read_json(p, what="navkit's truth.json")
    if not isinstance(data, dict) or not {"walls", "corners", "size"} <= set(data):
        raise FormatError(
            "missing keys", source=p, field="walls/corners/size", expected="navkit's truth.json"
        )
    return data
