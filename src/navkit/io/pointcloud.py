"""Point-cloud files: KITTI ``.bin`` / ``.label``, PCD v0.7 and PLY.

All readers validate what they read and raise :class:`navkit.errors.FormatError` naming the file,
the field and what was expected; a file that does not exist raises
:class:`navkit.errors.DataNotFoundError`. Writers are atomic (:mod:`navkit.io.atomic`): a failed
write never leaves a half-written file.

Conventions
-----------
- Points are returned as ``(N, 3)`` float64 rows (x, y, z in the file's units, normally metres);
  every other per-point field keeps the file's dtype in :attr:`PointCloud.fields` (shape ``(N,)``,
  or ``(N, COUNT)`` for PCD fields with ``COUNT > 1``).
- Colours are ``(N, 3)`` uint8 RGB in :attr:`PointCloud.colors`. In PCD they are the packed
  ``rgb`` / ``rgba`` field (a float32 or uint32 holding ``0xAARRGGBB``); the alpha byte of an
  ``rgba`` field is kept as ``fields["alpha"]``.
- Organised clouds (PCD ``HEIGHT > 1``) keep their ``WIDTH x HEIGHT`` layout: point ``i`` is
  row ``i // width``, column ``i % width``; :meth:`PointCloud.grid` reshapes. Invalid points
  (NaN coordinates) are kept, never dropped.
- PCD ``binary_compressed`` uses LZF (liblzf's format); :func:`lzf_decompress` and
  :func:`lzf_compress` implement it here without extra dependencies.
"""

from __future__ import annotations

import logging
import os
import re
from bisect import bisect_left
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import DataNotFoundError, FormatError, InputError
from navkit.io.atomic import atomic_write

__all__ = [
    "PointCloud",
    "lzf_compress",
    "lzf_decompress",
    "read_kitti_bin",
    "read_kitti_labels",
    "read_pcd",
    "read_ply",
    "write_kitti_bin",
    "write_kitti_labels",
    "write_pcd",
    "write_ply",
]

log = logging.getLogger(__name__)

PathLike = str | os.PathLike[str]

_COLOR_FIELDS = ("rgb", "rgba")


