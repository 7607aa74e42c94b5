"""``navkit obstacles detect`` on a KITTI sequence: the CLI's time per frame against the
detection time, and the bytes written per frame, with the default outputs beside every output.

The three SemanticKITTI frames of the recorded data are given ``repeats`` times (9 frames by
default, 3 with ``--quick``), in-process, with the sensor height measured from the ground
(first frame). Per mode (the same run, same load):

- ``frame time / detect time``: the sum over frames of read + height + detection + writing,
  divided by the sum of the detection times (the issue's target: <= 1.5 with the defaults);
- ``write ms per frame``, ``kB per frame``.

"all outputs" is ``--outputs labels,obstacles,grid,png,geojson --origin ...``, the set every run
wrote before ``--outputs`` existed (then with uncompressed JSON: 4.9 MB and 2.3-3.0 s of writing
per frame, measured on the same frames at the commit before).

Run: ``python -m benchmarks cli_outputs`` (``--quick``: one pass over the three frames).
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

from benchmarks.common import Row
from navkit import datasets
from navkit.errors import DataNotFoundError

MODES = {
    "default outputs": [],
    "all outputs": ["--outputs", "labels,obstacles,grid,png,geojson", "--origin", "49.0,8.4,0"],
}


def _run(folder: Path, out: Path, repeats: int, extra: list[str]) -> dict[str, float]:
    from typer.testing import CliRunner

    from navkit.cli.main import app

    args = ["obstacles", "detect", *[str(folder)] * repeats, "-o", str(out), "-q", *extra]
    res = CliRunner().invoke(app, args, catch_exceptions=False)
    if res.exit_code != 0:
        raise RuntimeError(res.output)
    frames = json.loads((out / "summary.json").read_text())["frames"]
    t = [f["timings_s"] for f in frames]
    return {
        "ratio": sum(x["frame_total"] for x in t) / sum(x["detect_total"] for x in t),
        "write_ms": 1e3 * sum(x["write_outputs"] for x in t) / len(t),
        "detect_ms": 1e3 * sum(x["detect_total"] for x in t) / len(t),
        "kB": sum(f["bytes_written"] for f in frames) / len(frames) / 1e3,
        "n": float(len(frames)),
    }


def run(quick: bool = False) -> list[Row]:
    try:
        folder = datasets.find("lidar/semantickitti-seq00")
    except DataNotFoundError:
        return [Row("cli_outputs", "KITTI frames absent", "-", None, note="NAVKIT_DATA not found")]
    repeats = 1 if quick else 3
    with tempfile.TemporaryDirectory() as tmp:
        res = {
            m: _run(folder, Path(tmp) / str(i), repeats, a)
            for i, (m, a) in enumerate(MODES.items())
        }
    d, a = res["default outputs"], res["all outputs"]
    n = int(d["n"])
    return [
        Row("cli_outputs", f"frame time / detect time ({n} KITTI frames)", "x", d["ratio"],
            a["ratio"], "all outputs", None, "target <= 1.5 with the defaults"),
        Row("cli_outputs", "writing per frame", "ms", d["write_ms"], a["write_ms"], "all outputs",
            a["write_ms"] / d["write_ms"], f"detection {d['detect_ms']:.0f} ms per frame"),
        Row("cli_outputs", "bytes per frame", "kB", d["kB"], a["kB"], "all outputs",
            a["kB"] / d["kB"], "ratio = all / default"),
    ]  # fmt: skip
