"""What sensors produce, and their models: range scans, cameras, stereo rigs, VO noise."""

from navkit.sensors.camera import PinholeCamera, RGBDFrame, StereoPair, StereoRig
from navkit.sensors.odometry import VisualOdometryNoise
from navkit.sensors.range_scan import RangeScan, grid_directions

__all__ = [
    "PinholeCamera",
    "RGBDFrame",
    "RangeScan",
    "StereoPair",
    "StereoRig",
    "VisualOdometryNoise",
    "grid_directions",
]
