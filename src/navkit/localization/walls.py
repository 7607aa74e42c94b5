"""Straight walls from 2D points: split-and-merge (ordered scans) and sequential RANSAC (clouds).

Paper 3 fits ``y = k x + b`` by least squares to the points of a wall (its eq. for ``k``, ``b``)
and needs "segmentation of the points into several lines first" for real rooms. navkit does both
steps robustly:

1. segmentation - :func:`split_and_merge` for points in scan order (a laser scan, one image row
   of a stereo floor profile), :func:`ransac_walls` for unordered clouds (stereo points of many
   views);
2. a total-least-squares line per segment (:func:`segment_from_points`; TLS instead of
   ``y = k x + b`` so vertical walls work), with its extent (the projections of the extreme
   points) and its uncertainty (standard errors of the direction and of the offset).

Segments keep their sufficient statistics (count, centroid, scatter matrix), so two segments of
the same wall merge into the exact TLS fit of the union of their points (:func:`merge_two`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from itertools import pairwise

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.domains import (
    NON_NEGATIVE,
    NON_NEGATIVE_INT,
    POSITIVE,
    POSITIVE_INT,
    SEED,
    Domain,
    domain_field,
)
from navkit.geometry._validate import as_points, check_settings

__all__ = [
    "SegmentationSettings",
    "WallSegment",
    "merge_two",
    "ransac_walls",
    "segment_from_points",
    "segment_from_stats",
    "split_and_merge",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SegmentationSettings:
    """How points are cut into straight walls.

    Attributes
    ----------
    split_distance : float
        Metres. A run is split where a point lies farther than this from the chord of the run
        (split-and-merge), and RANSAC inliers lie within this of the line.
    gap : float
        Metres. Neighbouring points farther apart than ``gap`` (or ``gap_per_metre`` times their
        range) never belong to the same wall segment (doors, occlusions).
    gap_per_metre : float
        Range-proportional part of the gap threshold (beam spacing grows with range).
    min_points : int
        Fewest points a wall segment needs.
    min_length : float
        Metres; shorter segments are dropped.
    merge_rms : float
        Metres. Adjacent segments whose joint TLS residual RMS is below this are merged.
    ransac_iterations : int
        Line hypotheses per RANSAC round (drawn at once, vectorised).
    max_walls : int
        Upper bound on RANSAC rounds (walls extracted from one cloud).
    seed : int
        Seed of RANSAC's generator (results are reproducible).
    absorb_factor : float
        RANSAC: after a wall is accepted, the points within ``absorb_factor * split_distance``
        of it (inside its extent) are removed with its inliers (its noise tail).
    min_fraction : float
        RANSAC: a wall also needs at least this fraction of the cloud's points (0 = off);
        suppresses ghost walls made of stereo outliers in large clouds (default 3 %).
    """

    split_distance: float = domain_field(0.05, POSITIVE)
    gap: float = domain_field(0.3, POSITIVE)
    gap_per_metre: float = domain_field(0.05, Domain(lo=0.0, note="m/m of range"))
    min_points: int = domain_field(8, Domain(integer=True, lo=2, note="a line needs 2"))
    min_length: float = domain_field(0.3, POSITIVE)
    merge_rms: float = domain_field(0.02, POSITIVE)
    ransac_iterations: int = domain_field(256, POSITIVE_INT)
    max_walls: int = domain_field(64, NON_NEGATIVE_INT)
    seed: int = domain_field(0, SEED)
    absorb_factor: float = domain_field(3.0, NON_NEGATIVE)
    min_fraction: float = domain_field(0.03, Domain(lo=0.0, hi=1.0, note="a fraction"))

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class WallSegment:
    """A straight wall segment fitted by total least squares.

    Attributes
    ----------
    start, end : (2,) arrays
        End points, metres (projections of the extreme supporting points onto the line).
    normal : (2,) array
        Unit normal of the line ``normal . p = rho``.
    rho : float
        Offset of the line, metres (``>= 0``).
    count : int
        Supporting points.
    centroid : (2,) array
        Mean of the supporting points.
    scatter : (2, 2) array
        ``sum (p - centroid)(p - centroid)^T`` of the supporting points, m^2 (for exact merges).
    rms : float
        RMS orthogonal residual, metres.
    sigma_angle : float
        Standard error of the line direction, radians: ``rms / sqrt(sum t_i^2)`` with ``t_i``
        the abscissae of the points along the line (first-order TLS error propagation).
    sigma_offset : float
        Standard error of the line's position at the centroid, metres: ``rms / sqrt(count)``.
    """

    start: NDArray[np.float64]
    end: NDArray[np.float64]
    normal: NDArray[np.float64]
    rho: float
    count: int
    centroid: NDArray[np.float64]
    scatter: NDArray[np.float64]
    rms: float
    sigma_angle: float
    sigma_offset: float

    @property
    def direction(self) -> NDArray[np.float64]:
        """Unit direction ``(2,)`` from ``start`` to ``end``."""
        d = self.end - self.start
        n = np.linalg.norm(d)
        return d / n if n > 0 else np.array([-self.normal[1], self.normal[0]])

    @property
    def length(self) -> float:
        """Length, metres."""
        return float(np.linalg.norm(self.end - self.start))

    @property
    def angle(self) -> float:
        """Direction angle from +x, radians, in ``[-pi/2, pi/2)`` (a wall has no sense)."""
        d = self.direction
        a = float(np.arctan2(d[1], d[0]))
        return (a + np.pi / 2) % np.pi - np.pi / 2

    def distance(self, points: ArrayLike) -> NDArray[np.float64]:
        """Signed distances ``normal . p - rho`` of points ``(N, 2)`` to the infinite line."""
        return as_points(points, 2) @ self.normal - self.rho

    def to_dict(self) -> dict[str, object]:
        """Plain JSON-able description."""
        return {
            "start": self.start.tolist(),
            "end": self.end.tolist(),
            "normal": self.normal.tolist(),
            "rho": self.rho,
            "angle_deg": float(np.degrees(self.angle)),
            "length": self.length,
            "count": self.count,
            "centroid": self.centroid.tolist(),
            "scatter": self.scatter.tolist(),
            "rms": self.rms,
            "sigma_angle_deg": float(np.degrees(self.sigma_angle)),
            "sigma_offset": self.sigma_offset,
        }


def segment_from_stats(
    count: int,
    centroid: NDArray[np.float64],
    scatter: NDArray[np.float64],
    extremes: NDArray[np.float64],
) -> WallSegment:
    """A :class:`WallSegment` from sufficient statistics and points spanning its extent.

    Parameters
    ----------
    count : int
        Supporting points ``n``.
    centroid : (2,) array
        Their mean.
    scatter : (2, 2) array
        ``sum (p - c)(p - c)^T``.
    extremes : (K, 2) array
        Points whose projections bound the segment (its supporting points, or the end points of
        merged segments).
    """
    w, V = np.linalg.eigh(scatter)  # ascending: w[0] across the line, w[1] along it
    normal = V[:, 0]
    rho = float(normal @ centroid)
    if rho < 0:
        normal, rho = -normal, -rho
    direction = np.array([-normal[1], normal[0]])
    t = (extremes - centroid) @ direction
    start = centroid + t.min() * direction
    end = centroid + t.max() * direction
    rms = float(np.sqrt(max(w[0], 0.0) / count))
    along = max(float(w[1]), 1e-18)
    return WallSegment(
        start=start,
        end=end,
        normal=normal,
        rho=rho,
        count=int(count),
        centroid=np.asarray(centroid, dtype=np.float64),
        scatter=np.asarray(scatter, dtype=np.float64),
        rms=rms,
        sigma_angle=float(rms / np.sqrt(along)),
        sigma_offset=float(rms / np.sqrt(count)),
    )


def segment_from_points(points: ArrayLike) -> WallSegment:
    """TLS wall segment through points ``(N, 2)`` (``N >= 2``), extent from the extreme points."""
    P = as_points(points, 2, min_count=2)
    c = P.mean(axis=0)
    D = P - c
    return segment_from_stats(len(P), c, D.T @ D, P)


def merge_two(a: WallSegment, b: WallSegment) -> WallSegment:
    """Exact TLS segment of the union of the points of ``a`` and ``b`` (from their statistics)."""
    n = a.count + b.count
    c = (a.count * a.centroid + b.count * b.centroid) / n
    da, db = a.centroid - c, b.centroid - c
    S = a.scatter + b.scatter + a.count * np.outer(da, da) + b.count * np.outer(db, db)
    return segment_from_stats(n, c, S, np.stack([a.start, a.end, b.start, b.end]))


def _runs(points: NDArray[np.float64], settings: SegmentationSettings) -> list[tuple[int, int]]:
    """Index ranges ``[i, j)`` of consecutive points without a gap between neighbours."""
    step = np.linalg.norm(np.diff(points, axis=0), axis=1)
    reach = np.linalg.norm(points, axis=1)
    limit = settings.gap + settings.gap_per_metre * np.maximum(reach[:-1], reach[1:])
    cuts = np.flatnonzero(step > limit) + 1
    bounds = np.concatenate([[0], cuts, [len(points)]])
    return [(int(i), int(j)) for i, j in pairwise(bounds) if j - i >= 2]


def _chord_distances(P: NDArray[np.float64]) -> NDArray[np.float64]:
    """Distances of the points of a run to the chord through its first and last point."""
    a, b = P[0], P[-1]
    d = b - a
    n = np.linalg.norm(d)
    if n < 1e-12:
        return np.linalg.norm(P - a, axis=1)
    return np.abs((P - a) @ np.array([-d[1], d[0]])) / n


def split_and_merge(
    points: ArrayLike, settings: SegmentationSettings | None = None, *, closed: bool = False
) -> list[WallSegment]:
    """Wall segments of points given in scan order (a laser scan, a floor profile).

    Stages (Nguyen et al. 2005, "split-and-merge"): cut the sequence at gaps; split each run
    recursively where a point lies farther than ``split_distance`` from the run's chord; merge
    neighbouring pieces whose joint TLS fit has ``rms < merge_rms``; fit a TLS line to each
    piece and keep pieces with enough points and length.

    Parameters
    ----------
    points : (N, 2) array
        Points in scan order, metres, in the sensor frame (gaps scale with the distance from the
        origin); rows with NaN (no return) are dropped.
    settings : SegmentationSettings, optional
    closed : bool
        The scan is a full turn (the last point neighbours the first): a wall cut by the wrap
        is joined again.

    Returns
    -------
    list of WallSegment
        In scan order.
    """
    s = settings or SegmentationSettings()
    P = as_points(points, 2)
    P = P[np.all(np.isfinite(P), axis=1)]
    if len(P) < s.min_points:
        return []
    # Stage 1: runs without gaps.  Stage 2: recursive split at the farthest point from the chord.
    pieces: list[tuple[int, int]] = []
    stack = _runs(P, s)[::-1]
    while stack:
        i, j = stack.pop()
        if j - i < 3:
            pieces.append((i, j))
            continue
        d = _chord_distances(P[i:j])
        k = int(np.argmax(d))
        if d[k] > s.split_distance and 0 < k < j - i - 1:
            stack.append((i + k, j))
            stack.append((i, i + k + 1))  # the split point ends the first piece and starts the next
        else:
            pieces.append((i, j))
    pieces.sort()
    # Stage 3: merge neighbours that are one line (joint TLS rms small, touching indices).
    merged: list[tuple[int, int]] = []
    for piece in pieces:
        if merged and merged[-1][1] > piece[0]:  # split pieces share their split point
            i0 = merged[-1][0]
            Q = P[i0 : piece[1]]
            c = Q.mean(axis=0)
            rms = float(np.sqrt(max(np.linalg.eigvalsh((Q - c).T @ (Q - c))[0], 0.0) / len(Q)))
            if rms < s.merge_rms and _chord_distances(Q).max() <= 2.0 * s.split_distance:
                merged[-1] = (i0, piece[1])
                continue
        merged.append(piece)
    # A full turn: the first and last pieces may be one wall cut by the wrap.
    if (
        closed
        and len(merged) > 1
        and np.linalg.norm(P[-1] - P[0]) <= s.gap + s.gap_per_metre * np.linalg.norm(P[0])
    ):
        Q = np.concatenate([P[merged[-1][0] : merged[-1][1]], P[merged[0][0] : merged[0][1]]])
        c = Q.mean(axis=0)
        rms = float(np.sqrt(max(np.linalg.eigvalsh((Q - c).T @ (Q - c))[0], 0.0) / len(Q)))
        if rms < s.merge_rms and _chord_distances(Q).max() <= 2.0 * s.split_distance:
            last = merged.pop()
            P = np.concatenate([P[last[0] :], P])  # the wrapped run becomes indices 0 .. n
            shift = len(P) - (len(P) - (last[1] - last[0]))
            merged = [(0, merged[0][1] + shift)] + [(i + shift, j + shift) for i, j in merged[1:]]
    # Stage 4: TLS fit, extent, uncertainty; drop short or thin pieces.
    out = []
    for i, j in merged:
        if j - i < s.min_points:
            continue
        seg = segment_from_points(P[i:j])
        if seg.length >= s.min_length:
            out.append(seg)
    return out


def ransac_walls(
    points: ArrayLike, settings: SegmentationSettings | None = None
) -> list[WallSegment]:
    """Wall segments of an unordered 2D cloud by sequential RANSAC.

    Each round draws ``ransac_iterations`` two-point line hypotheses at once, keeps the one with
    most inliers (within ``split_distance``), refits it by TLS, recomputes the inliers, cuts
    them along the line at gaps wider than ``gap`` and keeps each run with ``min_points``
    points and ``min_length`` metres as a segment; its points are removed and the next round
    starts. Stops when the best line has fewer than ``min_points`` inliers.

    Parameters
    ----------
    points : (N, 2) array
        Metres; NaN rows dropped.
    settings : SegmentationSettings, optional

    Returns
    -------
    list of WallSegment
        Longest first.
    """
    s = settings or SegmentationSettings()
    P = as_points(points, 2)
    P = P[np.all(np.isfinite(P), axis=1)]
    rng = np.random.default_rng(s.seed)
    min_count = max(s.min_points, int(np.ceil(s.min_fraction * len(P))))
    segments: list[WallSegment] = []
    remaining = P
    for _ in range(s.max_walls):
        if len(remaining) < min_count:
            break
        # Hypotheses from pairs of points (vectorised over hypotheses and points; subsample the
        # scoring set for very large clouds - the winner is re-scored on all points).
        idx = rng.integers(0, len(remaining), size=(s.ransac_iterations, 2))
        a, b = remaining[idx[:, 0]], remaining[idx[:, 1]]
        d = b - a
        norm = np.linalg.norm(d, axis=1)
        ok = norm > 1e-9
        if not ok.any():
            break
        a, d, norm = a[ok], d[ok], norm[ok]
        normals = np.stack([-d[:, 1], d[:, 0]], axis=1) / norm[:, None]
        score_set = remaining
        if len(score_set) > 4000:
            score_set = remaining[rng.choice(len(remaining), 4000, replace=False)]
        dist = np.abs(np.einsum("hnk,hk->hn", score_set[None, :, :] - a[:, None, :], normals))
        best = int(np.argmax((dist < s.split_distance).sum(axis=1)))
        inl = np.abs((remaining - a[best]) @ normals[best]) < s.split_distance
        if inl.sum() < min_count:
            break
        # TLS refit, then inliers of the refined line.
        line = segment_from_points(remaining[inl])
        inl = np.abs(remaining @ line.normal - line.rho) < s.split_distance
        Q_idx = np.flatnonzero(inl)
        t = (remaining[Q_idx] - line.centroid) @ line.direction
        order = np.argsort(t)
        Q_idx, t = Q_idx[order], t[order]
        cuts = np.flatnonzero(np.diff(t) > s.gap) + 1
        used = np.zeros(len(remaining), dtype=bool)
        for run in np.split(Q_idx, cuts):
            if len(run) < min_count:
                continue
            seg = segment_from_points(remaining[run])
            if seg.length >= s.min_length:
                segments.append(seg)
                used[run] = True
                # absorb the noise tail of this wall (points a little beyond the inlier band,
                # within its extent) so it does not seed slanted ghost walls in later rounds
                t_all = (remaining - seg.centroid) @ seg.direction
                t_seg = (np.stack([seg.start, seg.end]) - seg.centroid) @ seg.direction
                used |= (
                    (np.abs(remaining @ seg.normal - seg.rho) < s.absorb_factor * s.split_distance)
                    & (t_all >= t_seg.min() - s.split_distance)
                    & (t_all <= t_seg.max() + s.split_distance)
                )
        if not used.any():
            # The best line only had short pieces: remove its inliers so the search moves on.
            used = inl
        remaining = remaining[~used]
    segments.sort(key=lambda g: -g.length)
    return segments
