"""Planes on real recorded data: the PCL room scans and the pcl-kinect captures (paper 2).

- **PCL room scans** (two unorganised 360 deg laser scans of one room): navkit's plane
  registration without any initial guess (cloud extraction -> global plane-triple association
  verified by the points -> closed form) against Open3D point-to-plane ICP started from the PCL
  NDT tutorial's guess (the reference), Open3D ICP without a guess, and Open3D's guess-free
  FPFH + RANSAC global registration refined by the same ICP. Errors against the reference,
  point-to-plane residuals of every motion on the same correspondences, CPU ms.
- **pcl-kinect** (3 organised Kinect captures, fields ``x y z`` only, no ground truth): the
  plane solver's answer (2 plane directions, no colour -> a failure naming ``mu``), and the
  round-trip consistency of what geometry fixes (rotation and the translation across the
  planes' intersection line), beside Open3D point-to-plane ICP round trips.
- **slambook-ch5 2 -> 3** (>= 3 planes) against ``pose.txt``.

Every navkit figure is also computed with the paper's literal eq. 2 (``N1 . dT = rho1 - rho2``,
``SolverSettings(translation="rho")``) beside the default (eq. 2 at the planes' centroids,
:func:`navkit.planes.solve.plane_translation`): before -> after in one run.

CPU times are ``time.process_time`` medians, navkit and the peers in the same run.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from itertools import pairwise
from typing import Any

import numpy as np

from benchmarks.common import Row


def _rho_settings():
    from navkit.planes.motion import MotionSettings
    from navkit.planes.solve import SolverSettings

    return MotionSettings(solver=SolverSettings(translation="rho"))


AREA = "planes_real"
ROOM = "scans3d/pcl-room/room_scan{}.pcd"
KINECT = "rgbd/pcl-kinect/capture000{}.pcd"
# PCL "How to use Normal Distributions Transform" tutorial: initial guess of scan 2 -> scan 1
PCL_GUESS_ANGLE = 0.6931  # rad about z
PCL_GUESS_T = (1.79387, 0.720047, 0.0)


def cpu_median(fn: Callable[[], Any], repeats: int = 3) -> tuple[float, Any]:
    """Median CPU time (s) of ``fn()`` over ``repeats`` runs, and the last result."""
    times, out = [], None
    for _ in range(repeats):
        t0 = time.process_time()
        out = fn()
        times.append(time.process_time() - t0)
    return float(np.median(times)), out


def motion_error(T_est: np.ndarray, T_ref: np.ndarray) -> tuple[float, float]:
    """(rotation deg, translation cm) of ``T_ref^-1 T_est``."""
    from navkit.geometry import se3_inverse
    from navkit.geometry.rotations import rotation_angle

    E = se3_inverse(T_ref) @ T_est
    return float(np.degrees(rotation_angle(E[:3, :3]))), float(100 * np.linalg.norm(E[:3, 3]))


def point_to_plane(
    P1: np.ndarray, P2: np.ndarray, T: np.ndarray, voxel: float = 0.05, max_d: float = 0.1
) -> tuple[float, float]:
    """Point-to-plane RMS (cm) and fitness of motion ``T`` (scan 2 -> scan 1).

    Both clouds on a ``voxel`` grid (centroids); frame-1 normals from 16 neighbours; each moved
    frame-2 centroid is paired with its nearest frame-1 centroid within ``max_d``: the residual is
    the distance along that centroid's normal. Fitness = paired fraction.
    """
    from scipy.spatial import cKDTree

    from navkit.planes.extract_cloud import _normals, voxelize

    A, _ = voxelize(P1[np.all(np.isfinite(P1), axis=1)], voxel)
    B, _ = voxelize(P2[np.all(np.isfinite(P2), axis=1)], voxel)
    nA, _ = _normals(A, 16)
    X = B @ T[:3, :3].T + T[:3, 3]
    d, j = cKDTree(A).query(X, distance_upper_bound=max_d)
    ok = np.isfinite(d)
    r = np.einsum("ij,ij->i", X[ok] - A[j[ok]], nA[j[ok]])
    return float(100 * np.sqrt(np.mean(r**2))), float(ok.mean())


def _scatter_covariance(obs: Any, k: int) -> tuple[np.ndarray, float]:
    """Normal covariance ``(3, 3)`` and centroid-offset variance of plane ``k``'s TLS fit from
    its inliers' scatter matrix: ``C_N = sigma^2 sum_(in-plane k) e_k e_k^T / (n lambda_k)``,
    ``var = sigma^2 / n``, ``sigma`` = the fit's rms (first-order perturbation of the smallest
    eigenvector)."""
    seg = obs.segments[k]
    P = np.asarray(obs.points, dtype=np.float64).reshape(-1, 3)[seg.inliers]
    P = P[np.all(np.isfinite(P), axis=1)]
    X = P - P.mean(axis=0)
    lam, E = np.linalg.eigh(X.T @ X / len(P))
    s2 = seg.plane.rms**2
    C = s2 * (np.outer(E[:, 1], E[:, 1]) / lam[1] + np.outer(E[:, 2], E[:, 2]) / lam[2])
    return C / len(P), s2 / len(P)


def information_rows(name: str, o1: Any, o2: Any, pairs: Any, T_ref: np.ndarray) -> list[Row]:
    """The closed form on the same plane pairs with the planes' information as weights (tried,
    not the default): rotation by weighted Kabsch with ``1 / (tr C_N1 + tr C_N2)``, translation
    at the centroids with generalised least-squares weights ``1 / sqrt(D^T (C_N1 + R C_N2 R^T) D
    + var1 + var2)`` (``D = R c2 + t - c1``, iterated 3 times), beside the default weights
    ``sqrt(min inliers)``."""
    from navkit.geometry import se3_from_rt
    from navkit.planes.solve import _kabsch, plane_translation

    p1 = [o1.segments[i].plane for i, _ in pairs]
    p2 = [o2.segments[j].plane for _, j in pairs]
    N1 = np.array([p.normal for p in p1])
    N2 = np.array([p.normal for p in p2])
    w = np.sqrt(np.minimum([p.count for p in p1], [p.count for p in p2]).astype(float))
    C1 = [_scatter_covariance(o1, i) for i, _ in pairs]
    C2 = [_scatter_covariance(o2, j) for _, j in pairs]
    info = 1.0 / np.array([np.trace(a[0]) + np.trace(b[0]) for a, b in zip(C1, C2, strict=True)])
    out = []
    for rname, wr in (("sqrt(inliers)", w), ("information", info)):
        R = _kabsch(N1, N2, wr)
        t = plane_translation(R, p1, p2, w, "centroid")
        for _ in range(3):
            D = np.array([R @ b.centroid + t - a.centroid for a, b in zip(p1, p2, strict=True)])
            var = np.array(
                [
                    d @ (a[0] + R @ b[0] @ R.T) @ d + a[1] + b[1]
                    for d, a, b in zip(D, C1, C2, strict=True)
                ]
            )
            t = plane_translation(R, p1, p2, 1.0 / np.sqrt(var), "centroid")
        for tname, tt in (
            ("rho1 - rho2, sqrt(inliers)", plane_translation(R, p1, p2, w, "rho")),
            ("centroids, sqrt(inliers)", plane_translation(R, p1, p2, w, "centroid")),
            ("centroids, GLS", t),
        ):
            rot, tr = motion_error(se3_from_rt(R, tt), T_ref)
            out.append(
                Row(
                    AREA,
                    f"{name}: rotation weights {rname}, translation {tname}",
                    "cm",
                    tr,
                    note=f"rotation {rot:.2f} deg; {len(pairs)} pairs; information weights "
                    f"(max 1) {np.round(info / info.max(), 3).tolist()}",
                )
            )
    return out


def _o3d_cloud(P: np.ndarray, voxel: float):
    import open3d as o3d

    c = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P[np.all(np.isfinite(P), axis=1)]))
    c = c.voxel_down_sample(voxel)
    c.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=6 * voxel, max_nn=30))
    return c


def icp_p2plane(src, dst, T0: np.ndarray, distance: float) -> np.ndarray:
    """Open3D point-to-plane ICP ``src -> dst`` from ``T0`` (200 iterations)."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    return np.asarray(
        reg.registration_icp(
            src,
            dst,
            distance,
            T0,
            reg.TransformationEstimationPointToPlane(),
            reg.ICPConvergenceCriteria(max_iteration=200),
        ).transformation
    )


