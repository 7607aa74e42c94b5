"""LZF (PCD binary_compressed): known streams, property-based round trips, corrupt streams."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from navkit.io.pointcloud import LZFError, lzf_compress, lzf_decompress


def test_known_streams():
    # literal run: control byte c < 32 then c + 1 bytes
    assert lzf_decompress(b"\x02abc", 3) == b"abc"
    # 'a' then a back reference of length 7 + 2 = 9 at distance 1 (overlapping copy)
    assert lzf_decompress(b"\x00a\xe0\x00\x00", 10) == b"a" * 10
    # long reference: length byte 7 + extra 10 + 2 = 19 at distance 3 ("xyz" repeated)
    assert lzf_decompress(b"\x02xyz\xe0\x0a\x02", 22) == b"xyz" * 7 + b"x"
    # short reference (len field 1 -> 3 bytes) at distance 4, non-overlapping
    assert lzf_decompress(b"\x03abcd\x20\x03", 7) == b"abcdabc"


def test_compressor_finds_matches():
    data = bytes(range(64)) * 100  # period 64: everything after the first period is a match
    comp = lzf_compress(data)
    assert len(comp) < len(data) // 20
    assert lzf_decompress(comp, len(data)) == data
    zeros = bytes(100_000)
    assert len(lzf_compress(zeros)) < 100_000 // 80  # 264-byte references, 3 bytes each


@settings(max_examples=200, deadline=None, database=None)
@given(st.binary(max_size=3000))
def test_roundtrip_random_bytes(data):
    comp = lzf_compress(data)
    assert lzf_decompress(comp, len(data)) == data
    # incompressible input grows by at most one control byte per 32 literals
    assert len(comp) <= len(data) + (len(data) + 31) // 32


@settings(max_examples=200, deadline=None, database=None)
@given(st.lists(st.sampled_from([b"a", b"b", b"abc", b"\x00" * 40, b"xyzw" * 70]), max_size=300))
def test_roundtrip_repetitive(chunks):
    # repetitive data exercises long, overlapping and maximal (264-byte) back references
    data = b"".join(chunks)
    assert lzf_decompress(lzf_compress(data), len(data)) == data


@settings(max_examples=50, deadline=None, database=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 2000))
def test_roundtrip_float_columns(seed, n):
    # PCD binary_compressed payloads: float32 columns one after another
    rng = np.random.default_rng(seed)
    cols = rng.normal(size=(3, n)).astype(np.float32)
    cols[2] = np.round(cols[2], 1)  # a quantised column repeats bytes
    data = cols.tobytes()
    assert lzf_decompress(lzf_compress(data), len(data)) == data


@pytest.mark.parametrize(
    ("stream", "size", "message"),
    [
        (b"\x05abc", 6, "runs past the end"),
        (b"\x20\x00", 3, "before the start"),
        (b"\x00a\xe0", 10, "truncated"),
        (b"\x02abc", 2, "exceeds"),
        (b"\x02abc", 5, "decompressed to 3 bytes"),
    ],
)
def test_corrupt_streams(stream, size, message):
    with pytest.raises(LZFError, match=message):
        lzf_decompress(stream, size)
