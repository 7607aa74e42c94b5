"""Read ROS 1 bags and MCAP files whose index is missing, damaged or unreadable.

A robot that loses power or crashes leaves a bag without its index (ROS 1: the connection and
chunk-info records written at close; MCAP: the summary section and footer). Their messages are
intact up to the cut. :func:`scan_bag` reads them by walking the records from the start:

- ROS 1 (format 2.0): every top-level record; connection records give the topics and message
  definitions, chunk records (compression ``none``, ``bz2`` or ``lz4``) are decompressed and
  their message records read; a chunk cut short is decompressed as far as its bytes go and read
  up to its last whole message.
- MCAP: every record with ``mcap``'s stream reader; a chunk cut short is decompressed as far as
  its bytes go (``zstd`` or ``lz4``) and read up to its last whole message.

Messages come in file order (the order they were recorded). The result has the interface of
``rosbags``' ``AnyReader`` that :mod:`navkit.io.rosbag` uses (``connections``, ``messages``,
``deserialize``, ``start_time``, ``end_time``), so every reader there works on it.
"""

from __future__ import annotations

import bz2
import io
import os
import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from navkit.errors import FormatError

__all__ = ["ScannedBag", "ScannedConnection", "scan_bag"]

ROS1_MAGIC = b"#ROSBAG V2.0\n"
MCAP_MAGIC = b"\x89MCAP0\r\n"

# ROS 1 record op codes
_OP_MSG, _OP_CHUNK, _OP_CONN = 0x02, 0x05, 0x07


@dataclass
class ScannedConnection:
    """One topic's connection: id, topic, ROS 2 style type name, message count, definition."""

    id: int
    topic: str
    msgtype: str
    msgdef: str = ""
    msgcount: int = 0


@dataclass
class ScannedBag:
    """A bag read by scanning its records (see the module docstring)."""

    path: Path
    kind: str  # "ros1" or "mcap"
    connections: list[ScannedConnection] = field(default_factory=list)
    start_time: int = 0
    end_time: int = 0
    n_messages: int = 0
    typestore: Any = None

    def messages(
        self, connections: Sequence[ScannedConnection] | None = None
    ) -> Iterator[tuple[ScannedConnection, int, bytes]]:
        """``(connection, log time ns, raw message)`` of the wanted connections, in file order."""
        by_id = {c.id: c for c in self.connections}
        wanted = None if connections is None else {c.id for c in connections}
        for cid, t, raw in _records(self.path, self.kind, {}):
            if cid in by_id and (wanted is None or cid in wanted):
                yield by_id[cid], t, raw

    def deserialize(self, raw: bytes, msgtype: str) -> Any:
        """The message object of ``raw`` (ROS 1 serialisation or CDR)."""
        if self.kind == "ros1":
            return self.typestore.deserialize_ros1(raw, msgtype)
        return self.typestore.deserialize_cdr(raw, msgtype)

    def close(self) -> None:
        """Nothing to release: every pass opens and closes the file."""


def scan_bag(path: str | os.PathLike[str]) -> ScannedBag:
    """Scan a ROS 1 ``.bag`` or an ``.mcap`` file (or the ``.mcap`` files of a ROS 2 bag folder,
    in name order) record by record, up to its last whole message.

    Raises
    ------
    FormatError
        Neither format's magic bytes at the start, or no whole message at all.
    """
    p = Path(path)
    files = sorted(p.glob("*.mcap")) if p.is_dir() else [p]
    if not files:
        raise FormatError(
            "has no .mcap file to scan", source=p, field="bag", expected="a ROS 2 mcap bag folder"
        )
    kinds = {_kind(f) for f in files}
    if len(kinds) != 1:
        raise FormatError(
            "mixes file formats", source=p, field="bag", expected="one format per bag"
        )
    kind = kinds.pop()
    conns: dict[int, ScannedConnection] = {}
    bag = ScannedBag(p, kind)
    first = last = None
    n = 0
    for cid, t, _raw in _records(p, kind, conns):
        if cid not in conns:
            continue
        conns[cid].msgcount += 1
        n += 1
        first = t if first is None else min(first, t)
        last = t if last is None else max(last, t)
    if n == 0:
        raise FormatError(
            "has no whole message before its end",
            source=p,
            field="bag",
            expected="a ROS 1 bag or MCAP file with at least one complete message",
        )
    bag.connections = [c for c in conns.values() if c.msgcount]
    bag.start_time, bag.end_time, bag.n_messages = int(first or 0), int(last or 0), n
    bag.typestore = _typestore(kind, bag.connections)
    return bag