# --------------------------------------------------------------------------- the cloud type
@dataclass(frozen=True, eq=False)
class PointCloud:
    """A point cloud with optional per-point fields, colours and mesh faces.

    Parameters
    ----------
    points : (N, 3) float64 array
        x, y, z of each point (NaN rows = invalid points of an organised cloud).
    fields : dict of str to array, optional
        Other per-point fields, each of length ``N`` (``(N,)`` or ``(N, k)``), in the file's
        dtype, e.g. ``intensity``, ``normal_x``, ``label``.
    width, height : int, optional
        Layout; ``height == 1`` (default) is an unorganised cloud, ``width * height == N``.
    colors : (N, 3) uint8 array, optional
        RGB colours.
    faces : (M, k) int64 array, optional
        Polygon vertex indices (PLY meshes); ``k == 3`` for triangles.
    """

    points: NDArray[np.float64]
    fields: dict[str, NDArray[Any]] = field(default_factory=dict)
    width: int = -1
    height: int = 1
    colors: NDArray[np.uint8] | None = None
    faces: NDArray[np.int64] | None = None

    def __post_init__(self) -> None:
        pts = np.asarray(self.points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise InputError(
                f"points has shape {pts.shape}", field="points", expected="an (N, 3) array"
            )
        n = len(pts)
        object.__setattr__(self, "points", pts)
        width = n if self.width == -1 and self.height == 1 else int(self.width)
        height = int(self.height)
        if width < 0 or height < 1 or width * height != n:
            raise InputError(
                f"width {width} x height {height} does not match {n} points",
                field="width/height",
                expected="width * height == number of points",
            )
        object.__setattr__(self, "width", width)
        object.__setattr__(self, "height", height)
        fields = {}
        for name, value in dict(self.fields).items():
            arr = np.asarray(value)
            if arr.ndim == 0 or len(arr) != n:
                raise InputError(
                    f"has {0 if arr.ndim == 0 else len(arr)} values for {n} points",
                    field=name,
                    expected="one value (or one row) per point",
                )
            fields[str(name)] = arr
        object.__setattr__(self, "fields", fields)
        if self.colors is not None:
            col = np.asarray(self.colors)
            if col.shape != (n, 3):
                raise InputError(
                    f"colors has shape {col.shape}", field="colors", expected=f"({n}, 3) uint8"
                )
            if col.dtype != np.uint8:
                if np.issubdtype(col.dtype, np.floating) and np.nanmax(col, initial=0.0) <= 1.0:
                    col = np.clip(np.round(col * 255.0), 0, 255)
                col = col.astype(np.uint8)
            object.__setattr__(self, "colors", col)
        if self.faces is not None:
            fc = np.asarray(self.faces, dtype=np.int64)
            if fc.ndim != 2 or fc.shape[1] < 3:
                raise InputError(
                    f"faces has shape {fc.shape}", field="faces", expected="an (M, k>=3) array"
                )
            if fc.size and (fc.min() < 0 or fc.max() >= n):
                raise InputError(
                    f"face indices span [{fc.min()}, {fc.max()}] for {n} vertices",
                    field="faces",
                    expected=f"indices in [0, {n - 1}]",
                )
            object.__setattr__(self, "faces", fc)

    def __len__(self) -> int:
        return len(self.points)

    @property
    def is_organized(self) -> bool:
        """True for an image-like cloud (``height > 1``)."""
        return self.height > 1

    def grid(self) -> NDArray[np.float64]:
        """The points as an ``(height, width, 3)`` grid (a view; row-major like the file)."""
        return self.points.reshape(self.height, self.width, 3)

    @property
    def valid(self) -> NDArray[np.bool_]:
        """``(N,)`` True where all three coordinates are finite."""
        return np.asarray(np.isfinite(self.points).all(axis=1))


# --------------------------------------------------------------------------- helpers
def _existing(path: PathLike) -> Path:
    p = Path(path)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: no such file")
    return p


# --------------------------------------------------------------------------- KITTI
def read_kitti_bin(path: PathLike) -> NDArray[np.float32]:
    """Read a KITTI / SemanticKITTI Velodyne scan.

    Parameters
    ----------
    path : str or path
        A ``.bin`` file: little-endian float32 records ``x, y, z, reflectance`` (metres, [0, 1]).

    Returns
    -------
    (N, 4) float32 array
        One row per point, in the Velodyne frame (x forward, y left, z up).

    Raises
    ------
    FormatError
        If the size is not a multiple of 16 bytes (a truncated or foreign file).
    """
    p = _existing(path)
    size = p.stat().st_size
    if size % 16:
        raise FormatError(
            f"size is {size} bytes, not a multiple of 16 (truncated?)",
            source=p,
            field="points",
            expected="float32 records x, y, z, reflectance (16 bytes each)",
        )
    return np.fromfile(p, dtype="<f4").reshape(-1, 4)


def write_kitti_bin(path: PathLike, points: ArrayLike) -> None:
    """Write ``(N, 4)`` (x, y, z, reflectance) or ``(N, 3)`` (reflectance 0) as a KITTI ``.bin``."""
    pts = np.asarray(points, dtype=np.float32)
    if pts.ndim != 2 or pts.shape[1] not in (3, 4):
        raise InputError(
            f"points has shape {pts.shape}", field="points", expected="an (N, 3) or (N, 4) array"
        )
    if pts.shape[1] == 3:
        pts = np.column_stack([pts, np.zeros(len(pts), np.float32)])
    with atomic_write(path, "wb") as fh:
        fh.write(np.ascontiguousarray(pts, dtype="<f4").tobytes())


def read_kitti_labels(
    path: PathLike, n_points: int | None = None
) -> tuple[NDArray[np.uint16], NDArray[np.uint16]]:
    """Read SemanticKITTI point labels.

    Parameters
    ----------
    path : str or path
        A ``.label`` file: one little-endian uint32 per point.
    n_points : int, optional
        Number of points of the matching scan; a different label count is an error.

    Returns
    -------
    semantic : (N,) uint16
        Class id ``l & 0xFFFF`` (names in ``semantic-kitti.yaml``).
    instance : (N,) uint16
        Instance id ``l >> 16``.
    """
    p = _existing(path)
    size = p.stat().st_size
    if size % 4:
        raise FormatError(
            f"size is {size} bytes, not a multiple of 4 (truncated?)",
            source=p,
            field="labels",
            expected="one uint32 per point",
        )
    raw = np.fromfile(p, dtype="<u4")
    if n_points is not None and len(raw) != n_points:
        raise FormatError(
            f"holds {len(raw)} labels but the scan has {n_points} points",
            source=p,
            field="labels",
            expected=f"{n_points} labels",
        )
    return (raw & 0xFFFF).astype(np.uint16), (raw >> 16).astype(np.uint16)


def write_kitti_labels(
    path: PathLike, semantic: ArrayLike, instance: ArrayLike | None = None
) -> None:
    """Write SemanticKITTI labels ``semantic | instance << 16`` as uint32."""
    sem = np.asarray(semantic).astype(np.uint32)
    inst = np.zeros_like(sem) if instance is None else np.asarray(instance).astype(np.uint32)
    if sem.ndim != 1 or inst.shape != sem.shape:
        raise InputError(
            f"semantic {sem.shape} / instance {inst.shape}",
            field="labels",
            expected="two (N,) arrays of the same length",
        )
    with atomic_write(path, "wb") as fh:
        fh.write(((sem & 0xFFFF) | (inst << 16)).astype("<u4").tobytes())


# --------------------------------------------------------------------------- LZF
class LZFError(ValueError):
    """A corrupt LZF stream (wrapped into FormatError by the PCD reader)."""


def lzf_decompress(data: bytes | bytearray | memoryview, expected_size: int) -> bytes:
    """Decompress an LZF stream (liblzf format, as used by PCD ``binary_compressed``).

    The stream is a sequence of tokens: a control byte ``c < 32`` starts a literal run of
    ``c + 1`` bytes; otherwise ``c >> 5`` is the back-reference length - 2 (7 = read one more
    length byte) and ``((c & 31) << 8) + next byte + 1`` the distance back into the output.
    Decoding is inherently sequential; the loop runs once per *token* and copies with C-level
    slice assignments (overlapping references repeat their period), so a typical PCD payload
    decodes at tens of MB/s.

    Parameters
    ----------
    data : bytes
        The compressed stream.
    expected_size : int
        The exact uncompressed size in bytes.

    Raises
    ------
    LZFError
        If a token runs past the input, refers before the start of the output, or the output
        size differs from ``expected_size``.
    """
    src = bytes(data)
    n_in = len(src)
    out = bytearray(expected_size)
    ip = 0
    op = 0
    while ip < n_in:
        c = src[ip]
        ip += 1
        if c < 32:  # literal run
            c += 1
            if ip + c > n_in:
                raise LZFError(
                    f"literal run of {c} bytes at input offset {ip - 1} runs past the end"
                )
            if op + c > expected_size:
                raise LZFError(f"output exceeds the declared {expected_size} bytes")
            out[op : op + c] = src[ip : ip + c]
            ip += c
            op += c
        else:  # back reference
            length = c >> 5
            if length == 7:
                if ip >= n_in:
                    raise LZFError("back reference truncated at the end of the input")
                length += src[ip]
                ip += 1
            if ip >= n_in:
                raise LZFError("back reference truncated at the end of the input")
            ref = op - ((c & 0x1F) << 8) - src[ip] - 1
            ip += 1
            length += 2
            if ref < 0:
                raise LZFError(f"back reference before the start of the output (at {op})")
            if op + length > expected_size:
                raise LZFError(f"output exceeds the declared {expected_size} bytes")
            end = ref + length
            if end <= op:
                out[op : op + length] = out[ref:end]
            else:  # overlapping copy: the last (op - ref) bytes repeat
                period = out[ref:op]
                reps = -(-length // len(period))
                out[op : op + length] = (period * reps)[:length]
            op += length
    if op != expected_size:
        raise LZFError(f"decompressed to {op} bytes, the header declares {expected_size}")
    return bytes(out)


_LZF_MAX_OFF = 1 << 13  # 8192: distances 1..8192
_LZF_MAX_REF = 264  # 2 + 7 + 255
_LZF_MAX_LIT = 32


def lzf_compress(data: bytes | bytearray | memoryview) -> bytes:
    """Compress bytes into an LZF stream that liblzf (PCL, Open3D) decompresses.

    Candidate matches are found vectorised: every position's 3-byte prefix is keyed exactly
    (24 bits, no hash collisions) and a stable sort gives each position the most recent earlier
    position with the same prefix. A greedy parse then walks the input token by token (jumping
    straight to the next usable candidate), extends each match with a binary search over C-level
    slice comparisons, and emits literal runs of at most 32 bytes and back references of at most
    264 bytes within 8192 bytes, as liblzf does.
    """
    src = bytes(data)
    n = len(src)
    out = bytearray()
    if n == 0:
        return bytes(out)
    a = np.frombuffer(src, dtype=np.uint8)
    if n >= 3:
        key = (a[:-2].astype(np.int32) << 16) | (a[1:-1].astype(np.int32) << 8) | a[2:]
        # stable sort of the 24-bit keys as two LSD radix passes (NumPy's stable sort of
        # 16- and 8-bit integers is a radix sort: ~7x faster than sorting int32 keys)
        order = np.argsort((key & 0xFFFF).astype(np.uint16), kind="stable")
        order = order[np.argsort((key >> 16).astype(np.uint8)[order], kind="stable")]
        ks = key[order]
        same = ks[1:] == ks[:-1]
        prev = np.full(n - 2, -1, dtype=np.int64)
        prev[order[1:][same]] = order[:-1][same]  # most recent earlier position, same prefix
        pos = np.arange(n - 2)
        cand = np.flatnonzero((prev >= 0) & (pos - prev <= _LZF_MAX_OFF))
        cand_l: list[int] = cand.tolist()
        prev_l: list[int] = prev[cand].tolist()
    else:
        cand_l, prev_l = [], []

    def emit_literal(start: int, stop: int) -> None:
        while start < stop:
            k = min(_LZF_MAX_LIT, stop - start)
            out.append(k - 1)
            out.extend(src[start : start + k])
            start += k

    i = 0
    lit = 0
    c = 0  # index into the candidate list
    n_cand = len(cand_l)
    while True:
        c = bisect_left(cand_l, i, c)  # next usable candidate at or after i
        if c >= n_cand:
            break
        i = cand_l[c]
        p = prev_l[c]
        max_len = min(_LZF_MAX_REF, n - i)
        # the 3-byte prefix matches; extend by binary search (prefix equality is monotone)
        if max_len > 3 and src[i + 3] == src[p + 3]:
            lo, hi = 4, max_len
            while lo < hi:
                mid = (lo + hi + 1) >> 1
                if src[i : i + mid] == src[p : p + mid]:
                    lo = mid
                else:
                    hi = mid - 1
            length = lo
        else:
            length = 3
        emit_literal(lit, i)
        off = i - p - 1
        ln = length - 2
        if ln < 7:
            out.append((ln << 5) | (off >> 8))
        else:
            out.append((7 << 5) | (off >> 8))
            out.append(ln - 7)
        out.append(off & 0xFF)
        i += length
        lit = i
    emit_literal(lit, n)
    return bytes(out)


# --------------------------------------------------------------------------- PCD
_PCD_TYPES = {
    ("F", 4): "<f4",
    ("F", 8): "<f8",
    ("I", 1): "i1",
    ("I", 2): "<i2",
    ("I", 4): "<i4",
    ("I", 8): "<i8",
    ("U", 1): "u1",
    ("U", 2): "<u2",
    ("U", 4): "<u4",
    ("U", 8): "<u8",
}


@dataclass(frozen=True)
class _PcdHeader:
    fields: list[str]
    sizes: list[int]
    types: list[str]
    counts: list[int]
    width: int
    height: int
    points: int
    data: str
    viewpoint: tuple[float, ...]
    data_offset: int

    def dtype(self) -> np.dtype[Any]:
        names, formats = [], []
        for i, (name, size, typ, count) in enumerate(
            zip(self.fields, self.sizes, self.types, self.counts, strict=True)
        ):
            base = _PCD_TYPES[(typ, size)]
            names.append(name if name != "_" else f"_pad{i}")
            formats.append(base if count == 1 else (base, (count,)))
        return np.dtype({"names": names, "formats": formats})


def _parse_pcd_header(p: Path, buf: bytes) -> _PcdHeader:
    entries: dict[str, list[str]] = {}
    offset = 0
    data_offset = -1
    while offset < len(buf):
        nl = buf.find(b"\n", offset)
        end = len(buf) if nl < 0 else nl
        line = buf[offset:end].decode("ascii", errors="replace").strip()
        offset = end + 1
        if not line or line.startswith("#"):
            continue
        key, *values = line.split()
        key = key.upper()
        if key not in {
            "VERSION",
            "FIELDS",
            "COLUMNS",
            "SIZE",
            "TYPE",
            "COUNT",
            "WIDTH",
            "HEIGHT",
            "VIEWPOINT",
            "POINTS",
            "DATA",
        }:
            raise FormatError(
                f"unknown header line {line[:40]!r}",
                source=p,
                field="header",
                expected="PCD v0.7 header keys (VERSION FIELDS SIZE TYPE COUNT WIDTH HEIGHT "
                "VIEWPOINT POINTS DATA)",
            )
        entries["FIELDS" if key == "COLUMNS" else key] = values
        if key == "DATA":
            data_offset = min(offset, len(buf))
            break
    if data_offset < 0:
        raise FormatError("no DATA line", source=p, field="DATA", expected="a PCD v0.7 header")

    def need(key: str) -> list[str]:
        if key not in entries or not entries[key]:
            raise FormatError(
                "missing from the header", source=p, field=key, expected="a PCD v0.7 header"
            )
        return entries[key]

    def ints(key: str, values: list[str]) -> list[int]:
        try:
            out = [int(v) for v in values]
        except ValueError:
            raise FormatError(
                f"non-integer values {values[:6]}", source=p, field=key, expected="integers"
            ) from None
        if any(v < 0 for v in out):
            raise FormatError(f"negative values {values[:6]}", source=p, field=key)
        return out

    names = need("FIELDS")
    nf = len(names)
    sizes = ints("SIZE", need("SIZE"))
    types = [t.upper() for t in need("TYPE")]
    counts = ints("COUNT", entries.get("COUNT", ["1"] * nf))
    for key, nvals in (("SIZE", len(sizes)), ("TYPE", len(types)), ("COUNT", len(counts))):
        if nvals != nf:
            raise FormatError(
                f"has {nvals} entries for {nf} fields {names}",
                source=p,
                field=key,
                expected=f"{nf} entries, one per field",
            )
    for name, size, typ in zip(names, sizes, types, strict=True):
        if (typ, size) not in _PCD_TYPES:
            raise FormatError(
                f"field {name!r} has TYPE {typ} with SIZE {size}",
                source=p,
                field="TYPE",
                expected="F with size 4/8, I or U with size 1/2/4/8",
            )
    real = [n for n in names if n != "_"]
    if len(set(real)) != len(real):
        raise FormatError(f"duplicate field names {names}", source=p, field="FIELDS")
    width = ints("WIDTH", need("WIDTH")[:1])[0]
    height = ints("HEIGHT", entries.get("HEIGHT", ["1"])[:1])[0]
    points = ints("POINTS", entries.get("POINTS", [str(width * height)])[:1])[0]
    if points != width * height:
        raise FormatError(
            f"POINTS {points} differs from WIDTH {width} x HEIGHT {height}",
            source=p,
            field="POINTS",
            expected="POINTS == WIDTH * HEIGHT",
        )
    data = need("DATA")[0].lower()
    if data not in ("ascii", "binary", "binary_compressed"):
        raise FormatError(
            f"unknown encoding {data!r}",
            source=p,
            field="DATA",
            expected="ascii, binary or binary_compressed",
        )
    try:
        viewpoint = tuple(
            float(v) for v in entries.get("VIEWPOINT", ["0", "0", "0", "1", "0", "0", "0"])
        )
    except ValueError:
        raise FormatError(
            "non-numeric", source=p, field="VIEWPOINT", expected="7 numbers"
        ) from None
    return _PcdHeader(
        names, sizes, types, counts, width, height, points, data, viewpoint, data_offset
    )


def _pcd_records_ascii(p: Path, hdr: _PcdHeader, body: bytes) -> dict[str, NDArray[Any]]:
    ncol = sum(hdr.counts)
    tokens = np.array(body.split(), dtype=np.bytes_)
    if tokens.size != hdr.points * ncol:
        lines = body.count(b"\n")
        raise FormatError(
            f"DATA holds {tokens.size} values in about {lines} lines",
            source=p,
            field="DATA",
            expected=f"{hdr.points} points x {ncol} values = {hdr.points * ncol}",
        )
    tokens = tokens.reshape(hdr.points, ncol)
    out: dict[str, NDArray[Any]] = {}
    col = 0
    for name, size, typ, count in zip(hdr.fields, hdr.sizes, hdr.types, hdr.counts, strict=True):
        block = tokens[:, col : col + count]
        col += count
        if name == "_":
            continue
        dtype = np.dtype(_PCD_TYPES[(typ, size)])
        try:
            if name in _COLOR_FIELDS and typ == "F" and size == 4 and np.char.isdigit(block).all():
                # PCL writes the packed colour of an ascii file as its uint32 bit pattern
                vals = block.astype(np.uint64).astype("<u4").view("<f4")
            elif typ == "F":
                vals = block.astype(np.float64).astype(dtype)
            else:
                vals = block.astype(np.float64)
                if not np.all(vals == np.round(vals)):
                    raise ValueError("non-integer")
                vals = vals.astype(dtype)
        except ValueError:
            raise FormatError(
                "non-numeric or non-integer values",
                source=p,
                field=name,
                expected=f"{'floats' if typ == 'F' else 'integers'} (TYPE {typ})",
            ) from None
        out[name] = vals[:, 0] if count == 1 else vals
    return out


def _pcd_records_binary(p: Path, hdr: _PcdHeader, body: memoryview) -> dict[str, NDArray[Any]]:
    dt = hdr.dtype()
    need = hdr.points * dt.itemsize
    if len(body) < need:
        raise FormatError(
            f"DATA truncated: {len(body)} bytes for {hdr.points} points",
            source=p,
            field="DATA",
            expected=f"{need} bytes ({hdr.points} x {dt.itemsize})",
        )
    rec = np.frombuffer(body, dtype=dt, count=hdr.points)
    return {name: rec[name].copy() for name in dt.names or () if not name.startswith("_pad")}


def _pcd_records_compressed(p: Path, hdr: _PcdHeader, body: memoryview) -> dict[str, NDArray[Any]]:
    if len(body) < 8:
        raise FormatError(
            f"DATA truncated: {len(body)} bytes",
            source=p,
            field="DATA",
            expected="uint32 compressed size, uint32 uncompressed size, LZF data",
        )
    csize, usize = (int(v) for v in np.frombuffer(body[:8], dtype="<u4"))
    dt = hdr.dtype()
    need = hdr.points * dt.itemsize
    if usize != need:
        raise FormatError(
            f"uncompressed size {usize} bytes does not fit {hdr.points} points of {dt.itemsize} bytes",
            source=p,
            field="DATA",
            expected=f"{need} bytes",
        )
    if len(body) - 8 < csize:
        raise FormatError(
            f"DATA truncated: {len(body) - 8} compressed bytes, the header declares {csize}",
            source=p,
            field="DATA",
            expected=f"{csize} bytes of LZF data",
        )
    try:
        raw = lzf_decompress(body[8 : 8 + csize], usize) if usize else b""
    except LZFError as exc:
        raise FormatError(
            f"corrupt LZF data: {exc}", source=p, field="DATA", expected="a valid LZF stream"
        ) from None
    # binary_compressed stores field by field (all x, then all y, ...)
    out: dict[str, NDArray[Any]] = {}
    offset = 0
    for name, size, typ, count in zip(hdr.fields, hdr.sizes, hdr.types, hdr.counts, strict=True):
        nbytes = hdr.points * size * count
        if name != "_":
            vals = np.frombuffer(
                raw, dtype=_PCD_TYPES[(typ, size)], count=hdr.points * count, offset=offset
            )
            out[name] = vals.copy() if count == 1 else vals.reshape(hdr.points, count).copy()
        offset += nbytes
    return out


def _unpack_colors(packed: NDArray[Any]) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    u = (
        np.ascontiguousarray(packed).view("<u4")
        if packed.dtype.itemsize == 4
        else packed.astype("<u4")
    )
    rgb = np.column_stack([(u >> 16) & 0xFF, (u >> 8) & 0xFF, u & 0xFF]).astype(np.uint8)
    return rgb, ((u >> 24) & 0xFF).astype(np.uint8)


def read_pcd(path: PathLike) -> PointCloud:
    """Read a PCD v0.7 file (``ascii``, ``binary`` or ``binary_compressed``).

    Any field set is accepted (``x y z`` are required): ``rgb``/``rgba`` packed colours become
    :attr:`PointCloud.colors`, everything else (``intensity``, ``normal_x``, ``label``, fields with
    ``COUNT > 1`` as ``(N, COUNT)``) goes to :attr:`PointCloud.fields` in its file dtype. Padding
    fields named ``_`` are skipped. ``WIDTH x HEIGHT`` is kept (organised clouds); NaN points are
    kept.

    Raises
    ------
    FormatError
        Missing header keys or fields, SIZE / TYPE / COUNT entries that do not match FIELDS,
        truncated DATA, corrupt LZF data; the message names the file and the field.
    """
    p = _existing(path)
    buf = p.read_bytes()
    hdr = _parse_pcd_header(p, buf)
    body = memoryview(buf)[hdr.data_offset :]  # no copy of the (possibly large) payload
    if hdr.data == "ascii":
        rec = _pcd_records_ascii(p, hdr, bytes(body))
    elif hdr.data == "binary":
        rec = _pcd_records_binary(p, hdr, body)
    else:
        rec = _pcd_records_compressed(p, hdr, body)
    for axis in "xyz":
        if axis not in rec:
            raise FormatError(
                f"no field {axis!r} among {hdr.fields}",
                source=p,
                field="FIELDS",
                expected="fields x y z (and any others)",
            )
        if rec[axis].ndim != 1:
            raise FormatError("has COUNT > 1", source=p, field=axis, expected="COUNT 1")
    points = np.column_stack([rec.pop("x"), rec.pop("y"), rec.pop("z")]).astype(np.float64)
    colors = None
    for cname in _COLOR_FIELDS:
        if cname in rec and rec[cname].ndim == 1 and rec[cname].dtype.itemsize == 4:
            colors, alpha = _unpack_colors(rec.pop(cname))
            if cname == "rgba":
                rec["alpha"] = alpha
            break
    log.debug("read %s: %d points (%s), fields %s", p, len(points), hdr.data, hdr.fields)
    return PointCloud(points, rec, hdr.width, hdr.height, colors=colors)


def _as_cloud(cloud: PointCloud | ArrayLike) -> PointCloud:
    return (
        cloud if isinstance(cloud, PointCloud) else PointCloud(np.asarray(cloud, dtype=np.float64))
    )


def _pcd_type_of(dtype: np.dtype[Any]) -> tuple[str, int]:
    kind = {"f": "F", "i": "I", "u": "U", "b": "U"}.get(dtype.kind)
    if kind is None or (kind, dtype.itemsize) not in _PCD_TYPES:
        raise InputError(
            f"dtype {dtype} has no PCD type",
            field="fields",
            expected="float32/64 or (u)int8/16/32/64 arrays",
        )
    return kind, dtype.itemsize


def write_pcd(
    path: PathLike,
    cloud: PointCloud | ArrayLike,
    binary: bool = True,
    *,
    compressed: bool = False,
    point_dtype: type | np.dtype[Any] = np.float32,
    viewpoint: ArrayLike = (0, 0, 0, 1, 0, 0, 0),
) -> None:
    """Write a PCD v0.7 file atomically.

    Parameters
    ----------
    path : str or path
        Output ``.pcd`` file.
    cloud : PointCloud or (N, 3) array
        The points (and, for a :class:`PointCloud`, its fields, colours and layout).
    binary : bool
        ``DATA binary`` (default) or ``DATA ascii`` when False.
    compressed : bool
        ``DATA binary_compressed`` (LZF, fields stored one after another); implies binary.
    point_dtype : float32 or float64
        Storage type of x, y, z (float32 = PCL's default, ~1e-7 relative precision).
    viewpoint : 7 numbers
        ``tx ty tz qw qx qy qz`` of the acquisition viewpoint (PCD order, w first).

    Notes
    -----
    Colours are written as the packed ``rgb`` float field ``0x00RRGGBB`` (``rgba`` with
    ``fields["alpha"]`` as the alpha byte). In ascii files the packed colour is written as its
    uint32 bit pattern, as PCL does, so no colour turns into a NaN string.
    """
    pc = _as_cloud(cloud)
    n = len(pc)
    pdt = np.dtype(point_dtype).newbyteorder("<")
    if pdt.kind != "f":
        raise InputError(f"point_dtype {pdt}", field="point_dtype", expected="float32 or float64")
    columns: list[tuple[str, NDArray[Any]]] = [
        (axis, pc.points[:, k].astype(pdt)) for k, axis in enumerate("xyz")
    ]
    extra = dict(pc.fields)
    if pc.colors is not None:
        c = pc.colors.astype(np.uint32)
        alpha = extra.pop("alpha", None)
        packed = (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]
        name = "rgb"
        if alpha is not None:
            packed |= np.asarray(alpha).astype(np.uint32) << 24
            name = "rgba"
        columns.append((name, packed.astype("<u4").view("<f4")))
    for name, arr in extra.items():
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name) or name in "xyz":
            raise InputError(
                f"field name {name!r} cannot be written",
                field=name,
                expected="an identifier other than x, y, z",
            )
        a = np.asarray(arr)
        if a.ndim > 2:
            raise InputError(f"shape {a.shape}", field=name, expected="(N,) or (N, COUNT)")
        columns.append((name, a.astype(a.dtype.newbyteorder("<"))))
    types = [_pcd_type_of(a.dtype) for _, a in columns]
    counts = [1 if a.ndim == 1 else a.shape[1] for _, a in columns]
    vp = np.asarray(viewpoint, dtype=np.float64).ravel()
    if vp.size != 7:
        raise InputError(f"{vp.size} numbers", field="viewpoint", expected="7 numbers")
    encoding = "binary_compressed" if compressed else ("binary" if binary else "ascii")
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\n"
        "VERSION 0.7\n"
        f"FIELDS {' '.join(nm for nm, _ in columns)}\n"
        f"SIZE {' '.join(str(s) for _, s in types)}\n"
        f"TYPE {' '.join(t for t, _ in types)}\n"
        f"COUNT {' '.join(str(c) for c in counts)}\n"
        f"WIDTH {pc.width}\nHEIGHT {pc.height}\n"
        f"VIEWPOINT {' '.join(f'{v:.17g}' for v in vp)}\n"
        f"POINTS {n}\nDATA {encoding}\n"
    )
    with atomic_write(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        if encoding == "ascii":
            fh.write(_pcd_ascii_body(columns, n))
        elif encoding == "binary":
            dt = np.dtype(
                {
                    "names": [nm for nm, _ in columns],
                    "formats": [
                        a.dtype if a.ndim == 1 else (a.dtype, (a.shape[1],)) for _, a in columns
                    ],
                }
            )
            rec = np.empty(n, dtype=dt)
            for nm, a in columns:
                rec[nm] = a
            fh.write(rec.tobytes())
        else:
            raw = b"".join(np.ascontiguousarray(a).tobytes() for _, a in columns)
            comp = lzf_compress(raw)
            fh.write(np.array([len(comp), len(raw)], dtype="<u4").tobytes())
            fh.write(comp)
    log.debug("wrote %s: %d points (%s)", path, n, encoding)


def _pcd_ascii_body(columns: list[tuple[str, NDArray[Any]]], n: int) -> bytes:
    if n == 0:
        return b""
    parts: list[NDArray[Any]] = []
    for name, a in columns:
        a2 = a.reshape(n, -1)
        if name in _COLOR_FIELDS:
            parts.append(a2.view("<u4").astype(str))
        elif a2.dtype.kind == "f":
            fmt = "%.9g" if a2.dtype.itemsize == 4 else "%.17g"
            parts.append(np.char.mod(fmt, a2.astype(np.float64)))
        else:
            parts.append(a2.astype(str))
    table = np.concatenate(parts, axis=1)
    lines = [" ".join(row) for row in table.tolist()]
    return ("\n".join(lines) + "\n").encode("ascii")


# --------------------------------------------------------------------------- PLY
_PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}


