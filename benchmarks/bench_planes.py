"""Planes (paper 2) beside Open3D: motion from 1, 2 and >= 3 planes vs point-to-plane ICP and
colored ICP on the same frame pairs; plane extraction vs Open3D's ``segment_plane`` loop.

Run: ``python -m benchmarks planes`` (``--quick`` for fewer pairs).
"""

from __future__ import annotations

import itertools
import logging
import time
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from benchmarks.common import Row, median_time, time_ratio
from navkit.geometry import se3_from_rt, se3_from_xyz_quat, se3_inverse
from navkit.geometry.rotations import rotation_angle
from navkit.planes import (
    ExtractionSettings,
    MotionEstimate,
    OdometrySettings,
    PlaneOdometry,
    estimate_motion,
    extract_planes_organized,
    observe_rgbd,
)
from navkit.planes.frame import reproject_rgbd
from navkit.planes.metrics import ate, rpe
from navkit.sensors import PinholeCamera, RGBDFrame
from navkit.sim import Ground, Scene, Texture, Wall, render_rgbd
from navkit.sim.scanners import RangeNoise

log = logging.getLogger(__name__)
AREA = "planes"
CAM = PinholeCamera(525.0, 525.0, 319.5, 239.5, 640, 480)
NOISE = RangeNoise(relative_sigma=0.002)
BRICKS = Texture("bricks", scale=0.3, seed=3, color=(0.6, 0.3, 0.2), color2=(0.85, 0.8, 0.75))
R_FORWARD = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
R_AT_WALL = np.stack([[-1.0, 0, 0], [0, 0, -1.0], [0, -1.0, 0]], axis=1)


def _scene(n_dirs: int) -> Scene:
    prims = [Wall(origin=(-5, -1.5, 0), u=(30, 0, 0), v=(0, 0, 3), texture=BRICKS, name="wall")]
    if n_dirs >= 2:
        prims.append(Ground(texture=Texture("noise", scale=0.4, seed=5), name="floor"))
    if n_dirs >= 3:
        prims.append(
            Wall(
                origin=(8, -6, 0),
                u=(0, 12, 0),
                v=(0, 0, 3),
                texture=Texture("tiles", scale=0.3, seed=2),
                name="end",
            )
        )
    return Scene(prims)


def _start(n_dirs: int) -> np.ndarray:
    if n_dirs == 1:
        return se3_from_rt(R_AT_WALL, [0.0, 0.5, 1.2])
    return se3_from_rt(
        Rotation.from_euler("z", -25, degrees=True).as_matrix() @ R_FORWARD, [0.0, 0.0, 1.0]
    )


