"""PLY point clouds and meshes (ascii, binary little- and big-endian).

See :mod:`navkit.io.pointcloud` for the conventions shared by all point-cloud formats.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import FormatError, InputError
from navkit.io.atomic import atomic_write
from navkit.io.cloud import PathLike, PointCloud
from navkit.io.cloud import existing_file as _existing

__all__ = ["read_ply", "write_ply"]

log = logging.getLogger(__name__)

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


def _cast_column(p: Path, name: str, values: NDArray[np.float64], vt: str) -> NDArray[Any]:
    """Parsed ascii numbers to the property's type: integers must be whole and in range."""
    dtype = np.dtype(vt)
    if dtype.kind == "f":
        with np.errstate(over="ignore"):  # beyond float32's range -> inf
            return values.astype(dtype)
    info = np.iinfo(dtype)
    if not np.all((values == np.round(values)) & (values >= info.min) & (values <= info.max)):
        raise FormatError(
            "non-integer or out-of-range values",
            source=p,
            field=name,
            expected=f"integers in [{info.min}, {info.max}] ({dtype})",
        )
    return values.astype(dtype)


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
                cols[nm] = _cast_column(p, nm, table[:, k], vt)
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
