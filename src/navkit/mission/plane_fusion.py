"""Paper 2 in the mission: plane-based motion between camera frames, fused with the VO.

:class:`PlaneMotionFusion` takes one RGB-D frame at a time: paper 2's planes
(:func:`navkit.planes.observe_rgbd`) and the motion since the previous frame measured by one
:class:`navkit.planes.PlaneOdometry` (frame-to-map tracking, the dense refinement and
verification; the same object as ``navkit planes odometry`` and ``navkit run``), with the VO
increment over the same interval as a :class:`~navkit.planes.MotionPrior`. The plane increment
and the VO increment are blended (a complementary filter, weights by case) and the estimate is
corrected by the difference; an increment further than the gate from the VO is ignored, a
failed frame (:class:`~navkit.planes.MotionFailure`) is recorded with its reason.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from navkit.geometry import se3_inverse, wrap_angle
from navkit.mission.pose2d import compose, pose3, relative
from navkit.timing import Timings, timed

__all__ = ["PlaneMotionFusion", "PlaneRecord", "PlaneStep"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PlaneStep:
    """One camera frame's plane-based motion (paper 2) and what the fusion did with it.

    Attributes
    ----------
    time : float
        Seconds.
    n_planes : int
        Planes extracted in the frame.
    case : int
        Independent plane directions used (3 = ">= 3"; 1-2 = texture fixed the rest; 0 = none).
    status : str
        ``"ok"``, ``"failed: ..."`` or ``"gated"`` (too far from the VO increment).
    plane_inc, vo_inc, true_inc : (3,) arrays
        Body-frame increments ``(dx, dy, dtheta)`` since the previous frame: from the planes
        (NaN when failed), from the VO, and the truth.
    """

    time: float
    n_planes: int
    case: int
    status: str
    plane_inc: NDArray[np.float64]
    vo_inc: NDArray[np.float64]
    true_inc: NDArray[np.float64]


@dataclass
class PlaneRecord:
    """What the plane fusion recorded: every step and the plane map (points, normals)."""

    steps: list[PlaneStep] = field(default_factory=list)
    points: list[NDArray[np.float64]] = field(default_factory=list)
    normals: list[NDArray[np.float64]] = field(default_factory=list)


def _inc_from_se3(T: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.array([T[0, 3], T[1, 3], np.arctan2(T[1, 0], T[0, 0])])


class PlaneMotionFusion:
    """Corrects the estimate with plane-based motion between camera frames.

    Parameters
    ----------
    fusion : FusionSettings
        Gates and weights.
    T_body_camera : (4, 4) array
    record : PlaneRecord
    timings : Timings, optional
    vo_model : VisualOdometryNoise, optional
        The VO's noise model: the motion prior's uncertainty over each camera interval comes
        from it (:meth:`~navkit.sensors.VisualOdometryNoise.increment_sigma`; floors 1 cm and
        0.2 deg, a real VO is not exact at standstill as the model is). Without it, the fusion
        gate's third (``gate_m / 3``, ``gate_deg / 3``).
    """

    def __init__(
        self,
        fusion: Any,
        T_body_camera: NDArray[np.float64],
        record: PlaneRecord,
        timings: Timings | None = None,
        vo_model: Any = None,
    ) -> None:
        self.F, self.rec, self.timings = fusion, record, timings
        self.vo_model = vo_model
        self.T_bc = T_body_camera
        self.T_cb = se3_inverse(T_body_camera)
        self.prev: Any = None  # (vo pose, truth pose) at the previous frame
        self.prev_t: float | None = None  # its time, seconds
        from navkit.planes import PlaneOdometry

        self.odometry = PlaneOdometry()

    def add_frame(
        self,
        frame: Any,
        est: NDArray[np.float64],
        vo: NDArray[np.float64],
        truth: NDArray[np.float64],
        t: float,
        ground_z: float,
        outbound: bool,
    ) -> NDArray[np.float64]:
        """Use one RGB-D frame; returns the corrected estimate."""
        from navkit.planes import observe_rgbd

        with timed(self.timings, "planes_extract"):
            obs = observe_rgbd(frame)
        if self.prev is not None:
            est = self._motion(obs, est, vo, truth, t)
        else:
            with timed(self.timings, "planes_motion"):
                self.odometry.update(obs)  # the first frame: the odometry's world
        # plane map: the frame's large planes, moved to the map with the corrected estimate
        if outbound:
            self._add_plane_map(obs, pose3(est, ground_z) @ self.T_bc)
        self.prev = (vo.copy(), truth.copy())
        self.prev_t = t
        return est

    def _motion(
        self,
        obs: Any,
        est: NDArray[np.float64],
        vo: NDArray[np.float64],
        truth: NDArray[np.float64],
        t: float,
    ) -> NDArray[np.float64]:
        from navkit.planes import FrameMotion, MotionPrior
        from navkit.planes.solve import MotionEstimate

        F = self.F
        vo0, truth0 = self.prev
        vo_int = relative(vo0, vo)
        true_int = relative(truth0, truth)
        # T_c1_c2 predicted by the VO with its uncertainty: it gates the association, starts
        # the dense step where the planes leave freedom, and bounds what the pixels may say
        prior = MotionPrior(
            self.T_cb @ pose3(vo_int, 0.0) @ self.T_bc, *self._prior_sigmas(vo_int, t)
        )
        with timed(self.timings, "planes_motion"):
            res = self.odometry.update(obs, prior)
        mot = res.motion if isinstance(res, FrameMotion) else res
        if isinstance(mot, MotionEstimate):
            pinc = _inc_from_se3(self.T_bc @ mot.T @ self.T_cb)
            diff = pinc - vo_int
            ok_gate = np.hypot(diff[0], diff[1]) <= F.gate_m and abs(
                float(wrap_angle(diff[2]))
            ) <= np.radians(F.gate_deg)
            if ok_gate:
                geo = mot.case >= 3
                w_xy = F.weight_xy_geometry if geo else F.weight_xy_texture
                w_th = F.weight_heading_geometry if geo else F.weight_heading_texture
                fused = vo_int + np.array([w_xy, w_xy, w_th]) * diff
                est = compose(est, relative(vo_int, fused))
                status = "ok"
            else:
                status = "gated"
            case = int(mot.case)
        else:
            pinc = np.full(3, np.nan)
            status = f"failed: {getattr(mot, 'reason', 'exception')}"
            log.debug("plane motion at t=%.1f s: %s", t, status)
            case = int(getattr(mot, "case", 0))
        self.rec.steps.append(PlaneStep(t, len(obs.segments), case, status, pinc, vo_int, true_int))
        return est

    def _prior_sigmas(self, vo_int: NDArray[np.float64], t: float) -> tuple[float, float]:
        """``(sigma_rotation_deg, sigma_translation)`` of the VO increment since the last
        frame (class docstring)."""
        F = self.F
        if self.vo_model is None or self.prev_t is None:
            return F.gate_deg / 3.0, F.gate_m / 3.0
        steps = round((t - self.prev_t) * self.vo_model.rate_hz)
        sig_t, sig_h = self.vo_model.increment_sigma(float(np.hypot(vo_int[0], vo_int[1])), steps)
        return max(float(np.degrees(sig_h)), 0.2), max(sig_t, 0.01)

    def _add_plane_map(
        self,
        obs: Any,
        T_world_cam: NDArray[np.float64],
        min_points: int = 2000,
        keep: int = 300,
        max_depth: float = 10.0,
    ) -> None:
        """Store a sample of each large plane's points (map frame, within ``max_depth`` metres of
        the camera, where the depth noise stays centimetric) and its normal."""
        P = obs.points.reshape(-1, 3)
        R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]
        for seg in obs.segments:
            if seg.plane.count < min_points:
                continue
            inl = seg.inliers[P[seg.inliers, 2] <= max_depth]
            if len(inl) == 0:
                continue
            idx = inl[:: max(1, len(inl) // keep)]
            self.rec.points.append(P[idx] @ R.T + t)
            self.rec.normals.append(R @ seg.normal)
