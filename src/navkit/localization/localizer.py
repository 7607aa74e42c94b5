"""The online localizer: one scan (or wall fragment) at a time -> a fix, or an explicit failure.

:class:`Localizer` keeps the map (a :class:`~navkit.localization.mapping.WallMap` and its
likelihood field, whose pyramids the matcher caches on first use) and the last estimate, and
reads like the method, one line per stage (:meth:`Localizer.update`):

1. **prior** - the caller's own estimate (``prior=``: a fused estimate, as in the mission), or
   the last estimate moved by the odometry increments since (tracking), or none (global
   search); with a known ``heading`` (paper 3: the camera drive's angle sensor) the fragment
   is slid over the whole map at that heading instead;
2. **match** - multi-resolution correlative matching around the prior or over the whole map
   (:func:`~navkit.localization.matcher.match_scan`), or paper 3's correlation
   (:func:`~navkit.localization.correlation.locate_known_heading`);
3. **refine** (optional) - weighted point-to-line least squares against the map's walls
   (:func:`~navkit.localization.refine.refine_pose`), kept only when it converges and is not
   degenerate along a wall (a degenerate refinement is flagged on the fix);
4. **gates** - the matcher's score, elongated peak (ambiguity along a wall) and distinct second
   peak; with a known heading also the refinement's degeneracy, free space ("occluded") and
   negative information ("unseen wall", with a ``view``);
5. **blend** - an accepted fix within ``gate_m`` of the prediction pulls the estimate by
   ``fix_weight`` (1 = the estimate is the fix).

A confident fix is a :class:`Fix`; anything else is a :class:`LocalizationFailure` naming the
reason and the degrees of freedom left free (the convention of
:class:`navkit.planes.MotionFailure`), with the rejected candidate for reporting - never to be
written as a result.

Decisions (also in ``docs/localization.md``):

- ``odometry_delta=None`` means the motion since the last call is unknown: the search is
  global (unless a ``prior`` or ``heading`` is given). Increments given with scans that could
  not be localized (too few points) are accumulated into the next prediction.
- With ``recentre_on_rejected`` (default, the behaviour of ``navkit map locate`` before the
  Localizer) the next tracking window is centred on the last candidate even when it was
  rejected: the matcher's best pose in the window is right across a wall even when it slides
  along it, and the +-1 m window recovers. Off, a rejected fix leaves the prediction.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.domains import POSITIVE, Domain, domain_field
from navkit.errors import ConfigError, InputError, NavkitError
from navkit.geometry import (
    se2_compose,
    se2_from_xytheta,
    se2_inverse,
    se2_to_xytheta,
    wrap_angle,
)
from navkit.geometry._validate import as_points, check_settings
from navkit.localization._settings import settings_from_dict
from navkit.localization.correlation import (
    KnownHeadingFix,
    KnownHeadingSettings,
    locate_known_heading,
)
from navkit.localization.field import LikelihoodField
from navkit.localization.mapping import WallMap, WallMapSettings, build_map
from navkit.localization.matcher import MatcherSettings, ScanMatch, match_scan
from navkit.localization.raster import sample_segments
from navkit.localization.refine import PoseRefinement, RefineSettings, refine_pose
from navkit.localization.visibility import ViewModel
from navkit.localization.walls import WallSegment
from navkit.results import Failure, Result, deprecated_alias

__all__ = [
    "Fix",
    "LocalizationFailure",
    "Localizer",
    "LocalizerSettings",
    "stack_views",
]

log = logging.getLogger(__name__)

GLOBAL, TRACKING, KNOWN_HEADING = "global", "tracking", "known heading"
"""Values of ``Fix.method`` / ``LocalizationFailure.method``."""

_ALL_DOF = ("x", "y", "theta")


@dataclass(frozen=True)
class LocalizerSettings:
    """Everything the :class:`Localizer` decides with, defaults in one place.

    Attributes
    ----------
    sigma : float
        Metres; width of the likelihood field built from the map (scan noise plus map error).
    resolution : float or None
        Metres; cell of that field. None: the wall map's grid resolution (0.05 m for a map
        given as points).
    matcher : MatcherSettings
        Correlative matching (tracking window, ambiguity and second-peak rules, ``min_score``).
    known_heading : KnownHeadingSettings
        Paper 3's correlation with a known heading (its gates: occlusion, unseen walls).
    refine : bool
        Refine each fix by weighted point-to-line least squares against the map's walls (no
        effect without walls). With a known heading the refinement also enables the
        free-space and negative-information gates.
    refinement : RefineSettings
        The refinement's settings.
    range_sigma_coefficient : float
        1/m; a point's error along its ray is ``k r^2`` (stereo: ``disparity_sigma / (b f)``,
        :func:`~navkit.localization.refine.stereo_range_sigma`); 0 = every point weighs the
        same (laser).
    min_points : int
        Scans with fewer finite points are not matched (failure ``"too few points"``).
    fix_weight : float
        In ``(0, 1]``; an accepted fix moves the estimate this fraction of the way from the
        prediction (1: the estimate is the fix).
    gate_m : float or None
        Metres; an accepted fix farther than this from the prediction is not blended in
        (``Fix.used`` False). None: no gate.
    recentre_on_rejected : bool
        Centre the next tracking window on a rejected candidate (see the module docstring).
    """

    sigma: float = domain_field(0.1, POSITIVE)
    resolution: float | None = domain_field(None, POSITIVE)
    matcher: MatcherSettings = field(default_factory=MatcherSettings)
    known_heading: KnownHeadingSettings = field(default_factory=KnownHeadingSettings)
    refine: bool = False
    refinement: RefineSettings = field(default_factory=RefineSettings)
    range_sigma_coefficient: float = domain_field(0.0, Domain(lo=0.0, note="1/m, 0 = laser"))
    min_points: int = domain_field(3, Domain(integer=True, lo=3, note="a 2D pose needs 3"))
    fix_weight: float = domain_field(1.0, Domain(lo=0.0, hi=1.0, lo_open=True))
    gate_m: float | None = domain_field(None, POSITIVE)
    recentre_on_rejected: bool = True

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "settings") -> LocalizerSettings:
        """Build from a mapping (e.g. the ``[localizer]`` table of a ``settings.toml``), nested
        tables for ``matcher``, ``known_heading`` (with ``refine``) and ``refinement``; unknown
        keys are rejected."""
        return settings_from_dict(cls, data, source, "localizer")

    def __post_init__(self) -> None:
        check_settings(self)
        for name, cls in (
            ("matcher", MatcherSettings),
            ("known_heading", KnownHeadingSettings),
            ("refinement", RefineSettings),
        ):
            if not isinstance(getattr(self, name), cls):
                raise ConfigError(
                    f"is a {type(getattr(self, name)).__name__}",
                    field=name,
                    expected=f"a {cls.__name__}",
                )


@dataclass(frozen=True)
class Fix(Result):
    """A confident localization.

    Attributes
    ----------
    pose : (3,) array
        ``(x, y, theta)`` of the scan's frame in the map (refined when the refinement was kept),
        metres and radians.
    estimate : (3,) array
        The Localizer's estimate after this fix (the prediction blended with ``pose``; equal to
        ``pose`` with ``fix_weight = 1`` or without a prediction).
    prediction : (3,) array
        The prior: the caller's estimate or the odometry prediction (NaN when there is none: a
        global search). Tracking searches around it; a known-heading fix (searched over the
        whole map) is only gated and blended with it.
    method : str
        ``"global"``, ``"tracking"`` or ``"known heading"``.
    score : float
        Match score in ``[0, 1]`` (mean likelihood-field value, or the correlation peak).
    covariance : (3, 3) array or None
        m^2 / rad^2; from the point-to-line refinement when it ran (heading row and column zero
        with a known heading; infinite entries when degenerate), None without refinement.
    used : bool
        Blended into the estimate (within ``gate_m`` of the prediction).
    degenerate : bool
        The refinement found the translation undetermined along ``weak_direction`` (one straight
        wall); the match's pose was kept.
    direction : (2,) array
        World unit vector of the match peak's major axis.
    extent : float
        Metres; length of the match's near-optimal set along the peak's major axis.
    second_score : float
        Score of the best distinct second peak (NaN if none).
    exact : bool
        The search was exhaustive (False: the candidate budget cut it).
    refinement : PoseRefinement or None
    seconds : float
        Wall time of :meth:`Localizer.update`.
    match : ScanMatch or KnownHeadingFix
        The matcher's own result (:class:`navkit.localization.matcher.ScanMatch` or
        :class:`~navkit.localization.correlation.KnownHeadingFix`: the ambiguity report, the
        correlation surface, the correlation-only position ...).
    """

    pose: NDArray[np.float64]
    estimate: NDArray[np.float64]
    prediction: NDArray[np.float64]
    method: str
    score: float
    covariance: NDArray[np.float64] | None
    used: bool
    degenerate: bool
    direction: NDArray[np.float64]
    extent: float
    second_score: float
    exact: bool
    refinement: PoseRefinement | None
    seconds: float
    match: ScanMatch | KnownHeadingFix

    ambiguous: ClassVar[bool] = False
    reason: ClassVar[str] = ""
    free_dof: ClassVar[tuple[str, ...]] = ()

    @property
    def refined(self) -> bool:
        """The refinement converged, was not degenerate, and gave ``pose``."""
        rf = self.refinement
        return bool(rf is not None and rf.converged and not rf.degenerate)

    @property
    def weak_direction(self) -> NDArray[np.float64]:
        """World unit vector of the least determined direction: the refinement's weakest one
        when it is degenerate, else the match peak's major axis."""
        rf = self.refinement
        return rf.weak_direction if rf is not None and rf.degenerate else self.direction


