"""Localization (paper 3, issue 12): the correlative matcher of this revision against the one of
an earlier revision (``--before``, a git revision; its ``matcher.py`` and its compiled kernels
``_kernels.py`` loaded from git into this process on the same maps and fields) and the point-to-point ICP baseline of
``benchmarks.bench_localization`` - all three interleaved scan by scan in one process, CPU time
(``time.process_time``) medians per log:

- tracking: the scans of ``bench_localization`` (prior = corrected pose + uniform error up to
  0.5 m / 10 deg, the same for all three), ``match_scan`` with that prior (what
  ``Localizer.register(points, prior=...)`` runs; no wall refinement on a point map);
- global: no prior (ICP cannot).

The two matchers take turns running first on a scan (the first run on a scan pays its cold
caches: ~10 % under load); ICP runs after both.

Success = within 0.3 m and 5 deg of the corrected pose (and ``ok`` for a global fix). The two
matchers' fixes are compared: same verdicts, ambiguity reasons, poses and peak extents within
``--tol`` metres / radians.

Run from the repository root::

    PYTHONPATH=.:src .venv/bin/python benchmarks/localization_before_after.py \
        [--before cf36993] [--scans 20] [--global-scans 3] [--logs intel aces]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path

import numpy as np

from benchmarks.bench_localization import LOGS, SUCCESS_DEG, SUCCESS_M, icp_2d
from navkit.localization import build_map_from_scans
from navkit.localization import matcher as M


def _git_show(rev: str, path: str) -> str | None:
    """The text of ``path`` at git revision ``rev`` (None if it has no such file)."""
    root = Path(__file__).resolve().parents[1]
    res = subprocess.run(
        ["git", "show", f"{rev}:{path}"], cwd=root, capture_output=True, text=True, check=False
    )
    return res.stdout if res.returncode == 0 else None


def load_matcher(rev: str) -> types.ModuleType:
    """``navkit/localization/matcher.py`` at git revision ``rev`` as a module of its own, with
    that revision's compiled kernels (``_kernels.py``, written to a temporary directory and
    imported as a module of its own, Numba's cache beside it) when it has them - so "before"
    runs the kernels it was written with, not this tree's."""
    src = _git_show(rev, "src/navkit/localization/matcher.py")
    if src is None:
        raise SystemExit(f"revision {rev} has no src/navkit/localization/matcher.py")
    kernels = _git_show(rev, "src/navkit/localization/_kernels.py")
    if kernels is not None:
        name = f"navkit_kernels_{rev}"
        tmp = Path(tempfile.gettempdir()) / "navkit_before_kernels"
        tmp.mkdir(exist_ok=True)
        path = tmp / f"{name}.py"
        if not path.exists() or path.read_text() != kernels:
            path.write_text(kernels)
        if str(tmp) not in sys.path:
            sys.path.insert(0, str(tmp))
        src = src.replace("from navkit.localization import _kernels", f"import {name} as _kernels")
    mod = types.ModuleType(f"navkit_matcher_{rev}")
    sys.modules[mod.__name__] = mod  # dataclasses look their module up
    exec(compile(src, f"{rev}:matcher.py", "exec"), mod.__dict__)  # our own source, from git
    return mod


def _ok(pose: np.ndarray, ref: np.ndarray) -> bool:
    dth = abs((pose[2] - ref[2] + np.pi) % (2 * np.pi) - np.pi)
    return bool(np.hypot(*(pose[:2] - ref[:2])) <= SUCCESS_M and np.degrees(dth) <= SUCCESS_DEG)


