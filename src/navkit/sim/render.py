"""Rendering of range scans, RGB-D frames and rectified stereo pairs, each with its truth."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError
from navkit.geometry import se3_from_rt
from navkit.geometry.linalg import rows_dot, rows_matmul, rows_norm
from navkit.sensors import (
    PinholeCamera,
    RangeScan,
    RGBDFrame,
    StereoPair,
    StereoRig,
    grid_directions,
)
from navkit.sim.scanners import RangeNoise, SpinningLidar, TiltingScanner
from navkit.sim.scene import RayHits, Scene

__all__ = [
    "CAMERA_HEIGHT",
    "CAMERA_HFOV_DEG",
    "CAMERA_PITCH_DOWN_DEG",
    "DEPTH_MAX",
    "DEPTH_RELATIVE_SIGMA",
    "SKY_COLOR",
    "STEREO_BASELINE",
    "STEREO_PIXEL_NOISE",
    "SUN_DIRECTION",
    "SimRGBD",
    "SimScan",
    "SimStereo",
    "body_pose_under",
    "render_rgbd",
    "render_scan",
    "render_stereo",
    "shade",
]

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

SUN_DIRECTION = np.array([0.35, 0.25, 0.90]) / np.linalg.norm([0.35, 0.25, 0.90])
"""Unit vector towards the light (world frame) used by :func:`shade`."""
SKY_COLOR = np.array([0.70, 0.80, 0.92])
"""RGB of rays that hit nothing."""
AMBIENT = 0.45
"""Share of the light that does not depend on the surface orientation."""

# the one home of the simulated cameras' defaults: navkit.mission.settings.CameraSettings and
# StereoSettings (the mission's and the demo's cameras) take these; each use picks only its
# image size
CAMERA_HEIGHT = 1.0
"""Height of the simulated robot's cameras (RGB-D and stereo) above the ground, metres."""
CAMERA_PITCH_DOWN_DEG = 12.0
"""Downward pitch of the forward RGB-D camera, degrees (the stereo pair is level)."""
CAMERA_HFOV_DEG = 80.0
"""Horizontal field of view of the simulated cameras, degrees."""
DEPTH_RELATIVE_SIGMA = 0.003
"""RGB-D depth noise proportional to the depth."""
DEPTH_MAX = 10.0
"""RGB-D range, metres: no depth beyond (a RealSense D435 returns about 10 m)."""
STEREO_BASELINE = 0.3
"""Baseline of the simulated stereo pair, metres."""
STEREO_PIXEL_NOISE = 2.0
"""Image noise of the simulated stereo pair, grey levels (1-sigma)."""


def _rng(rng: np.random.Generator | int | None) -> np.random.Generator:
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