@dataclass
class _PlyElement:
    name: str
    count: int
    props: list[tuple[str, str, str | None]]  # (name, value type, list count type or None)

    @property
    def has_list(self) -> bool:
        return any(c is not None for _, _, c in self.props)


def _parse_ply_header(p: Path, buf: bytes) -> tuple[str, list[_PlyElement], int]:
    end = buf.find(b"end_header")
    if not buf.startswith(b"ply") or end < 0:
        raise FormatError(
            "not a PLY file", source=p, field="header", expected="'ply' ... 'end_header'"
        )
    nl = buf.find(b"\n", end)
    body_start = len(buf) if nl < 0 else nl + 1
    fmt = ""
    elements: list[_PlyElement] = []
    for raw in buf[:end].decode("ascii", errors="replace").splitlines()[1:]:
        parts = raw.split()
        if not parts or parts[0] in ("comment", "obj_info"):
            continue
        if parts[0] == "format":
            fmt = parts[1] if len(parts) > 1 else ""
        elif parts[0] == "element" and len(parts) == 3 and parts[2].isdigit():
            elements.append(_PlyElement(parts[1], int(parts[2]), []))
        elif parts[0] == "property" and elements:
            if len(parts) == 5 and parts[1] == "list":
                if parts[2] not in _PLY_TYPES or parts[3] not in _PLY_TYPES:
                    raise FormatError(f"unknown list types in {raw!r}", source=p, field=parts[4])
                elements[-1].props.append((parts[4], _PLY_TYPES[parts[3]], _PLY_TYPES[parts[2]]))
            elif len(parts) == 3 and parts[1] in _PLY_TYPES:
                elements[-1].props.append((parts[2], _PLY_TYPES[parts[1]], None))
            else:
                raise FormatError(
                    f"bad property line {raw!r}",
                    source=p,
                    field="property",
                    expected="property TYPE NAME or property list CTYPE TYPE NAME",
                )
        else:
            raise FormatError(f"bad header line {raw!r}", source=p, field="header")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise FormatError(
            f"unknown format {fmt!r}",
            source=p,
            field="format",
            expected="ascii, binary_little_endian or binary_big_endian",
        )
    return fmt, elements, body_start


