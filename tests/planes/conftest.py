"""Simulated scenes for the planes tests: a textured corridor seen so that 1, 2 or >= 3 plane
directions are visible, rendered before and after a known motion."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from navkit.geometry import se3_from_rt
from navkit.sensors import PinholeCamera
from navkit.sim import Ground, Scene, Texture, Wall, render_rgbd
from navkit.sim.scanners import RangeNoise

BRICKS = Texture("bricks", scale=0.3, seed=3, color=(0.6, 0.3, 0.2), color2=(0.85, 0.8, 0.75))
NOISE = Texture("noise", scale=0.4, seed=5)
TILES = Texture("tiles", scale=0.3, seed=2)
SOLID = Texture("solid")

# camera looking along world +x (optical z), x right = world -y, y down = world -z
R_FORWARD = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
# camera looking at the wall y = -1.5 (optical z = world -y)
R_AT_WALL = np.stack([[-1.0, 0, 0], [0, 0, -1.0], [0, -1.0, 0]], axis=1)

CAMERA = PinholeCamera(262.5, 262.5, 159.5, 119.5, 320, 240)
DEPTH_NOISE = RangeNoise(relative_sigma=0.002)  # 2 mm per metre, Kinect-like at short range
MOTION = se3_from_rt(Rotation.from_rotvec([0.03, -0.08, 0.05]).as_matrix(), [0.12, -0.05, 0.2])


def corridor(n_dirs: int, texture: Texture | None = None) -> Scene:
    """A brick wall (y = -1.5); with the floor (n_dirs >= 2); with an end wall at x = 8 (3)."""
    prims = [
        Wall(
            origin=(-5, -1.5, 0), u=(30, 0, 0), v=(0, 0, 3), texture=texture or BRICKS, name="wall"
        )
    ]
    if n_dirs >= 2:
        prims.append(Ground(texture=texture or NOISE, name="floor"))
    if n_dirs >= 3:
        prims.append(
            Wall(origin=(8, -6, 0), u=(0, 12, 0), v=(0, 0, 3), texture=texture or TILES, name="end")
        )
    return Scene(prims)


def start_pose(n_dirs: int) -> np.ndarray:
    if n_dirs == 1:
        return se3_from_rt(R_AT_WALL, [0.0, 0.5, 1.2])
    return se3_from_rt(
        Rotation.from_euler("z", -25, degrees=True).as_matrix() @ R_FORWARD, [0.0, 0.0, 1.0]
    )


@dataclass(frozen=True)
class Pair:
    scene: Scene
    f1: object
    f2: object
    T_1_2: np.ndarray


def render_pair(
    n_dirs: int, motion: np.ndarray = MOTION, texture: Texture | None = None, seed: int = 0
) -> Pair:
    scene = corridor(n_dirs, texture)
    T1 = start_pose(n_dirs)
    T2 = T1 @ motion
    f1 = render_rgbd(scene, CAMERA, T1, noise=DEPTH_NOISE, rng=seed + 1)
    f2 = render_rgbd(scene, CAMERA, T2, noise=DEPTH_NOISE, rng=seed + 2)
    return Pair(scene, f1, f2, motion)


@pytest.fixture(scope="session")
def pairs() -> dict[int, Pair]:
    """Rendered once per session: the 1-, 2- and 3-direction corridor pairs."""
    return {k: render_pair(k) for k in (1, 2, 3)}