def pcl_guess() -> np.ndarray:
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0, 0, PCL_GUESS_ANGLE]).as_matrix()
    T[:3, 3] = PCL_GUESS_T
    return T


def room_reference(P1: np.ndarray, P2: np.ndarray) -> dict[str, np.ndarray]:
    """Open3D point-to-plane ICP from the PCL tutorial's guess (5 cm voxels) at 30, 20, 10 cm
    correspondence distance; the 10 cm run is the reference, the others show its spread."""
    s1, s2 = _o3d_cloud(P1, 0.05), _o3d_cloud(P2, 0.05)
    return {f"{d:.2f}": icp_p2plane(s2, s1, pcl_guess(), d) for d in (0.3, 0.2, 0.1)}


def fpfh_ransac(P1: np.ndarray, P2: np.ndarray, voxel: float = 0.1) -> np.ndarray:
    """Open3D's guess-free global registration: FPFH features + RANSAC, then point-to-plane ICP
    at 10 cm (the pipeline of Open3D's global registration tutorial)."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    s1, s2 = _o3d_cloud(P1, voxel), _o3d_cloud(P2, voxel)
    param = o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100)
    f1 = reg.compute_fpfh_feature(s1, param)
    f2 = reg.compute_fpfh_feature(s2, param)
    res = reg.registration_ransac_based_on_feature_matching(
        s2,
        s1,
        f2,
        f1,
        True,
        1.5 * voxel,
        reg.TransformationEstimationPointToPoint(False),
        3,
        [
            reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
            reg.CorrespondenceCheckerBasedOnDistance(1.5 * voxel),
        ],
        reg.RANSACConvergenceCriteria(100000, 0.999),
    )
    return icp_p2plane(_o3d_cloud(P2, 0.05), _o3d_cloud(P1, 0.05), res.transformation, 0.1)


def room_rows(quick: bool) -> list[Row]:
    from navkit import datasets
    from navkit.io.pointcloud import read_pcd
    from navkit.planes import MotionEstimate, estimate_motion, extract_planes_cloud
    from navkit.planes.frame import PlaneObservation
    from navkit.planes.solve import normal_rank

    RHO = _rho_settings()
    P1, P2 = (read_pcd(datasets.find(ROOM.format(k))).points for k in (1, 2))
    reps = 1 if quick else 3
    rows: list[Row] = []
    obs = []
    for k, P in ((1, P1), (2, P2)):
        cpu, ext = cpu_median(lambda P=P: extract_planes_cloud(P), reps)
        rank = normal_rank(np.array([s.normal for s in ext.segments]), 15.0)[0]
        rows.append(
            Row(
                AREA,
                f"room scan {k}: cloud plane extraction ({len(P)} points)",
                "ms CPU",
                1000 * cpu,
                note=f"{len(ext)} planes, {rank} directions, rms <= "
                f"{max(s.rms for s in ext.segments[:6]) * 100:.1f} cm (6 largest)",
            )
        )
        obs.append(PlaneObservation(ext, P))
    cpu_nk, est = cpu_median(lambda: estimate_motion(obs[0], obs[1]), reps)
    est_rho = estimate_motion(obs[0], obs[1], settings=RHO)
    t0 = time.process_time()
    ref = room_reference(P1, P2)
    cpu_icp = (time.process_time() - t0) / 3
    T_ref = ref["0.10"]
    spread = [motion_error(ref[k], T_ref) for k in ("0.30", "0.20")]
    r_ref, f_ref = point_to_plane(P1, P2, T_ref)
    ok = isinstance(est, MotionEstimate)
    if isinstance(est_rho, MotionEstimate):
        rows.append(
            Row(
                AREA,
                "room scans 2 -> 1, no guess: eq. 2 as rho1 - rho2 (before) vs ICP reference",
                "deg / cm",
                None,
                note="rotation {:.2f} deg, translation {:.1f} cm, {} pairs".format(
                    *motion_error(est_rho.T, T_ref), len(est_rho.pairs)
                ),
            )
        )
    if ok:
        e_rot, e_t = motion_error(est.T, T_ref)
        r_nk, f_nk = point_to_plane(P1, P2, est.T)
        zdeg = float(np.degrees(np.arctan2(est.T[1, 0], est.T[0, 0])))
    rows.append(
        Row(
            AREA,
            "room scans 2 -> 1, no guess: rotation error vs ICP reference",
            "deg",
            e_rot if ok else None,
            max(s[0] for s in spread),
            "ICP reference: its own spread (30/20 vs 10 cm)",
            note=(
                f"navkit case {est.case}, {len(est.pairs)} plane pairs, turn about z "
                f"{zdeg:.2f} deg; reference {np.degrees(np.arctan2(T_ref[1, 0], T_ref[0, 0])):.2f}"
                if ok
                else f"navkit failure: {est}"
            ),
        )
    )
    rows.append(
        Row(
            AREA,
            "room scans 2 -> 1, no guess: translation error vs ICP reference",
            "cm",
            e_t if ok else None,
            max(s[1] for s in spread),
            "ICP reference: its own spread",
            note=f"navkit t = {np.round(est.T[:3, 3], 3).tolist() if ok else '-'}, "
            f"reference t = {np.round(T_ref[:3, 3], 3).tolist()}",
        )
    )
    rows.append(
        Row(
            AREA,
            "room scans: point-to-plane RMS within 10 cm (5 cm voxels)",
            "cm",
            r_nk if ok else None,
            r_ref,
            "Open3D p2plane ICP from the PCL guess",
            note=f"fitness navkit {f_nk:.3f}, ICP {f_ref:.3f}" if ok else "",
        )
    )
    rows.append(
        Row(
            AREA,
            "room scans: registration CPU time",
            "ms CPU",
            1000 * cpu_nk,
            1000 * cpu_icp,
            "Open3D p2plane ICP (with the guess)",
            cpu_icp / cpu_nk,
            "navkit: association + solve, extraction excluded (rows above)",
        )
    )
    if ok:
        rows += information_rows("room scans 2 -> 1", obs[0], obs[1], est.pairs, T_ref)
    # peers without a guess
    s1, s2 = _o3d_cloud(P1, 0.05), _o3d_cloud(P2, 0.05)
    T_id = icp_p2plane(s2, s1, np.eye(4), 0.1)
    rows.append(
        Row(
            AREA,
            "room scans: Open3D p2plane ICP from the identity (no guess)",
            "deg / cm",
            None,
            motion_error(T_id, T_ref)[0],
            "ICP rotation error (deg)",
            note=f"translation error {motion_error(T_id, T_ref)[1]:.1f} cm",
        )
    )
    if not quick:
        cpu_g, T_g = cpu_median(lambda: fpfh_ransac(P1, P2), 1)
        eg = motion_error(T_g, T_ref)
        rows.append(
            Row(
                AREA,
                "room scans: Open3D FPFH + RANSAC + ICP (no guess)",
                "deg",
                e_rot if ok else None,
                eg[0],
                "FPFH+RANSAC+ICP rotation error",
                note=f"translation error {eg[1]:.1f} cm; CPU {1000 * cpu_g:.0f} ms "
                f"(navkit {1000 * cpu_nk:.0f} ms + extraction)",
            )
        )
    return rows


def kinect_rows(quick: bool) -> list[Row]:
    from navkit import datasets
    from navkit.geometry.rotations import rotation_angle
    from navkit.io.pointcloud import read_pcd
    from navkit.planes import estimate_motion, observe_points
    from navkit.planes.motion import matched_pairs
    from navkit.planes.solve import PartialMotion, SolverSettings, two_plane_geometry

    clouds = [read_pcd(datasets.find(KINECT.format(k))) for k in (1, 2, 3)]
    rows: list[Row] = []
    colours = [c.colors is not None for c in clouds]
    obs = [observe_points(c.grid()) for c in clouds]
    est01 = estimate_motion(obs[0], obs[1])
    rows.append(
        Row(
            AREA,
            "pcl-kinect: colour in the PCD / plane solver A -> B",
            "-",
            None,
            note=f"colour fields: {colours}; fields {sorted(clouds[0].fields)}; "
            f"solver: {type(est01).__name__} case {est01.case} "
            f"free {getattr(est01, 'free_dof', ())}",
        )
    )

    def partial(a: int, b: int, method: str = "centroid") -> PartialMotion:
        sa, sb = obs[a].segments, obs[b].segments
        pr = matched_pairs(obs[a], obs[b])
        g = two_plane_geometry(
            [sa[i].plane for i, _ in pr],
            [sb[j].plane for _, j in pr],
            SolverSettings(translation=method),
        )
        assert isinstance(g, PartialMotion), g
        return g

    keys = [(a, b) for a in range(3) for b in range(3) if a != b]
    P = {k: partial(*k) for k in keys}
    P_rho = {k: partial(*k, method="rho") for k in keys}
    s = [_o3d_cloud(c.points, 0.02) for c in clouds]
    icp = {k: icp_p2plane(s[k[1]], s[k[0]], np.eye(4), 0.05) for k in P}

    def cycle(
        c: tuple[int, ...], P: dict[tuple[int, int], PartialMotion] = P
    ) -> tuple[float, float, float, float]:
        R, t, T = np.eye(3), np.zeros(3), np.eye(4)
        for a, b in pairwise(c):
            g = P[a, b]
            t = R @ g.t0 + t
            R = R @ g.R
            T = T @ icp[a, b]
        d = P[c[0], c[1]].d
        across = float(100 * np.linalg.norm(t - (t @ d) * d))
        rot = float(np.degrees(rotation_angle(R)))
        return rot, across, *motion_error(T, np.eye(4))

    for c in ((0, 1, 0), (1, 2, 1), (0, 2, 0), (0, 1, 2, 0)):
        rot, across, irot, it = cycle(c)
        across_rho = cycle(c, P_rho)[1]
        name = " -> ".join("ABC"[k] for k in c)
        rows.append(
            Row(
                AREA,
                f"pcl-kinect {name}: translation across the line (geometry's DoF)",
                "cm",
                across,
                it,
                "Open3D p2plane ICP round trip (full translation, cm)",
                note=f"eq. 2 as rho1 - rho2 (before): {across_rho:.2f} cm; "
                f"rotation: navkit {rot:.4f} deg (same two planes: identity by "
                f"construction), ICP {irot:.3f} deg; A->B turn "
                f"{np.degrees(rotation_angle(P[c[0], c[1]].R)):.2f} deg",
            )
        )
    return rows


def slambook_rows(quick: bool) -> list[Row]:
    from navkit import datasets
    from navkit.geometry import se3_from_xyz_quat, se3_inverse
    from navkit.io.rgbd import read_simple_rgbd
    from navkit.planes import MotionEstimate, estimate_motion, observe_rgbd

    root = datasets.find("rgbd/slambook-ch5")
    seq = read_simple_rgbd(
        root, {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0}
    )
    Tw = [se3_from_xyz_quat(p[:3], p[3:]) for p in np.loadtxt(root / "pose.txt")]
    o1, o2 = observe_rgbd(seq.frame(1)), observe_rgbd(seq.frame(2))
    cpu, est = cpu_median(lambda: estimate_motion(o1, o2), 1 if quick else 3)
    est_rho = estimate_motion(o1, o2, settings=_rho_settings())
    truth = se3_inverse(Tw[1]) @ Tw[2]
    if isinstance(est_rho, MotionEstimate):
        rot_b, tr_b = motion_error(est_rho.T, truth)
        before = f"before (eq. 2 as rho1 - rho2): {tr_b:.1f} cm / {rot_b:.2f} deg; "
    else:
        before = f"before: {est_rho}; "
    if not isinstance(est, MotionEstimate):
        return [Row(AREA, "slambook 2 -> 3", "-", None, note=f"failure: {est}")]
    rot, tr = motion_error(est.T, truth)
    return [
        *information_rows("slambook 2 -> 3", o1, o2, est.pairs, truth),
        Row(
            AREA,
            "slambook 2 -> 3, no prior: translation / rotation error vs pose.txt",
            "cm",
            tr,
            note=f"rotation {rot:.2f} deg; {before}case {est.case}, pairs {list(est.pairs)}; "
            f"{1000 * cpu:.0f} ms CPU",
        ),
    ]


def run(quick: bool = False) -> list[Row]:
    return room_rows(quick) + kinect_rows(quick) + slambook_rows(quick)