def _ply_binary_element(
    p: Path, el: _PlyElement, body: memoryview, offset: int, order: str
) -> tuple[dict[str, NDArray[Any]], int]:
    """Parse one binary element; returns its columns and the offset after it."""
    if not el.has_list:
        dt = np.dtype([(nm, order + t) for nm, t, _ in el.props])
        need = el.count * dt.itemsize
        if len(body) - offset < need:
            raise FormatError(
                f"element '{el.name}' truncated: {len(body) - offset} bytes left",
                source=p,
                field=el.name,
                expected=f"{need} bytes",
            )
        rec = np.frombuffer(body, dtype=dt, count=el.count, offset=offset)
        return {nm: rec[nm].copy() for nm, _, _ in el.props}, offset + need
    if len(el.props) == 1 and el.count > 0:
        # the usual face element: one list; fast path when every list has the same length
        nm, vt, ct = el.props[0]
        assert ct is not None
        cdt = np.dtype(order + ct)
        k = int(np.frombuffer(body, dtype=cdt, count=1, offset=offset)[0])
        rdt = np.dtype([("n", cdt), ("v", order + vt, (k,))])
        if len(body) - offset >= el.count * rdt.itemsize:
            rec = np.frombuffer(body, dtype=rdt, count=el.count, offset=offset)
            if np.all(rec["n"] == k):
                return {nm: rec["v"].astype(np.int64)}, offset + el.count * rdt.itemsize
    # general case: lists of varying length, parsed element by element (rare in practice)
    cols: dict[str, list[Any]] = {nm: [] for nm, _, _ in el.props}
    for _ in range(el.count):
        for nm, vt, ct in el.props:
            if ct is None:
                dt = np.dtype(order + vt)
                if offset + dt.itemsize > len(body):
                    raise FormatError(f"element '{el.name}' truncated", source=p, field=nm)
                cols[nm].append(np.frombuffer(body, dtype=dt, count=1, offset=offset)[0])
                offset += dt.itemsize
            else:
                cdt = np.dtype(order + ct)
                if offset + cdt.itemsize > len(body):
                    raise FormatError(f"element '{el.name}' truncated", source=p, field=nm)
                k = int(np.frombuffer(body, dtype=cdt, count=1, offset=offset)[0])
                offset += cdt.itemsize
                vdt = np.dtype(order + vt)
                if offset + k * vdt.itemsize > len(body):
                    raise FormatError(f"element '{el.name}' truncated", source=p, field=nm)
                cols[nm].append(np.frombuffer(body, dtype=vdt, count=k, offset=offset))
                offset += k * vdt.itemsize
    out: dict[str, NDArray[Any]] = {}
    for nm, vt, ct in el.props:
        out[nm] = np.array(cols[nm], dtype=vt) if ct is None else _fan_triangulate(cols[nm])
    return out, offset


