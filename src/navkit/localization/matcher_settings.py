"""The settings of the correlative scan matcher (:mod:`navkit.localization.matcher`) and its
peak analysis (:mod:`navkit.localization.peaks`)."""

from __future__ import annotations

from dataclasses import dataclass

from navkit.domains import NON_NEGATIVE, POSITIVE, POSITIVE_INT, Domain, domain_field
from navkit.geometry._validate import check_settings

__all__ = ["MatcherSettings"]

_DEGREES_POSITIVE = Domain(lo=0.0, lo_open=True, note="degrees")


@dataclass(frozen=True)
class MatcherSettings:
    """Correlative matcher settings.

    Attributes
    ----------
    linear_window : float
        Metres; half-width of the translation search around the prior (ignored without a prior:
        the whole field is searched).
    angular_window_deg : float
        Degrees; half-width of the heading search around the prior (360 without a prior).
    angular_step_deg : float or None
        Heading step; None = Olson's rule, the farthest (95th percentile) point moves one cell.
    point_spacing : float
        Metres; the scan is thinned to one point per cell of this size before matching.
    max_candidates : int
        Budget of node evaluations per branch-and-bound; when it runs out the best leaf so far
        is returned and the fix is flagged ``exact=False``.
    refine : bool
        Sub-cell refinement of the winner on the bicubic field.
    peak_tolerance : float
        Poses whose score is within this fraction of the best belong to the peak (ambiguity).
    ambiguity_extent : float
        Metres; a peak longer than this along its major axis is reported ambiguous.
    ambiguity_window : float
        Metres; half-width of the neighbourhood examined for the peak's shape.
    second_peak_ratio : float
        A distinct second peak scoring at least this fraction of the best is reported ambiguous.
    exclusion_radius : float
        Metres; poses nearer than this to the best (and within ``exclusion_angle_deg``) are the
        same peak, not a second one.
    exclusion_angle_deg : float
        Degrees, see ``exclusion_radius``.
    min_score : float
        A fix scoring below this is reported as failed (``ok=False``).
    global_resolution : float
        Metres; a global search (no prior) runs on the field max-pooled to about this cell size
        (and its rotation step), then a fine search of +-2 coarse cells / steps around the
        winner at full resolution. Exact on the coarse field; the fine stage recovers the full
        resolution (the coarse field over-rates poses by at most one coarse cell of offset).
    """

    linear_window: float = domain_field(1.0, POSITIVE)
    angular_window_deg: float = domain_field(20.0, _DEGREES_POSITIVE)
    angular_step_deg: float | None = domain_field(None, _DEGREES_POSITIVE)
    point_spacing: float = domain_field(0.1, POSITIVE)
    max_candidates: int = domain_field(20_000_000, POSITIVE_INT)
    refine: bool = True
    peak_tolerance: float = domain_field(
        0.05, Domain(lo=0.0, hi=1.0, lo_open=True, hi_open=True, note="a fraction of the best")
    )
    ambiguity_extent: float = domain_field(0.5, NON_NEGATIVE)
    ambiguity_window: float = domain_field(1.5, POSITIVE)
    second_peak_ratio: float = domain_field(0.9, Domain(lo=0.0, hi=1.0, lo_open=True))
    exclusion_radius: float = domain_field(1.0, POSITIVE)
    exclusion_angle_deg: float = domain_field(15.0, Domain(lo=0.0, note="degrees"))
    min_score: float = domain_field(0.3, Domain(lo=0.0, hi=1.0, note="a score, 0 = accept all"))
    global_resolution: float = domain_field(0.2, POSITIVE)

    def __post_init__(self) -> None:
        check_settings(self)


_DEFAULT_SETTINGS = MatcherSettings()  # frozen: built (and checked) once, not per fix