def _motions(n: int, seed: int) -> list[np.ndarray]:
    """Frame-to-frame motions of a hand-held / robot camera: up to ~5 deg and ~25 cm."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        rv = rng.normal(0, 0.04, 3)
        t = rng.normal(0, 0.1, 3)
        t[2] = abs(t[2]) + 0.05
        out.append(se3_from_rt(Rotation.from_rotvec(rv).as_matrix(), t))
    return out


def _err(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    E = se3_inverse(T_true) @ T_est
    return float(np.degrees(rotation_angle(E[:3, :3]))), float(100 * np.linalg.norm(E[:3, 3]))


# ---------------------------------------------------------------------------------------- Open3D


def _o3d():
    from navkit.errors import require_module

    return require_module("open3d", "bench", "the Open3D comparison")


def _pcd(o3d, frame: RGBDFrame, voxel: float):
    P = frame.points().reshape(-1, 3)
    C = frame.color.reshape(-1, 3) / 255.0
    ok = np.all(np.isfinite(P), axis=1)
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P[ok]))
    pc.colors = o3d.utility.Vector3dVector(C[ok])
    return pc.voxel_down_sample(voxel)


def _icp_point_to_plane(o3d, f1: RGBDFrame, f2: RGBDFrame) -> np.ndarray:
    reg = o3d.pipelines.registration
    src, tgt = _pcd(o3d, f2, 0.02), _pcd(o3d, f1, 0.02)
    tgt.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.08, max_nn=30))
    r = reg.registration_icp(
        src,
        tgt,
        0.1,
        np.eye(4),
        reg.TransformationEstimationPointToPlane(),
        reg.ICPConvergenceCriteria(max_iteration=50),
    )
    return np.asarray(r.transformation)


def _icp_colored(o3d, f1: RGBDFrame, f2: RGBDFrame) -> np.ndarray:
    """Open3D's colored ICP (Park et al. 2017), its example's multi-scale schedule (voxels 4, 2,
    1 cm; 50, 30, 14 iterations) with a correspondence distance of 3 voxels (the example's 1 voxel
    cannot capture frame-to-frame motions of ~10 cm from the identity)."""
    reg = o3d.pipelines.registration
    T = np.eye(4)
    for radius, iters in ((0.04, 50), (0.02, 30), (0.01, 14)):
        src, tgt = _pcd(o3d, f2, radius), _pcd(o3d, f1, radius)
        for pc in (src, tgt):
            pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * radius, max_nn=30))
        r = reg.registration_colored_icp(
            src,
            tgt,
            3 * radius,
            T,
            reg.TransformationEstimationForColoredICP(),
            reg.ICPConvergenceCriteria(
                relative_fitness=1e-6, relative_rmse=1e-6, max_iteration=iters
            ),
        )
        T = np.asarray(r.transformation)
    return T


def _segment_plane_loop(o3d, points: np.ndarray, n_planes: int) -> int:
    """Open3D's usual multi-plane loop: segment_plane, remove inliers, repeat."""
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    found = 0
    for _ in range(n_planes):
        if len(pc.points) < 3000:
            break
        _, inl = pc.segment_plane(distance_threshold=0.02, ransac_n=3, num_iterations=200)
        if len(inl) < 3000:
            break
        pc = pc.select_by_index(inl, invert=True)
        found += 1
    return found


# ------------------------------------------------------------------------------------ benchmarks


@dataclass
class _Case:
    name: str
    f1: RGBDFrame
    f2: RGBDFrame
    truth: np.ndarray


def _sim_cases(n_per_case: int) -> dict[int, list[_Case]]:
    out: dict[int, list[_Case]] = {}
    for n_dirs in (1, 2, 3):
        scene = _scene(n_dirs)
        T1 = _start(n_dirs)
        f1 = render_rgbd(scene, CAM, T1, noise=NOISE, rng=1, supersample=2).frame
        cases = []
        for k, M in enumerate(_motions(n_per_case, 10 * n_dirs)):
            f2 = render_rgbd(scene, CAM, T1 @ M, noise=NOISE, rng=2 + k, supersample=2).frame
            cases.append(_Case(f"sim {n_dirs}-plane #{k}", f1, f2, M))
        out[n_dirs] = cases
    return out


