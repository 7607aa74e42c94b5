"""Where am I: correlative scan matching over ``(x, y, theta)`` against a wall map.

Paper 3 slides the observed wall fragment along the map with a *known* heading
(:mod:`navkit.localization.correlation`). When the heading is unknown the same correlation is
searched over rotations too; done naively that costs ``n_x n_y n_theta N`` look-ups. Olson's
real-time correlative scan matching (Olson, ICRA 2009) makes it fast and exact:

1. the map as a likelihood field (:class:`~navkit.localization.field.LikelihoodField`);
2. for each rotation of the search window, the scan's points rotated once and rounded to cells
   (rotation step such that the farthest point moves at most one cell);
3. a max-pooled resolution pyramid: a node covering ``2^h x 2^h`` translations gets an upper
   bound of their scores with one look-up per point;
4. branch-and-bound: nodes are expanded depth-first in batches sorted by bound (each batch's
   scores one vectorised gather over all its candidates, ``uint8`` look-up tables), pruned when
   their bound cannot beat the best exact score found. The bound to beat starts optimistic
   (Cartographer's "good initial score bound"): a first pass assumes a leaf within 3 % of the
   top bound; it stays exact (see ``_Search.run``). On the global search the upper levels'
   nodes also cover blocks of rotations, bounded by the window dilated by the rotation's sweep
   (``_Search._group_tables``);
5. sub-cell refinement of the winner on the bicubic field (quadratic fits, see ``_refine``);
6. an ambiguity report: the shape of the score around the peak (a straight featureless wall is
   flat along itself: its direction and extent are reported) and the best *distinct* second
   peak (the same pass prunes at ``second_peak_ratio`` times the best and keeps every leaf
   above it; the runner-up is the best of those outside the winner's neighbourhood).

Speed: everything that depends on the map only is computed once and cached on the field
object - the global search's coarse field and the ``uint8`` pyramid of its region, and for
windows around a prior (tracking, the global fine stage, the peak analysis) one zero-padded
``uint8`` pyramid of the whole map (:meth:`LikelihoodField.padded_pyramid_u8`). The scan is
thinned to one point per coarse cell for the coarse stage; the fine angular step is used only
in the +-2-step fine stage; the peak analysis is a branch-and-bound too (all translations
within ``peak_tolerance`` of the best, not the whole window scored).

The inner loops - the search tables, the expansion and scoring of nodes, the depth-first
search, the sub-cell scores - are compiled (Numba, :mod:`navkit.localization._kernels`,
``docs/kernels.md``); under ``navkit.jit.use("numpy")`` their NumPy twins run, the test oracles
(identical fixes).

The score of a pose is the mean field value at the scan's points, in ``[0, 1]``.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError
from navkit.geometry import wrap_angle
from navkit.geometry._validate import as_points, as_vectors, check_coordinates
from navkit.jit import kernels_enabled
from navkit.localization.field import LikelihoodField
from navkit.localization.matcher_settings import _DEFAULT_SETTINGS, MatcherSettings
from navkit.localization.peaks import analyse_peak
from navkit.localization.search import (
    _GLOBAL_TOP_BLOCKS,
    _ROT_GROUPS,
    _argbest,
    _p95,
    _rotate,
    _Search,
)

__all__ = ["Ambiguity", "MatcherSettings", "ScanMatch", "analyse_peak", "match_scan", "score_poses"]

log = logging.getLogger(__name__)


#: A search angle (window, step), degrees.


@dataclass(frozen=True)
class Ambiguity:
    """How well a fix is determined.

    Attributes
    ----------
    ambiguous : bool
        True when the peak is elongated beyond ``ambiguity_extent`` or a distinct second peak
        scores at least ``second_peak_ratio`` of the best.
    reason : str
        ``""``, ``"elongated peak"`` (e.g. a single straight wall), ``"second peak"`` or both.
    direction : (2,) array
        World unit vector of the peak's major axis (along the wall for a straight wall).
    extent : float
        Metres; length of the near-optimal set along ``direction`` (``>= 2 * window`` means
        "at least": the peak runs out of the examined window).
    extent_minor : float
        Metres; its width across.
    covariance : (2, 2) array
        m^2; score-weighted covariance of the near-optimal translations.
    second_score : float
        Score of the best distinct second peak (NaN if none reached ``second_peak_ratio`` of
        the best). After a global search it is the coarse-field score scaled by the ratio of
        the fine to the coarse best score (so it compares with ``ScanMatch.score``).
    second_pose : (3,) array
        Its ``(x, y, theta)``, NaN if none.
    """

    ambiguous: bool
    reason: str
    direction: NDArray[np.float64]
    extent: float
    extent_minor: float
    covariance: NDArray[np.float64]
    second_score: float = float("nan")
    second_pose: NDArray[np.float64] = field(default_factory=lambda: np.full(3, np.nan))


@dataclass(frozen=True)
class ScanMatch:
    """A localization result.

    Attributes
    ----------
    pose : (3,) array
        ``(x, y, theta)`` of the scan's frame in the map, metres and radians.
    score : float
        Mean likelihood-field value at the scan points, ``[0, 1]``.
    ok : bool
        ``score >= min_score`` and not ambiguous.
    ambiguity : Ambiguity
    exact : bool
        False if the candidate cap cut the branch-and-bound (the optimum is then likely, not
        guaranteed).
    n_points : int
        Scan points used (after thinning).
    n_evaluated : int
        Bound / score evaluations (pyramid nodes) spent.
    seconds : float
        Wall time of the fix.
    """

    pose: NDArray[np.float64]
    score: float
    ok: bool
    ambiguity: Ambiguity
    exact: bool
    n_points: int
    n_evaluated: int
    seconds: float


# --------------------------------------------------------------------------- helpers
def _thin(points: NDArray[np.float64], spacing: float) -> NDArray[np.float64]:
    """One point (the first) per ``spacing``-sized cell."""
    keys = np.floor(points / spacing).astype(np.int64)
    if len(keys) == 0:
        return points
    # one integer per cell (row-major over the cells' bounding box; the same cells as unique
    # rows, several times faster)
    lo = keys.min(axis=0)
    span = int(keys[:, 1].max() - lo[1]) + 1
    if float(keys[:, 0].max() - lo[0] + 1) * span < 2.0**62:
        _, first = np.unique((keys[:, 0] - lo[0]) * span + (keys[:, 1] - lo[1]), return_index=True)
    else:
        _, first = np.unique(keys, axis=0, return_index=True)
    return points[np.sort(first)]


_MAX_HEADINGS = 100_000


def _heading_count(span: float, step: float, reach: float) -> int:
    """``ceil(span / step)``, or :class:`InputError` when the step underflows (a huge reach)."""
    n = span / step if step > 0 else np.inf
    if not n <= _MAX_HEADINGS:
        raise InputError(
            f"reach {reach:.3g} m (95th percentile of the ranges) needs {n:.3g} headings",
            field="points",
            expected=f"ranges that need at most {_MAX_HEADINGS} headings at the field's "
            "resolution (or set MatcherSettings.angular_step_deg)",
        )
    return int(np.ceil(n))


def score_poses(fld: LikelihoodField, points: ArrayLike, poses: ArrayLike) -> NDArray[np.float64]:
    """Scores ``(M,)`` (mean nearest-cell field value) of scan points ``(N, 2)`` at poses ``(M, 3)``."""
    P = as_points(points, 2)
    X = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    W = _rotate(X[:, 2], P) + X[:, None, :2]
    return fld.lookup(W).mean(axis=1).astype(np.float64)


def _fine_scores(
    fld: LikelihoodField, pts: NDArray[np.float64], poses: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Mean sub-cell (bicubic, :meth:`LikelihoodField.interpolate_cubic`) field values of the
    scan at poses ``(M, 3)``.

    Compiled (:func:`navkit.jit.kernels_enabled`): :func:`navkit.localization._kernels.cubic_pose_scores`,
    one loop over poses and points. The NumPy version below is its oracle: the same operations
    in the same order (the stencil summed row by row, the points in order - ``cumsum``, not
    NumPy's pairwise sum), so the scores are identical.
    """
    V = fld.cubic_grid()
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    if kernels_enabled():
        from navkit.localization import _kernels

        return _kernels.cubic_pose_scores(  # type: ignore[no-any-return]
            V, float(fld.origin[0]), float(fld.origin[1]), float(fld.resolution),
            np.ascontiguousarray(pts), np.ascontiguousarray(poses), c, s,
        )  # fmt: skip
    Hp, Wp = V.shape
    x, y = pts[None, :, 0], pts[None, :, 1]
    c, s = c[:, None], s[:, None]
    ux = ((c * x - s * y + poses[:, None, 0]) - fld.origin[0]) / fld.resolution + 1.5
    uy = ((s * x + c * y + poses[:, None, 1]) - fld.origin[1]) / fld.resolution + 1.5
    fx, fy = np.floor(ux), np.floor(uy)
    inside = (fx >= 1) & (fx <= Wp - 3) & (fy >= 1) & (fy <= Hp - 3)
    wx, wy = _catmull_rom_rows(ux - fx), _catmull_rom_rows(uy - fy)
    x0 = np.clip(fx, 1, Wp - 3).astype(np.intp)
    y0 = np.clip(fy, 1, Hp - 3).astype(np.intp)
    flat = V.ravel()
    v = np.zeros(ux.shape)
    for a in range(4):
        at = (y0 - 1 + a) * Wp + x0
        row = wx[0] * flat[at - 1] + wx[1] * flat[at]
        row = row + wx[2] * flat[at + 1]
        row = row + wx[3] * flat[at + 2]
        v = wy[0] * row if a == 0 else v + wy[a] * row
    v = np.where(inside, v, 0.0)
    return np.asarray(np.cumsum(v, axis=1)[:, -1] / pts.shape[0], dtype=np.float64)