def main() -> None:
    from scipy.spatial import cKDTree

    from navkit import datasets
    from navkit.io.carmen import read_carmen

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default="cf36993", help="git revision of the 'before' matcher")
    parser.add_argument("--scans", type=int, default=20, help="tracking fixes per log")
    parser.add_argument("--global-scans", type=int, default=3, help="global fixes per log")
    parser.add_argument("--logs", nargs="*", default=list(LOGS))
    parser.add_argument("--tol", type=float, default=1e-6)
    args = parser.parse_args()
    old = load_matcher(args.before)
    print(
        "log | tracking ms before -> after (ICP) | success before / after / ICP | "
        "global ms before -> after | global success before / after | same fixes"
    )
    for name in args.logs:
        lg = read_carmen(datasets.find(f"laser2d/{name}-corrected.log.gz"))
        every = max(2, len(lg) // 1200)
        m = build_map_from_scans(lg.ranges[::every], lg.bearings, lg.poses[::every], max_range=30.0)
        fld = m.likelihood_field(0.1)
        assert fld.points is not None
        tree = cKDTree(fld.points)
        rng = np.random.default_rng(0)
        idx = np.linspace(0, len(lg) - 1, args.scans).astype(int)
        ref = lg.poses[idx]
        prior = ref + rng.uniform(-1, 1, (len(idx), 3)) * [0.5, 0.5, np.radians(10)]
        gidx = idx[:: max(1, len(idx) // args.global_scans)][: args.global_scans]
        # the per-map caches (padded pyramid, coarse field, region pyramids) and the kernels'
        # first calls, for both matchers
        for mod in (old, M):
            mod.match_scan(fld, lg.points(int(idx[0]), 30.0), prior[0])
            mod.match_scan(fld, lg.points(int(gidx[0]), 30.0), None)
        t: dict[str, list[float]] = {}
        ok: dict[str, list[bool]] = {}
        same = True
        cases = [(int(k), p, r, "track") for k, p, r in zip(idx, prior, ref, strict=True)]
        cases += [(int(k), None, lg.poses[k], "global") for k in gidx]
        for c, (k, p, r, kind) in enumerate(cases):
            pts = lg.points(k, 30.0)
            fixes = {}
            # alternate which matcher runs first on a scan (the first pays the cold caches)
            pair = (("before", old), ("after", M))
            for label, mod in pair if c % 2 == 0 else pair[::-1]:
                c0 = time.process_time()
                fixes[label] = f = mod.match_scan(fld, pts, p)
                t.setdefault(f"{kind} {label}", []).append(time.process_time() - c0)
                good = _ok(f.pose, r) and (kind == "track" or f.ok)
                ok.setdefault(f"{kind} {label}", []).append(good)
            a, b = fixes["before"], fixes["after"]
            agree = bool(
                a.ok == b.ok
                and np.allclose(a.pose, b.pose, rtol=0, atol=args.tol)
                and a.ambiguity.reason == b.ambiguity.reason
                and np.isclose(a.ambiguity.extent, b.ambiguity.extent, rtol=0, atol=args.tol)
            )
            same &= agree
            if not agree:  # list it: pose, score, verdict and runner-up of both
                for label, f in (("before", a), ("after", b)):
                    print(
                        f"  {name} {kind} scan {k} {label}: pose {np.round(f.pose, 4)} "
                        f"score {f.score:.6f} ok {f.ok} reason {f.ambiguity.reason!r} "
                        f"second {f.ambiguity.second_score:.6f} at "
                        f"{np.round(f.ambiguity.second_pose, 4)} "
                        f"{'success' if _ok(f.pose, r) else 'miss'}",
                        flush=True,
                    )
            if kind == "track":
                c0 = time.process_time()
                est = icp_2d(fld.points, tree, pts, p)
                t.setdefault("track icp", []).append(time.process_time() - c0)
                ok.setdefault("track icp", []).append(_ok(est, r))
        ms = {key: 1e3 * float(np.median(v)) for key, v in t.items()}
        pc = {key: 100.0 * float(np.mean(v)) for key, v in ok.items()}
        print(
            f"{name} | {ms['track before']:.2f} -> {ms['track after']:.2f} "
            f"({ms['track icp']:.2f}; after / ICP {ms['track after'] / ms['track icp']:.2f}x) | "
            f"{pc['track before']:.0f} / {pc['track after']:.0f} / {pc['track icp']:.0f} % | "
            f"{ms['global before']:.1f} -> {ms['global after']:.1f} | "
            f"{pc['global before']:.0f} / {pc['global after']:.0f} % | {same}",
            flush=True,
        )


if __name__ == "__main__":
    main()
