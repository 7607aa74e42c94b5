"""PCD v0.7 point clouds (``ascii``, ``binary``, ``binary_compressed``).

Colours are the packed ``rgb`` / ``rgba`` field (a float32 or uint32 holding ``0xAARRGGBB``);
organised clouds keep their ``WIDTH x HEIGHT`` layout and NaN points. See
:mod:`navkit.io.pointcloud` for the conventions shared by all point-cloud formats.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import FormatError, InputError
from navkit.io.atomic import atomic_write
from navkit.io.cloud import PathLike, PointCloud
from navkit.io.cloud import existing_file as _existing
from navkit.io.lzf import LZFError, lzf_compress, lzf_decompress, max_lzf_output

__all__ = ["read_pcd", "write_pcd"]

log = logging.getLogger(__name__)

_COLOR_FIELDS = ("rgb", "rgba")

#: Largest point record accepted (bytes): PCL's widest common records (FPFH, 33 floats; SHOT,
#: 352 floats) are a few kB; a lying COUNT must not make a NumPy dtype of gigabytes.
_MAX_POINT_BYTES = 1 << 16

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
        names: list[str] = []
        formats: list[Any] = []
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
    if any(c < 1 for c in counts) or sum(s * c for s, c in zip(sizes, counts, strict=True)) > (
        _MAX_POINT_BYTES
    ):
        raise FormatError(
            f"COUNT {counts[:6]} with SIZE {sizes[:6]}",
            source=p,
            field="COUNT",
            expected=f"counts >= 1 and at most {_MAX_POINT_BYTES} bytes per point",
        )
    width = ints("WIDTH", need("WIDTH")[:1])[0]
    height = ints("HEIGHT", need("HEIGHT")[:1] if "HEIGHT" in entries else ["1"])[0]
    points = ints("POINTS", need("POINTS")[:1] if "POINTS" in entries else [str(width * height)])[0]
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
                with np.errstate(over="ignore"):  # beyond float32's range -> inf, as PCL does
                    vals = block.astype(np.float64).astype(dtype)
            else:
                vals = block.astype(np.float64)
                info = np.iinfo(dtype)
                if not np.all(vals == np.round(vals)) or not np.all(
                    (vals >= info.min) & (vals <= info.max)
                ):
                    raise ValueError("non-integer or out of range")
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
    if usize > max_lzf_output(min(csize, len(body) - 8)):
        raise FormatError(
            f"{csize} compressed bytes cannot hold {usize} bytes ({hdr.points} points)",
            source=p,
            field="DATA",
            expected=f"an uncompressed size of at most {max_lzf_output(csize)} bytes",
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
    with np.errstate(invalid="ignore"):  # signalling NaNs in the file are NaN points
        points = np.column_stack([rec.pop(a).astype(np.float64) for a in "xyz"])
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
