"""Compile every navkit kernel into Numba's on-disk cache, then write the stamp (:mod:`navkit.jit`).

:func:`warm_up` runs the small built-in mission (every capability's per-frame path: the lidar's
obstacles, the camera's planes and motion, the stereo room map, the laser fixes, the stored path
and the return along it) and a few calls the mission does not make (a global fix without a
prior, a float32 lidar cloud, every bounding shape), all on the compiled kernels; each kernel
compiles on its first call and is written to the cache. Then the stamp tells later processes
under ``NAVKIT_JIT=auto`` that the kernels are ready.

Run by ``navkit compile`` in the foreground and, under ``NAVKIT_JIT=auto`` on a machine with no
stamp, as the background process ``python -m navkit.runtime.warmup --stamp --lock LOCK``
(:func:`navkit.jit.kernels_enabled`).
"""

from __future__ import annotations

import argparse
import logging
import os
import subprocess
import sys
import time
import traceback
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from navkit import jit
from navkit.errors import NavkitError

__all__ = ["WarmUp", "compiled_kernels", "warm_up"]

log = logging.getLogger(__name__)

ProgressFn = Callable[[Iterator[str], str, int], Iterator[str]]

_MODULES = tuple(
    "navkit." + rel.removesuffix(".py").replace("/", ".") for rel in jit.KERNEL_MODULES
)


@dataclass(frozen=True)
class WarmUp:
    """What :func:`warm_up` did."""

    seconds: dict[str, float]  # wall seconds per step
    compiled: int  # kernel specialisations compiled in this process (cache misses)
    loaded: int  # specialisations loaded from the cache (cache hits)
    stamp: Path | None  # the stamp written (None when not asked)


def compiled_kernels() -> dict[str, tuple[int, int, int]]:
    """Every Numba kernel of navkit's kernel modules (imported here) -> (signatures, cache
    misses = compilations, cache hits = loads) in this process.

    A kernel called only from other kernels gets no signature of its own when its callers load
    from the cache, so "no signature" does not mean "never used"; the cache misses of a
    workload in a fresh process after :func:`warm_up` are the test of its coverage
    (``tests/runtime/test_warmup.py``)."""
    import importlib

    from numba.core.registry import CPUDispatcher

    out: dict[str, tuple[int, int, int]] = {}
    for name in _MODULES:
        mod = importlib.import_module(name)
        for attr, obj in vars(mod).items():
            if isinstance(obj, CPUDispatcher) and obj.__module__ == name:
                out[f"{name}.{attr}"] = (
                    len(obj.signatures),
                    sum(getattr(obj, "_cache_misses").values()),  # noqa: B009 - private
                    sum(getattr(obj, "_cache_hits").values()),  # noqa: B009
                )
    return out


def _mission() -> None:
    from navkit.mission import Mission, MissionSettings
    from navkit.mission.settings import builtin_route_path, load_route
    from navkit.sim import load_scene

    route, overrides = load_route(builtin_route_path("yard"))
    settings = MissionSettings.small().with_overrides(overrides, source="mission_yard.toml")
    Mission(load_scene("yard"), route, settings).run()


def _lidar_cloud() -> None:
    """A float32 spinning-lidar cloud (as recordings give) through grid recovery and the eight
    stages with the default shapes, on a level and on a tilted mounting; and an organised grid
    (:func:`~navkit.obstacles.detect_obstacles`)."""
    from navkit.obstacles import (
        Mounting,
        ObstacleSettings,
        detect_obstacles,
        detect_obstacles_in_grid,
    )
    from navkit.obstacles.grids import cloud_to_grid
    from navkit.sim import Box, Ground, Scene, SpinningLidar, TiltingScanner, render_scan

    boxes = [((5, 0, 0.5), (1, 1, 1)), ((0, 6, 0.8), (2, 1, 1.6)), ((-4, -4, 0.6), (1, 3, 1.2))]
    scene = Scene([Ground(), *(Box(c, size) for c, size in boxes)])
    T = np.eye(4)
    T[2, 3] = 1.0
    sim = render_scan(scene, SpinningLidar(n_beams=32, n_columns=720), T)
    # ring by ring, each ring one sweep (as KITTI stores a cloud): the grid from the storage order
    P = sim.scan.points("sensor").transpose(1, 0, 2).reshape(-1, 3)
    P = P[np.isfinite(P[:, 0])]
    with jit.use("eager"):
        grid = cloud_to_grid(P.astype(np.float32))
        cloud_to_grid(P[::-1], ring_method="elevation")  # any order
        settings = ObstacleSettings()
        detect_obstacles_in_grid(grid, Mounting(1.0), settings)
        detect_obstacles_in_grid(grid, Mounting(1.0, pitch_deg=3.0), settings)
        tilting = render_scan(scene, TiltingScanner(), T).scan
        detect_obstacles(tilting, settings)


