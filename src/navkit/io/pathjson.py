"""``path.json``: the stored path on disk (format documented in ``docs/path.md``).

::

    {"format": "navkit-path", "version": 1, "tolerance": eps, "length": L,
     "frame": {...},
     "segments": [{"s0": s0, "length": l, "x": [a0, a1, a2, a3], "y": [b0, b1, b2, b3]}, ...]}

``x(s) = a0 + a1 u + a2 u^2 + a3 u^3`` with ``u = s - s0`` in ``[0, l]`` (the same for y),
segments in path order (after loop removal). Written atomically, read with every field checked.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from navkit.errors import FormatError
from navkit.io.atomic import read_json, write_json
from navkit.path.spline import PathSpline

__all__ = ["FORMAT", "VERSIONS", "read_path_json", "write_path_json"]

#: The ``format`` field every path.json carries, and the versions this reader understands.
FORMAT = "navkit-path"
VERSIONS = (1,)


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
        If it is not UTF-8 JSON, its ``format`` (when given) is not ``navkit-path``, its
        ``version`` (when given; absent = 1) is not one this navkit reads, its ``tolerance`` is not a finite distance > 0, or a field is
        missing / malformed (the message names the field).
    """
    p = Path(path)
    data = read_json(p, what="a path.json written by navkit")
    if not isinstance(data, dict):
        raise FormatError("top level is not an object", source=p, expected="a JSON object")
    # absent format / version: a hand-written file, read as version 1; present: must be known
    if data.get("format", FORMAT) != FORMAT:
        raise FormatError(
            f"format is {data.get('format')!r}", source=p, field="format", expected=repr(FORMAT)
        )
    version = data.get("version", VERSIONS[0])
    if isinstance(version, bool) or version not in VERSIONS:
        raise FormatError(
            f"version {version!r} is not known to this navkit",
            source=p,
            field="version",
            expected=" or ".join(map(str, VERSIONS)),
        )
    tol = data.get("tolerance")
    if tol is not None and (
        isinstance(tol, bool)
        or not isinstance(tol, (int, float))
        or not math.isfinite(tol)
        or tol <= 0
    ):
        raise FormatError(
            f"is {tol!r}", source=p, field="tolerance", expected="a finite distance > 0 (m)"
        )
    return PathSpline.from_dict(data, source=str(p))