def _fan_triangulate(polys: list[NDArray[Any]]) -> NDArray[np.int64]:
    """Polygons of any size as an ``(M, 3)`` triangle fan each (or (M, k) when all equal)."""
    if not polys:
        return np.zeros((0, 3), np.int64)
    sizes = {len(q) for q in polys}
    if len(sizes) == 1:
        return np.asarray(polys, dtype=np.int64)
    tris = [
        np.column_stack([np.full(len(q) - 2, q[0]), q[1:-1], q[2:]]) for q in polys if len(q) >= 3
    ]
    return np.concatenate(tris).astype(np.int64)


def _ply_ascii_elements(
    p: Path, elements: list[_PlyElement], body: bytes
) -> dict[str, dict[str, NDArray[Any]]]:
    lines = body.decode("ascii", errors="replace").splitlines()
    lines = [ln for ln in lines if ln.strip()]
    out: dict[str, dict[str, NDArray[Any]]] = {}
    row = 0
    for el in elements:
        chunk = lines[row : row + el.count]
        if len(chunk) < el.count:
            raise FormatError(
                f"element '{el.name}' truncated: {len(chunk)} of {el.count} lines",
                source=p,
                field=el.name,
                expected=f"{el.count} lines",
            )
        row += el.count
        cols: dict[str, NDArray[Any]] = {}
        if not el.has_list:
            try:
                table = np.array(" ".join(chunk).split(), dtype=np.float64)
            except ValueError:
                raise FormatError("non-numeric values", source=p, field=el.name) from None
            if table.size != el.count * len(el.props):
                raise FormatError(
                    f"element '{el.name}' has {table.size} values",
                    source=p,
                    field=el.name,
                    expected=f"{el.count} x {len(el.props)}",
                )
            table = table.reshape(el.count, len(el.props))
            for k, (nm, vt, _) in enumerate(el.props):
                cols[nm] = table[:, k].astype(vt)
        else:
            cols.update(_ply_ascii_list_element(p, el, chunk))
        out[el.name] = cols
    return out