def _global_fix() -> None:
    """A laser fix without a prior (the branch-and-bound's global search) in an L-shaped room."""
    from navkit.localization import Localizer

    corners = np.array([[0, 0], [10, 0], [10, 4], [5, 4], [5, 8], [0, 8]], dtype=np.float64)
    ends = zip(corners, np.roll(corners, -1, 0), strict=True)
    walls = np.concatenate([np.linspace(a, b, 200, endpoint=False) for a, b in ends])
    pose = np.array([2.5, 2.0, 0.4])
    c, s = np.cos(pose[2]), np.sin(pose[2])
    local = (walls - pose[:2]) @ np.array([[c, -s], [s, c]])
    Localizer.from_points(walls).update(local[::3])


def _camera_frames() -> None:
    """A 640 x 480 RGB-D frame's planes, plane odometry over two such frames, and a 320 x 240
    stereo pair's disparity (the default left-right check)."""
    from navkit.geometry import se3_from_rt
    from navkit.mission.pose2d import T_body_camera, pose3
    from navkit.planes import PlaneOdometry, extract_planes_organized, observe_rgbd
    from navkit.sensors import PinholeCamera, StereoRig
    from navkit.sim import load_scene, render_rgbd, render_stereo
    from navkit.stereo import DisparitySettings, compute_disparity

    scene = load_scene("yard")
    T = pose3(np.array(scene.start, dtype=np.float64), 0.0) @ T_body_camera(0.6, 10.0)
    cam = PinholeCamera(525.0, 525.0, 319.5, 239.5, 640, 480)
    frame = render_rgbd(scene, cam, T).frame
    extract_planes_organized(frame.points())
    odometry = PlaneOdometry()  # the dense step's kernels: two frames 2 cm apart
    odometry.update(observe_rgbd(frame))
    odometry.update(
        observe_rgbd(render_rgbd(scene, cam, T @ se3_from_rt(np.eye(3), [0.02, 0, 0])).frame)
    )
    small = PinholeCamera(260.0, 260.0, 159.5, 119.5, 320, 240)
    pair = render_stereo(scene, StereoRig(small, 0.12), T, supersample=1).pair
    compute_disparity(pair.left, pair.right)
    compute_disparity(pair.left, pair.right, DisparitySettings(fill="background"))


def _path_record() -> None:
    """A noisy figure eight driven twice through the path recorder: every path kernel (the
    exact deviation test of a point, the freeze's passes, the loop search and cut), whatever
    the mission's short route happens to need."""
    from navkit.path import ApproximatorSettings, approximate

    t = np.linspace(0.0, 4.0 * np.pi, 800)
    xy = np.c_[10.0 * np.sin(t), 5.0 * np.sin(2.0 * t)]
    xy += np.random.default_rng(0).normal(0.0, 0.01, xy.shape)
    approximate(xy, ApproximatorSettings(tolerance=0.05), timed=False)


STEPS: dict[str, Callable[[], None]] = {
    "mission (small)": _mission,
    "path recording": _path_record,
    "lidar cloud, every shape": _lidar_cloud,
    "global laser fix": _global_fix,
    "camera frames": _camera_frames,
}


