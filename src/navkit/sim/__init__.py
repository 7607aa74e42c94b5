"""The built-in simulated world: primitives, ray casting and sensors, every render with its truth.

Build a :class:`Scene` from primitives (:class:`Ground` with optional hills, :class:`Box`,
:class:`Prism` ramps, :class:`Sphere`, :class:`Hemisphere`, :class:`Cylinder`, textured
:class:`Wall`), or load one from TOML (:func:`load_scene`, :func:`builtin_scene_path`), then render
range scans (:func:`render_scan` with a :class:`TiltingScanner` or :class:`SpinningLidar`), RGB-D
frames (:func:`render_rgbd`) and rectified stereo pairs (:func:`render_stereo`). Each render returns
the truth: which primitive every ray hit (ground / obstacle labels), true points, the exact poses.
:meth:`Scene.true_planes` gives the planar faces. :func:`simulate_unicycle` drives a robot.
The helpers (scanner noise in :mod:`~navkit.sim.scanners`, obstacle footprints in
:mod:`~navkit.sim.footprints`, scene (de)serialisation in :mod:`~navkit.sim.scene_io`, ray hits in
:mod:`~navkit.sim.scene`) are imported from their modules.

Frames: world z up; ``T_a_b`` maps frame b to frame a; scanners x forward, y left, z up; cameras
OpenCV optical (x right, y down, z forward).
"""

from navkit.sim.primitives import Box, Cylinder, Ground, Hemisphere, Prism, Sphere, Wall
from navkit.sim.render import SimRGBD, SimScan, SimStereo, render_rgbd, render_scan, render_stereo
from navkit.sim.scanners import SpinningLidar, TiltingScanner
from navkit.sim.scene import Scene
from navkit.sim.scene_io import builtin_scene_path, builtin_scenes, load_scene
from navkit.sim.texture import Texture
from navkit.sim.unicycle import simulate_unicycle

__all__ = [
    "Box",
    "Cylinder",
    "Ground",
    "Hemisphere",
    "Prism",
    "Scene",
    "SimRGBD",
    "SimScan",
    "SimStereo",
    "Sphere",
    "SpinningLidar",
    "Texture",
    "TiltingScanner",
    "Wall",
    "builtin_scene_path",
    "builtin_scenes",
    "load_scene",
    "render_rgbd",
    "render_scan",
    "render_stereo",
    "simulate_unicycle",
]
