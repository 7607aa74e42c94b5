"""The four capabilities together: a robot that goes out, maps, localizes and comes back.

A simulated unicycle robot with a spinning lidar, an RGB-D camera and visual odometry is driven
out by a scripted operator (:mod:`navkit.mission.driver`); every lidar scan's obstacles (paper 1)
go into a global 2D obstacle map (:class:`navkit.obstacles.ObstacleMapper`); plane-based motion
(paper 2) corrects the VO; a room map built on the first visit gives correlation fixes later
(paper 3); the path memory (paper 4) records the trajectory and, when the link is lost, brings the
robot back along it, round a block or stopping if there is no way round. :class:`Mission` is the
composer (:meth:`Mission.step`: one line per capability, each an online object);
:func:`run_mission` runs it,
:func:`mission_metrics` scores it against the truth, :func:`run_to_dir` / :func:`run_demo` write
``report.html``, ``metrics.json`` and the maps.
"""

from navkit.mission.demo import run_demo, run_scene_file, run_to_dir
from navkit.mission.driver import PurePursuit
from navkit.mission.metrics import mission_metrics
from navkit.mission.run import (
    Fix2D,
    Mission,
    MissionLog,
    PlaneStep,
    StepRecord,
    StepSink,
    run_mission,
)
from navkit.mission.settings import (
    BlockSettings,
    CameraSettings,
    FusionSettings,
    LidarSettings,
    MissionMapSettings,
    MissionSettings,
    RobotSettings,
    Route,
    StereoSettings,
    VOSettings,
    builtin_route_path,
    load_route,
)

__all__ = [
    "BlockSettings",
    "CameraSettings",
    "Fix2D",
    "FusionSettings",
    "LidarSettings",
    "Mission",
    "MissionLog",
    "MissionMapSettings",
    "MissionSettings",
    "PlaneStep",
    "PurePursuit",
    "RobotSettings",
    "Route",
    "StepRecord",
    "StepSink",
    "StereoSettings",
    "VOSettings",
    "builtin_route_path",
    "load_route",
    "mission_metrics",
    "run_demo",
    "run_mission",
    "run_scene_file",
    "run_to_dir",
]