@dataclass(frozen=True)
class LocalizationFailure(Failure):
    """No fix: the scan leaves degrees of freedom free, or contradicts the map.

    Attributes
    ----------
    reason : str
        ``"too few points"``, ``"low score"``, or the gates that refused the candidate joined by
        ``" and "``: ``"elongated peak"`` (the scan slides along a wall), ``"second peak"`` (it
        fits in two places), ``"degenerate"`` (the refinement finds one wall direction only),
        ``"occluded"`` (it would have been seen through a map wall), ``"unseen wall"`` (the map
        predicts a wall in view the scan lacks).
    free_dof : tuple of str
        The degrees of freedom not determined: ``"x"``, ``"y"``, ``"theta"``, or ``"along"`` for
        the translation along ``direction`` (a straight wall). ``"too few points"``, ``"low
        score"``, ``"second peak"``, ``"occluded"`` and ``"unseen wall"`` leave ``x, y`` (and
        ``theta`` unless the heading was known) free.
    method : str
        ``"global"``, ``"tracking"`` or ``"known heading"``.
    estimate : (3,) array
        The Localizer's estimate after this scan (the prediction, or the rejected candidate with
        ``recentre_on_rejected``; NaN when there is none).
    prediction : (3,) array
        The prior, as in :class:`Fix` (NaN when there is none).
    candidate : (3,) array
        The rejected best pose, for reporting only (NaN with too few points).
    score, extent, second_score : float
        As in :class:`Fix` (NaN with too few points).
    direction : (2,) array
        World unit vector of the peak's major axis or the refinement's weak direction.
    ambiguous : bool
        A gate other than the score refused it.
    exact : bool
    refinement : PoseRefinement or None
    seconds : float
    match : ScanMatch, KnownHeadingFix or None
        The matcher's own result (None with too few points).
    """

    reason: str
    free_dof: tuple[str, ...]
    method: str
    estimate: NDArray[np.float64]
    prediction: NDArray[np.float64]
    candidate: NDArray[np.float64] = field(default_factory=lambda: np.full(3, np.nan))
    score: float = float("nan")
    direction: NDArray[np.float64] = field(default_factory=lambda: np.full(2, np.nan))
    extent: float = float("nan")
    second_score: float = float("nan")
    ambiguous: bool = False
    exact: bool = True
    refinement: PoseRefinement | None = None
    seconds: float = 0.0
    match: ScanMatch | KnownHeadingFix | None = None

    used: ClassVar[bool] = False

    @property
    def refined(self) -> bool:
        rf = self.refinement
        return bool(rf is not None and rf.converged and not rf.degenerate)


