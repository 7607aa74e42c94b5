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

The package exports the online object, the settings and results and the entry functions
(:func:`build_map`, :func:`match_scan`, :func:`locate_known_heading`, :func:`evaluate_fixes`);
the stage functions are imported from their modules. ``Fix`` is the Localizer's result; the matcher's own result is
:class:`navkit.localization.matcher.ScanMatch`.
"""

from navkit.localization.correlation import (
    KnownHeadingFix,
    KnownHeadingSettings,
    locate_known_heading,
)
from navkit.localization.evaluation import evaluate_fixes
from navkit.localization.localizer import Fix, LocalizationFailure, Localizer, LocalizerSettings
from navkit.localization.mapping import WallMap, WallMapSettings, build_map, build_map_from_scans
from navkit.localization.matcher import MatcherSettings, ScanMatch, match_scan

__all__ = [
    "Fix",
    "KnownHeadingFix",
    "KnownHeadingSettings",
    "LocalizationFailure",
    "Localizer",
    "LocalizerSettings",
    "MatcherSettings",
    "ScanMatch",
    "WallMap",
    "WallMapSettings",
    "build_map",
    "build_map_from_scans",
    "evaluate_fixes",
    "locate_known_heading",
    "match_scan",
]