def _catmull_rom_rows(t: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    """The four Catmull-Rom weights of offsets ``t`` (as ``field._catmull_rom``), one array each."""
    t2 = t * t
    t3 = t2 * t
    return [
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
    ]


def _bilinear_scores(
    fld: LikelihoodField, pts: NDArray[np.float64], poses: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Mean bilinear field values (:meth:`LikelihoodField.interpolate`) of the scan at poses
    ``(M, 3)``; compiled: :func:`navkit.localization._kernels.bilinear_pose_scores`, the NumPy
    version below its oracle (the same operations in the same order: identical scores)."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    if kernels_enabled():
        from navkit.localization import _kernels

        return _kernels.bilinear_pose_scores(  # type: ignore[no-any-return]
            fld.values, float(fld.origin[0]), float(fld.origin[1]), float(fld.resolution),
            np.ascontiguousarray(pts), np.ascontiguousarray(poses), c, s,
        )  # fmt: skip
    from navkit.localization.field import _gather

    x, y = pts[None, :, 0], pts[None, :, 1]
    c, s = c[:, None], s[:, None]
    ux = ((c * x - s * y + poses[:, None, 0]) - fld.origin[0]) / fld.resolution - 0.5
    uy = ((s * x + c * y + poses[:, None, 1]) - fld.origin[1]) / fld.resolution - 0.5
    x0, y0 = np.floor(ux).astype(np.intp), np.floor(uy).astype(np.intp)
    fx, fy = ux - x0, uy - y0
    v00 = _gather(fld.values, x0, y0)
    v10 = _gather(fld.values, x0 + 1, y0)
    v01 = _gather(fld.values, x0, y0 + 1)
    v11 = _gather(fld.values, x0 + 1, y0 + 1)
    v = v00 * (1 - fx) * (1 - fy) + v10 * fx * (1 - fy) + v01 * (1 - fx) * fy + v11 * fx * fy
    return np.asarray(np.cumsum(v, axis=1)[:, -1] / pts.shape[0], dtype=np.float64)


_STENCIL = np.stack(
    np.meshgrid([-1.0, 0.0, 1.0], [-1.0, 0.0, 1.0], [-1.0, 0.0, 1.0], indexing="ij"), -1
).reshape(-1, 3)
# least squares of the quadratic model on the stencil, columns 1, u, v, w, u^2, v^2, w^2, uv,
# uw, vw: its pseudo-inverse, once (instead of an SVD per round)
_STENCIL_FIT = np.linalg.pinv(
    np.column_stack(
        [
            np.ones(len(_STENCIL)),
            _STENCIL,
            _STENCIL**2,
            _STENCIL[:, 0] * _STENCIL[:, 1],
            _STENCIL[:, 0] * _STENCIL[:, 2],
            _STENCIL[:, 1] * _STENCIL[:, 2],
        ]
    )
)


# _refine's start: offsets -2..2 cells in x and y, -1..1 step in theta (theta varying fastest,
# then y, then x); scaled per call (the same products as arange(-2, 3) * dxy, exactly)
_START_GRID = np.stack(
    np.meshgrid(np.arange(-2.0, 3.0), np.arange(-2.0, 3.0), np.arange(-1.0, 2.0), indexing="ij"),
    -1,
).reshape(-1, 3)


def _refine(
    fld: LikelihoodField, pts: NDArray[np.float64], x0: NDArray[np.float64], dxy: float, dth: float
) -> NDArray[np.float64]:
    """Sub-cell maximum of the smooth score near ``x0`` (within one cell / one rotation step).

    The score here is the bicubic (Catmull-Rom) field (:meth:`LikelihoodField.
    interpolate_cubic`): smooth across cells, where a piecewise-bilinear field would pin the
    optimum to cell centres (3x larger errors in the tests' simulation), and 16 look-ups per
    point instead of a KD-tree query (the former exact distances: as accurate, see
    ``docs/localization.md``).

    First the best of +-2 cells / +-1 step around the discrete optimum (bilinear: it only
    picks the start), then three rounds: score a 3 x 3 x 3 stencil (half a cell, half a
    step), fit a quadratic in ``(x, y, theta)`` by least squares, jump to its maximum when it
    is one (negative-definite Hessian) and inside the box, otherwise to the best stencil
    point; halve the stencil.
    """
    x = np.asarray(x0, dtype=np.float64).copy()
    # Phase 1: exact scores on the grid around the discrete optimum (+-2 cells, +-1 step): the
    # nearest-cell scores of the search are noisy by up to half a cell per point, so on a
    # shallow peak the discrete winner can sit a cell or two from the true optimum.
    cand = x + _START_GRID * np.array([dxy, dxy, dth])
    # (bilinear here, a quarter of the cubic's look-ups: it only picks the start cell)
    v1 = _bilinear_scores(fld, pts, cand)
    x = cand[int(np.argmax(v1))].copy()
    # Phase 2: quadratic model rounds.
    h = np.array([dxy / 2, dxy / 2, dth / 2])
    lo, hi = x - np.array([dxy, dxy, dth]), x + np.array([dxy, dxy, dth])
    for _ in range(3):
        U = _STENCIL  # offsets in units of h
        v = _fine_scores(fld, pts, x + U * h)
        # quadratic model v = c + g.u + 0.5 u^T A u, least squares (the stencil's fixed
        # pseudo-inverse)
        c = _STENCIL_FIT @ v
        g = c[1:4]
        A = np.array([[2 * c[4], c[7], c[8]], [c[7], 2 * c[5], c[9]], [c[8], c[9], 2 * c[6]]])
        step = None
        if np.all(np.linalg.eigvalsh(A) < 0):
            u = -np.linalg.solve(A, g)
            if np.all(np.abs(u) <= 1.5):
                step = u
        if step is None:
            step = U[int(np.argmax(v))]
        x = np.clip(x + step * h, lo, hi)
        h = h / 2
    return x


def match_scan(
    fld: LikelihoodField,
    points: ArrayLike,
    prior: ArrayLike | None = None,
    settings: MatcherSettings | None = None,
) -> ScanMatch:
    """Locate a scan in the map by multi-resolution correlative matching.

    Parameters
    ----------
    fld : LikelihoodField
        The map (see :meth:`LikelihoodField.from_points`; from a wall map use
        :func:`navkit.localization.raster.sample_segments`).
    points : (N, 2) array
        The scan's points in its own frame (x forward, y left), metres; NaN rows dropped.
    prior : (3,) array, optional
        ``(x, y, theta)`` guess; the search covers ``linear_window`` / ``angular_window_deg``
        around it. None = global search: the whole field, all headings.
    settings : MatcherSettings, optional

    Returns
    -------
    ScanMatch
    """
    t0 = time.perf_counter()
    s = settings or _DEFAULT_SETTINGS
    P = as_points(points, 2)
    check_coordinates(P, field="points")
    P = P[np.all(np.isfinite(P), axis=1)]
    if len(P) < 3:
        raise InputError(
            f"has {len(P)} finite points", field="points", expected="at least 3 scan points"
        )
    if prior is not None:
        prior = as_vectors(prior, 3, "prior", finite=True).reshape(-1)
        if prior.shape != (3,):
            raise InputError(f"has shape {prior.shape}", field="prior", expected="(x, y, theta)")
        check_coordinates(prior, field="prior")
    P = _thin(P, s.point_spacing)
    r = fld.resolution
    reach = max(_p95(np.linalg.norm(P, axis=1)), r)  # P is finite here (rows with NaN dropped)
    step = (
        np.radians(s.angular_step_deg)
        if s.angular_step_deg
        else float(np.arccos(1 - r**2 / (2 * reach**2)))
    )
    levels = len(fld.pyramid)
    if prior is None:
        # Global: exact branch-and-bound on a coarser field, all headings, the whole map.
        factor = max(1, round(s.global_resolution / r))
        coarse = fld.coarsen(factor)
        rc = coarse.resolution
        H, W = coarse.shape
        n_cells = max(H, W)
        centre = coarse.origin + 0.5 * np.array([W, H]) * rc
        base = centre - (n_cells // 2) * rc
        step_c = (
            float(np.arccos(max(1 - rc**2 / (2 * reach**2), -1.0)))  # a scan smaller than a cell
            if not s.angular_step_deg
            else step * factor
        )
        n_th = _heading_count(2 * np.pi, step_c, reach)
        thetas = np.asarray(-np.pi + np.arange(n_th) * (2 * np.pi / n_th), dtype=np.float64)
        step_c = 2 * np.pi / n_th
        Pc = _thin(P, rc) if rc > s.point_spacing else P
        cache = coarse.__dict__.setdefault("_search_regions", [])
        levels_g = max(levels, int(np.ceil(np.log2(max(n_cells, 1) / _GLOBAL_TOP_BLOCKS))) + 1)
        search = _Search(
            coarse, Pc, thetas, base, n_cells, cache=cache, levels=levels_g, rot_groups=_ROT_GROUPS
        )
        # keep = second_peak_ratio: the same pass collects every leaf within that ratio of the
        # optimum, from which the runner-up peak is taken. (A separate runner-up search - the
        # optimum with keep = 1, then the best leaf above the ratio outside the winner's
        # neighbourhood - was tried: 1.2-1.4x slower, the optimum alone costs most of it.)
        best, exact = search.run(levels_g, -1.0, s.max_candidates, keep=s.second_peak_ratio)
        assert best is not None
        coarse_best = best
        x0 = search.pose(best[1], best[2], best[3])
        lin, ang = 2 * rc, 2 * step_c
    else:
        x0 = np.asarray(prior, dtype=np.float64).reshape(3)
        lin, ang = s.linear_window, np.radians(s.angular_window_deg)
        search, coarse_best, exact = None, None, True
    m = int(np.ceil(lin / r))
    n_th = _heading_count(ang, step, reach)
    fine = _Search(fld, P, x0[2] + np.arange(-n_th, n_th + 1) * step, x0[:2] - m * r, 2 * m + 1)
    # A window around a prior (tracking, and the global search's fine stage) is small and its
    # optimum rarely near the top bound, so a shallower breadth stage, a narrower beam, smaller
    # batches and a more optimistic first pass prune sooner (measured on Acapulco: ~12 % less
    # CPU per tracking fix, the same fixes; the coarse global search keeps the class
    # defaults). The search stays exact.
    fine.breadth, fine.beam, fine.batch, fine.optimism = 1024, 16, 512, 0.05
    best, exact_f = fine.run(
        levels, -1.0, s.max_candidates, keep=s.second_peak_ratio if search is None else 1.0
    )
    assert best is not None  # lower = -1 < any score
    exact = exact and exact_f
    score, kb, ixb, iyb = best
    pose = fine.pose(kb, ixb, iyb)
    if s.refine:
        pose = _refine(fld, P, pose, r, step)
    pose[2] = float(wrap_angle(pose[2]))
    evaluated = fine.evaluated
    # Ambiguity: the peak's shape, then a distinct second peak (on the field that was searched
    # globally, or in the tracking window).
    direction, extent, extent_minor, cov, _ = analyse_peak(fld, P, pose, s, angular_step=step)
    sec_search = search if search is not None else fine
    sb = coarse_best if coarse_best is not None else best
    res_s = sec_search.f.resolution
    excl_cells = s.exclusion_radius / res_s
    excl_ang = np.radians(s.exclusion_angle_deg)
    th_best = sec_search.thetas[sb[1]]
    ixb, iyb = sb[2], sb[3]

    # per rotation of the search, once (the same values as per leaf: elementwise)
    near_rot = np.abs(wrap_angle(sec_search.thetas - th_best)) < excl_ang

    def exclude(
        k: NDArray[np.intp], ix: NDArray[np.intp], iy: NDArray[np.intp], size: int = 1
    ) -> NDArray[np.bool_]:
        # A block of size x size translations lies in the neighbourhood when its farthest
        # corner does (the distance is convex); size 1: the leaf itself.
        dx = np.maximum(np.abs(ix - ixb), np.abs(ix + (size - 1) - ixb))
        dy = np.maximum(np.abs(iy - iyb), np.abs(iy + (size - 1) - iyb))
        near_t = np.hypot(dx, dy) < excl_cells
        return near_t & near_rot[k]

    second: tuple[float, int, int, int] | None = None
    exact2 = True
    # The runner-up: the best collected leaf (all leaves scoring > second_peak_ratio * best were
    # kept by the search) outside the winner's neighbourhood.
    ls, lk, lx, ly = (np.concatenate(a) for a in zip(*sec_search.leaves, strict=True))
    cand = (ls > s.second_peak_ratio * sb[0]) & ~exclude(lk, lx, ly)
    if cand.any():  # of equal scores the lowest (k, ix, iy): independent of the search order
        c = np.flatnonzero(cand)
        j = int(c[_argbest(ls[c], lk[c], lx[c], ly[c])])
        second = (float(ls[j]), int(lk[j]), int(lx[j]), int(ly[j]))
    evaluated += search.evaluated if search is not None else 0
    second_score, second_pose = float("nan"), np.full(3, np.nan)
    if second is not None:
        second_score = second[0] * score / max(sb[0], 1e-12) if search is not None else second[0]
        second_pose = sec_search.pose(second[1], second[2], second[3])
        second_pose[2] = float(wrap_angle(second_pose[2]))
    reasons = []
    if extent > s.ambiguity_extent:
        reasons.append("elongated peak")
    if second is not None:
        reasons.append("second peak")
    amb = Ambiguity(
        ambiguous=bool(reasons),
        reason=" and ".join(reasons),
        direction=direction,
        extent=extent,
        extent_minor=extent_minor,
        covariance=cov,
        second_score=second_score,
        second_pose=second_pose,
    )
    final_score = float(_fine_scores(fld, P, pose[None])[0])
    fix = ScanMatch(
        pose=pose,
        score=final_score,
        ok=bool(final_score >= s.min_score and not amb.ambiguous),
        ambiguity=amb,
        exact=bool(exact and exact2),
        n_points=len(P),
        n_evaluated=int(evaluated),
        seconds=time.perf_counter() - t0,
    )
    log.debug(
        "fix %s score %.3f (%d evaluations, %.1f ms)",
        pose,
        final_score,
        fix.n_evaluated,
        1e3 * fix.seconds,
    )
    return fix
