"""Organised plane extraction: this working tree against a git revision's, and Open3D's loop.

The revision's ``src/navkit/planes/segments.py``, ``extract.py`` and ``_kernels.py`` are loaded
beside the working tree (``git show REV:...`` into a temporary folder, the extract module's imports
of ``segments`` and ``_kernels`` redirected: the revision runs its own compiled kernels), and the two
versions and Open3D's ``segment_plane`` loop are timed interleaved in one process on the
benchmark's frames (``bench_planes.extraction_frames``): CPU time medians, 3 x ``--repeats``.

Run from the repository root::

    PYTHONPATH=. .venv/bin/python benchmarks/planes_extract_vs_rev.py [--rev HEAD] [--repeats 15]
        [--frames benchmark|7scenes|cape] [--no-open3d]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import types
from pathlib import Path

import numpy as np

from benchmarks.bench_planes import _cpu_median, _o3d, _segment_plane_loop, extraction_frames
from navkit.planes import ExtractionSettings, extract_planes_organized


def _load_revision(rev: str) -> types.ModuleType:
    """The revision's organised extraction as a module (``rev_extract``), with the revision's
    own compiled kernels (``rev_kernels``, when it has ``_kernels.py``): the three files are
    written to a temporary folder and imported from there (Numba caches beside them)."""
    import importlib.util
    import tempfile

    folder = Path(tempfile.mkdtemp(prefix="navkit-rev-"))
    src = {}
    for name in ("segments", "extract", "_kernels"):
        res = subprocess.run(
            ["git", "show", f"{rev}:src/navkit/planes/{name}.py"], capture_output=True, text=True
        )
        if res.returncode == 0:
            src[name] = res.stdout
        elif name != "_kernels":
            raise SystemExit(f"{rev}: no src/navkit/planes/{name}.py ({res.stderr.strip()})")
    code = src["extract"].replace("from navkit.planes.segments import", "from rev_segments import")
    code = code.replace("from navkit.planes import _kernels", "import rev_kernels as _kernels")
    src["extract"] = code
    mods = {}
    for name in ("_kernels", "segments", "extract"):
        if name not in src:
            continue
        path = folder / f"rev{name if name.startswith('_') else '_' + name}.py"
        path.write_text(src[name])
        mod_name = path.stem
        spec = importlib.util.spec_from_file_location(mod_name, path)
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        sys.modules[mod_name] = mod
        spec.loader.exec_module(mod)
        mods[name] = mod
    return mods["extract"]


def _same(a: object, b: object) -> str:
    """How two extraction results compare: ``"identical"`` (labels, inliers, planes, outlines and
    areas bit for bit), ``"same labels, floats within X"`` (labels, inliers and outline sizes
    identical; the largest relative difference of the normals, rho, centroids, RMS, outlines
    and areas) or the first structural difference."""
    ra, rb = a.segments, b.segments  # type: ignore[attr-defined]
    if len(ra) != len(rb):
        return f"{len(ra)} vs {len(rb)} planes"
    if not np.array_equal(a.labels, b.labels):  # type: ignore[attr-defined]
        return "labels differ"
    worst = 0.0
    for k, (x, y) in enumerate(zip(ra, rb, strict=True)):
        if not np.array_equal(x.inliers, y.inliers):
            return f"plane {k}: inliers differ"
        if x.outline.shape != y.outline.shape:
            return f"plane {k}: outline sizes differ ({len(x.outline)} vs {len(y.outline)})"
        for u, v in (
            (x.normal, y.normal),
            (x.rho, y.rho),
            (x.plane.centroid, y.plane.centroid),
            (x.plane.rms, y.plane.rms),
            (x.outline, y.outline),
            (x.area, y.area),
        ):
            u, v = np.asarray(u, float), np.asarray(v, float)
            scale = max(float(np.abs(v).max(initial=0.0)), 1e-300)
            worst = max(worst, float(np.abs(u - v).max(initial=0.0)) / scale)
    return "identical" if worst == 0 else f"same labels, floats within {worst:.1e} relative"


def _frames(which: str) -> list[tuple[str, np.ndarray]]:
    """``(name, (H, W, 3) grid)`` of the chosen frames."""
    if which == "benchmark":
        return [(name, f.points()) for name, f in extraction_frames()]
    from navkit import datasets
    from navkit.io.rgbd import open_rgbd_sequence, read_cape_frame

    if which == "cape":
        return [("CAPE tunnel", read_cape_frame(datasets.find("rgbd/cape-tunnel")).points)]
    seq = open_rgbd_sequence(datasets.find("rgbd/7scenes-tsdf"))
    return [(f"7-Scenes #{i}", seq.frame(i).points()) for i in range(0, len(seq), 10)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rev", default="HEAD", help="git revision to compare with")
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument(
        "--frames",
        choices=("benchmark", "7scenes", "cape"),
        default="benchmark",
        help="the benchmark's frames (simulated + slambook), every 10th 7-Scenes frame, or CAPE",
    )
    parser.add_argument("--no-open3d", action="store_true", help="skip Open3D's loop (slow)")
    args = parser.parse_args()
    before = _load_revision(args.rev)
    o3d = None if args.no_open3d else _o3d()
    full = ExtractionSettings(refine="full")
    print(f"frame | planes ({args.rev} -> now) | {args.rev} ms | now ms | now full ms | Open3D ms")
    for name, P in _frames(args.frames):
        now_res, before_res = extract_planes_organized(P), before.extract_planes_organized(P)
        n, nb = len(now_res), len(before_res)
        same = _same(before_res, now_res)
        flat = P.reshape(-1, 3)
        flat = flat[np.all(np.isfinite(flat), axis=1)]
        t: dict[str, list[float]] = {"before": [], "now": [], "full": [], "o3d": []}
        for _ in range(3):
            t["before"].append(
                _cpu_median(lambda P=P: before.extract_planes_organized(P), args.repeats)
            )
            t["now"].append(_cpu_median(lambda P=P: extract_planes_organized(P), args.repeats))
            t["full"].append(
                _cpu_median(lambda P=P: extract_planes_organized(P, full), args.repeats)
            )
            if o3d is not None:
                t["o3d"].append(
                    _cpu_median(
                        lambda flat=flat, n=n: _segment_plane_loop(o3d, flat, n),
                        max(1, args.repeats // 3),
                    )
                )
        m = {k: 1000 * float(np.median(v)) if v else float("nan") for k, v in t.items()}
        print(
            f"{name} | {nb} -> {n} | {m['before']:.1f} | {m['now']:.1f} | {m['full']:.1f} | "
            f"{m['o3d']:.0f} | {m['before'] / m['now']:.2f}x | Open3D {m['o3d'] / m['now']:.0f}x"
            f" | results {same}"
        )


if __name__ == "__main__":
    main()
