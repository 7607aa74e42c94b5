"""Write output files atomically: a reader never sees a half-written file.

Data go to a temporary file in the same folder, which replaces the target only when the write
succeeded; on any error the temporary file is removed and the old target (if any) is untouched.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

import numpy as np

__all__ = [
    "atomic_path",
    "atomic_write",
    "read_json",
    "settings_to_toml",
    "to_jsonable",
    "write_json",
    "write_run_files",
    "write_text",
]


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; it replaces ``path`` when the block succeeds.

    The temporary name keeps the target's suffix, so writers that pick a format by extension
    (OpenCV's ``imwrite``, matplotlib's ``savefig``) still work.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=target.suffix)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; outputs get the usual permissions
    try:
        yield Path(tmp)
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "w") -> Iterator[IO[Any]]:
    """Open a temporary file for writing (``"w"`` text, ``"wb"`` binary); commit on success."""
    with atomic_path(path) as tmp, open(tmp, mode, encoding=None if "b" in mode else "utf-8") as fh:
        yield fh


def to_jsonable(obj: Any) -> Any:
    """Convert NumPy scalars/arrays, paths and dataclasses to plain JSON types (NaN -> None)."""
    import dataclasses

    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return to_jsonable(obj.item())
    if isinstance(obj, float):
        return obj if np.isfinite(obj) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj


def write_json(path: str | os.PathLike[str], data: Any, indent: int = 2) -> None:
    """Write ``data`` as JSON atomically (NumPy types converted, NaN written as null)."""
    with atomic_write(path) as fh:
        json.dump(to_jsonable(data), fh, indent=indent, allow_nan=False)
        fh.write("\n")


def write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write text atomically."""
    with atomic_write(path) as fh:
        fh.write(text)


def read_json(path: str | os.PathLike[str], *, what: str = "a JSON file") -> Any:
    """Read a JSON file (the one JSON reader of navkit).

    Raises
    ------
    DataNotFoundError
        The file does not exist.
    FormatError
        It is not UTF-8 JSON (the message names the file and ``what`` was expected).
    """
    import json

    from navkit.errors import DataNotFoundError, FormatError

    p = Path(path)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: no such file ({what})")
    try:
        return json.loads(p.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise FormatError(f"not valid JSON ({exc})", source=p, expected=what) from None


def settings_to_toml(settings: Any) -> str:
    """Settings (dataclasses, dicts, arrays) as TOML text; TOML has no null, so None values are
    left out."""
    import tomli_w

    def clean(value: Any) -> Any:
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items() if v is not None}
        if isinstance(value, list):
            return [clean(v) for v in value if v is not None]
        return value

    return tomli_w.dumps(clean(to_jsonable(settings)))


def write_run_files(
    out: str | os.PathLike[str],
    settings: Any,
    summary: dict[str, Any],
    *,
    reference: str | None = None,
) -> None:
    """Write ``settings.toml`` (the resolved settings; TOML has no null, so None values are left
    out) and ``summary.json`` (with the navkit version and the command line) into ``out``
    atomically: what every navkit run writes next to its outputs.

    Parameters
    ----------
    reference : str, optional
        What the summary's headline figures (errors, success rates, scores) are measured
        against, written as the ``"reference"`` field right after the version and the command
        line - e.g. ``"simulator ground truth"``, ``"SemanticKITTI labels"``, or, for a map
        located with the same log it was built from, ``"self-consistency: the map was built from
        this log's poses; not an accuracy figure"``. A ``"reference"`` key in ``summary`` is
        taken when the keyword is not given.
    """
    import sys

    from navkit import __version__

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "settings.toml", settings_to_toml(settings))
    head: dict[str, Any] = {"navkit_version": __version__, "argv": sys.argv[1:]}
    ref = reference if reference is not None else summary.get("reference")
    if ref is not None:
        head["reference"] = ref
    write_json(
        out / "summary.json", {**head, **{k: v for k, v in summary.items() if k != "reference"}}
    )
