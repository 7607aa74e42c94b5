"""``navkit run``'s plane capability (paper 2): each RGB-D frame through
:class:`navkit.planes.PlaneOdometry`, the camera's and the robot's poses on TF, and the frame's
planes as outlines and textured quads (:mod:`navkit.runtime.capabilities` routes the frames)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from navkit.runtime.messages import (
    CameraData,
    Message,
    Output,
    Polyline,
    TexturedPlane,
)
from navkit.runtime.pipeline import Pipeline
from navkit.runtime.stage_base import PoseBuffer, StageResult

__all__ = ["PlanesStage", "textured_planes"]


def textured_planes(
    obs: Any,
    color: NDArray[np.uint8],
    T_world_frame: NDArray[np.float64],
    step: int = 8,
    max_texture_px: int = 128,
) -> list[TexturedPlane]:
    """Each plane of an RGB-D frame as a mesh textured with the colour pixels of its region.

    Vertices: the region's pixels every ``step`` pixels (both ways), each where the pixel's ray
    (through its depth point) meets the plane's fit (flat, no depth noise), in the world frame; triangles: two
    per grid square whose four corners are in the region; texture: the colour image's crop
    around the region, decimated so its longer side is at most ``max_texture_px``.

    Parameters
    ----------
    obs : PlaneObservation
        The frame's planes (organised ``points (H, W, 3)`` in the camera frame).
    color : (H, W, 3) uint8
    T_world_frame : (4, 4)
    """
    P = np.asarray(obs.points)
    if P.ndim != 3 or color.shape[:2] != P.shape[:2]:
        return []
    H, W = P.shape[:2]
    R, t = T_world_frame[:3, :3], T_world_frame[:3, 3]
    out = []
    for k, seg in enumerate(obs.segments):
        rows, cols = np.divmod(np.asarray(seg.inliers, dtype=np.int64), W)
        if rows.size < 16:
            continue
        r0, c0 = int(rows.min()), int(cols.min())
        r0, c0 = r0 - r0 % step, c0 - c0 % step  # the vertex grid: multiples of step
        mask = np.zeros((H, W), bool)
        mask[rows, cols] = True
        rr, cc = np.mgrid[r0 : rows.max() + 1 : step, c0 : cols.max() + 1 : step]
        X = P[rr, cc]
        ok = mask[rr, cc] & np.all(np.isfinite(X), axis=-1)
        n, rho = np.asarray(seg.plane.normal, dtype=np.float64), float(seg.plane.rho)
        with np.errstate(divide="ignore", invalid="ignore"):
            X = X * (rho / (X @ n))[..., None]  # along the pixel's ray onto the plane
        ok &= np.all(np.isfinite(X), axis=-1)
        idx = -np.ones(ok.shape, np.int64)
        idx[ok] = np.arange(int(ok.sum()))
        a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
        quad = (a >= 0) & (b >= 0) & (c >= 0) & (d >= 0)
        if not quad.any():
            continue
        tris = np.concatenate(
            [np.stack([a[quad], c[quad], b[quad]], 1), np.stack([b[quad], c[quad], d[quad]], 1)]
        )
        r1, c1 = int(rr.max()) + 1, int(cc.max()) + 1
        dec = max(1, int(np.ceil(max(r1 - r0, c1 - c0) / max_texture_px)))
        tex = np.ascontiguousarray(color[r0:r1:dec, c0:c1:dec])
        h, w = tex.shape[0] * dec, tex.shape[1] * dec  # the pixels the texels cover
        uv = np.c_[(cc[ok] - c0 + 0.5) / w, (rr[ok] - r0 + 0.5) / h]
        out.append(TexturedPlane(k, X[ok] @ R.T + t, tris, uv, tex))
    return out


class PlanesStage:
    """Paper 2's plane odometry on depth (+ colour) frames with ``CameraInfo``
    (``planes.PlaneOdometry.update``); publishes the camera pose and the frame's planes."""

    name = "planes"

    def __init__(self, pipe: Pipeline, out: Path) -> None:
        from navkit.planes import ExtractionSettings, OdometrySettings, PlaneOdometry
        from navkit.planes.motion import MotionSettings
        from navkit.planes.solve import SolverSettings

        c = self.cfg = pipe.planes
        self.topics = pipe.topics
        self.es = ExtractionSettings(cell=c.cell)
        self.odo = PlaneOdometry(
            OdometrySettings(
                motion=MotionSettings(solver=SolverSettings(nu=c.nu)),
                max_keyframes=c.max_keyframes,
                max_history=c.max_history,
                max_map_planes=c.max_map_planes,
            )
        )
        self.camera: CameraData | None = None
        self.depth: Message | None = None
        self.color: Message | None = None
        self.n = self.n_ok = 0
        self.out = out / "planes"
        # the trajectory is streamed to trajectory.tum (bounded memory); its size at the last
        # line this stage wrote (a resumed run truncates what a killed run wrote after it)
        self.traj_bytes = 0
        self.last_stamp_ns: int | None = None
        self.anchored = False  # the static root -> planes_odom was published

    def _append_pose(self, stamp_ns: int, T: NDArray[np.float64]) -> None:
        """One TUM line (``t tx ty tz qx qy qz qw``, as :func:`navkit.io.trajectory.write_tum`);
        a stamp not after the last one is skipped (the TUM reader refuses repeats)."""
        from navkit.geometry import se3_to_xyz_quat

        if self.last_stamp_ns is not None and stamp_ns <= self.last_stamp_ns:
            return
        self.last_stamp_ns = stamp_ns
        xyz, q = se3_to_xyz_quat(T[None])
        vals = " ".join(f"{v:.12g}" for v in (*xyz[0], *q[0]))
        line = f"{stamp_ns * 1e-9:.9f} {vals}\n"
        if self.traj_bytes == 0:
            line = "# timestamp tx ty tz qx qy qz qw\n" + line
        self.out.mkdir(parents=True, exist_ok=True)
        path = self.out / "trajectory.tum"
        with open(path, "r+b" if path.exists() else "wb") as fh:
            fh.truncate(self.traj_bytes)
            fh.seek(self.traj_bytes)
            fh.write(line.encode())
            self.traj_bytes = fh.tell()

    def handle(self, msg: Message, poses: PoseBuffer) -> StageResult:
        if msg.kind == "camera_info":
            self.camera = msg.data
            return StageResult()
        if msg.kind == "depth":
            self.depth = msg
        else:
            self.color = msg
        d, c = self.depth, self.color
        if d is None or self.camera is None:
            return StageResult()
        tol = int(self.cfg.max_time_offset_s * 1e9)
        paired = c is not None and abs(c.stamp_ns - d.stamp_ns) <= tol
        if not paired and self.topics.color and msg.kind == "depth":
            return StageResult()  # wait for the colour of this depth frame
        return self._frame(d, c if paired else None, poses)

    def _robot(
        self,
        d: Message,
        poses: PoseBuffer,
        T: NDArray[np.float64],
        cov_left: NDArray[np.float64] | None,
    ) -> list[Output]:
        """The frame's transforms and the robot's pose: ``planes_odom -> camera`` on ``/tf``
        when the recording's TF tree has no parent for the camera; else, once, a static
        ``root -> planes_odom`` that puts the odometry's origin where the tree had the camera
        at the first frame (the camera keeps its parent: one parent per frame). The robot
        (``base_link`` / ``base_footprint`` when the tree connects it to the camera, else the
        camera) in ``planes_odom`` as ``PoseWithCovarianceStamped``, with the covariance of
        PlaneOdometry's result (:attr:`~navkit.planes.FrameMotion.covariance` at the robot's
        position); a frame without one (a failure, the planes alone) is marked not estimated
        (element 0 = -1, as ``sensor_msgs/Imu`` marks a missing covariance)."""
        stamp, cam = d.stamp_ns, d.frame_id.lstrip("/")
        outs: list[Output] = []
        base = cam
        tree = poses.published if poses.published is not None else poses.tf
        if cam:
            if cam not in tree.parent:
                outs.append(Output("/tf", "tf", stamp, "planes_odom", [(cam, T)]))
            elif not self.anchored:
                root = tree._chain(cam)[-1]
                T_root_cam = tree.lookup(root, cam, stamp)
                if T_root_cam is not None:
                    self.anchored = True
                    T_root_po = T_root_cam @ np.linalg.inv(T)
                    outs.append(
                        Output("/tf_static", "tf", stamp, root, [("planes_odom", T_root_po)])
                    )
            base = next(
                (b for b in ("base_link", "base_footprint") if poses.tf.can_transform(cam, b)),
                cam,
            )
        T_cam_base = poses.tf.lookup(cam, base, stamp) if base != cam else None
        T_base = T if T_cam_base is None else T @ T_cam_base
        from navkit.planes.odometry import ros_pose_covariance

        if cov_left is None:  # no dense step measured this frame: not estimated
            cov = np.zeros((6, 6))
            cov[0, 0] = -1.0
        else:
            cov = ros_pose_covariance(cov_left, T_base[:3, 3])
        outs.append(Output("/navkit/planes/pose", "pose_cov", stamp, "planes_odom", (T_base, cov)))
        outs.append(Output("/navkit/planes/sensor_pose", "pose", stamp, "planes_odom", T))
        return outs

    def _frame(self, d: Message, c: Message | None, poses: PoseBuffer) -> StageResult:
        from navkit.planes import FrameMotion, observe_rgbd
        from navkit.sensors import PinholeCamera, RGBDFrame

        cam = self.camera
        assert cam is not None
        depth = d.data
        color = (
            c.data
            if c is not None and c.data.shape[:2] == depth.shape
            else np.zeros((*depth.shape, 3), np.uint8)
        )
        pc = PinholeCamera(cam.fx, cam.fy, cam.cx, cam.cy, depth.shape[1], depth.shape[0])
        self.depth = self.color = None
        obs = observe_rgbd(RGBDFrame(color, depth, pc, d.stamp), self.es)
        r = self.odo.update(obs)  # a FrameMotion, or a MotionFailure at the prediction
        T = self.odo.poses[-1]  # the trajectory's pose of the frame (the prediction if failed)
        self.n += 1
        self.n_ok += isinstance(r, FrameMotion)
        self._append_pose(d.stamp_ns, T)
        outs = self._robot(d, poses, T, r.covariance if isinstance(r, FrameMotion) else None)
        lines = []
        R, t = T[:3, :3], T[:3, 3]
        for k, seg in enumerate(obs.extraction.segments):
            P = np.asarray(seg.outline_3d(), dtype=np.float64)  # camera frame
            if P.ndim == 2 and len(P) >= 3:
                lines.append(Polyline("planes", k, P @ R.T + t, (0.2, 0.7, 0.3, 1.0)))
        if lines:
            outs.append(
                Output("/navkit/planes/outlines", "markers", d.stamp_ns, "planes_odom", lines)
            )
        if c is not None and self.cfg.textures:
            planes = textured_planes(obs, color, T)
            if planes:
                outs.append(
                    Output(
                        "/navkit/planes/textured",
                        "textured_planes",
                        d.stamp_ns,
                        "planes_odom",
                        planes,
                    )
                )
        return StageResult(
            outs,
            {
                "status": "tracked" if isinstance(r, FrameMotion) else "failed",
                "reason": r.note if isinstance(r, FrameMotion) else r.reason,
                "case": r.case,
                "planes": r.n_planes,
                "motion_ms": r.ms,
                "source": r.source if isinstance(r, FrameMotion) else "",
            },
        )

    def finish(self, out: Path, stamp_ns: int) -> StageResult:
        if not self.n:
            return StageResult(record={"frames": 0})
        from navkit.io.atomic import write_json

        self.out.mkdir(parents=True, exist_ok=True)
        traj = self.out / "trajectory.tum"
        if traj.exists() and traj.stat().st_size > self.traj_bytes:
            with open(traj, "r+b") as fh:  # lines a killed run wrote after its checkpoint
                fh.truncate(self.traj_bytes)
        write_json(self.out / "map.json", self.odo.map.to_dict())
        return StageResult(
            record={"frames": self.n, "tracked": self.n_ok, "map_planes": len(self.odo.map.planes)}
        )


# --------------------------------------------------------------------------- path memory
