"""Huge, infinite, NaN and signed-zero coordinates into every public function that reaches a kernel.

Each function family runs in its own subprocess under ``NAVKIT_JIT=eager`` (the compiled kernels
are what runs), so a kernel that writes out of bounds and kills the process with a signal shows
as a negative return code instead of taking pytest down. A subprocess runs all the cases of its
family (the compilation is paid once per family) and prints one JSON line with each case's
outcome: ``"valid"`` (a result came back), ``"error"`` (a :class:`navkit.errors.NavkitError`) or
``"crash: <type>: <message>"`` (anything else, e.g. an ``IndexError`` under
``NUMBA_BOUNDSCHECK=1`` or a ``MemoryError``). The test requires a zero exit code and no crash.

The poison values: 1e30 and 1e300 (finite, but beyond any index arithmetic: ``|x| / cell`` does
not fit an integer), +-inf and NaN (no-returns in sensor data) and -0.0 (a signed zero: must act
as 0). Each is put into a few coordinates of a valid input ("some"), into every coordinate
("all"), and the whole valid input is multiplied by it ("scaled").

Run as a script, ``python test_kernel_inputs.py FAMILY`` runs that family's cases in-process.
"""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

POISON = {"1e30": 1e30, "1e300": 1e300, "inf": np.inf, "-inf": -np.inf, "nan": np.nan, "-0": -0.0}

#: Wall-clock bound for one family's subprocess (compilation on an empty Numba cache included).
TIMEOUT_S = 900


