"""Planes on a real RGB-D sequence: navkit vs Open3D's dense RGB-D odometry and colored ICP.

Data: the 100 consecutive 7-Scenes frames of ``rgbd/7scenes-tsdf`` (30 Hz, hand-held Kinect,
0.1-1.4 cm between frames; reference = the dataset's KinectFusion poses), taken every 1, 5, 10
and 20 frames, and the slambook-ch5 pairs 1 -> 2 and 2 -> 3 (large motions).

**Transfer table**: both shared sequences, every frame, with ONE default
``OdometrySettings`` - 7-Scenes and ``rgbd/tum-fr3-structure-notexture-far`` (100 real Kinect
frames of large untextured planes; reference = motion capture, ``groundtruth.txt``
interpolated at the frame times by :func:`navkit.planes.metrics.poses_at`; frames before the
motion capture starts are tracked but not scored): tracked share, frames tracked but more than
5 cm / 2 deg off, RPE median, ATE, CPU per frame and its ratio to Open3D hybrid, same run.

Methods, each tracking frame k against the frames before it and chaining:

- **navkit**: :class:`navkit.planes.PlaneOdometry` with its defaults (planes frame-to-map,
  dense photometric + geometric refinement and verification against a keyframe); plane
  extraction is included in its CPU time. A frame it reports as failed is counted as a failure
  and left out of its RPE / ATE (its pose is a prediction, never written as a result).
- **Open3D hybrid**: ``o3d.pipelines.odometry.compute_rgbd_odometry`` with
  ``RGBDOdometryJacobianFromHybridTerm`` (default option: 3 levels, 20/10/5 iterations),
  frame k against frame k-1; ``success == False`` is counted as a failure and the identity is
  chained (what a user of it gets).
- **Open3D colored ICP**: ``registration_colored_icp`` coarse to fine (voxels 4, 2, 1 cm,
  50 / 30 / 14 iterations, as Open3D's tutorial), frame k against frame k-1 from the identity.

Figures: RPE between consecutive evaluated frames (translation cm, rotation deg: median, p95,
max), ATE (cm, evo's definition, Umeyama-aligned), failures reported, **silent** errors (frames
reported as tracked with an error above 5 cm or 2 deg), CPU ms per frame
(``time.process_time``: all threads; in the same run).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from benchmarks.common import Row

AREA = "planes_seq"
SEQ = "rgbd/7scenes-tsdf"
TUM = "rgbd/tum-fr3-structure-notexture-far"
SLAMBOOK = "rgbd/slambook-ch5"
SLAMBOOK_CAMERA = {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0}


def _rel_errors(P: np.ndarray, G: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Translation (m) and rotation (deg) errors of consecutive steps where both ends are ok."""
    from scipy.spatial.transform import Rotation

    from navkit.geometry import se3_inverse

    et, er = [], []
    scored = ok & np.isfinite(G).all(axis=(1, 2))
    for k in range(1, len(P)):
        if not (scored[k] and scored[k - 1]):
            continue
        E = se3_inverse(se3_inverse(G[k - 1]) @ G[k]) @ (se3_inverse(P[k - 1]) @ P[k])
        et.append(np.linalg.norm(E[:3, 3]))
        er.append(np.degrees(Rotation.from_matrix(E[:3, :3]).magnitude()))
    return np.array(et), np.array(er)


def _navkit(frames: list, cameras: Any) -> tuple[np.ndarray, np.ndarray, list[float], list[str]]:
    from navkit.planes import FrameMotion, PlaneOdometry, observe_rgbd

    odo = PlaneOdometry()
    cpu, sources = [], []
    for f in frames:
        t0 = time.process_time()
        r = odo.update(observe_rgbd(f))
        cpu.append(1000 * (time.process_time() - t0))
        sources.append(r.source if isinstance(r, FrameMotion) else f"failed: {r.reason}"[:40])
    return odo.trajectory, odo.tracked, cpu, sources