def _ply_ascii_list_element(p: Path, el: _PlyElement, chunk: list[str]) -> dict[str, NDArray[Any]]:
    """An ascii element with list properties (faces): vectorised when every line is alike."""
    rows = [ln.split() for ln in chunk]
    if len(el.props) == 1 and rows and len({len(r) for r in rows}) == 1:
        nm = el.props[0][0]
        try:
            table = np.array(rows, dtype=np.float64)
        except ValueError:
            raise FormatError("non-numeric values", source=p, field=nm) from None
        if np.all(table[:, 0] == table.shape[1] - 1):
            return {nm: table[:, 1:].astype(np.int64)}
    # general case: lists of varying length or mixed with scalars, consumed line by line
    cols: dict[str, list[Any]] = {nm: [] for nm, _, _ in el.props}
    for k, toks in enumerate(rows):
        pos = 0
        try:
            for nm, _, ct in el.props:
                if ct is None:
                    cols[nm].append(float(toks[pos]))
                    pos += 1
                else:
                    m = int(toks[pos])
                    cols[nm].append(np.array(toks[pos + 1 : pos + 1 + m], dtype=np.int64))
                    if len(cols[nm][-1]) != m:
                        raise IndexError
                    pos += 1 + m
        except (IndexError, ValueError):
            pos = -1
        if pos != len(toks):
            raise FormatError(
                f"line {k + 1} of element '{el.name}' does not match its properties",
                source=p,
                field=el.name,
                expected=" ".join(nm if ct is None else f"n {nm}[n]" for nm, _, ct in el.props),
            )
    out: dict[str, NDArray[Any]] = {}
    for nm, vt, ct in el.props:
        out[nm] = np.array(cols[nm], dtype=vt) if ct is None else _fan_triangulate(cols[nm])
    return out