def _variants(base: np.ndarray, rng: np.random.Generator) -> Iterator[tuple[str, np.ndarray]]:
    """``base`` with each poison value in a few coordinates, in all of them, and as a factor."""
    yield "base", base.copy()
    flat_n = base.size
    some = rng.choice(flat_n, size=max(1, flat_n // 50), replace=False)
    for label, v in POISON.items():
        a = base.copy()
        a.reshape(-1)[some] = v
        yield f"some-{label}", a
        yield f"all-{label}", np.full_like(base, v)
        with np.errstate(all="ignore"):
            yield f"scaled-{label}", base * v


# ----------------------------------------------------------------------------- the families
# each returns (case name, zero-argument callable) pairs; built lazily inside the subprocess


def _obstacle_grid() -> np.ndarray:
    """A level floor seen by a 61 x 21 scanner 1.5 m up, with a 0.8 m box on it."""
    az = np.radians(np.linspace(-60, 60, 61))
    el = np.radians(np.linspace(-40, -5, 21))
    d = 1.5 / np.sin(-el)
    P = np.stack(
        [
            np.outer(np.cos(az), d * np.cos(el)),
            np.outer(np.sin(az), d * np.cos(el)),
            np.zeros((az.size, el.size)),
        ],
        axis=-1,
    )
    P[25:35, 8:12, 2] = 0.8
    return P


def _lidar_cloud() -> np.ndarray:
    """A 16-beam spinning lidar on level ground, 1.7 m up, in storage order (ring by ring)."""
    n_az = 360
    az = np.linspace(-np.pi, np.pi, n_az, endpoint=False)
    el = np.radians(np.linspace(-15, 15, 16))
    rows = []
    for e in el:
        r = np.where(e < -0.01, 1.7 / np.sin(-min(e, -0.01)), 30.0)
        rows.append(
            np.c_[
                r * np.cos(e) * np.cos(az), r * np.cos(e) * np.sin(az), np.full(n_az, r * np.sin(e))
            ]
        )
    return np.concatenate(rows)


def _obstacles_cases() -> Iterator[tuple[str, Callable[[], Any]]]:
    from navkit.obstacles import (
        Mounting,
        ObstacleMapper,
        ObstacleSettings,
        detect_obstacles,
        detect_obstacles_grid,
        detect_obstacles_in_grid,
    )
    from navkit.obstacles.grids import cloud_to_grid, organized_to_grid
    from navkit.sensors import RangeScan

    rng = np.random.default_rng(0)
    P = _obstacle_grid()
    compiled = ObstacleSettings()  # the kernels: this process runs under NAVKIT_JIT=eager
    for label, a in _variants(P, rng):
        yield (
            f"detect_obstacles_grid/{label}",
            lambda a=a: detect_obstacles_grid(a, (0, 0, 1.5), compiled),
        )
        yield (
            f"detect_obstacles_in_grid/{label}",
            lambda a=a: detect_obstacles_in_grid(organized_to_grid(a), Mounting(1.5), compiled),
        )
    az = np.radians(np.linspace(-60, 60, 61))
    el = np.radians(np.linspace(-40, -5, 21))
    d = np.tile(1.5 / np.sin(-el), (az.size, 1))
    for label, a in _variants(d, rng):
        yield (
            f"detect_obstacles/{label}",
            lambda a=a: detect_obstacles(RangeScan(a, az, el, 1.5), compiled),
        )
    cloud = _lidar_cloud()
    for label, a in _variants(cloud, rng):
        yield f"cloud_to_grid/{label}", lambda a=a: cloud_to_grid(a)
        yield (
            f"cloud_to_grid/elevation/{label}",
            lambda a=a: cloud_to_grid(a, ring_method="elevation"),
        )
    for n in (10**9, 2**31, 2**63 - 1, 0, -5):
        yield (
            f"cloud_to_grid/n_columns={n}",
            lambda n=n: cloud_to_grid(cloud, n_columns=n),
        )
    for n in (10**9, 0):
        yield (
            f"cloud_to_grid/n_rings={n}",
            lambda n=n: cloud_to_grid(cloud, n_rings=n, ring_method="elevation"),
        )
    det = detect_obstacles_grid(P, (0, 0, 1.5), compiled)
    for label, v in POISON.items():
        T = np.eye(4)
        T[0, 3] = v
        yield (
            f"ObstacleMapper.update/pose-{label}",
            lambda T=T: ObstacleMapper([-20, -20], [20, 20]).update(det, T),
        )
        xy = np.array([[1.0, 2.0], [v, 0.5], [0.5, v]])
        yield (
            f"ObstacleMapper.add_points/{label}",
            lambda xy=xy: ObstacleMapper([-20, -20], [20, 20]).add_points(xy, xy),
        )
        yield f"ObstacleMapper/hi-{label}", lambda v=v: ObstacleMapper([-20, -20], [v, 20])
        yield f"ObstacleMapper/lo-{label}", lambda v=v: ObstacleMapper([-v, -20], [20, 20])


def _geometry_cases() -> Iterator[tuple[str, Callable[[], Any]]]:
    from navkit.geometry.polygons import convex_hull_2d
    from navkit.geometry.shapes import (
        compute_shapes,
        ellipse_a6,
        hull_points,
        min_circle_welzl,
        mvee_khachiyan,
    )

    rng = np.random.default_rng(1)
    pts = rng.normal(size=(40, 2)) * [2.0, 0.5]
    for label, a in _variants(pts, rng):
        yield f"compute_shapes/{label}", lambda a=a: compute_shapes([a, pts])
        yield (
            f"compute_shapes/hulls/{label}",
            lambda a=a: compute_shapes([a], are_hulls=True),
        )
        for fn in (hull_points, convex_hull_2d, min_circle_welzl, mvee_khachiyan, ellipse_a6):
            yield f"{fn.__name__}/{label}", lambda a=a, fn=fn: fn(a)


def _room(n: int = 400) -> np.ndarray:
    """Points on the walls of an L-shaped 8 x 6 m room (map frame)."""
    corners = np.array([[0, 0], [8, 0], [8, 3], [5, 3], [5, 6], [0, 6], [0, 0]], float)
    t = np.linspace(0, 1, n // 6, endpoint=False)
    return np.concatenate([a + t[:, None] * (b - a) for a, b in itertools.pairwise(corners)])


def _localization_cases() -> Iterator[tuple[str, Callable[[], Any]]]:
    from navkit.localization import Localizer, match_scan
    from navkit.localization.field import LikelihoodField
    from navkit.localization.matcher import score_poses

    rng = np.random.default_rng(2)
    room = _room()
    pose = np.array([2.0, 1.5, 0.3])
    c, s = np.cos(pose[2]), np.sin(pose[2])
    scan = (room - pose[:2]) @ np.array([[c, -s], [s, c]])
    field = LikelihoodField.from_points(room, 0.05, 0.1)
    loc = Localizer.from_points(room)
    for label, a in _variants(scan, rng):
        yield f"match_scan/global/{label}", lambda a=a: match_scan(field, a)
        yield f"match_scan/prior/{label}", lambda a=a: match_scan(field, a, prior=pose)
        yield f"score_poses/{label}", lambda a=a: score_poses(field, a, pose[None])
        yield f"Localizer.update/{label}", lambda a=a: loc.update(a)
    for label, a in _variants(room, rng):
        yield (
            f"LikelihoodField.from_points/{label}",
            lambda a=a: LikelihoodField.from_points(a, 0.05, 0.1),
        )
        yield f"Localizer.from_points/{label}", lambda a=a: Localizer.from_points(a).update(scan)
    for label, v in POISON.items():
        bad = np.array([v, 1.0, 0.2])
        yield f"match_scan/prior-{label}", lambda bad=bad: match_scan(field, scan, prior=bad)
        yield f"score_poses/pose-{label}", lambda bad=bad: score_poses(field, scan, bad[None])
        yield (
            f"Localizer.update/prior-{label}",
            lambda bad=bad: Localizer.from_points(room).update(scan, prior=bad),
        )


def _planes_grid() -> np.ndarray:
    """A 96 x 128 organised grid: a floor 1.2 m below the camera and a wall 4 m ahead."""
    v, u = np.mgrid[0:96, 0:128].astype(float)
    x = (u - 64) / 100.0
    y = (v - 48) / 100.0
    depth = np.where(y > 0.3, 1.2 / np.maximum(y, 1e-3), 4.0)
    depth = np.minimum(depth, 4.0)
    return np.stack([x * depth, y * depth, depth], axis=-1)


def _planes_cases() -> Iterator[tuple[str, Callable[[], Any]]]:
    from navkit.planes import extract_planes_cloud, extract_planes_organized

    rng = np.random.default_rng(3)
    G = _planes_grid()
    for label, a in _variants(G, rng):
        yield f"extract_planes_organized/{label}", lambda a=a: extract_planes_organized(a)
    cloud = G[::2, ::2].reshape(-1, 3)
    for label, a in _variants(cloud, rng):
        yield f"extract_planes_cloud/{label}", lambda a=a: extract_planes_cloud(a)


def _stereo_cases() -> Iterator[tuple[str, Callable[[], Any]]]:
    from navkit.stereo import DisparitySettings, compute_disparity
    from navkit.stereo.disparity import fill_background, lr_consistency, warp_right_disparity

    rng = np.random.default_rng(4)
    left = rng.random((48, 96))
    right = np.roll(left, -8, axis=1)
    settings = DisparitySettings(num_disparities=16, block_size=5, fill="background")
    for label, a in _variants(left, rng):
        yield f"compute_disparity/{label}", lambda a=a: compute_disparity(a, right, settings)
    disp = np.full((48, 96), 8.0)
    for label, a in _variants(disp, rng):
        yield f"warp_right_disparity/{label}", lambda a=a: warp_right_disparity(a)
        yield f"lr_consistency/{label}", lambda a=a: lr_consistency(a, disp)
        yield f"lr_consistency/right/{label}", lambda a=a: lr_consistency(disp, a)
        yield f"fill_background/{label}", lambda a=a: fill_background(a)


def _path_cases() -> Iterator[tuple[str, Callable[[], Any]]]:
    from navkit.path import OnlineApproximator, approximate
    from navkit.path.loops import find_crossings, remove_loops

    rng = np.random.default_rng(5)
    t = np.linspace(0, 4 * np.pi, 300)
    track = np.c_[t, np.sin(t)] + 0.001 * rng.normal(size=(t.size, 2))
    loop = np.c_[np.cos(t) + 0.2 * t, np.sin(t)]
    for label, a in _variants(track, rng):
        yield f"approximate/{label}", lambda a=a: approximate(a, timed=False)
        yield f"approximate/loops/{label}", lambda a=a: _loops(a, remove_loops, find_crossings)

        def online(a: np.ndarray = a) -> Any:
            rec = OnlineApproximator()
            for p in a:
                rec.update(p)
            return rec.finish()

        yield f"OnlineApproximator/{label}", online
    for label, a in _variants(loop, rng):
        yield f"approximate/loop/{label}", lambda a=a: approximate(a, timed=False)


def _loops(
    points: np.ndarray, remove_loops: Callable[..., Any], find_crossings: Callable[..., Any]
) -> Any:
    from navkit.path import ApproximatorSettings, approximate

    res = approximate(points, ApproximatorSettings(remove_loops=False), timed=False)
    find_crossings(res.raw_spline)
    return remove_loops(res.raw_spline)


FAMILIES: dict[str, Callable[[], Iterator[tuple[str, Callable[[], Any]]]]] = {
    "obstacles": _obstacles_cases,
    "geometry": _geometry_cases,
    "localization": _localization_cases,
    "planes": _planes_cases,
    "stereo": _stereo_cases,
    "path": _path_cases,
}


def run_family(name: str) -> dict[str, str]:
    """Every case of ``name`` in this process: ``{case: outcome}``; progress on stderr (the case
    that was running when a signal ended the process is the last one named there)."""
    import warnings

    from navkit.errors import NavkitError

    warnings.simplefilter("ignore")  # NumPy's overflow warnings are not the point here
    outcomes: dict[str, str] = {}
    for case, fn in FAMILIES[name]():
        print(f"case {case}", file=sys.stderr, flush=True)
        try:
            fn()
            outcomes[case] = "valid"
        except NavkitError:
            outcomes[case] = "error"
        except Exception as exc:
            tb = traceback.format_exception(exc)[-3:]
            outcomes[case] = f"crash: {type(exc).__name__}: {exc} | {''.join(tb).strip()[-400:]}"
    return outcomes


# ----------------------------------------------------------------------------- the test


def _family_outcomes(name: str) -> tuple[int, dict[str, str], str]:
    src = Path(__import__("navkit").__file__).resolve().parents[1]
    env = dict(os.environ, NAVKIT_JIT="eager", PYTHONPATH=str(src), PYTHONFAULTHANDLER="1")
    proc = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), name],
        capture_output=True,
        text=True,
        env=env,
        timeout=TIMEOUT_S,
    )
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    outcomes = json.loads(lines[-1]) if lines else {}
    return proc.returncode, outcomes, proc.stderr


