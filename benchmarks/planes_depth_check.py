"""Where should the depth-consistency check of texture solutions draw the line?

:func:`navkit.planes.motion.depth_consistency` moves frame 2's off-plane points by a candidate
motion into frame 1's camera and counts the fraction in frame 1's free space (``violation``);
:class:`~navkit.planes.motion.MotionSettings` rejects texture solutions above 0.35. This study
measures the statistic on simulated pairs with known motion: a corridor (textured wall +
floor) with off-plane objects (balls, boxes, a pillar) at random places, random camera motions,
depth noise from 0.2 % to 2 % of the range (Kinect: ``0.0025 d^2`` is 1 % at 4 m), for the true
motion and for the true motion spoiled along the degrees of freedom the texture fixes (slides
along the wall-floor line and in the wall, turns about the wall's normal).

Run: ``python -m benchmarks.planes_depth_check`` (prints a table; ~2 min).
"""

from __future__ import annotations

import logging

import numpy as np
from scipy.spatial.transform import Rotation

from navkit.geometry import se3_from_rt
from navkit.planes import ExtractionSettings, observe_rgbd
from navkit.planes.motion import depth_consistency
from navkit.sensors import PinholeCamera
from navkit.sim import Box, Ground, Scene, Sphere, Texture, Wall, render_rgbd
from navkit.sim.scanners import RangeNoise

log = logging.getLogger(__name__)

CAM = PinholeCamera(262.5, 262.5, 159.5, 119.5, 320, 240)
R_FORWARD = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
BRICKS = Texture("bricks", scale=0.3, seed=3, color=(0.6, 0.3, 0.2), color2=(0.85, 0.8, 0.75))
ERRORS_CM = (2.0, 5.0, 10.0, 20.0, 40.0)
TURNS_DEG = (1.0, 3.0, 10.0)


def _scene(rng: np.random.Generator) -> Scene:
    prims = [
        Wall(origin=(-5, -1.5, 0), u=(30, 0, 0), v=(0, 0, 3), texture=BRICKS, name="wall"),
        Ground(texture=Texture("noise", scale=0.4, seed=5), name="floor"),
    ]
    for k in range(3):
        x, y = rng.uniform(1.5, 5.0), rng.uniform(-1.2, 1.5)
        if k == 0:
            prims.append(Sphere(center=(x, y, 0.4), radius=0.35, name="ball"))
        elif k == 1:
            prims.append(Box(center=(x, y, 0.3), size=(0.5, 0.6, 0.6), yaw=rng.uniform(0, 1)))
        else:
            prims.append(Box(center=(x, y, 1.0), size=(0.3, 0.3, 2.0), name="pillar"))
    return Scene(prims)


def _pairs(n: int, sigma: float, seed: int):
    rng = np.random.default_rng(seed)
    for k in range(n):
        scene = _scene(rng)
        T1 = se3_from_rt(
            Rotation.from_euler("z", rng.uniform(-30, -10), degrees=True).as_matrix() @ R_FORWARD,
            [rng.uniform(-1.0, 0.0), rng.uniform(-0.5, 0.8), 1.0],
        )
        M = se3_from_rt(
            Rotation.from_rotvec(rng.normal(0, 0.04, 3)).as_matrix(), rng.normal(0, 0.1, 3)
        )
        noise = RangeNoise(relative_sigma=sigma)
        f1 = render_rgbd(scene, CAM, T1, noise=noise, rng=2 * k + seed)
        f2 = render_rgbd(scene, CAM, T1 @ M, noise=noise, rng=2 * k + 1 + seed)
        yield (
            T1,
            M,
            observe_rgbd(f1.frame, ExtractionSettings(cell=10)),
            observe_rgbd(f2.frame, ExtractionSettings(cell=10)),
        )


def _planes_of(obs, T_world_cam) -> list[int]:
    """Segments of a frame that are the wall (y = -1.5) or the floor (z = 0): the matched
    planes of a texture step, left out of the check as :func:`estimate_motion` does."""
    R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]
    out = []
    for n_w, d_w in (([0.0, 1.0, 0.0], -1.5), ([0.0, 0.0, 1.0], 0.0)):
        n_c = R.T @ np.array(n_w)
        rho = d_w - np.array(n_w) @ t
        for j, s in enumerate(obs.segments):
            if abs(s.normal @ n_c) > 0.99 and abs(abs(rho) - s.rho) < 0.1:
                out.append(j)
    return out


def study(n: int = 12, sigmas: tuple[float, ...] = (0.002, 0.005, 0.01, 0.02)) -> list[dict]:
    rows = []
    for sigma in sigmas:
        true_v: list[float] = []
        wrong: dict[str, list[float]] = {}
        for T1, M, o1, o2 in _pairs(n, sigma, seed=int(sigma * 1e4)):
            # frame-1 directions of the DoF the texture fixes: along the wall-floor line (x of
            # the world), up the wall (z), turns about the wall normal (y)
            R1 = T1[:3, :3]
            ex, ez, ey = R1.T @ [1.0, 0, 0], R1.T @ [0, 0, 1.0], R1.T @ [0, 1.0, 0]
            excl = _planes_of(o2, T1 @ M)
            c = depth_consistency(o1, o2, M, excl)
            if c.tested < 500:
                continue
            true_v.append(c.violation)
            for e in ERRORS_CM:
                for name, d in (("along the line", ex), ("up the wall", ez)):
                    for sgn in (-1, 1):
                        S = se3_from_rt(np.eye(3), sgn * e / 100 * d)
                        v = depth_consistency(o1, o2, S @ M, excl).violation
                        wrong.setdefault(f"{e:.0f} cm {name}", []).append(v)
            for a in TURNS_DEG:
                for sgn in (-1, 1):
                    S = se3_from_rt(Rotation.from_rotvec(sgn * np.radians(a) * ey).as_matrix(), 0)
                    v = depth_consistency(o1, o2, S @ M, excl).violation
                    wrong.setdefault(f"{a:.0f} deg about the wall normal", []).append(v)
        rows.append({"sigma": sigma, "true": np.array(true_v), "wrong": wrong})
    return rows


def main() -> None:
    logging.basicConfig(level=logging.WARNING)
    for r in study():
        t = r["true"]
        print(
            f"\ndepth noise {100 * r['sigma']:.1f} % of range: true motion, {len(t)} pairs: "
            f"violation median {np.median(t):.3f}, 95 % {np.percentile(t, 95):.3f}, "
            f"max {np.max(t):.3f}"
        )
        for name, v in r["wrong"].items():
            v = np.asarray(v)
            print(
                f"  {name:32s} median {np.nanmedian(v):.3f}  min {np.nanmin(v):.3f}  "
                f"rejected at 0.35: {np.mean(v > 0.35) * 100:.0f} %, "
                f"at 0.25: {np.mean(v > 0.25) * 100:.0f} %"
            )


if __name__ == "__main__":
    main()