def _o3d_rgbd(o3d, f):
    color = o3d.geometry.Image(np.ascontiguousarray(f.color))
    depth = np.where(np.isfinite(f.depth), f.depth * 1000.0, 0).astype(np.uint16)
    return o3d.geometry.RGBDImage.create_from_color_and_depth(
        color,
        o3d.geometry.Image(depth),
        depth_scale=1000.0,
        depth_trunc=4.0,
        convert_rgb_to_intensity=True,
    )


def _o3d_intrinsic(o3d, cam):
    return o3d.camera.PinholeCameraIntrinsic(cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy)


def _open3d_hybrid(frames: list) -> tuple[np.ndarray, np.ndarray, list[float]]:
    from navkit.errors import require_module

    o3d = require_module("open3d", "bench", "the Open3D peers")
    odo = o3d.pipelines.odometry
    K = _o3d_intrinsic(o3d, frames[0].camera)
    option = odo.OdometryOption()
    jac = odo.RGBDOdometryJacobianFromHybridTerm()
    poses, ok, cpu = [np.eye(4)], [True], []
    prev = _o3d_rgbd(o3d, frames[0])
    for f in frames[1:]:
        t0 = time.process_time()
        cur = _o3d_rgbd(o3d, f)
        success, T, _ = odo.compute_rgbd_odometry(cur, prev, K, np.eye(4), jac, option)
        cpu.append(1000 * (time.process_time() - t0))
        poses.append(poses[-1] @ (np.asarray(T) if success else np.eye(4)))
        ok.append(bool(success))
        prev = cur
    return np.array(poses), np.array(ok), cpu


def _o3d_cloud(o3d, f):
    rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
        o3d.geometry.Image(np.ascontiguousarray(f.color)),
        o3d.geometry.Image(np.where(np.isfinite(f.depth), f.depth * 1000, 0).astype(np.uint16)),
        depth_scale=1000.0,
        depth_trunc=4.0,
        convert_rgb_to_intensity=False,
    )
    return o3d.geometry.PointCloud.create_from_rgbd_image(rgbd, _o3d_intrinsic(o3d, f.camera))


def _open3d_colored_icp(frames: list) -> tuple[np.ndarray, np.ndarray, list[float]]:
    from navkit.errors import require_module

    o3d = require_module("open3d", "bench", "the Open3D peers")
    reg = o3d.pipelines.registration
    poses, ok, cpu = [np.eye(4)], [True], []
    prev = _o3d_cloud(o3d, frames[0])
    for f in frames[1:]:
        t0 = time.process_time()
        cur = _o3d_cloud(o3d, f)
        T = np.eye(4)
        good = True
        for voxel, iters in ((0.04, 50), (0.02, 30), (0.01, 14)):
            s, t = cur.voxel_down_sample(voxel), prev.voxel_down_sample(voxel)
            for c in (s, t):
                c.estimate_normals(
                    o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30)
                )
            try:
                res = reg.registration_colored_icp(
                    s,
                    t,
                    voxel,
                    T,
                    reg.TransformationEstimationForColoredICP(),
                    reg.ICPConvergenceCriteria(1e-6, 1e-6, iters),
                )
                T = np.asarray(res.transformation)
            except RuntimeError:
                good = False
                break
        cpu.append(1000 * (time.process_time() - t0))
        poses.append(poses[-1] @ T)
        ok.append(good)
        prev = cur
    return np.array(poses), np.array(ok), cpu


def _stats(P, G, ok, cpu) -> dict[str, float]:
    from navkit.planes.metrics import ate

    et, er = _rel_errors(P, G, ok)
    silent = int(np.sum((et > 0.05) | (er > 2.0)))
    scored = ok & np.isfinite(G).all(axis=(1, 2))
    return {
        "rpe_t_med": 100 * float(np.median(et)) if len(et) else np.nan,
        "rpe_t_p95": 100 * float(np.percentile(et, 95)) if len(et) else np.nan,
        "rpe_t_max": 100 * float(et.max()) if len(et) else np.nan,
        "rpe_r_med": float(np.median(er)) if len(er) else np.nan,
        "rpe_r_p95": float(np.percentile(er, 95)) if len(er) else np.nan,
        "rpe_r_max": float(er.max()) if len(er) else np.nan,
        "ate": 100 * ate(P[scored], G[scored]) if scored.sum() >= 3 else np.nan,
        "tracked": float(ok.mean()),
        "failures": int(len(ok) - ok.sum()),
        "silent": silent,
        "cpu_ms": float(np.median(cpu)) if cpu else np.nan,
    }


