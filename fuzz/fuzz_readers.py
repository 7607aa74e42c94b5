"""Coverage-guided fuzzing of navkit's binary readers with atheris (``make fuzz``).

Each input's first byte picks a reader (KITTI ``.bin`` / ``.label``, PCD, PLY, PFM, PNG depth,
``.npy``, ``.npz``, LZF); the rest is the file. A navkit error is the expected answer to bad bytes; any other
exception, or an allocation beyond the RLIMIT_AS set below, is a finding (atheris stops and
writes the crashing input to ``crash-*``).

Usage::

    make fuzz                                   # 2 minutes per run by default
    python fuzz/fuzz_readers.py -max_total_time=600 fuzz/corpus

Needs the optional extra ``fuzz`` (``pip install 'navkit[fuzz]'``: atheris).
"""

from __future__ import annotations

import os
import resource
import sys
import tempfile
from pathlib import Path

from navkit.errors import require_module

atheris = require_module("atheris", "fuzz", "coverage-guided fuzzing")

with atheris.instrument_imports():
    import navkit.io.arrays as arrays
    import navkit.io.images as images
    import navkit.io.kitti as kitti
    import navkit.io.lzf as lzf
    import navkit.io.pcd as pcd
    import navkit.io.ply as ply
    from navkit.errors import NavkitError

WORK = Path(tempfile.mkdtemp(prefix="navkit-fuzz-"))
READERS = [
    (".bin", kitti.read_kitti_bin),
    (".label", kitti.read_kitti_labels),
    (".pcd", pcd.read_pcd),
    (".ply", ply.read_ply),
    (".pfm", images.read_pfm),
    (".png", lambda p: images.read_depth(p, 1000.0)),
    (".npy", arrays.read_npy),
    (".npz", arrays.read_npz),
]
MEMORY_LIMIT = int(os.environ.get("NAVKIT_FUZZ_RLIMIT_AS", 2 * 2**30))


def one_input(data: bytes) -> None:
    if not data:
        return
    choice, body = data[0], data[1:]
    if choice % (len(READERS) + 1) == len(READERS):
        try:
            lzf.lzf_decompress(body[4:], int.from_bytes(body[:4].ljust(4, b"\0"), "little"))
        except lzf.LZFError:
            pass
        return
    suffix, reader = READERS[choice % (len(READERS) + 1)]
    path = WORK / f"input{suffix}"
    path.write_bytes(body)
    try:
        reader(path)
    except NavkitError:
        pass


def main() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    atheris.Setup(sys.argv, one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
