"""Wall maps and where-am-I by correlation (paper 3, with the parts the paper leaves implicit).

Stages, usable apart from NumPy arrays:

- :mod:`~navkit.localization.walls` - 2D points -> straight wall segments (split-and-merge for
  ordered scans, RANSAC for clouds), TLS lines with extents and uncertainty;
- :mod:`~navkit.localization.mapping` - views with known poses -> :class:`WallMap` (the same
  wall seen twice merged, corners, room outline, occupancy grid, JSON);
- :mod:`~navkit.localization.correlation` - the paper's method: known heading, the fragment
  slid over the map, the maximum of the correlation, the robot position by the paper's formula,
  with an ambiguity report;
- :mod:`~navkit.localization.refine` - the final weighted point-to-line least-squares pose
  refinement against the map's walls (stereo depth-error weights, degeneracy along one wall);
- :mod:`~navkit.localization.matcher` - unknown heading: multi-resolution correlative scan
  matching over ``(x, y, theta)`` (Olson 2009) with sub-cell refinement and an ambiguity report;
- :mod:`~navkit.localization.localizer` - the online object: :class:`Localizer` keeps the map
  and the estimate and turns one scan at a time into a :class:`Fix` (prior, match, refinement,
  gates, blending with odometry) or a :class:`LocalizationFailure`;
- :mod:`~navkit.localization.evaluation` - a localized sequence scored against reference poses.

``Fix`` is the Localizer's result; the matcher's own result is
:class:`navkit.localization.matcher.ScanMatch`.
"""

from navkit.localization.correlation import (
    KnownHeadingFix,
    KnownHeadingSettings,
    correlate_profiles,
    locate_known_heading,
    robot_position,
)
from navkit.localization.evaluate import evaluate_map
from navkit.localization.evaluation import evaluate_fixes, pose_errors, reported_poses
from navkit.localization.field import LikelihoodField
from navkit.localization.localizer import (
    Fix,
    LocalizationFailure,
    Localizer,
    LocalizerSettings,
    stack_views,
)
from navkit.localization.mapping import (
    Corner,
    MapSettings,
    WallMap,
    build_map,
    build_map_from_scans,
    find_corners,
    find_outline,
    merge_segments,
)
from navkit.localization.matcher import (
    Ambiguity,
    MatcherSettings,
    ScanMatch,
    analyse_peak,
    match_scan,
    score_poses,
)
from navkit.localization.raster import rasterize, sample_segments
from navkit.localization.refine import (
    PoseRefinement,
    RefineSettings,
    refine_pose,
    stereo_range_sigma,
)
from navkit.localization.walls import (
    SegmentationSettings,
    WallSegment,
    merge_two,
    ransac_walls,
    segment_from_points,
    split_and_merge,
)

__all__ = [
    "Ambiguity",
    "Corner",
    "Fix",
    "KnownHeadingFix",
    "KnownHeadingSettings",
    "LikelihoodField",
    "LocalizationFailure",
    "Localizer",
    "LocalizerSettings",
    "MapSettings",
    "MatcherSettings",
    "PoseRefinement",
    "RefineSettings",
    "ScanMatch",
    "SegmentationSettings",
    "WallMap",
    "WallSegment",
    "analyse_peak",
    "build_map",
    "build_map_from_scans",
    "correlate_profiles",
    "evaluate_fixes",
    "evaluate_map",
    "find_corners",
    "find_outline",
    "locate_known_heading",
    "match_scan",
    "merge_segments",
    "merge_two",
    "pose_errors",
    "ransac_walls",
    "rasterize",
    "refine_pose",
    "reported_poses",
    "robot_position",
    "sample_segments",
    "score_poses",
    "segment_from_points",
    "split_and_merge",
    "stack_views",
    "stereo_range_sigma",
]