def sequence_rows(quick: bool) -> tuple[list[Row], list[str]]:
    from navkit import datasets
    from navkit.geometry import se3_inverse
    from navkit.io.rgbd import open_rgbd_sequence

    seq = open_rgbd_sequence(datasets.find(SEQ))
    assert seq.reference is not None
    n = 40 if quick else len(seq)
    all_frames = [seq.frame(i) for i in range(n)]
    rows, table = [], []
    for step in (1, 10) if quick else (1, 5, 10, 20):
        idx = list(range(0, n, step))
        frames = [all_frames[i] for i in idx]
        G = se3_inverse(seq.reference[idx[0]]) @ seq.reference[idx]
        res = {}
        P, ok, cpu, _ = _navkit(frames, None)
        res["navkit"] = _stats(P, G, ok, cpu[1:])
        P, ok, cpu = _open3d_hybrid(frames)
        res["Open3D hybrid"] = _stats(P, G, ok, cpu)
        P, ok, cpu = _open3d_colored_icp(frames)
        res["Open3D colored ICP"] = _stats(P, G, ok, cpu)
        for name, s in res.items():
            table.append(
                f"| {step} | {name} | {s['rpe_t_med']:.2f} / {s['rpe_t_p95']:.2f} / "
                f"{s['rpe_t_max']:.2f} | {s['rpe_r_med']:.2f} / {s['rpe_r_p95']:.2f} / "
                f"{s['rpe_r_max']:.2f} | {s['ate']:.2f} | {s['failures']} | {s['silent']} | "
                f"{s['cpu_ms']:.0f} |"
            )
            print(table[-1], flush=True)
        nk, hy, ci = res["navkit"], res["Open3D hybrid"], res["Open3D colored ICP"]
        for key, unit, label in (
            ("rpe_t_med", "cm", "RPE translation median"),
            ("rpe_t_max", "cm", "RPE translation max (tracked frames)"),
            ("rpe_r_med", "deg", "RPE rotation median"),
            ("ate", "cm", "ATE"),
            ("silent", "frames", "tracked frames off by > 5 cm or 2 deg"),
            ("failures", "frames", "failures reported"),
            ("cpu_ms", "ms", "CPU per frame"),
        ):
            ratio = hy[key] / nk[key] if key == "cpu_ms" and nk[key] > 0 else None
            rows.append(
                Row(
                    AREA,
                    f"7-Scenes step {step} ({len(idx)} frames): {label}",
                    unit,
                    nk[key],
                    hy[key],
                    "Open3D hybrid RGB-D odometry",
                    ratio,
                    note=f"Open3D colored ICP {ci[key]:.3g}",
                )
            )
    return rows, table


def load_sequence(name: str, n: int | None = None) -> tuple[list, np.ndarray]:
    """The first ``n`` frames of a shared sequence and their reference poses ``T_world_camera``
    (7-Scenes: its own poses; TUM: ``groundtruth.txt`` interpolated at the frame times, NaN
    where it does not cover them)."""
    from navkit import datasets
    from navkit.io.rgbd import open_rgbd_sequence
    from navkit.io.trajectory import read_tum
    from navkit.planes.metrics import poses_at

    root = datasets.find(name)
    seq = open_rgbd_sequence(root)
    n = len(seq) if n is None else min(n, len(seq))
    if seq.reference is not None:
        G = seq.reference[:n]
    else:
        tr = read_tum(root / "groundtruth.txt")
        G = poses_at(seq.timestamps[:n], tr.timestamps, tr.poses)
    return [seq.frame(i) for i in range(n)], G