def _pose(T: ArrayLike, field: str) -> FloatArray:
    try:
        M = np.asarray(T, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"not numeric: {exc}", field=field, expected="(4, 4) rigid transform"
        ) from exc
    if M.shape != (4, 4) or not np.all(np.isfinite(M)):
        raise InputError(
            f"has shape {M.shape}", field=field, expected="finite (4, 4) rigid transform"
        )
    R = M[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise InputError("rotation block is not a rotation", field=field, expected="R in SO(3)")
    return M


def shade(hits: RayHits, directions: FloatArray) -> FloatArray:
    """Lambertian shading ``albedo * (AMBIENT + (1 - AMBIENT) max(0, n . sun))`` in ``[0, 1]``.

    Misses get :data:`SKY_COLOR`. ``directions`` are the rays (unused except for the sky shape).
    """
    lam = np.clip(rows_dot(hits.normal, SUN_DIRECTION), 0.0, 1.0)
    rgb = hits.color * (AMBIENT + (1.0 - AMBIENT) * lam)[:, None]
    up = np.clip(directions[:, 2] / rows_norm(directions), 0.0, 1.0)
    sky = SKY_COLOR[None, :] * (1.0 - 0.25 * up[:, None]) + 0.25 * up[:, None] * np.array(
        [0.4, 0.55, 0.85]
    )
    return np.where(hits.hit[:, None], rgb, sky)


def body_pose_under(scene: Scene, T_world_sensor: ArrayLike) -> FloatArray:
    """The level body frame of a sensor pose: z up, origin on the ground under the sensor.

    Its yaw is the heading of the sensor's x axis (of its y axis turned by -90 deg when x is
    vertical); its origin is ``(x, y, ground_height(x, y))``.
    """
    T = _pose(T_world_sensor, "T_world_sensor")
    R = T[:3, :3]
    if np.hypot(R[0, 0], R[1, 0]) > 1e-9:
        yaw = np.arctan2(R[1, 0], R[0, 0])
    else:
        yaw = np.arctan2(R[1, 1], R[0, 1]) - np.pi / 2
    c, s = np.cos(yaw), np.sin(yaw)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    x, y = T[0, 3], T[1, 3]
    z = float(scene.ground_height(x, y))
    return se3_from_rt(Rz, np.array([x, y, z]))


@dataclass(frozen=True)
class SimScan:
    """A simulated range scan and its truth.

    Attributes
    ----------
    scan : RangeScan
        What the sensor reports (noisy ranges, NaN = no return or dropout); its body frame is
        level, z up, on the ground under the sensor, yawed like the sensor.
    T_world_body : (4, 4) array
        Pose of that body frame in the world.
    hit_index : (n_az, n_el) int64
        Primitive hit by each ray (-1 = nothing within ``max_range``); the truth of the ray, also
        where the return was dropped (mask with ``scan.valid``).
    is_ground : (n_az, n_el) bool
        True where the ray hit a ground primitive.
    points_world : (n_az, n_el, 3) float64
        True hit points, world frame, NaN on a miss.
    true_ranges : (n_az, n_el) float64
        Noise-free ranges, NaN on a miss.
    T_world_sensor : (4, 4) array
        Pose of the sensor.
    normals_world : (n_az, n_el, 3) float64
        True unit surface normals at the hits (facing the sensor), NaN on a miss.
    """

    scan: RangeScan
    T_world_body: FloatArray
    hit_index: NDArray[np.int64]
    is_ground: NDArray[np.bool_]
    points_world: FloatArray
    true_ranges: FloatArray
    T_world_sensor: FloatArray
    normals_world: FloatArray


def render_scan(
    scene: Scene,
    scanner: TiltingScanner | SpinningLidar,
    T_world_sensor: ArrayLike,
    noise: RangeNoise | None = None,
    rng: np.random.Generator | int | None = None,
    max_range: float = np.inf,
    timestamp: float = float("nan"),
) -> SimScan:
    """Render a range scan of ``scene`` by ``scanner`` at ``T_world_sensor``.

    Parameters
    ----------
    scene : Scene
    scanner : TiltingScanner or SpinningLidar
        Anything with ``azimuth`` and ``elevation`` arrays (radians).
    T_world_sensor : (4, 4) array
        Sensor pose; the sensor frame is x forward, y left, z up (azimuth from +x, elevation up).
    noise : RangeNoise, optional
        Range noise and dropouts (none by default).
    rng : numpy Generator or int seed, optional
        Randomness of the noise.
    max_range : float
        Hits beyond this are no return (metres).

    Returns
    -------
    SimScan
    """
    noise = RangeNoise() if noise is None else noise
    T = _pose(T_world_sensor, "T_world_sensor")
    az, el = np.asarray(scanner.azimuth), np.asarray(scanner.elevation)
    d_sensor = grid_directions(az, el)  # (n_az, n_el, 3)
    shape = d_sensor.shape[:2]
    D = rows_matmul(d_sensor.reshape(-1, 3), T[:3, :3].T)
    hits = scene.cast(T[:3, 3], D, max_range=max_range, with_color=False)
    true_ranges = hits.distance.reshape(shape)
    ranges = noise.apply(true_ranges, _rng(rng))
    T_wb = body_pose_under(scene, T)
    T_bs = np.linalg.inv(T_wb) @ T
    scan = RangeScan(
        ranges,
        az,
        el,
        sensor_height=float(T_bs[2, 3]),
        R_body_sensor=T_bs[:3, :3],
        max_range=max_range,
        timestamp=timestamp,
    )
    index = hits.index.reshape(shape)
    return SimScan(
        scan,
        T_wb,
        index,
        scene.is_ground_index(index),
        hits.point.reshape(*shape, 3),
        true_ranges,
        T,
        hits.normal.reshape(*shape, 3),
    )


@dataclass(frozen=True)
class SimRGBD:
    """A simulated RGB-D frame and its truth.

    Attributes
    ----------
    frame : RGBDFrame
        Shaded colour and (noisy) depth along the optical axis, metres, NaN = no return.
    hit_index : (H, W) int64
        Primitive seen at each pixel (-1 = sky).
    T_world_camera : (4, 4) array
        Camera pose (OpenCV optical frame: x right, y down, z forward).
    depth_true : (H, W) float64
        Noise-free depth, NaN on a miss.
    normals_world : (H, W, 3) float64
        True surface normals (facing the camera), NaN on a miss.
    """

    frame: RGBDFrame
    hit_index: NDArray[np.int64]
    T_world_camera: FloatArray
    depth_true: FloatArray
    normals_world: FloatArray


def _render_camera(
    scene: Scene, camera: PinholeCamera, T: FloatArray, supersample: int
) -> tuple[RayHits, FloatArray, FloatArray]:
    """Cast one ray per pixel centre; colour averaged over ``supersample^2`` sub-pixel rays.

    Sub-pixel rays are intersected only with the primitive seen by the pixel centre
    (:meth:`Scene.cast_on`): this filters textures (mortar lines, checkers) at a fraction of the
    cost of full casts; a sub-ray that misses that primitive (a silhouette pixel) takes the
    centre colour, so silhouettes are not anti-aliased.
    """
    if int(supersample) < 1:
        raise InputError(f"is {supersample}", field="supersample", expected="an integer >= 1")
    rays = camera.pixel_rays().reshape(-1, 3)  # z = 1, optical frame
    D = rows_matmul(rays, T[:3, :3].T)
    hits = scene.cast(T[:3, 3], D)
    depth = hits.distance / rows_norm(rays)  # distance along z of the optical frame
    rgb = shade(hits, D)
    k = int(supersample)
    if k > 1:
        offs = (np.arange(k) + 0.5) / k - 0.5
        acc = np.zeros_like(rgb)
        for dv in offs:
            for du in offs:
                Ds = rows_matmul(
                    rays + np.array([du / camera.fx, dv / camera.fy, 0.0]), T[:3, :3].T
                )
                sub = scene.cast_on(hits.index, T[:3, 3], Ds)
                same = sub.hit | ~hits.hit  # sky stays sky (its colour follows the sub-ray)
                acc += np.where(same[:, None], shade(sub, Ds), rgb)
        rgb = acc / (k * k)
    return hits, depth, rgb


def _to_uint8(rgb: FloatArray) -> NDArray[np.uint8]:
    return np.clip(np.rint(rgb * 255.0), 0, 255).astype(np.uint8)


def render_rgbd(
    scene: Scene,
    camera: PinholeCamera,
    T_world_camera: ArrayLike,
    noise: RangeNoise | None = None,
    rng: np.random.Generator | int | None = None,
    supersample: int = 1,
    timestamp: float = float("nan"),
    max_depth: float = np.inf,
) -> SimRGBD:
    """Render a registered colour + depth frame (a Kinect-like RGB-D camera).

    Colour is the texture albedo with Lambertian shading (:func:`shade`); depth is the distance
    along the optical axis, with ``noise`` applied to it (relative part proportional to depth).

    Parameters
    ----------
    camera : PinholeCamera
    T_world_camera : (4, 4) array
        Camera pose, OpenCV optical frame (x right, y down, z forward).
    supersample : int
        Colour anti-aliasing: average of ``supersample^2`` rays per pixel (depth and truth come
        from the pixel-centre ray).
    max_depth : float
        Depth sensor range, metres: farther pixels get NaN depth (``depth_true`` and the colour
        image are not limited). A Kinect-type camera reaches about 8 m.
    """
    noise = RangeNoise() if noise is None else noise
    T = _pose(T_world_camera, "T_world_camera")
    hits, depth, rgb = _render_camera(scene, camera, T, supersample)
    shape = (camera.height, camera.width)
    depth_true = depth.reshape(shape)
    depth_noisy = noise.apply(depth_true, _rng(rng))
    depth_noisy[~(depth_true < max_depth)] = np.nan
    frame = RGBDFrame(_to_uint8(rgb.reshape(*shape, 3)), depth_noisy, camera, timestamp)
    return SimRGBD(frame, hits.index.reshape(shape), T, depth_true, hits.normal.reshape(*shape, 3))


@dataclass(frozen=True)
class SimStereo:
    """A simulated rectified stereo pair and its truth.

    Attributes
    ----------
    pair : StereoPair
        Left and right RGB uint8 images (with pixel noise, if any) and the rig.
    disparity : (H, W) float64
        True left disparity ``b f / z - doffs`` in pixels, NaN where the left ray hits nothing.
    depth : (H, W) float64
        True depth of the left image along its optical axis, NaN on a miss.
    hit_index : (H, W) int64
        Primitive seen by each left pixel.
    T_world_left : (4, 4) array
        Pose of the left camera (OpenCV optical frame); the right one is ``baseline`` along its x.
    """

    pair: StereoPair
    disparity: FloatArray
    depth: FloatArray
    hit_index: NDArray[np.int64]
    T_world_left: FloatArray


def render_stereo(
    scene: Scene,
    rig: StereoRig,
    T_world_left: ArrayLike,
    rng: np.random.Generator | int | None = None,
    pixel_noise: float = 0.0,
    supersample: int = 2,
    timestamp: float = float("nan"),
) -> SimStereo:
    """Render both cameras of a rectified rig by ray casting, with the true left disparity.

    The right camera is the left one moved ``rig.baseline`` along the left optical x axis, with
    its principal point shifted by ``rig.doffs`` (Middlebury convention), so that
    ``u_left - u_right = b fx / z - doffs`` exactly.

    Parameters
    ----------
    pixel_noise : float
        Standard deviation of additive Gaussian image noise, in 8-bit grey levels.
    supersample : int
        Texture anti-aliasing (``supersample^2`` colour samples per pixel, see
        :func:`_render_camera`); 2 by default, since aliased fine textures (mortar joints) are
        not what real lenses deliver.
    """
    if not (np.isfinite(pixel_noise) and pixel_noise >= 0):
        raise InputError(f"is {pixel_noise}", field="pixel_noise", expected="grey levels >= 0")
    T = _pose(T_world_left, "T_world_left")
    cam = rig.camera
    right_cam = PinholeCamera(cam.fx, cam.fy, cam.cx + rig.doffs, cam.cy, cam.width, cam.height)
    T_right = T @ se3_from_rt(np.eye(3), np.array([rig.baseline, 0.0, 0.0]))
    hits_l, depth_l, rgb_l = _render_camera(scene, cam, T, supersample)
    _, _, rgb_r = _render_camera(scene, right_cam, T_right, supersample)
    shape = (cam.height, cam.width)
    left = rgb_l.reshape(*shape, 3) * 255.0
    right = rgb_r.reshape(*shape, 3) * 255.0
    if pixel_noise > 0:
        g = _rng(rng)
        left = left + pixel_noise * g.standard_normal(left.shape)
        right = right + pixel_noise * g.standard_normal(right.shape)
    to8 = lambda a: np.clip(np.rint(a), 0, 255).astype(np.uint8)  # noqa: E731
    pair = StereoPair(to8(left), to8(right), rig, timestamp)
    depth = depth_l.reshape(shape)
    return SimStereo(pair, rig.disparity_from_depth(depth), depth, hits_l.index.reshape(shape), T)
