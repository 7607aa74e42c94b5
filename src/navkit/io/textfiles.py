"""Reading user text files (JSON, TOML, plain text) with one clear error per failure.

Every failure a user's file can cause - missing, a folder, unreadable, not UTF-8, not valid
JSON / TOML, nested so deeply that the parser recurses out of stack, too large - becomes a
:class:`navkit.errors.FormatError` (or :class:`~navkit.errors.DataNotFoundError`) naming the file,
never a traceback.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

from navkit.errors import DataNotFoundError, FormatError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = ["MAX_TEXT_BYTES", "load_json_file", "load_toml_file", "read_text_file"]

#: Largest settings / calibration / path file read as text (bytes): such files are kB; a larger
#: one is the wrong file, refused before it is read into memory.
MAX_TEXT_BYTES = 64 * 2**20


def read_text_file(path: str | os.PathLike[str], what: str = "a UTF-8 text file") -> str:
    """The text of ``path`` (UTF-8).

    Raises
    ------
    DataNotFoundError
        If ``path`` is not a file.
    FormatError
        If it cannot be read, is larger than :data:`MAX_TEXT_BYTES` or is not UTF-8.
    """
    p = Path(path)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: no such file")
    try:
        size = p.stat().st_size
        if size > MAX_TEXT_BYTES:
            raise FormatError(
                f"is {size} bytes", source=p, expected=f"{what} of at most {MAX_TEXT_BYTES} bytes"
            )
        return p.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise FormatError(
            f"not UTF-8 text (byte {exc.start}: {exc.reason})", source=p, expected=what
        ) from None
    except OSError as exc:
        raise FormatError(f"cannot be read: {exc.strerror}", source=p, expected=what) from None


def load_json_file(path: str | os.PathLike[str], what: str = "a JSON file") -> Any:
    """Parse ``path`` as JSON (errors as in :func:`read_text_file`, plus invalid / too deep)."""
    text = read_text_file(path, what)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise FormatError(
            f"not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})",
            source=path,
            expected=what,
        ) from None
    except RecursionError:
        raise FormatError("nested too deeply", source=path, expected=what) from None


def load_toml_file(path: str | os.PathLike[str], what: str = "a TOML file") -> dict[str, Any]:
    """Parse ``path`` as TOML (errors as in :func:`read_text_file`, plus invalid / too deep)."""
    text = read_text_file(path, what)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise FormatError(f"not valid TOML ({exc})", source=path, expected=what) from None
    except RecursionError:
        raise FormatError("nested too deeply", source=path, expected=what) from None
