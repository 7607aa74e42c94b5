"""``navkit run``: recordings streamed through the online capabilities.

- :mod:`~navkit.runtime.sources`: ROS 1 / ROS 2 bags, MCAP, KITTI, CARMEN, RGB-D folders and
  trajectory files as time-ordered :class:`~navkit.runtime.messages.Message` streams;
- :mod:`~navkit.runtime.pipeline`: topics -> capabilities and the run's settings (TOML);
- :mod:`~navkit.runtime.capabilities`: one adapter ("stage") per capability;
- :mod:`~navkit.runtime.run`: the loop, crash-safe outputs, checkpoints and ``--resume``.

Dependency rule: ``runtime`` may import the capabilities, ``mission``, ``io`` and ``viz``; nothing
below it imports ``runtime``.
"""

from navkit.runtime.messages import CameraData, Message, Output, Polyline, ScanData
from navkit.runtime.pipeline import Pipeline, resolve_pipeline
from navkit.runtime.run import NullLogger, run_recording
from navkit.runtime.sources import open_source

__all__ = [
    "CameraData",
    "Message",
    "NullLogger",
    "Output",
    "Pipeline",
    "Polyline",
    "ScanData",
    "open_source",
    "resolve_pipeline",
    "run_recording",
]
