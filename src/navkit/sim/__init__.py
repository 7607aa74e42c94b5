"""The built-in simulated world: primitives, ray casting and sensors, every render with its truth.

Build a :class:`Scene` from primitives (:class:`Ground` with optional hills, :class:`Box`,
:class:`Prism` ramps, :class:`Sphere`, :class:`Hemisphere`, :class:`Cylinder`, textured
:class:`Wall`), or load one from TOML (:func:`load_scene`, :func:`builtin_scene_path`), then render
range scans (:func:`render_scan` with a :class:`TiltingScanner` or :class:`SpinningLidar`), RGB-D
frames (:func:`render_rgbd`) and rectified stereo pairs (:func:`render_stereo`). Each render returns
the truth: which primitive every ray hit (ground / obstacle labels), true points, the exact poses.
:meth:`Scene.true_planes` gives the planar faces. :func:`simulate_unicycle` drives a robot.

Frames: world z up; ``T_a_b`` maps frame b to frame a; scanners x forward, y left, z up; cameras
OpenCV optical (x right, y down, z forward).
"""

from navkit.sim.footprints import Footprint, footprint, true_footprints
from navkit.sim.primitives import (
    T_MIN,
    Box,
    Cylinder,
    Ground,
    Hemisphere,
    Primitive,
    Prism,
    Sphere,
    Wall,
)
from navkit.sim.render import (
    SimRGBD,
    SimScan,
    SimStereo,
    body_pose_under,
    render_rgbd,
    render_scan,
    render_stereo,
    shade,
)
from navkit.sim.scanners import RangeNoise, SpinningLidar, TiltingScanner
from navkit.sim.scene import RayHits, Scene
from navkit.sim.scene_io import (
    builtin_scene_path,
    builtin_scenes,
    load_scene,
    scene_from_dict,
    scene_to_dict,
    scene_to_toml,
)
from navkit.sim.texture import TEXTURE_KINDS, Texture
from navkit.sim.unicycle import simulate_unicycle, unicycle_step

__all__ = [
    "TEXTURE_KINDS",
    "T_MIN",
    "Box",
    "Cylinder",
    "Footprint",
    "Ground",
    "Hemisphere",
    "Primitive",
    "Prism",
    "RangeNoise",
    "RayHits",
    "Scene",
    "SimRGBD",
    "SimScan",
    "SimStereo",
    "Sphere",
    "SpinningLidar",
    "Texture",
    "TiltingScanner",
    "Wall",
    "body_pose_under",
    "builtin_scene_path",
    "builtin_scenes",
    "footprint",
    "load_scene",
    "render_rgbd",
    "render_scan",
    "render_stereo",
    "scene_from_dict",
    "scene_to_dict",
    "scene_to_toml",
    "shade",
    "simulate_unicycle",
    "true_footprints",
    "unicycle_step",
]