def transfer_rows(quick: bool) -> tuple[list[Row], list[str]]:
    """The transfer table: both shared sequences, one default settings object, navkit and Open3D
    hybrid (single-threaded: ``OMP_NUM_THREADS=1`` is the caller's) in the same run."""
    from navkit.errors import DataNotFoundError
    from navkit.geometry import se3_inverse

    rows, table = [], []
    for label, name in (("7-Scenes", SEQ), ("TUM fr3 structure_notexture_far", TUM)):
        try:
            frames, G = load_sequence(name, 30 if quick else None)
        except DataNotFoundError as exc:
            rows.append(Row(AREA, f"{label}: transfer", "-", None, note=f"skipped: {exc}"))
            continue
        first = int(np.argmax(np.isfinite(G).all(axis=(1, 2))))
        Gr = se3_inverse(G[first]) @ G
        res = {}
        P, ok, cpu, _ = _navkit(frames, None)
        res["navkit"] = _stats(se3_inverse(P[first]) @ P, Gr, ok, cpu[1:])
        try:
            P, ok, cpu = _open3d_hybrid(frames)
            res["Open3D hybrid"] = _stats(se3_inverse(P[first]) @ P, Gr, ok, cpu)
        except Exception as exc:  # the peer is optional (bench extra)
            print(f"Open3D hybrid skipped: {exc}")
        nk = res["navkit"]
        hy = res.get("Open3D hybrid")
        for who, st in res.items():
            ratio = st["cpu_ms"] / hy["cpu_ms"] if hy else np.nan
            table.append(
                f"| {label} ({len(frames)}) | {who} | {100 * st['tracked']:.0f} % | "
                f"{st['silent']} | {st['rpe_t_med']:.2f} cm / {st['rpe_r_med']:.2f} deg | "
                f"{st['ate']:.2f} | {st['cpu_ms']:.0f} | {ratio:.2f}x |"
            )
            print(table[-1], flush=True)
        for key, unit, what in (
            ("tracked", "share", "tracked share"),
            ("silent", "frames", "tracked but > 5 cm / 2 deg off"),
            ("rpe_t_med", "cm", "RPE translation median"),
            ("ate", "cm", "ATE"),
            ("cpu_ms", "ms", "CPU per frame"),
        ):
            rows.append(
                Row(
                    AREA,
                    f"{label} ({len(frames)} frames, one settings object): {what}",
                    unit,
                    nk[key],
                    hy[key] if hy else None,
                    "Open3D hybrid RGB-D odometry",
                    (hy[key] / nk[key] if hy and key == "cpu_ms" and nk[key] > 0 else None),
                )
            )
    return rows, table


def slambook_rows(quick: bool) -> tuple[list[Row], list[str]]:
    from navkit import datasets
    from navkit.geometry import se3_from_xyz_quat, se3_inverse
    from navkit.io.rgbd import read_simple_rgbd

    root = datasets.find(SLAMBOOK)
    seq = read_simple_rgbd(root, SLAMBOOK_CAMERA)
    Tw = np.array([se3_from_xyz_quat(p[:3], p[3:]) for p in np.loadtxt(root / "pose.txt")])
    rows, table = [], []
    for a, b in ((0, 1), (1, 2)):
        frames = [seq.frame(a), seq.frame(b)]
        G = se3_inverse(Tw[a]) @ Tw[[a, b]]
        out = {}
        P, ok, cpu, src = _navkit(frames, None)
        out["navkit"] = (P, ok, cpu[1:], src[1])
        P, ok, cpu = _open3d_hybrid(frames)
        out["Open3D hybrid"] = (P, ok, cpu, "")
        P, ok, cpu = _open3d_colored_icp(frames)
        out["Open3D colored ICP"] = (P, ok, cpu, "")
        for name, (P, ok, cpu, src) in out.items():
            et, er = _rel_errors(P, G, np.array([True, True]))
            status = "tracked" if ok[1] else "failure reported"
            table.append(
                f"| slambook {a + 1} -> {b + 1} | {name} | {100 * et[0]:.1f} cm / {er[0]:.2f} deg "
                f"| {status} {src} | {cpu[0]:.0f} |"
            )
            print(table[-1], flush=True)
            if name == "navkit":
                rows.append(
                    Row(
                        AREA,
                        f"slambook {a + 1} -> {b + 1}: translation error ({status})",
                        "cm",
                        100 * et[0] if ok[1] else None,
                        note=f"rotation {er[0]:.2f} deg; {src}",
                    )
                )
    return rows, table