def warm_up(*, stamp: bool = True, progress: ProgressFn | None = None) -> WarmUp:
    """Run :data:`STEPS` on the compiled kernels (compiling what the cache lacks) and, when all
    of them finished and ``stamp``, write the stamp (:func:`navkit.jit.write_stamp`)."""
    if jit.status().enabled is False:  # a process never switches implementation
        raise NavkitError(
            "this process already runs the NumPy twins (NAVKIT_JIT found no compiled kernels); "
            "warm up in a new process: `navkit compile`"
        )
    os.environ[jit.ENV] = "eager"  # this process and anything it starts run the kernels
    seconds: dict[str, float] = {}
    names: Iterator[str] = iter(list(STEPS))
    if progress is not None:
        names = progress(names, "compiling navkit's kernels", len(STEPS))
    for name in names:
        log.info("warm-up: %s", name)
        t0 = time.perf_counter()
        STEPS[name]()
        seconds[name] = time.perf_counter() - t0
    kernels = compiled_kernels()
    jit.failed_path().unlink(missing_ok=True)
    return WarmUp(
        seconds,
        sum(m for _, m, _ in kernels.values()),
        sum(h for _, _, h in kernels.values()),
        jit.write_stamp() if stamp else None,
    )


_background: subprocess.Popen[bytes] | None = None  # the warm-up this process started


def start_background() -> bool:
    """Start one detached ``python -m navkit.runtime.warmup --stamp`` at idle CPU priority unless
    one runs or an earlier one failed; True when the compilation is (being) done elsewhere.

    The command line registers it with :func:`navkit.jit.on_missing_kernels`; an ``OSError``
    (no process could be started) leaves no lock behind and reaches the caller, which then
    compiles in its own process.
    """
    global _background
    lock = jit.lock_path()
    lock.parent.mkdir(parents=True, exist_ok=True)
    if jit.failed_path().exists():
        log.warning(
            "the background compilation of navkit's kernels failed (%s): this run uses their "
            "NumPy twins; `navkit compile` shows the error",
            jit.failed_path(),
        )
        return True
    if lock.exists() and not jit.lock_is_fresh(lock):
        lock.unlink(missing_ok=True)
    try:
        fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    except FileExistsError:
        log.info("navkit's kernels are being compiled by another process; NumPy twins run here")
        return True
    env = dict(os.environ, **{jit.ENV: "eager"})
    logfile = lock.with_suffix(".log")
    try:
        with open(logfile, "wb") as out:
            proc = subprocess.Popen(
                [sys.executable, "-m", "navkit.runtime.warmup", "--stamp", "--lock", str(lock)],
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
    except OSError:
        os.close(fd)
        lock.unlink(missing_ok=True)
        raise
    _background = proc  # kept: it outlives this call (and may outlive the process)
    os.write(fd, f"{proc.pid}\n".encode())
    os.close(fd)
    log.info(
        "navkit's compiled kernels are not built on this machine yet: this run uses their NumPy "
        "twins (same results, slower) while process %d compiles them for the next runs "
        "(`navkit compile` does it in the foreground; NAVKIT_JIT=eager|numpy to choose)",
        proc.pid,
    )
    return True


def main(argv: list[str] | None = None) -> int:
    """``python -m navkit.runtime.warmup [--stamp] [--lock FILE]`` (the background warm-up)."""
    ap = argparse.ArgumentParser(prog="python -m navkit.runtime.warmup", description=__doc__)
    ap.add_argument("--stamp", action="store_true", help="write the stamp when done")
    ap.add_argument("--lock", type=Path, help="lock file to remove when done")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s: %(message)s")
    # the lowest CPU priority there is: on Linux SCHED_IDLE runs only on otherwise idle CPU
    # time (a foreground run sharing the core loses almost nothing), elsewhere nice 19
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (AttributeError, OSError):
        try:
            os.nice(19)
        except OSError:
            pass
    try:
        res = warm_up(stamp=args.stamp)
        log.info(
            "compiled %d, loaded %d; steps %s; stamp %s",
            res.compiled,
            res.loaded,
            {k: round(v, 1) for k, v in res.seconds.items()},
            res.stamp,
        )
        return 0
    except Exception:
        # later processes must not start a failing warm-up again and again: they read this
        # marker, run the NumPy twins and point at the log (navkit.jit)
        log.exception("the warm-up failed")
        jit.failed_path().write_text(traceback.format_exc())
        return 1
    finally:
        if args.lock is not None:
            args.lock.unlink(missing_ok=True)


if __name__ == "__main__":
    raise SystemExit(main())