def read_ply(path: PathLike) -> PointCloud:
    """Read a PLY file (ascii, binary_little_endian, binary_big_endian).

    The ``vertex`` element gives the points (``x y z``), colours (``red green blue``, uint8 or
    float in [0, 1]) and any other vertex properties as fields (``nx``, ``intensity``, ...).
    The ``face`` element (``vertex_indices`` or ``vertex_index``) gives :attr:`PointCloud.faces`:
    ``(M, k)`` when every face has ``k`` corners, otherwise fan-triangulated to ``(M', 3)``.
    Other elements are skipped.
    """
    p = _existing(path)
    buf = p.read_bytes()
    fmt, elements, start = _parse_ply_header(p, buf)
    if fmt == "ascii":
        data = _ply_ascii_elements(p, elements, buf[start:])
    else:
        order = "<" if fmt == "binary_little_endian" else ">"
        body = memoryview(buf)[start:]
        data = {}
        offset = 0
        for el in elements:
            data[el.name], offset = _ply_binary_element(p, el, body, offset, order)
    vertex = data.get("vertex")
    if vertex is None or not all(a in vertex for a in "xyz"):
        raise FormatError(
            "no vertex element with x, y, z",
            source=p,
            field="vertex",
            expected="element vertex N with properties x y z",
        )
    points = np.column_stack([vertex.pop("x"), vertex.pop("y"), vertex.pop("z")])
    colors = None
    if all(c in vertex for c in ("red", "green", "blue")):
        rgb = np.column_stack([vertex.pop("red"), vertex.pop("green"), vertex.pop("blue")])
        if rgb.dtype.kind == "f":
            rgb = np.clip(np.round(rgb * 255.0), 0, 255)
        colors = rgb.astype(np.uint8)
    faces = None
    face_el = data.get("face", {})
    for key in ("vertex_indices", "vertex_index"):
        if key in face_el:
            faces = face_el[key].astype(np.int64)
            if faces.size and (faces.min() < 0 or faces.max() >= len(points)):
                raise FormatError(
                    f"face indices span [{faces.min()}, {faces.max()}]",
                    source=p,
                    field=key,
                    expected=f"indices in [0, {len(points) - 1}]",
                )
    return PointCloud(points, vertex, colors=colors, faces=faces)


