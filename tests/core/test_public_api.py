"""Each package's public surface, pinned.

A package exports its online object, its settings and results and its main entry functions
(``docs/architecture.md``, "Public API"); everything else is imported from the module that defines
it. A change to a surface is a deliberate edit of :data:`SURFACES`. No package exports a name
defined in another package, so each name has one import path.
"""

from __future__ import annotations

import ast
import importlib
import inspect
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2] / "src" / "navkit"

SURFACES: dict[str, list[str]] = {
    "batch": [
        "BatchResult",
        "BatchSettings",
        "BatchTask",
        "DONE_MARKER",
        "MANIFEST",
        "Rate",
        "execute_task",
        "is_complete",
        "iter_batch",
        "local_cluster",
        "mission_sweep_tasks",
        "parse_seeds",
        "run_batch",
        "settings_hash",
        "summarize",
        "wilson_interval",
    ],
    "experiments": ["obstacles"],
    "geometry": [
        "EULER_ORDER_PAPER",
        "R_BODY_FROM_OPTICAL",
        "T_BODY_FROM_OPTICAL",
        "se2_apply",
        "se2_compose",
        "se2_from_xytheta",
        "se2_inverse",
        "se2_to_xytheta",
        "se3_apply",
        "se3_compose",
        "se3_from_rt",
        "se3_from_xyz_quat",
        "se3_inverse",
        "se3_to_rt",
        "se3_to_xyz_quat",
        "wrap_angle",
    ],
    "io": [
        "OccupancyGrid",
        "PointCloud",
        "Trajectory",
        "read_depth",
        "read_image",
        "read_occupancy_grid",
        "read_pointcloud",
        "read_trajectory",
    ],
    "localization": [
        "Fix",
        "KnownHeadingFix",
        "KnownHeadingSettings",
        "LocalizationFailure",
        "Localizer",
        "LocalizerSettings",
        "WallMapSettings",
        "MatcherSettings",
        "ScanMatch",
        "WallMap",
        "build_map",
        "build_map_from_scans",
        "evaluate_fixes",
        "locate_known_heading",
        "match_scan",
    ],
    "mission": [
        "BlockSettings",
        "CameraSettings",
        "Fix2D",
        "FusionSettings",
        "LidarSettings",
        "Mission",
        "MissionLog",
        "MissionSettings",
        "MissionMapSettings",
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
    ],
    "obstacles": [
        "MapUpdate",
        "MappedObstacle",
        "ObstacleMapperSettings",
        "Mounting",
        "Obstacle",
        "ObstacleDetection",
        "ObstacleGrid",
        "ObstacleMapper",
        "ObstacleSettings",
        "ScanGrid",
        "detect_obstacles",
        "detect_obstacles_grid",
        "detect_obstacles_in_grid",
    ],
    "path": [
        "ApproximationResult",
        "ApproximatorSettings",
        "OnlineApproximator",
        "PathSpline",
        "PathUpdate",
        "Return",
        "ReturnFailure",
        "ReturnStep",
        "ReturnTripSettings",
        "Skipped",
        "WayAhead",
        "WayBlocked",
        "approximate",
    ],
    "planes": [
        "CloudExtractionSettings",
        "ExtractionResult",
        "ExtractionSettings",
        "FrameMotion",
        "MapPlane",
        "MotionEstimate",
        "MotionFailure",
        "MotionPrior",
        "MotionSettings",
        "OdometrySettings",
        "PlaneMap",
        "PlaneObservation",
        "PlaneOdometry",
        "PlaneSegment",
        "estimate_motion",
        "extract_planes_cloud",
        "extract_planes_organized",
        "observe_points",
        "observe_rgbd",
    ],
    "runtime": [
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
    ],
    "sensors": [
        "PinholeCamera",
        "RGBDFrame",
        "RangeScan",
        "StereoPair",
        "StereoRig",
        "VisualOdometryNoise",
        "grid_directions",
    ],
    "sim": [
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
    ],
    "stereo": [
        "DisparityResult",
        "DisparitySettings",
        "FloorplanSettings",
        "compute_disparity",
        "disparity_to_points",
        "stereo_wall_points",
    ],
}

# Module-level helpers of an ``__init__`` that are not exports.
NOT_EXPORTS = {"TYPE_CHECKING", "Any", "annotations", "importlib", "np"}


def _packages_with_all() -> list[str]:
    """Every subpackage of navkit whose ``__init__.py`` declares ``__all__``."""
    found = []
    for init in sorted(SRC.glob("*/__init__.py")):
        tree = ast.parse(init.read_text())
        if any(
            isinstance(node, ast.Assign)
            and any(getattr(t, "id", None) == "__all__" for t in node.targets)
            for node in tree.body
        ):
            found.append(init.parent.name)
    return found


def _resolve(package: str, name: str) -> object:
    """``navkit.<package>.<name>``: an attribute, or a submodule listed in ``__all__`` (which
    ``from navkit.<package> import *`` imports)."""
    module = importlib.import_module(f"navkit.{package}")
    if hasattr(module, name):
        return getattr(module, name)
    return importlib.import_module(f"navkit.{package}.{name}")


def test_every_package_surface_is_pinned():
    assert _packages_with_all() == sorted(SURFACES)


@pytest.mark.parametrize("package", sorted(SURFACES))
def test_surface_is_pinned(package):
    module = importlib.import_module(f"navkit.{package}")
    assert len(set(module.__all__)) == len(module.__all__), "duplicates in __all__"
    assert sorted(module.__all__) == sorted(SURFACES[package])


@pytest.mark.parametrize("package", sorted(SURFACES))
def test_every_export_resolves(package):
    module = importlib.import_module(f"navkit.{package}")
    for name in module.__all__:
        assert _resolve(package, name) is not None, f"navkit.{package}.{name}"


@pytest.mark.parametrize("package", sorted(SURFACES))
def test_no_public_name_outside_all(package):
    """Names the package binds (other than its submodules) are its exports: no lingering
    package-level imports that bypass ``__all__``."""
    module = importlib.import_module(f"navkit.{package}")
    public = {
        name
        for name, value in vars(module).items()
        if not name.startswith("_") and not inspect.ismodule(value)
    }
    assert public - NOT_EXPORTS <= set(module.__all__)


@pytest.mark.parametrize("package", sorted(SURFACES))
def test_no_reexport_of_another_package(package):
    """Every export is defined inside the package: its ``__init__`` imports navkit names only
    from its own modules, and each exported class or function says so in ``__module__``."""
    tree = ast.parse((SRC / package / "__init__.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("navkit"):
            assert node.level == 0
            assert node.module.startswith(f"navkit.{package}."), (
                f"navkit.{package} imports {[a.name for a in node.names]} from {node.module}"
            )
    module = importlib.import_module(f"navkit.{package}")
    for name in module.__all__:
        value = _resolve(package, name)
        if inspect.ismodule(value):
            assert value.__name__ == f"navkit.{package}.{name}"
        elif inspect.isclass(value) or inspect.isfunction(value):
            assert value.__module__.startswith(f"navkit.{package}."), (
                f"navkit.{package}.{name} is defined in {value.__module__}"
            )