@dataclass(frozen=True)
class _Match:
    """One matcher's answer in a common form (internal)."""

    pose: NDArray[np.float64]
    score: float
    ok: bool
    reason: str
    direction: NDArray[np.float64]
    extent: float
    second_score: float
    exact: bool
    refinement: PoseRefinement | None
    raw: ScanMatch | KnownHeadingFix


def _free_dof(reason: str, heading_known: bool) -> tuple[str, ...]:
    """Degrees of freedom a refusal leaves free (see :class:`LocalizationFailure`)."""
    xy = ("x", "y") if heading_known else _ALL_DOF
    if reason in ("too few points", "low score", ""):
        return xy
    parts = reason.split(" and ")
    if any(p in ("second peak", "occluded", "unseen wall") for p in parts):
        return xy
    return ("along",)  # elongated peak / degenerate: the translation along the wall


def stack_views(
    views: Sequence[ArrayLike], poses: ArrayLike, pose: ArrayLike | None = None
) -> NDArray[np.float64]:
    """One fragment from several views: each view's body-frame points ``(N_i, 2)``, taken at
    ``poses[i] = (x, y, theta)``, moved into the body frame at ``pose`` (default: the first
    view's) - e.g. a camera turned on its drive at one place (relative headings from its angle
    sensor, paper 3), or the last few views along the way with the odometry's relative motion.

    Returns
    -------
    (sum N_i, 2) array
    """
    P = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if len(P) != len(views):
        raise InputError(
            f"has {len(P)} poses for {len(views)} views",
            field="poses",
            expected="one (x, y, theta) per view",
        )
    if len(views) == 0:
        return np.zeros((0, 2))
    ref = se2_inverse(se2_from_xytheta(*(P[0] if pose is None else np.asarray(pose, float))))
    parts = []
    for v, p in zip(views, P, strict=True):
        B = as_points(v, 2, "views")
        rel = se2_compose(ref, se2_from_xytheta(*p))
        parts.append(B @ rel[:2, :2].T + rel[:2, 2] if len(B) else B)
    return np.concatenate(parts)


