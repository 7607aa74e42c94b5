"""LZF compression (liblzf's format), as used by PCD ``binary_compressed``.

Pure Python + NumPy, no extra dependency; :func:`lzf_decompress` never writes past the size it is
told to expect, so a corrupt or hostile stream cannot make it allocate more.
"""

from __future__ import annotations

from bisect import bisect_left

import numpy as np

__all__ = ["LZFError", "lzf_compress", "lzf_decompress", "max_lzf_output"]

#: Largest expansion of an LZF stream: a 3-byte back reference yields at most 264 bytes.
_LZF_MAX_RATIO = 88


def max_lzf_output(n_compressed: int) -> int:
    """Upper bound of the decompressed size of ``n_compressed`` bytes of LZF (checked before
    allocating, so a lying size field cannot reserve gigabytes)."""
    return _LZF_MAX_RATIO * n_compressed


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
        If ``expected_size`` is more than the stream can expand to (:func:`max_lzf_output`,
        checked before anything is allocated), a token runs past the input, refers before the
        start of the output, or the output size differs from ``expected_size``.
    """
    src = bytes(data)
    n_in = len(src)
    if expected_size < 0 or expected_size > max_lzf_output(n_in):
        raise LZFError(
            f"{n_in} compressed bytes cannot hold {expected_size} bytes "
            f"(LZF expands at most {_LZF_MAX_RATIO}x)"
        )
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