def colour_depth_offset(frames: list, search: int = 30) -> list[tuple[int, int, float]]:
    """Per frame, the shift ``(dx, dy)`` (pixels) of the colour image against the depth image
    that best aligns colour edges with depth edges (normalised cross-correlation of blurred
    edge maps, ``cv2.matchTemplate``), and the median depth of the depth edges (m).

    Colour pixel ``p + (dx, dy)`` shows what depth pixel ``p`` measures. Registered RGB-D
    gives (0, 0); 7-Scenes does not (docs/planes.md, "7-Scenes")."""
    import cv2

    from navkit.planes.texture import to_gray

    out = []
    for f in frames:
        d = np.nan_to_num(f.depth, nan=0.0).astype(np.float32)
        g = to_gray(f.color)
        ed = np.hypot(cv2.Sobel(d, cv2.CV_32F, 1, 0), cv2.Sobel(d, cv2.CV_32F, 0, 1))
        ed = ((ed > 0.5) & (d > 0)).astype(np.float32)  # depth steps > ~6 cm per pixel
        eg = np.hypot(cv2.Sobel(g, cv2.CV_32F, 1, 0), cv2.Sobel(g, cv2.CV_32F, 0, 1))
        ed, eg = cv2.GaussianBlur(ed, (0, 0), 1.5), cv2.GaussianBlur(eg, (0, 0), 1.5)
        tpl = ed[search:-search, search:-search]
        score = cv2.matchTemplate(eg, tpl, cv2.TM_CCORR_NORMED)
        _, _, _, (x, y) = cv2.minMaxLoc(score)
        z = float(np.nanmedian(f.depth[ed > 0.2]))
        out.append((x - search, y - search, z))
    return out


def run(quick: bool = False) -> list[Row]:
    from navkit.errors import DataNotFoundError

    rows: list[Row] = []
    r, table = transfer_rows(quick)
    rows += r
    print(
        "| sequence (frames) | method | tracked | tracked but > 5 cm / 2 deg off | RPE median "
        "| ATE cm | CPU ms/frame | CPU vs Open3D |"
    )
    print("|---|---|---|---|---|---|---|---|")
    print("\n".join(table))
    try:
        r, table = sequence_rows(quick)
        rows += r
        print(
            "| step | method | RPE t cm med / p95 / max | RPE r deg med / p95 / max | ATE cm "
            "| failures | silent > 5 cm / 2 deg | CPU ms/frame |"
        )
        print("|---|---|---|---|---|---|---|---|")
        print("\n".join(table))
    except DataNotFoundError as exc:
        rows.append(Row(AREA, "7-Scenes sequence", "-", None, note=f"skipped: {exc}"))
    try:
        from navkit import datasets
        from navkit.io.rgbd import open_rgbd_sequence

        seq = open_rgbd_sequence(datasets.find(SEQ))
        offs = np.array(colour_depth_offset([seq.frame(i) for i in range(0, len(seq), 10)]))
        for (dx, dy, z), i in zip(offs, range(0, len(seq), 10), strict=True):
            print(
                f"7-Scenes frame {i}: colour offset against depth ({dx:+.0f}, {dy:+.0f}) px "
                f"at {z:.2f} m"
            )
        rows.append(
            Row(
                AREA,
                "7-Scenes colour vs depth offset (median |shift|, frames 0, 10, ..., 90)",
                "px",
                float(np.median(np.hypot(offs[:, 0], offs[:, 1]))),
                note=f"dx {np.median(offs[:, 0]):+.0f}, dy {np.median(offs[:, 1]):+.0f} px; "
                "registered RGB-D would be 0",
            )
        )
    except DataNotFoundError as exc:
        rows.append(Row(AREA, "7-Scenes colour offset", "-", None, note=f"skipped: {exc}"))
    try:
        r, table = slambook_rows(quick)
        rows += r
        print("| pair | method | error | reported | CPU ms |")
        print("|---|---|---|---|---|")
        print("\n".join(table))
    except DataNotFoundError as exc:
        rows.append(Row(AREA, "slambook pairs", "-", None, note=f"skipped: {exc}"))
    return rows