def _compare(cases: list[_Case], label: str, o3d) -> list[Row]:
    nav_r, nav_t, nav_ms, p2p_r, p2p_t, p2p_ms, col_r, col_t, col_ms = ([] for _ in range(9))
    ok = 0
    for c in cases:
        t0 = time.perf_counter()
        est = estimate_motion(observe_rgbd(c.f1), observe_rgbd(c.f2))
        nav_ms.append(1000 * (time.perf_counter() - t0))
        if isinstance(est, MotionEstimate):
            ok += 1
            r, t = _err(est.T, c.truth)
            nav_r.append(r)
            nav_t.append(t)
        for fn, rr, tt, ms in (
            (_icp_point_to_plane, p2p_r, p2p_t, p2p_ms),
            (_icp_colored, col_r, col_t, col_ms),
        ):
            t0 = time.perf_counter()
            try:
                r, t = _err(fn(o3d, c.f1, c.f2), c.truth)
            except (
                RuntimeError
            ) as exc:  # Open3D gives up (no correspondences): counted as a failure
                log.warning("%s on %s: %s", fn.__name__, c.name, str(exc).splitlines()[0][:120])
                r, t = float("inf"), float("inf")
            ms.append(1000 * (time.perf_counter() - t0))
            rr.append(r)
            tt.append(t)
    med = lambda v: float(np.median(v)) if v else None  # noqa: E731
    n_fail = sum(not np.isfinite(v) for v in col_t)
    n = f"navkit solved {ok}/{len(cases)}, colored ICP failed {n_fail}; median over pairs"
    return [
        Row(
            AREA,
            f"{label}: translation error",
            "cm",
            med(nav_t),
            med(col_t),
            "Open3D colored ICP",
            None if not nav_t else med(col_t) / max(med(nav_t), 1e-9),
            n + "; ratio = peer error / navkit error",
        ),
        Row(
            AREA,
            f"{label}: translation error",
            "cm",
            med(nav_t),
            med(p2p_t),
            "Open3D point-to-plane ICP",
            None if not nav_t else med(p2p_t) / max(med(nav_t), 1e-9),
            "ratio = peer error / navkit error",
        ),
        Row(
            AREA,
            f"{label}: rotation error",
            "deg",
            med(nav_r),
            med(col_r),
            "Open3D colored ICP",
            None if not nav_r else med(col_r) / max(med(nav_r), 1e-9),
            "ratio = peer error / navkit error",
        ),
        Row(
            AREA,
            f"{label}: rotation error",
            "deg",
            med(nav_r),
            med(p2p_r),
            "Open3D point-to-plane ICP",
            None if not nav_r else med(p2p_r) / max(med(nav_r), 1e-9),
            "ratio = peer error / navkit error",
        ),
        Row(
            AREA,
            f"{label}: time per pair",
            "ms",
            med(nav_ms),
            med(col_ms),
            "Open3D colored ICP",
            time_ratio(med(nav_ms), med(col_ms)),
            "navkit: extraction of both frames + association + solver",
        ),
        Row(
            AREA,
            f"{label}: time per pair",
            "ms",
            med(nav_ms),
            med(p2p_ms),
            "Open3D point-to-plane ICP",
            time_ratio(med(nav_ms), med(p2p_ms)),
            "",
        ),
    ]


def _cpu_median(fn, repeats: int) -> float:
    """Median CPU time (``time.process_time``: this process, all its threads) of ``fn()`` in
    seconds after one warm-up run - robust to the other processes on a shared machine."""
    fn()
    cpu = []
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        cpu.append(time.process_time() - t0)
    return float(np.median(cpu))