def write_ply(
    path: PathLike,
    points: PointCloud | ArrayLike,
    colors: ArrayLike | None = None,
    faces: ArrayLike | None = None,
    *,
    binary: bool = True,
    point_dtype: type | np.dtype[Any] = np.float32,
) -> None:
    """Write a PLY file atomically (binary little-endian by default, ascii with ``binary=False``).

    Parameters
    ----------
    points : (N, 3) array or PointCloud
        Vertex positions (a PointCloud also contributes its colours, faces and 1-D fields).
    colors : (N, 3) uint8 array, optional
        Vertex colours (``red green blue`` uchar); floats in [0, 1] are scaled by 255.
    faces : (M, k) int array, optional
        Polygons as vertex indices (``property list uchar int vertex_indices``).
    point_dtype : float32 or float64
        Storage type of x, y, z (``float`` or ``double``).
    """
    if isinstance(points, PointCloud):
        pc = points
        if colors is not None or faces is not None:
            pc = PointCloud(
                pc.points,
                pc.fields,
                pc.width,
                pc.height,
                colors=pc.colors if colors is None else np.asarray(colors),
                faces=pc.faces if faces is None else np.asarray(faces),
            )
    else:
        pc = PointCloud(
            np.asarray(points, dtype=np.float64),
            colors=None if colors is None else np.asarray(colors),
            faces=None if faces is None else np.asarray(faces),
        )
    n = len(pc)
    pdt = np.dtype(point_dtype)
    ply_name = {
        "f4": "float",
        "f8": "double",
        "i1": "char",
        "u1": "uchar",
        "i2": "short",
        "u2": "ushort",
        "i4": "int",
        "u4": "uint",
    }
    cols: list[tuple[str, NDArray[Any]]] = [
        (a, pc.points[:, k].astype(pdt)) for k, a in enumerate("xyz")
    ]
    if pc.colors is not None:
        cols += [(c, pc.colors[:, k]) for k, c in enumerate(("red", "green", "blue"))]
    for name, arr in pc.fields.items():
        if arr.ndim == 1 and arr.dtype.str[1:] in ply_name:
            cols.append((name, arr))
        else:
            log.warning(
                "write_ply: field %r (%s %s) has no PLY type; skipped", name, arr.dtype, arr.shape
            )
    lines = [
        "ply",
        f"format {'binary_little_endian' if binary else 'ascii'} 1.0",
        "comment written by navkit",
        f"element vertex {n}",
    ]
    lines += [f"property {ply_name[a.dtype.str[1:]]} {nm}" for nm, a in cols]
    fc = pc.faces
    if fc is not None:
        lines += [f"element face {len(fc)}", "property list uchar int vertex_indices"]
        if fc.shape[1] > 255:
            raise InputError("faces with more than 255 corners", field="faces")
    lines.append("end_header")
    with atomic_write(path, "wb") as fh:
        fh.write(("\n".join(lines) + "\n").encode("ascii"))
        if binary:
            dt = np.dtype([(nm, a.dtype.newbyteorder("<")) for nm, a in cols])
            rec = np.empty(n, dtype=dt)
            for nm, a in cols:
                rec[nm] = a
            fh.write(rec.tobytes())
            if fc is not None:
                fdt = np.dtype([("n", "u1"), ("v", "<i4", (fc.shape[1],))])
                frec = np.empty(len(fc), dtype=fdt)
                frec["n"] = fc.shape[1]
                frec["v"] = fc
                fh.write(frec.tobytes())
        else:
            parts = []
            for _, a in cols:
                if a.dtype.kind == "f":
                    fmt = "%.9g" if a.dtype.itemsize == 4 else "%.17g"
                    parts.append(np.char.mod(fmt, a.astype(np.float64))[:, None])
                else:
                    parts.append(a.astype(str)[:, None])
            if n:
                table = np.concatenate(parts, axis=1).tolist()
                fh.write(("\n".join(" ".join(r) for r in table) + "\n").encode("ascii"))
            if fc is not None and len(fc):
                ftab = np.column_stack([np.full(len(fc), fc.shape[1]), fc]).astype(str).tolist()
                fh.write(("\n".join(" ".join(r) for r in ftab) + "\n").encode("ascii"))
