"""NumPy ``.npy`` / ``.npz`` files read with their declared sizes checked first.

``np.load`` trusts the header: a 100-byte ``.npy`` member of a ``.npz`` that declares a shape of
10^12 makes NumPy allocate the whole array before reading, and an empty or truncated file raises
``EOFError``, ``zipfile.BadZipFile`` or ``ValueError`` deep inside NumPy. These readers parse the
header, compare the declared bytes with what the file (or the zip member) can hold, refuse
object arrays (no pickles), and raise :class:`navkit.errors.FormatError` naming the file and the
array.
"""

from __future__ import annotations

import io
import os
import zipfile
import zlib
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray

from navkit.errors import DataNotFoundError, FormatError

__all__ = ["read_npy", "read_npz"]

#: Deflate never expands more than about 1032:1; a member declaring more is lying.
_MAX_DEFLATE_RATIO = 1032
#: NumPy writes headers of a few hundred bytes; NumPy itself refuses more than 10 kB by default.
_MAX_HEADER_BYTES = 1 << 16


def _existing(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: no such file")
    return p


def _read_array(fh: IO[bytes], available: int, source: Path, name: str) -> NDArray[Any]:
    """Read one ``.npy`` stream whose payload can be at most ``available`` bytes."""
    fmt = np.lib.format
    # the header's own length field is checked before anything of that length is read
    head = fh.read(8)
    if len(head) < 8 or head[:6] != b"\x93NUMPY" or head[6] not in (1, 2, 3):
        raise FormatError(
            "not a .npy array (bad magic)", source=source, field=name, expected="a .npy header"
        )
    size_field = fh.read(2 if head[6] == 1 else 4)
    header_len = int.from_bytes(size_field, "little")
    if len(size_field) not in (2, 4) or header_len > min(available, _MAX_HEADER_BYTES):
        raise FormatError(
            f"header length {header_len} bytes",
            source=source,
            field=name,
            expected=f"at most {min(available, _MAX_HEADER_BYTES)} bytes",
        )
    fh_header = io.BytesIO(head + size_field + fh.read(header_len))
    try:
        version = fmt.read_magic(fh_header)
        if version == (1, 0):
            shape, fortran, dtype = fmt.read_array_header_1_0(fh_header)
        else:
            shape, fortran, dtype = fmt.read_array_header_2_0(fh_header)
    except Exception as exc:  # NumPy's header parser raises many kinds (tokenizer, literal_eval)
        raise FormatError(
            f"not a .npy array: {exc}", source=source, field=name, expected="a NumPy .npy header"
        ) from None
    if not all(isinstance(d, int) and d >= 0 for d in shape):
        raise FormatError(
            f"shape {shape}", source=source, field=name, expected="non-negative dimensions"
        )
    if dtype.hasobject:
        raise FormatError(
            "holds Python objects", source=source, field=name, expected="a numeric array"
        )
    count = int(np.prod(shape, dtype=np.float64)) if shape else 1
    nbytes = count * dtype.itemsize
    if nbytes > available:
        raise FormatError(
            f"declares {shape} {dtype} = {nbytes} bytes but holds at most {available}",
            source=source,
            field=name,
            expected="a complete array",
        )
    data = fh.read(nbytes)
    if len(data) != nbytes:
        raise FormatError(
            f"truncated: {len(data)} of {nbytes} bytes",
            source=source,
            field=name,
            expected="a complete array",
        )
    arr = np.frombuffer(data, dtype=dtype, count=count)
    return arr.reshape(shape[::-1]).T.copy() if fortran else arr.reshape(shape).copy()


def read_npy(path: str | os.PathLike[str]) -> NDArray[Any]:
    """Read a ``.npy`` file (no pickles), its declared size checked against the file's."""
    p = _existing(path)
    with open(p, "rb") as fh:
        return _read_array(fh, p.stat().st_size, p, "array")


def read_npz(path: str | os.PathLike[str]) -> dict[str, NDArray[Any]]:
    """Read every array of a ``.npz`` file (no pickles), each member's size checked first."""
    p = _existing(path)
    out: dict[str, NDArray[Any]] = {}
    try:
        with zipfile.ZipFile(p) as zf:
            for info in zf.infolist():
                name = info.filename.removesuffix(".npy")
                bound = info.file_size
                if info.compress_type != zipfile.ZIP_STORED:
                    bound = min(bound, info.compress_size * _MAX_DEFLATE_RATIO)
                with zf.open(info) as fh:
                    out[name] = _read_array(fh, bound, p, name)
    except (
        zipfile.BadZipFile,
        zipfile.LargeZipFile,
        zlib.error,
        EOFError,
        OSError,
        ValueError,
        NotImplementedError,  # compression methods / versions zipfile does not know
        RuntimeError,  # encrypted members
    ) as exc:
        if isinstance(exc, FormatError):
            raise
        raise FormatError(
            f"not a readable .npz: {exc}", source=p, expected="a NumPy .npz archive"
        ) from None
    return out
