"""``navkit run``'s plane odometry over a long RGB-D stream: resident memory stays flat.

The 7-Scenes frames (``rgbd/7scenes-tsdf``, 100 frames at 30 Hz) are streamed again and again
(restamped, so the recording is 2,000 frames long; ``--quick``: 300) through
:func:`navkit.runtime.run_recording` with the planes stage only, once with the run's default
memory bounds (``[planes] max_keyframes = 20, max_history = 100, max_map_planes = 40``) and
once unbounded (``max_keyframes = 200`` as ``OdometrySettings``' default, ``max_history = 0``,
``max_map_planes = 0``). Resident memory (``/proc/self/statm``, after ``gc.collect()``) is
sampled every 100 frames; the figure is the growth from frame 500 (or the first sample in
``--quick``) to the end, in MB per 1,000 frames.

Run one variant alone (a process each, so their RSS do not mix):
``python -c "from benchmarks.bench_runtime_soak import soak; print(soak('bounded', 2000))"``.
"""

from __future__ import annotations

import gc
import os
import shutil
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from benchmarks.common import Row

VARIANTS = {
    "bounded": {},
    "unbounded": {"max_keyframes": 200, "max_history": 0, "max_map_planes": 0},
}


@dataclass
class LoopedSource:
    """A recording played ``n_items`` items long: when it ends it starts again, restamped one
    item period after its last item (the camera jumps back to the first frame's place)."""

    base: Any
    n_items: int
    name: str = ""
    topics: dict[str, str] = field(default_factory=dict)
    start_ns: int = 0
    end_ns: int = 0

    def __post_init__(self) -> None:
        b = self.base
        self.name = f"{b.name} (looped to {self.n_items} items)"
        self.topics = dict(b.topics)
        self.period = (b.end_ns - b.start_ns) // max(b.n_items - 1, 1)
        self.span = b.end_ns - b.start_ns + self.period
        self.start_ns = b.start_ns
        self.end_ns = b.start_ns + (self.n_items - 1) * self.period

    def messages(self, skip: int = 0) -> Iterator[tuple[int, list[Any]]]:
        from dataclasses import replace

        k, loop = 0, 0
        while True:
            for _, msgs in self.base.messages():
                if k >= self.n_items:
                    return
                if k >= skip:
                    off = loop * self.span
                    yield k, [replace(m, stamp_ns=m.stamp_ns + off) for m in msgs]
                k += 1
            loop += 1


def _rss_mb() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6


def soak(variant: str, n_frames: int, every: int = 100) -> dict[str, Any]:
    """One run: ``{"frames", "rss_mb": [(frame, MB), ...], "planes": summary record}``."""
    from navkit import datasets
    from navkit.runtime import open_source, run_recording

    base = open_source(datasets.find("rgbd/7scenes-tsdf"))
    # one item = one frame's colour or depth image (+ camera info first): 2 items per frame
    per_frame = max(round(base.n_items / 100), 1)
    src = LoopedSource(base, n_frames * per_frame)
    samples: list[tuple[int, float]] = []
    count = {"items": 0}

    def probe(_done: float, _total: float) -> None:
        count["items"] += 1
        frame = count["items"] // per_frame
        if count["items"] % (every * per_frame) == 0:
            gc.collect()
            samples.append((frame, _rss_mb()))

    tmp = Path(tempfile.mkdtemp(prefix="bench_soak_"))
    try:
        cfg = {
            "run": {"capabilities": ["planes"], "checkpoint_every": 100_000},
            "planes": VARIANTS[variant],
        }
        summary = run_recording(src, tmp / "run", cfg, on_progress=probe)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {"frames": n_frames, "rss_mb": samples, "planes": summary["capabilities"]["planes"]}


def _growth(samples: list[tuple[int, float]], start: int) -> tuple[float, float, float]:
    """(MB at ``start`` or the first sample after, MB at the end, MB per 1,000 frames)."""
    first = next((s for s in samples if s[0] >= start), samples[0])
    last = samples[-1]
    per_k = 1000 * (last[1] - first[1]) / max(last[0] - first[0], 1)
    return first[1], last[1], per_k


def run(quick: bool = False) -> list[Row]:
    n = 300 if quick else 2000
    start = 100 if quick else 500
    rows = []
    res = {v: soak(v, n) for v in VARIANTS}
    (b0, b1, bk), (u0, u1, uk) = (_growth(res[v]["rss_mb"], start) for v in VARIANTS)
    rows.append(
        Row(
            "runtime_soak",
            f"7-Scenes looped to {n} frames: RSS growth (planes stage)",
            "MB per 1000 frames",
            bk,
            peer=uk,
            peer_name="unbounded",
            note=f"bounded {b0:.0f} -> {b1:.0f} MB, unbounded {u0:.0f} -> {u1:.0f} MB "
            f"(frame {start} -> {n}); tracked {res['bounded']['planes']['tracked']} / "
            f"{res['unbounded']['planes']['tracked']} of {n}",
        )
    )
    return rows
