"""The simulated robot of the mission: a unicycle in a :class:`navkit.sim.Scene` with its sensors.

It holds the truth (the true pose and the raw dead-reckoned VO pose) and the random generator;
every reading comes from :mod:`navkit.sim` with the sensor settings of
:class:`~navkit.mission.settings.MissionSettings`. The mission's estimate never looks at the
truth except to log it next to the estimate.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from navkit.mission.pose2d import T_body_camera, compose, pose3, relative
from navkit.mission.settings import MissionSettings
from navkit.timing import Timings, timed

__all__ = ["SimRobot"]


class SimRobot:
    """The robot in the scene: moves, reads the VO, the lidar, the RGB-D camera and the stereo rig.

    Parameters
    ----------
    scene : navkit.sim.Scene
    start : (3,) array
        True start pose ``(x, y, theta)``.
    settings : MissionSettings
    timings : Timings, optional
    """

    def __init__(
        self,
        scene: Any,
        start: NDArray[np.float64],
        settings: MissionSettings,
        timings: Timings | None = None,
    ) -> None:
        from navkit.sensors import PinholeCamera, StereoRig, VisualOdometryNoise
        from navkit.sim import SpinningLidar
        from navkit.sim.scanners import RangeNoise

        s = settings
        self.scene, self.s, self.timings = scene, s, timings
        self.rng = np.random.default_rng(s.seed)
        self.truth, self.vo = start.copy(), start.copy()
        self.vo_model = VisualOdometryNoise(
            rate_hz=1.0 / s.robot.dt,
            scale_bias=s.vo.scale_bias,
            scale_sigma=s.vo.scale_sigma,
            heading_bias_per_m=np.radians(s.vo.heading_bias_deg_per_m),
            heading_sigma=np.radians(s.vo.heading_sigma_deg),
        )
        L, C, S = s.lidar, s.camera, s.stereo
        self.lidar = SpinningLidar(
            n_beams=L.n_beams,
            n_columns=L.n_columns,
            elevation_min_deg=L.elevation_min_deg,
            elevation_max_deg=L.elevation_max_deg,
        )
        self.lidar_noise = RangeNoise(L.relative_sigma, L.absolute_sigma, L.dropout)
        self.camera = PinholeCamera.from_fov(C.width_px, C.height_px, C.hfov_deg)
        self.T_bc = T_body_camera(C.height, C.pitch_down_deg)
        self.rig = StereoRig(
            PinholeCamera.from_fov(S.width_px, S.height_px, S.hfov_deg), S.baseline
        )
        self.T_b_stereo = T_body_camera(S.height, 0.0)

    def ground(self) -> float:
        """Ground height under the robot, metres."""
        return float(self.scene.ground_height(self.truth[0], self.truth[1]))

    def move(self, v: float, omega: float) -> NDArray[np.float64]:
        """Drive one control period (exact unicycle arc); returns the VO increment ``(3,)``: the
        true body increment corrupted by :class:`~navkit.sensors.VisualOdometryNoise`'s model."""
        from navkit.sim.unicycle import unicycle_step

        m, rng = self.vo_model, self.rng
        new_truth = unicycle_step(self.truth, v, omega, self.s.robot.dt)
        inc_true = relative(self.truth, new_truth)
        dist = float(np.hypot(inc_true[0], inc_true[1]))
        moving = dist > 0 or inc_true[2] != 0
        scale = 1.0 + m.scale_bias + m.scale_sigma * rng.standard_normal()
        dth = inc_true[2] + (
            m.heading_bias_per_m * dist + m.heading_sigma * rng.standard_normal() if moving else 0.0
        )
        inc_vo = np.array([inc_true[0] * scale, inc_true[1] * scale, dth])
        self.truth = new_truth
        self.vo = compose(self.vo, inc_vo)
        return inc_vo

    def scan(self, t: float) -> Any:
        """A lidar scan (:class:`navkit.sim.SimScan`, with the truth of every ray)."""
        from navkit.sim import render_scan

        L = self.s.lidar
        with timed(self.timings, "sim_lidar"):
            return render_scan(
                self.scene,
                self.lidar,
                pose3(self.truth, self.ground() + L.height),
                self.lidar_noise,
                self.rng,
                L.max_range,
                t,
            )

    def rgbd(self, t: float) -> Any:
        """An RGB-D frame (:class:`navkit.sim.SimRGBD`)."""
        from navkit.sim import render_rgbd
        from navkit.sim.scanners import RangeNoise

        C = self.s.camera
        T_wc = pose3(self.truth, self.ground()) @ self.T_bc
        with timed(self.timings, "sim_camera"):
            return render_rgbd(
                self.scene,
                self.camera,
                T_wc,
                RangeNoise(C.depth_relative_sigma),
                self.rng,
                timestamp=t,
                max_depth=C.max_depth,
            )

    def stereo(self, t: float, pan: float) -> Any:
        """A stereo pair of the level rig on its pan drive at ``pan`` radians."""
        from navkit.sim import render_stereo

        S = self.s.stereo
        T_ws = (
            pose3(self.truth, self.ground())
            @ pose3(np.array([0.0, 0.0, pan]), 0.0)
            @ self.T_b_stereo
        )
        with timed(self.timings, "sim_stereo"):
            return render_stereo(
                self.scene,
                self.rig,
                T_ws,
                self.rng,
                pixel_noise=S.pixel_noise,
                supersample=S.supersample,
                timestamp=t,
            ).pair