def _extraction_rows(o3d, frames: list[tuple[str, RGBDFrame]], repeats: int) -> list[Row]:
    """Organised plane extraction of 640 x 480 frames: navkit (default boundary refinement, and
    the exact per-pixel refinement ``refine="full"``) against Open3D's ``segment_plane`` loop
    asked for as many planes, CPU time of each in the same run (medians), ratio peer / navkit."""
    rows = []
    fast, full = ExtractionSettings(), ExtractionSettings(refine="full")
    for name, f in frames:
        P = f.points()
        n_planes = len(extract_planes_organized(P, fast))
        flat = P.reshape(-1, 3)
        flat = flat[np.all(np.isfinite(flat), axis=1)]
        # interleaved so that both see the same load: navkit, Open3D, navkit full, repeated
        t_nav, t_o3d, t_full = [], [], []
        for _ in range(3):
            t_nav.append(_cpu_median(lambda P=P: extract_planes_organized(P, fast), repeats))
            t_o3d.append(
                _cpu_median(
                    lambda flat=flat, k=n_planes: _segment_plane_loop(o3d, flat, k),
                    max(1, repeats // 3),
                )
            )
            t_full.append(_cpu_median(lambda P=P: extract_planes_organized(P, full), repeats))
        nav, peer, exact = (float(np.median(t)) for t in (t_nav, t_o3d, t_full))
        wall = median_time(lambda P=P: extract_planes_organized(P, fast), repeats=repeats)
        rows.append(
            Row(
                AREA,
                f"plane extraction 640x480 ({name}, {n_planes} planes), CPU time",
                "ms",
                1000 * nav,
                1000 * peer,
                "Open3D segment_plane loop",
                time_ratio(nav, peer),
                f"process_time medians, same run; same number of planes asked of Open3D; "
                f"ratio > 1: navkit faster; refine='full': {1000 * exact:.1f} ms; "
                f"navkit wall time {1000 * wall:.1f} ms",
            )
        )
    return rows


def extraction_frames() -> list[tuple[str, RGBDFrame]]:
    """The extraction benchmark's frames: the simulated >= 3-plane corridor (640 x 480, depth
    noise 0.2 %) and, when the recorded data is present, the three slambook-ch5 Kinect frames."""
    from navkit.errors import DataNotFoundError

    scene = _scene(3)
    frames = [
        (
            "sim corridor",
            render_rgbd(scene, CAM, _start(3), noise=NOISE, rng=1, supersample=2).frame,
        )
    ]
    try:
        from navkit.datasets import find
        from navkit.io.rgbd import read_simple_rgbd

        seq = read_simple_rgbd(
            find("rgbd/slambook-ch5"),
            {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0},
        )
        frames += [(f"slambook real #{i + 1}", seq.frame(i)) for i in range(len(seq))]
    except DataNotFoundError as exc:  # recorded data absent: the simulator row still stands
        log.warning("real-data extraction rows skipped: %s", exc)
    return frames


def _cape_rows(o3d) -> list[Row]:
    from navkit.datasets import find
    from navkit.io.rgbd import read_cape_frame

    f = read_cape_frame(find("rgbd/cape-tunnel"))
    cases = []
    for k, M in enumerate(_motions(3, 99)):
        a = reproject_rgbd(f.points, f.color_registered, f.ir_camera, np.eye(4))
        b = reproject_rgbd(f.points, f.color_registered, f.ir_camera, se3_inverse(M))
        cases.append(_Case(f"cape #{k}", a, b, M))
    return _compare(cases, "CAPE tunnel (real wall + floor, synthetic motion)", o3d)


def _slambook_rows() -> list[Row]:
    from navkit.datasets import find
    from navkit.io.rgbd import read_simple_rgbd

    root = find("rgbd/slambook-ch5")
    seq = read_simple_rgbd(
        root, {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0}
    )
    P = np.loadtxt(root / "pose.txt")
    Tw = [se3_from_xyz_quat(p[:3], p[3:]) for p in P]
    obs = [observe_rgbd(seq.frame(i)) for i in range(len(seq))]
    rows = []
    for a, b in ((0, 1), (1, 2), (0, 2)):
        truth = se3_inverse(Tw[a]) @ Tw[b]
        for prior, tag in ((None, "no prior"), (truth, "reference as association prior")):
            est = estimate_motion(obs[a], obs[b], prior)
            if isinstance(est, MotionEstimate):
                r, t = _err(est.T, truth)
                note = (
                    f"case {est.case}; {tag}; motion {np.degrees(rotation_angle(truth[:3, :3])):.1f} deg, "
                    f"{100 * np.linalg.norm(truth[:3, 3]):.0f} cm; rotation error {r:.2f} deg"
                )
                rows.append(
                    Row(
                        AREA,
                        f"slambook frames {a + 1}->{b + 1} translation error",
                        "cm",
                        t,
                        note=note,
                    )
                )
            else:
                rows.append(
                    Row(
                        AREA,
                        f"slambook frames {a + 1}->{b + 1}",
                        "cm",
                        None,
                        note=f"{tag}: {est.reason}",
                    )
                )
    return rows


def _sequence_rows(o3d, n_frames: int) -> list[Row]:
    """A 2-plane corridor walk: navkit odometry vs chained colored ICP, ATE / RPE (evo's definitions)."""
    scene = _scene(2)
    step = se3_from_rt(Rotation.from_rotvec([0, -0.03, 0]).as_matrix(), [0.02, 0.0, 0.15])
    T = _start(2)
    frames, truth = [], []
    for k in range(n_frames):
        frames.append(render_rgbd(scene, CAM, T, noise=NOISE, rng=k, supersample=2).frame)
        truth.append(T)
        T = T @ step
    truth = se3_inverse(truth[0]) @ np.array(truth)
    odo = PlaneOdometry(OdometrySettings())
    t0 = time.perf_counter()
    for f in frames:
        odo.update(observe_rgbd(f))
    nav_ms = 1000 * (time.perf_counter() - t0) / n_frames
    est = odo.trajectory
    chain = [np.eye(4)]
    t0 = time.perf_counter()
    for a, b in itertools.pairwise(frames):
        chain.append(chain[-1] @ _icp_colored(o3d, a, b))
    col_ms = 1000 * (time.perf_counter() - t0) / n_frames
    chain = np.array(chain)
    return [
        Row(
            AREA,
            f"sim corridor {n_frames} frames (2 planes): ATE",
            "cm",
            100 * ate(est, truth),
            100 * ate(chain, truth),
            "Open3D colored ICP (chained)",
            100 * ate(chain, truth) / max(100 * ate(est, truth), 1e-9),
            "evo definition (SE(3) Umeyama alignment, translation RMSE); ratio = peer / navkit",
        ),
        Row(
            AREA,
            f"sim corridor {n_frames} frames (2 planes): RPE",
            "cm",
            100 * rpe(est, truth)[0],
            100 * rpe(chain, truth)[0],
            "Open3D colored ICP (chained)",
            rpe(chain, truth)[0] / max(rpe(est, truth)[0], 1e-12),
            "delta 1 frame, translation RMSE",
        ),
        Row(
            AREA,
            f"sim corridor {n_frames} frames: time per frame",
            "ms",
            nav_ms,
            col_ms,
            "Open3D colored ICP",
            time_ratio(nav_ms, col_ms),
            "navkit: extraction + tracking + map merge",
        ),
    ]


def _loop_frames(n_frames: int, image_sigma: float = 20.0) -> tuple[list, np.ndarray]:
    """A 2-plane corridor walk out and back (``n_frames // 2`` steps each way), depth noise
    0.5 % of range, ``image_sigma`` (of 255) Gaussian noise on the colour: the truth-known
    sequence of ``tests/planes/test_tracking.py`` at 640 x 480."""
    scene = _scene(2)
    step = se3_from_rt(Rotation.from_rotvec([0, -0.03, 0]).as_matrix(), [0.02, 0.0, 0.12])
    rng = np.random.default_rng(0)
    T = _start(2)
    obs, truth = [], []
    for k in range(n_frames):
        truth.append(T)
        f = render_rgbd(scene, CAM, T, noise=RangeNoise(relative_sigma=0.005), rng=k).frame
        col = np.clip(f.color + rng.normal(0.0, image_sigma, f.color.shape), 0, 255)
        obs.append(observe_rgbd(RGBDFrame(col.astype(np.uint8), f.depth, f.camera, float(k))))
        T = T @ (se3_inverse(step) if k >= n_frames // 2 else step)
    return obs, se3_inverse(truth[0]) @ np.array(truth)


def _glitch_frames() -> tuple[list, np.ndarray]:
    """A 2-plane corridor walk that slows from 12 to 6 cm per frame just as frame 5 is blank
    (uniform brightness): the sequence of
    ``test_tracking.py::test_frame_to_map_recovers_after_a_failed_frame`` at 640 x 480."""
    scene = _scene(2)
    turn = Rotation.from_rotvec([0, -0.03, 0]).as_matrix()
    T = _start(2)
    obs, truth = [], []
    speeds = [0.12, 0.12, 0.12, 0.12, 0.06, 0.06, 0.12, 0.12, 0.12]
    for k in range(len(speeds) + 1):
        truth.append(T)
        f = render_rgbd(scene, CAM, T, noise=RangeNoise(relative_sigma=0.005), rng=k).frame
        col = f.color if k != 5 else np.full_like(f.color, 128)
        obs.append(observe_rgbd(RGBDFrame(col, f.depth, f.camera, float(k))))
        if k < len(speeds):
            T = T @ se3_from_rt(turn, [0.02, 0.0, speeds[k]])
    return obs, se3_inverse(truth[0]) @ np.array(truth)


def _tracking_mode_rows(n_frames: int) -> list[Row]:
    """Frame-to-map vs frame-to-frame tracking on the same out-and-back corridor walk (both
    navkit; the 'peer' column is frame-to-frame). CPU time per frame (``time.process_time``),
    extraction excluded (the same for both)."""
    rows = _mode_rows(*_loop_frames(n_frames), f"sim corridor out and back, {n_frames} frames")
    rows += _mode_rows(*_glitch_frames(), "sim corridor, blank frame 5 while slowing down")
    return rows


def _mode_rows(obs: list, truth: np.ndarray, label: str) -> list[Row]:
    n_frames = len(obs)
    out = {}
    for f2m in (False, True):
        odo = PlaneOdometry(OdometrySettings(frame_to_map=f2m))
        t0 = time.process_time()
        for o in obs:
            odo.update(o)
        cpu = 1000 * (time.process_time() - t0) / n_frames
        est = odo.trajectory
        end = np.linalg.norm((se3_inverse(truth[-1]) @ est[-1])[:3, 3])
        out[f2m] = (ate(est, truth), rpe(est, truth), end, cpu)
    m, f = out[True], out[False]
    return [
        Row(
            AREA,
            f"{label}: ATE",
            "cm",
            100 * m[0],
            100 * f[0],
            "frame-to-frame",
            f[0] / max(m[0], 1e-12),
            "frame-to-map vs frame-to-frame; ratio = f2f / f2m",
        ),
        Row(
            AREA,
            f"{label}: RPE",
            "cm",
            100 * m[1][0],
            100 * f[1][0],
            "frame-to-frame",
            f[1][0] / max(m[1][0], 1e-12),
            "delta 1 frame, translation RMSE",
        ),
        Row(
            AREA,
            f"{label}: error of the last frame",
            "cm",
            100 * m[2],
            100 * f[2],
            "frame-to-frame",
            f[2] / max(m[2], 1e-12),
            "the last frame (out and back: where the walk started)",
        ),
        Row(
            AREA,
            f"{label}: tracking CPU per frame",
            "ms",
            m[3],
            f[3],
            "frame-to-frame",
            time_ratio(m[3], f[3]),
            "process time, extraction excluded",
        ),
    ]


def run(quick: bool = False) -> list[Row]:
    o3d = _o3d()
    rows: list[Row] = []
    cases = _sim_cases(1 if quick else 3)
    for n_dirs, label in (
        (1, "sim 1 plane (brick wall)"),
        (2, "sim 2 planes (wall + floor)"),
        (3, "sim >=3 planes"),
    ):
        rows += _compare(cases[n_dirs], label, o3d)
    frames = [("sim corridor", cases[3][0].f1)]
    from navkit.errors import DataNotFoundError

    try:
        from navkit.datasets import find
        from navkit.io.rgbd import read_simple_rgbd

        seq = read_simple_rgbd(
            find("rgbd/slambook-ch5"),
            {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0},
        )
        frames.append(("slambook real", seq.frame(0)))
        real = True
    except DataNotFoundError as exc:  # recorded data absent: the simulator rows still stand
        log.warning("real-data rows skipped: %s", exc)
        real = False
    rows += _extraction_rows(o3d, extraction_frames(), 5 if quick else 9)
    if real:
        rows += _cape_rows(o3d)
        rows += _slambook_rows()
    rows += _sequence_rows(o3d, 5 if quick else 10)
    rows += _tracking_mode_rows(10 if quick else 16)
    return rows