def _kind(f: Path) -> str:
    with open(f, "rb") as fh:
        head = fh.read(len(ROS1_MAGIC))
    if head.startswith(ROS1_MAGIC):
        return "ros1"
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    raise FormatError(
        f"starts with {head[:8]!r}",
        source=f,
        field="magic",
        expected="'#ROSBAG V2.0' (ROS 1) or the MCAP magic",
    )


def _records(
    path: Path, kind: str, conns: dict[int, ScannedConnection]
) -> Iterator[tuple[int, int, bytes]]:
    files = sorted(path.glob("*.mcap")) if path.is_dir() else [path]
    if kind == "ros1":
        yield from _ros1_messages(files[0], conns)
        return
    for k, f in enumerate(files):  # channel ids are per file: offset them per file
        yield from _mcap_messages(f, conns, k << 32)


def _typestore(kind: str, connections: Sequence[ScannedConnection]) -> Any:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if kind == "ros1" else Stores.LATEST)
    for c in connections:
        if c.msgdef and c.msgtype not in store.fielddefs:
            try:
                store.register(get_types_from_msg(c.msgdef, c.msgtype))
            except Exception:  # a definition the type system cannot take: its messages fail
                continue
    return store


# --------------------------------------------------------------------------- ROS 1
def _ros1_fields(header: bytes) -> dict[str, bytes]:
    out: dict[str, bytes] = {}
    pos = 0
    while pos + 4 <= len(header):
        (n,) = struct.unpack_from("<I", header, pos)
        pos += 4
        name, _, value = header[pos : pos + n].partition(b"=")
        out[name.decode("latin-1")] = value
        pos += n
    return out


def _ros1_walk(buf: memoryview | bytes) -> Iterator[tuple[dict[str, bytes], memoryview]]:
    """``(header fields, data)`` of every whole record in ``buf``."""
    mv = memoryview(buf)
    pos, end = 0, len(mv)
    while pos + 4 <= end:
        (hlen,) = struct.unpack_from("<I", mv, pos)
        if pos + 4 + hlen + 4 > end:
            return
        header = bytes(mv[pos + 4 : pos + 4 + hlen])
        (dlen,) = struct.unpack_from("<I", mv, pos + 4 + hlen)
        start = pos + 8 + hlen
        if start + dlen > end:
            return
        yield _ros1_fields(header), mv[start : start + dlen]
        pos = start + dlen


def _ros1_conn(fields: dict[str, bytes], data: memoryview) -> ScannedConnection:
    from rosbags.typesys.msg import normalize_msgtype

    d = _ros1_fields(bytes(data))
    (cid,) = struct.unpack("<I", fields["conn"])
    topic = fields.get("topic", d.get("topic", b"")).decode()
    typ = d.get("type", b"").decode()
    return ScannedConnection(
        cid, topic, normalize_msgtype(typ), d.get("message_definition", b"").decode()
    )


def _ros1_inner(
    buf: bytes | memoryview, conns: dict[int, ScannedConnection]
) -> Iterator[tuple[int, int, bytes]]:
    for fields, data in _ros1_walk(buf):
        op = fields.get("op", b"\x00")[0]
        if op == _OP_CONN:
            c = _ros1_conn(fields, data)
            conns.setdefault(c.id, c)
        elif op == _OP_MSG:
            (cid,) = struct.unpack("<I", fields["conn"])
            sec, nsec = struct.unpack("<II", fields["time"])
            yield cid, sec * 1_000_000_000 + nsec, bytes(data)


def _decompress_partial(compression: str, data: bytes | memoryview) -> bytes:
    """As much of a (possibly cut) compressed block as decompresses."""
    if compression == "none":
        return bytes(data)
    if compression == "bz2":
        try:
            return bz2.BZ2Decompressor().decompress(bytes(data))
        except OSError:
            return b""
    if compression == "lz4":
        import lz4.frame

        try:
            return lz4.frame.LZ4FrameDecompressor().decompress(bytes(data))
        except RuntimeError:
            return b""
    if compression == "zstd":
        import zstandard

        try:
            return zstandard.ZstdDecompressor().decompressobj().decompress(bytes(data))
        except zstandard.ZstdError:
            return b""
    raise FormatError(
        f"compression {compression!r}",
        source="chunk",
        field="compression",
        expected="none, bz2, lz4 or zstd",
    )