class Localizer:
    """Localize scans in a 2D map, one at a time (see the module docstring).

    Parameters
    ----------
    wall_map : WallMap, optional
        The map (its walls serve the refinement and the gates, its outline restricts a
        known-heading search); its likelihood field is built from it unless ``field`` is given.
    settings : LocalizerSettings, optional
    field : LikelihoodField, optional
        A ready field (e.g. of an obstacle map's occupied cells, see :meth:`from_points`).
    view : ViewModel, optional
        The sensor's view of one scan, for the negative-information gate of known-heading fixes.
    """

    def __init__(
        self,
        wall_map: WallMap | None = None,
        settings: LocalizerSettings | None = None,
        *,
        field: LikelihoodField | None = None,
        view: ViewModel | None = None,
    ) -> None:
        self.settings = settings or LocalizerSettings()
        if wall_map is None and field is None:
            raise InputError("no map", field="wall_map", expected="a WallMap or a LikelihoodField")
        self.map = wall_map
        s = self.settings
        if field is None:
            assert wall_map is not None
            field = wall_map.likelihood_field(s.sigma, s.resolution)
        self.field = field
        self.view = view
        self._pose: NDArray[np.float64] | None = None  # the last estimate
        self._motion: NDArray[np.float64] | None = np.eye(3)  # odometry since then (None: unknown)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_points(cls, points: ArrayLike, settings: LocalizerSettings | None = None) -> Localizer:
        """A Localizer on a map given as occupied points ``(N, 2)`` (no walls: no refinement)."""
        s = settings or LocalizerSettings()
        fld = LikelihoodField.from_points(points, s.resolution or 0.05, s.sigma)
        return cls(None, s, field=fld)

    @classmethod
    def from_views(
        cls,
        views: Sequence[ArrayLike],
        poses: ArrayLike,
        settings: LocalizerSettings | None = None,
        map_settings: WallMapSettings | None = None,
        *,
        ordered: bool = False,
        min_walls: int = 2,
    ) -> Localizer:
        """Map a place from views (body-frame wall points ``(N_i, 2)`` at ``poses (V, 3)``) and
        localize in it.

        The wall map (:func:`~navkit.localization.mapping.build_map`) when it finds at least
        ``min_walls`` walls: the field is built from its walls sampled every 5 cm; otherwise
        (or when mapping fails) from the views' points themselves (``Localizer.map`` is then
        the failed or poor map, or None).
        """
        s = settings or LocalizerSettings()
        P = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        if len(views) == 0 or len(P) != len(views):
            raise InputError(
                f"{len(views)} views and {len(P)} poses",
                field="views",
                expected="at least one view, one (x, y, theta) pose per view",
            )
        wm: WallMap | None
        try:
            wm = build_map(list(views), P, map_settings, ordered=ordered)
        except NavkitError as exc:
            log.warning("map from %d views failed: %s", len(views), exc)
            wm = None
        if wm is not None and len(wm.walls) >= min_walls:
            pts = sample_segments(wm.walls, 0.05)
        else:
            pts = np.vstack(
                [stack_views([v], [p], np.zeros(3)) for v, p in zip(views, P, strict=True)]
            )
        fld = LikelihoodField.from_points(pts, s.resolution or 0.05, s.sigma)
        return cls(wm, s, field=fld)

    # ------------------------------------------------------------------ state
    @property
    def pose(self) -> NDArray[np.float64] | None:
        """The current estimate ``(x, y, theta)`` (None before the first fix)."""
        return None if self._pose is None else self._pose.copy()

    def reset(self, pose: ArrayLike | None = None) -> None:
        """Forget the estimate (or set it to ``pose``); the map and its caches stay."""
        self._pose = None if pose is None else np.asarray(pose, dtype=np.float64).reshape(3)
        self._motion = np.eye(3)

    # ------------------------------------------------------------------ one scan
    def update(
        self,
        points: ArrayLike,
        *,
        odometry_delta: ArrayLike | None = None,
        heading: float | None = None,
        prior: ArrayLike | None = None,
    ) -> Fix | LocalizationFailure:
        """Localize one scan (stages 1-5 of the module docstring).

        Parameters
        ----------
        points : (N, 2) array
            The scan's (or fragment's) points in its own frame, x forward, y left, metres; NaN
            rows are dropped.
        odometry_delta : (3,) array, optional
            Body-frame increment ``(dx, dy, dtheta)`` since the previous call (None: unknown).
        heading : float, optional
            Known heading (radians): paper 3's correlation at that heading over the whole map.
        prior : (3,) array, optional
            The caller's own estimate of the pose; replaces the odometry prediction.

        Returns
        -------
        Fix or LocalizationFailure
            The fix, or why there is none and which degrees of freedom the scan leaves free.
        """
        t0 = time.perf_counter()
        s = self.settings
        # 1. the prior
        self._accumulate(odometry_delta)
        prediction = self._predict(prior)
        method = (
            KNOWN_HEADING if heading is not None else GLOBAL if prediction is None else TRACKING
        )
        P = as_points(points, 2)
        P = P[np.all(np.isfinite(P), axis=1)]
        if len(P) < s.min_points:
            # the motion is kept for the next scan; the estimate stays
            return self._fail("too few points", method, prediction, None, t0, heading)
        # 2.-4. match, refine, gates
        if heading is not None:
            m = self._known_heading(P, float(heading))
        else:
            m = self._correlative(P, prediction)
        if not m.ok:
            return self._fail(m.reason or "low score", method, prediction, m, t0, heading)
        # 5. blend with the prediction
        used = (
            prediction is None
            or s.gate_m is None
            or bool(float(np.hypot(*(m.pose[:2] - prediction[:2]))) <= s.gate_m)
        )
        if prediction is None:
            estimate = m.pose.copy()
        elif used:
            estimate = _blend(prediction, m.pose, s.fix_weight)
        else:
            estimate = prediction.copy()
        self._set(estimate)
        rf = m.refinement
        return Fix(
            pose=m.pose,
            estimate=estimate,
            prediction=_nan3() if prediction is None else prediction,
            method=method,
            score=m.score,
            covariance=None if rf is None else rf.covariance,
            used=used,
            degenerate=bool(rf is not None and rf.degenerate),
            direction=m.direction,
            extent=m.extent,
            second_score=m.second_score,
            exact=m.exact,
            refinement=rf,
            seconds=time.perf_counter() - t0,
            match=m.raw,
        )

    def register(
        self,
        points: ArrayLike,
        *,
        odometry_delta: ArrayLike | None = None,
        heading: float | None = None,
        prior: ArrayLike | None = None,
    ) -> Fix | LocalizationFailure:
        """Deprecated alias of :meth:`update` (removed in the next release)."""
        deprecated_alias("Localizer.register", "Localizer.update")
        return self.update(points, odometry_delta=odometry_delta, heading=heading, prior=prior)

    # ------------------------------------------------------------------ stages
    def _accumulate(self, delta: ArrayLike | None) -> None:
        if delta is None:
            self._motion = None
        elif self._motion is not None:
            d = np.asarray(delta, dtype=np.float64).reshape(-1)
            if d.shape != (3,) or not np.all(np.isfinite(d)):
                raise InputError(
                    f"is {d}", field="odometry_delta", expected="a finite (dx, dy, dtheta)"
                )
            self._motion = se2_compose(self._motion, se2_from_xytheta(*d))

    def _predict(self, prior: ArrayLike | None) -> NDArray[np.float64] | None:
        if prior is not None:
            p = np.asarray(prior, dtype=np.float64).reshape(-1)
            if p.shape != (3,) or not np.all(np.isfinite(p)):
                raise InputError(f"is {p}", field="prior", expected="a finite (x, y, theta)")
            return p.copy()
        if self._pose is None or self._motion is None:
            return None
        return se2_to_xytheta(se2_compose(se2_from_xytheta(*self._pose), self._motion))

    def _range_sigma(self, P: NDArray[np.float64]) -> NDArray[np.float64] | None:
        k = self.settings.range_sigma_coefficient
        return None if k == 0 else k * np.einsum("ij,ij->i", P, P)

    def _walls(self) -> list[WallSegment] | None:
        walls = None if self.map is None else self.map.walls
        return walls if self.settings.refine and walls else None

    def _correlative(self, P: NDArray[np.float64], prior: NDArray[np.float64] | None) -> _Match:
        fix = match_scan(self.field, P, prior, self.settings.matcher)
        a = fix.ambiguity
        pose, rf = fix.pose, None
        walls = self._walls()
        if walls:
            rf = refine_pose(
                walls,
                P,
                fix.pose,
                range_sigma=self._range_sigma(P),
                settings=self.settings.refinement,
            )
            if rf.converged and not rf.degenerate:
                pose = rf.pose
        reason = a.reason if a.ambiguous else ("" if fix.ok else "low score")
        return _Match(
            pose,
            fix.score,
            fix.ok,
            reason,
            a.direction,
            a.extent,
            a.second_score,
            fix.exact,
            rf,
            fix,
        )

    def _known_heading(self, P: NDArray[np.float64], heading: float) -> _Match:
        s = self.settings
        walls = self._walls()
        outline = None if self.map is None else self.map.outline
        kf = locate_known_heading(
            self.field,
            P,
            heading,
            walls=walls,
            range_sigma=self._range_sigma(P),
            region=outline if outline is not None and len(outline) >= 3 else None,
            view=self.view if walls else None,
            settings=s.known_heading,
        )
        reason = kf.reason if kf.ambiguous else ("" if kf.ok else "low score")
        return _Match(
            np.array([*kf.position, heading]),
            kf.score,
            kf.ok,
            reason,
            kf.peak_direction,
            kf.peak_extent,
            kf.second_score,
            True,  # the FFT correlation scores every offset
            kf.refinement,
            kf,
        )

    def _fail(
        self,
        reason: str,
        method: str,
        prediction: NDArray[np.float64] | None,
        m: _Match | None,
        t0: float,
        heading: float | None,
    ) -> LocalizationFailure:
        if m is not None:
            if self.settings.recentre_on_rejected:
                self._set(m.pose.copy())
            elif prediction is not None:
                self._set(prediction)
        estimate = self._pose.copy() if self._pose is not None else _nan3()
        log.debug("%s localization failed: %s", method, reason)
        return LocalizationFailure(
            reason=reason,
            free_dof=_free_dof(reason, heading is not None),
            method=method,
            estimate=estimate,
            prediction=_nan3() if prediction is None else prediction,
            candidate=_nan3() if m is None else m.pose,
            score=float("nan") if m is None else m.score,
            direction=np.full(2, np.nan) if m is None else m.direction,
            extent=float("nan") if m is None else m.extent,
            second_score=float("nan") if m is None else m.second_score,
            ambiguous=bool(m is not None and m.reason not in ("", "low score")),
            exact=True if m is None else m.exact,
            refinement=None if m is None else m.refinement,
            seconds=time.perf_counter() - t0,
            match=None if m is None else m.raw,
        )

    def _set(self, pose: NDArray[np.float64]) -> None:
        self._pose = pose
        self._motion = np.eye(3)


def _blend(a: NDArray[np.float64], b: NDArray[np.float64], w: float) -> NDArray[np.float64]:
    """``(1 - w) a + w b`` for poses, the heading difference wrapped (``w = 1``: exactly ``b``)."""
    if w == 1.0:
        return b.copy()
    out = a + w * (b - a)
    out[2] = a[2] + w * float(wrap_angle(b[2] - a[2]))
    return out


def _nan3() -> NDArray[np.float64]:
    return np.full(3, np.nan)
