"""Paper 4: online cubic-spline memory of a trajectory, loop removal, arc length, return home.

Mode 1 (recording): :class:`OnlineApproximator` / :func:`approximate` turn positions arriving one
at a time into a :class:`PathSpline` (cubic segments over arc length) within a tolerance, cutting
loops out as they close. Mode 2 (return): :class:`~navkit.path.control.ReturnController` steers
a robot back along the stored path to its start; :class:`Return` is the online object of the
whole way back (round a blocked stretch on an obstacle map, or a :class:`ReturnFailure`). Both
take one observation per :meth:`update` call and return a typed result or a typed failure
(:mod:`navkit.results`). The stages (loop removal in :mod:`~navkit.path.loops`, the spline fits
in :mod:`~navkit.path.fitting`) are imported from their modules. Everything works on NumPy
arrays; file formats live at the edge (``path.json`` in :mod:`navkit.io.pathjson`, trajectories
in ``navkit.io.trajectory``).
"""

from navkit.path.approximator import (
    ApproximationResult,
    ApproximatorSettings,
    OnlineApproximator,
    PathUpdate,
    Skipped,
    approximate,
)
from navkit.path.returning import (
    Return,
    ReturnFailure,
    ReturnStep,
    ReturnTripSettings,
    WayAhead,
    WayBlocked,
)
from navkit.path.spline import PathSpline

__all__ = [
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
]