def _ros1_messages(
    f: Path, conns: dict[int, ScannedConnection]
) -> Iterator[tuple[int, int, bytes]]:
    data = f.read_bytes()
    mv = memoryview(data)[len(ROS1_MAGIC) :]
    pos, end = 0, len(mv)
    while pos + 4 <= end:
        (hlen,) = struct.unpack_from("<I", mv, pos)
        if pos + 8 + hlen > end:
            return
        fields = _ros1_fields(bytes(mv[pos + 4 : pos + 4 + hlen]))
        (dlen,) = struct.unpack_from("<I", mv, pos + 4 + hlen)
        start = pos + 8 + hlen
        body = mv[start : min(start + dlen, end)]  # a cut record keeps what is there
        op = fields.get("op", b"\x00")[0]
        if op == _OP_CHUNK:
            comp = fields.get("compression", b"none").decode()
            yield from _ros1_inner(_decompress_partial(comp, body), conns)
        elif op == _OP_CONN and len(body) == dlen:
            c = _ros1_conn(fields, body)
            conns.setdefault(c.id, c)
        elif op == _OP_MSG and len(body) == dlen:
            (cid,) = struct.unpack("<I", fields["conn"])
            sec, nsec = struct.unpack("<II", fields["time"])
            yield cid, sec * 1_000_000_000 + nsec, bytes(body)
        if start + dlen > end:
            return
        pos = start + dlen


# --------------------------------------------------------------------------- MCAP
def _mcap_messages(
    f: Path, conns: dict[int, ScannedConnection], offset: int
) -> Iterator[tuple[int, int, bytes]]:
    from mcap.records import Channel, Chunk, Message, Schema
    from mcap.stream_reader import StreamReader

    schemas: dict[int, Schema] = {}
    data = f.read_bytes()
    stream = io.BytesIO(data)
    reader = StreamReader(stream, emit_chunks=True, record_size_limit=len(data))

    def take(records: Iterator[Any]) -> Iterator[tuple[int, int, bytes]]:
        for rec in records:
            if isinstance(rec, Schema):
                schemas[rec.id] = rec
            elif isinstance(rec, Channel):
                sch = schemas.get(rec.schema_id)
                conns.setdefault(
                    offset + rec.id,
                    ScannedConnection(
                        offset + rec.id,
                        rec.topic,
                        sch.name if sch else "",
                        sch.data.decode("utf-8", "replace") if sch else "",
                    ),
                )
            elif isinstance(rec, Message):
                yield offset + rec.channel_id, rec.log_time, bytes(rec.data)
            elif isinstance(rec, Chunk):
                inner = _decompress_partial(rec.compression or "none", rec.data)
                yield from _mcap_inner(inner, take)

    try:
        yield from take(_guarded(reader.records))
    except _Cut:
        pass
    # a chunk cut short: the stream reader stops before it; decompress what is there
    yield from _mcap_cut_chunk(data, take)


class _Cut(Exception):
    """The file ends inside a record."""


def _guarded(records: Iterator[Any]) -> Iterator[Any]:
    from mcap.exceptions import McapError

    try:
        yield from records
    except (McapError, EOFError, struct.error, ValueError):
        raise _Cut from None


def _mcap_inner(buf: bytes, take: Any) -> Iterator[tuple[int, int, bytes]]:
    """The whole records of a chunk's (possibly cut) decompressed records."""
    from mcap.stream_reader import StreamReader

    reader = StreamReader(io.BytesIO(buf), skip_magic=True, record_size_limit=len(buf) + 1)
    try:
        yield from take(_guarded(reader.records))
    except _Cut:
        return


def _mcap_cut_chunk(data: bytes, take: Any) -> Iterator[tuple[int, int, bytes]]:
    """Find the last chunk record that runs past the end of the file and read what it holds.

    Walks the records from the start by their lengths (opcode u8, length u64)."""
    pos, end = len(MCAP_MAGIC), len(data)
    while pos + 9 <= end:
        op = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        body_start = pos + 9
        if body_start + length <= end:
            pos = body_start + length
            continue
        if op != 0x06:  # only a cut chunk still holds whole messages
            return
        # chunk: start u64, end u64, uncompressed size u64, crc u32, compression str, records
        p = body_start + 28
        if p + 4 > end:
            return
        (clen,) = struct.unpack_from("<I", data, p)
        comp = data[p + 4 : p + 4 + clen].decode("utf-8", "replace")
        p += 4 + clen + 8
        if p > end:
            return
        inner = _decompress_partial(comp or "none", data[p:end])
        yield from _mcap_inner(inner, take)
        return