def _test(name: str) -> None:
    code, outcomes, stderr = _family_outcomes(name)
    started = [ln[5:] for ln in stderr.splitlines() if ln.startswith("case ")]
    assert code == 0, (
        f"{name}: the subprocess ended with code {code} during case "
        f"{started[-1] if started else '?'}\n{stderr[-3000:]}"
    )
    # the unpoisoned inputs are valid: the cases exercise the kernels, not only the checks
    refused = {k: v for k, v in outcomes.items() if k.endswith("/base") and v != "valid"}
    assert not refused, f"{name}: valid inputs not accepted: {refused}"
    crashes = {k: v for k, v in outcomes.items() if v.startswith("crash")}
    assert not crashes, f"{name}: {len(crashes)} of {len(outcomes)} cases crashed:\n" + "\n".join(
        f"  {k}: {v}" for k, v in crashes.items()
    )
    assert len(outcomes) == len(started) and outcomes, f"{name}: cases missing from the report"


def test_obstacles() -> None:
    _test("obstacles")


def test_geometry() -> None:
    _test("geometry")


def test_localization() -> None:
    _test("localization")


def test_planes() -> None:
    _test("planes")


def test_stereo() -> None:
    _test("stereo")


def test_path() -> None:
    _test("path")


if __name__ == "__main__":
    print(json.dumps(run_family(sys.argv[1])), flush=True)
