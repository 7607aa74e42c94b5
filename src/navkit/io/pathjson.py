"""``path.json``: the stored path on disk (format documented in ``docs/path.md``).

::

    {"format": "navkit-path", "version": 1, "tolerance": eps, "length": L,
     "frame": {...},
     "segments": [{"s0": s0, "length": l, "x": [a0, a1, a2, a3], "y": [b0, b1, b2, b3]}, ...]}

``x(s) = a0 + a1 u + a2 u^2 + a3 u^3`` with ``u = s - s0`` in ``[0, l]`` (the same for y),
segments in path order (after loop removal). Written atomically, read with every field checked.
"""

from __future__ import annotations

import os
from pathlib import Path

from navkit.io.atomic import read_json, write_json
from navkit.path.spline import PathSpline

__all__ = ["read_path_json", "write_path_json"]


def write_path_json(path: str | os.PathLike[str], spline: PathSpline) -> Path:
    """Write ``spline`` to ``path`` atomically (a failed write leaves no partial file)."""
    write_json(path, spline.to_dict())
    return Path(path)


def read_path_json(path: str | os.PathLike[str]) -> PathSpline:
    """Read a ``path.json``.

    Raises
    ------
    DataNotFoundError
        If the file does not exist.
    FormatError
        If it is not JSON or a field is missing / malformed (the message names the field).
    """
    p = Path(path)
    data = read_json(p, what="a path.json written by navkit")
    return PathSpline.from_dict(data, source=str(p))
