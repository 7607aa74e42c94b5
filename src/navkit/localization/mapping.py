"""A 2D wall map: segments, corners, the room outline, an occupancy grid.

Paper 3 builds the map of the room from wall points seen with known poses: least-squares lines,
corners at their intersections (``x = (b2 - b1)/(k1 - k2)``, ``y = (k1 b2 - k2 b1)/(k1 - k2)``),
then "simple heuristics" for the room outline. navkit's version:

1. wall segments of each view in its own frame (:mod:`navkit.localization.walls`), moved to the
   world by the view's pose (paper eq. 2, an SE(2) motion here);
2. the same wall seen twice merged: segments with directions within ``merge_angle``, lying
   within ``merge_distance`` of each other's line and overlapping (or a gap below ``merge_gap``)
   are joined transitively and refitted exactly (TLS of the union of their points);
   with a stereo error model (``range_sigma_coefficient``) and the sensor positions, each wall
   is then refitted by inverse-variance weighted TLS (:func:`refit_walls_weighted`) and the
   walls merged once more;
3. corners where two walls at more than ``corner_min_angle`` meet within ``corner_reach`` of an
   end of both (the line intersection, the TLS equivalent of the paper's formulas);
4. the outline: cycles of walls linked by corners (and collinear walls linked across doorways),
   the largest by area is the room, smaller ones are islands (columns);
5. an occupancy grid: walls occupied, free space from the views' rays (or inside the outline).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from navkit.domains import NON_NEGATIVE, POSITIVE, Domain, domain_field
from navkit.errors import FormatError, InputError
from navkit.geometry import se2_apply, se2_from_xytheta
from navkit.geometry._validate import as_points, check_settings
from navkit.geometry.polygons import polygon_area, signed_area
from navkit.localization.field import LikelihoodField
from navkit.localization.raster import rasterize, sample_segments
from navkit.localization.walls import (
    SegmentationSettings,
    WallSegment,
    merge_two,
    ransac_walls,
    segment_from_stats,
    split_and_merge,
)

__all__ = [
    "Corner",
    "WallMap",
    "WallMapSettings",
    "build_map",
    "build_map_from_scans",
    "drop_corner_stubs",
    "drop_wall_shadows",
    "find_corners",
    "find_outline",
    "merge_segments",
    "refit_walls_weighted",
]

log = logging.getLogger(__name__)

#: Finest occupancy grid cell accepted, metres.
MIN_RESOLUTION = 1e-3

#: A share of another wall's support (or density) below which a wall is dropped; 0 = off.
_FRACTION_OFF = Domain(lo=0.0, note="a fraction, 0 = off")

MAP_FORMAT = "navkit-wall-map"
MAP_VERSION = 1


@dataclass(frozen=True)
class WallMapSettings:
    """How wall maps are built.

    Attributes
    ----------
    segmentation : SegmentationSettings
        Cutting points into walls.
    merge_angle_deg : float
        Two segments are the same wall only if their directions differ by less than this.
    merge_distance : float
        Metres; ... and the shorter one's end points lie within this of the longer one's line.
    merge_gap : float
        Metres; ... and their extents overlap or leave a gap shorter than this.
    corner_min_angle_deg : float
        Walls meeting at less than this angle do not make a corner.
    corner_reach : float
        Metres; a corner must lie within this of an end of both walls.
    doorway_max : float
        Metres; collinear walls whose facing ends are closer than this are linked across a
        doorway when tracing the outline.
    resolution : float
        Occupancy grid cell size, metres (at least :data:`MIN_RESOLUTION`, 1 mm; the grid's
        cell count is bounded too, see ``navkit.geometry._validate.check_grid_size``).
    min_wall_length : float
        Metres; merged walls shorter than this are dropped from the map.
    min_relative_support : float
        Walls with fewer points than this fraction of the 75th-percentile wall's are dropped
        (stray pieces of stereo outliers; a no-op for laser maps, whose walls have few points).
    min_strongest_support : float
        Unordered clouds (stereo): walls with fewer points than this fraction of the strongest
        wall's, scaled by their length relative to it, are dropped too (a 0.6 m column face
        needs a 0.6 m share of the support, not that of an 8 m wall).
    min_relative_density : float
        Unordered clouds (stereo): walls with fewer points per metre than this fraction of the
        strongest wall's are dropped (stray pieces of outliers spread thin along a line).
    shadow_distance : float
        Metres; see :func:`drop_wall_shadows`.
    shadow_support : float
        Fraction; see :func:`drop_wall_shadows`.
    range_sigma_coefficient : float
        1/m; ``k`` in a point's error along its ray ``sigma_ray = k r^2`` (stereo:
        ``sigma_d / (b f)``, paper 3 eq. 1 differentiated; see
        :func:`~navkit.localization.refine.stereo_range_sigma`). Positive: after merging, each
        wall is refitted by inverse-variance weighted TLS (:func:`refit_walls_weighted`) when
        the views' sensor positions are known. 0 (default): plain TLS (laser).
    sigma_floor : float
        Metres; error of a point across its wall not due to its range, added in quadrature to
        the weighted refit's variances.
    """

    segmentation: SegmentationSettings = field(default_factory=SegmentationSettings)
    merge_angle_deg: float = domain_field(
        5.0, Domain(lo=0.0, hi=90.0, lo_open=True, hi_open=True, note="degrees")
    )
    merge_distance: float = domain_field(0.1, POSITIVE)
    merge_gap: float = domain_field(0.3, POSITIVE)
    corner_min_angle_deg: float = domain_field(30.0, Domain(lo=0.0, hi=90.0, note="degrees"))
    corner_reach: float = domain_field(0.4, POSITIVE)
    doorway_max: float = domain_field(1.5, Domain(lo=0.0, note="metres, 0 = no doorways"))
    resolution: float = domain_field(
        0.05, Domain(lo=MIN_RESOLUTION, note="metres; finer than 1 mm is a typo")
    )
    min_wall_length: float = domain_field(0.3, POSITIVE)
    min_relative_support: float = domain_field(0.05, _FRACTION_OFF)
    shadow_distance: float = domain_field(0.25, NON_NEGATIVE)
    min_strongest_support: float = domain_field(0.03, _FRACTION_OFF)
    shadow_support: float = domain_field(0.1, _FRACTION_OFF)
    min_relative_density: float = domain_field(0.2, _FRACTION_OFF)
    range_sigma_coefficient: float = domain_field(0.0, Domain(lo=0.0, note="1/m, 0 = laser"))
    sigma_floor: float = domain_field(0.01, NON_NEGATIVE)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], source: str = "settings") -> WallMapSettings:
        """Build from a mapping (e.g. the ``[map]`` table of a ``settings.toml``), a nested
        ``segmentation`` table; unknown keys are rejected."""
        from navkit.localization._settings import settings_from_dict

        return settings_from_dict(cls, data, source, "map")  # type: ignore[no-any-return]

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class Corner:
    """Two walls meeting.

    Attributes
    ----------
    point : (2,) array
        Intersection of the two wall lines, metres.
    walls : tuple of int
        Indices of the two walls in the map.
    angle_deg : float
        Angle between the walls, degrees in ``(0, 90]``.
    sigma : float
        First-order standard error of the corner position, metres, from the walls' offset and
        direction errors (``sigma_offset + sigma_angle * distance from centroid``, combined in
        quadrature, divided by ``sin(angle)``).
    """

    point: NDArray[np.float64]
    walls: tuple[int, int]
    angle_deg: float
    sigma: float


@dataclass(frozen=True)
class WallMap:
    """A 2D map of straight walls.

    Attributes
    ----------
    walls : list of WallSegment
        World frame, metres.
    corners : list of Corner
    outline : (K, 2) array or None
        Room outline polygon (counter-clockwise), or None when no closed cycle of walls exists.
    islands : list of (K, 2) arrays
        Smaller closed cycles (columns, furniture blocks).
    occupancy : (H, W) int8 array or None
        -1 unknown, 0 free, 100 occupied; row 0 = min y (use ``np.flipud`` for an image).
    resolution : float
        Cell size of ``occupancy``, metres.
    origin : (2,) array
        World ``(x, y)`` of the lower-left corner of cell ``[0, 0]``.
    """

    walls: list[WallSegment]
    corners: list[Corner] = field(default_factory=list)
    outline: NDArray[np.float64] | None = None
    islands: list[NDArray[np.float64]] = field(default_factory=list)
    occupancy: NDArray[np.int8] | None = None
    resolution: float = 0.05
    origin: NDArray[np.float64] = field(default_factory=lambda: np.zeros(2))

    @property
    def bounds(self) -> NDArray[np.float64]:
        """``(2, 2)`` rows min ``(x, y)`` and max ``(x, y)`` of the wall end points."""
        if not self.walls:
            return np.zeros((2, 2))
        E = np.concatenate([[w.start, w.end] for w in self.walls])
        return np.stack([E.min(axis=0), E.max(axis=0)])

    def occupied_points(self) -> NDArray[np.float64]:
        """Centres ``(K, 2)`` of the occupied grid cells, or wall samples when there is no grid."""
        if self.occupancy is None:
            return sample_segments(self.walls, self.resolution / 2)
        rows, cols = np.nonzero(self.occupancy == 100)
        return (np.stack([cols, rows], axis=1) + 0.5) * self.resolution + self.origin

    def likelihood_field(
        self, sigma: float = 0.1, resolution: float | None = None
    ) -> LikelihoodField:
        """The map as a likelihood field for :func:`navkit.localization.matcher.match_scan`.

        Built from points every 2 cm along the walls (exact, sub-cell positions) plus the
        occupied cells farther than one cell from every wall (clutter that is not a straight
        wall; cell centres would blur the walls by up to half a cell).
        """
        from scipy.spatial import cKDTree

        wall_pts = sample_segments(self.walls, 0.02)
        cells = self.occupied_points()
        if len(wall_pts) and len(cells):
            d, _ = cKDTree(wall_pts).query(cells, distance_upper_bound=2 * self.resolution)
            cells = cells[d > self.resolution]
        pts = np.concatenate([wall_pts, cells])
        return LikelihoodField.from_points(pts, resolution or self.resolution, sigma)

    def to_dict(self) -> dict[str, object]:
        """JSON-able description (without the grid, which goes to PGM + YAML)."""
        return {
            "format": MAP_FORMAT,
            "version": MAP_VERSION,
            "units": "metres, radians unless *_deg",
            "walls": [w.to_dict() for w in self.walls],
            "corners": [
                {
                    "point": c.point.tolist(),
                    "walls": list(c.walls),
                    "angle_deg": c.angle_deg,
                    "sigma": c.sigma,
                }
                for c in self.corners
            ],
            "outline": None if self.outline is None else self.outline.tolist(),
            "islands": [i.tolist() for i in self.islands],
            "resolution": self.resolution,
            "origin": self.origin.tolist(),
        }

    @classmethod
    def from_dict(cls, data: object, source: str = "map") -> WallMap:
        """Inverse of :meth:`to_dict` (the occupancy grid is not restored).

        Raises
        ------
        FormatError
            If the dictionary is not a navkit wall map (names the missing / bad field).
        """
        if not isinstance(data, dict) or data.get("format") != MAP_FORMAT:
            raise FormatError(
                "not a navkit wall map", source=source, field="format", expected=f"'{MAP_FORMAT}'"
            )
        try:
            walls = []
            for k, w in enumerate(data["walls"]):
                walls.append(
                    segment_from_stats(
                        int(w["count"]),
                        np.asarray(w["centroid"], dtype=np.float64).reshape(2),
                        np.asarray(w["scatter"], dtype=np.float64).reshape(2, 2),
                        np.asarray([w["start"], w["end"]], dtype=np.float64).reshape(2, 2),
                    )
                )
                if walls[-1].count < 2:
                    raise ValueError(f"walls[{k}].count < 2")
            corners = [
                Corner(
                    np.asarray(c["point"], float).reshape(2),
                    (int(c["walls"][0]), int(c["walls"][1])),
                    float(c["angle_deg"]),
                    float(c["sigma"]),
                )
                for c in data.get("corners", [])
            ]
            outline = data.get("outline")
            return cls(
                walls=walls,
                corners=corners,
                outline=None if outline is None else np.asarray(outline, float).reshape(-1, 2),
                islands=[np.asarray(i, float).reshape(-1, 2) for i in data.get("islands", [])],
                resolution=float(data.get("resolution", 0.05)),
                origin=np.asarray(data.get("origin", [0.0, 0.0]), float).reshape(2),
            )
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise FormatError(
                f"bad wall entry: {exc}",
                source=source,
                field="walls",
                expected="walls with start, end, count, centroid, scatter",
            ) from exc


# --------------------------------------------------------------------------- merging
def merge_segments(
    segments: Sequence[WallSegment], settings: WallMapSettings | None = None
) -> list[WallSegment]:
    """Merge segments of the same wall (seen from several views), transitively.

    Pairs are compared vectorised (in blocks, so thousands of segments fit in memory); linked
    pairs form connected components, each refitted exactly from the pooled statistics.

    Returns
    -------
    list of WallSegment
        Longest first; walls shorter than ``min_wall_length`` dropped.
    """
    s = settings or WallMapSettings()
    segs = list(segments)
    if not segs:
        return []
    M = len(segs)
    S = np.array([w.start for w in segs])
    E = np.array([w.end for w in segs])
    N = np.array([w.normal for w in segs])
    rho = np.array([w.rho for w in segs])
    D = np.array([w.direction for w in segs])
    C = 0.5 * (S + E)
    half = 0.5 * np.linalg.norm(E - S, axis=1)
    cos_max = np.cos(np.radians(s.merge_angle_deg))
    rows, cols = [], []
    block = max(1, 2_000_000 // M)
    for i0 in range(0, M, block):
        i = slice(i0, min(M, i0 + block))
        parallel = np.abs(D[i] @ D.T) > cos_max
        # end points of j against the line of i, and of i against the line of j
        dSj = np.abs(S @ N[i].T - rho[i]).T
        dEj = np.abs(E @ N[i].T - rho[i]).T
        dSi = np.abs(np.einsum("ik,jk->ij", S[i], N) - rho[None, :])
        dEi = np.abs(np.einsum("ik,jk->ij", E[i], N) - rho[None, :])
        # the shorter segment's end points must lie near the longer one's line
        j_shorter = half[None, :] <= half[i][:, None]
        near = np.where(j_shorter, np.maximum(dSj, dEj), np.maximum(dSi, dEi)) < s.merge_distance
        # gap between extents along the direction of i
        centre_gap = np.abs(np.einsum("ijk,ik->ij", C[None, :, :] - C[i][:, None, :], D[i]))
        overlap = centre_gap - half[i][:, None] - half[None, :] < s.merge_gap
        # a short piece lying on a longer wall (both ends near its line, inside its extent) is
        # part of it whatever its direction (stereo smear at corners makes slanted stubs)
        t_s = np.einsum("ijk,ik->ij", S[None, :, :] - C[i][:, None, :], D[i])
        t_e = np.einsum("ijk,ik->ij", E[None, :, :] - C[i][:, None, :], D[i])
        inside = (np.abs(t_s) <= half[i][:, None]) & (np.abs(t_e) <= half[i][:, None])
        subsumed = j_shorter & (np.maximum(dSj, dEj) < s.merge_distance) & inside
        # a short piece's direction is poorly determined (stereo noise over < 1 m): when both
        # its ends lie near the longer one's line it is the same wall up to 15 deg
        short = np.minimum(half[i][:, None], half[None, :]) < 0.5
        loose = np.abs(D[i] @ D.T) > np.cos(np.radians(max(15.0, s.merge_angle_deg)))
        link = (parallel & near & overlap) | (loose & short & near & overlap) | subsumed
        r, c = np.nonzero(link)
        rows.append(r + i0)
        cols.append(c)
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    graph = coo_matrix((np.ones(len(r), dtype=np.int8), (r, c)), shape=(M, M))
    n_comp, labels = connected_components(graph, directed=False)
    merged = []
    for k in range(n_comp):
        members = np.flatnonzero(labels == k)
        wall = segs[members[0]]
        for m in members[1:]:
            wall = merge_two(wall, segs[m])
        if wall.length >= s.min_wall_length:
            merged.append(wall)
    merged.sort(key=lambda w: -w.length)
    log.debug("merged %d segments into %d walls", M, len(merged))
    return merged


# --------------------------------------------------------------------------- corners, outline
def find_corners(
    walls: Sequence[WallSegment], settings: WallMapSettings | None = None
) -> list[Corner]:
    """Corners where two walls meet (line intersection near an end of both walls).

    The intersection of the TLS lines ``n1 . p = rho1`` and ``n2 . p = rho2`` is the paper's
    ``x = (b2 - b1)/(k1 - k2), y = (k1 b2 - k2 b1)/(k1 - k2)`` in a form valid for vertical walls.
    """
    s = settings or WallMapSettings()
    if len(walls) < 2:
        return []
    N = np.array([w.normal for w in walls])
    rho = np.array([w.rho for w in walls])
    S = np.array([w.start for w in walls])
    E = np.array([w.end for w in walls])
    i, j = np.triu_indices(len(walls), k=1)
    det = N[i, 0] * N[j, 1] - N[i, 1] * N[j, 0]
    sin_min = np.sin(np.radians(s.corner_min_angle_deg))
    ok = np.abs(det) >= sin_min
    i, j, det = i[ok], j[ok], det[ok]
    # Cramer's rule for [n_i; n_j] p = [rho_i; rho_j]
    px = (rho[i] * N[j, 1] - rho[j] * N[i, 1]) / det
    py = (N[i, 0] * rho[j] - N[j, 0] * rho[i]) / det
    P = np.stack([px, py], axis=1)

    def near_end(k: NDArray[np.intp]) -> NDArray[np.bool_]:
        return (
            np.minimum(np.linalg.norm(P - S[k], axis=1), np.linalg.norm(P - E[k], axis=1))
            <= s.corner_reach
        )

    keep = near_end(i) & near_end(j)
    corners = []
    for a, b, p, dt in zip(i[keep], j[keep], P[keep], det[keep], strict=True):
        wa, wb = walls[a], walls[b]
        ea = np.hypot(wa.sigma_offset, wa.sigma_angle * np.linalg.norm(p - wa.centroid))
        eb = np.hypot(wb.sigma_offset, wb.sigma_angle * np.linalg.norm(p - wb.centroid))
        corners.append(
            Corner(
                p,
                (int(a), int(b)),
                float(np.degrees(np.arcsin(min(1.0, abs(dt))))),
                float(np.hypot(ea, eb) / abs(dt)),
            )
        )
    return corners


def find_outline(
    walls: Sequence[WallSegment], corners: Sequence[Corner], settings: WallMapSettings | None = None
) -> tuple[NDArray[np.float64] | None, list[NDArray[np.float64]]]:
    """Closed cycles of walls: the largest (by area) is the outline, the rest are islands.

    Walls are nodes; corners link them, and so do collinear walls whose facing ends are less
    than ``doorway_max`` apart (a doorway: the outline runs across it). Every connected group in
    which each wall has exactly two links is a cycle; its polygon visits the corners in order
    (a doorway link contributes the two door jambs).

    Returns
    -------
    outline : (K, 2) array or None
        Counter-clockwise polygon, metres.
    islands : list of (K, 2) arrays
    """
    s = settings or WallMapSettings()
    M = len(walls)
    links: dict[int, list[tuple[int, list[NDArray[np.float64]]]]] = {k: [] for k in range(M)}
    for c in corners:
        a, b = c.walls
        links[a].append((b, [c.point]))
        links[b].append((a, [c.point]))
    cos_max = np.cos(np.radians(s.merge_angle_deg))
    if M > 1:
        # candidate doorway pairs, vectorised: parallel, on one line, facing ends close
        D = np.array([w.direction for w in walls])
        N = np.array([w.normal for w in walls])
        rho = np.array([w.rho for w in walls])
        C = np.array([w.centroid for w in walls])
        ends = np.stack([[w.start, w.end] for w in walls])  # (M, 2, 2)
        ia, ib = np.triu_indices(M, k=1)
        par = np.abs(np.einsum("ij,ij->i", D[ia], D[ib])) >= cos_max
        line = np.abs(np.einsum("ij,ij->i", C[ib], N[ia]) - rho[ia]) <= 2 * s.merge_distance
        gaps = np.linalg.norm(ends[ia][:, :, None, :] - ends[ib][:, None, :, :], axis=3).reshape(
            -1, 4
        )
        near = gaps.min(axis=1) <= s.doorway_max
        for a, b, g in zip(
            ia[par & line & near], ib[par & line & near], gaps[par & line & near], strict=True
        ):
            ea, eb = divmod(int(np.argmin(g)), 2)
            links[int(a)].append((int(b), [ends[a, ea], ends[b, eb]]))
            links[int(b)].append((int(a), [ends[b, eb], ends[a, ea]]))
    polygons = []
    seen = np.zeros(M, dtype=bool)
    for start in range(M):
        if seen[start] or len(links[start]) != 2:
            continue
        # walk the cycle
        poly: list[NDArray[np.float64]] = []
        prev, cur = -1, start
        ok = True
        visited = []
        while True:
            if len(links[cur]) != 2:
                ok = False
                break
            visited.append(cur)
            nxt = [(n, pts) for n, pts in links[cur] if n != prev] if prev >= 0 else [links[cur][0]]
            if not nxt:
                ok = False
                break
            n, pts = nxt[0]
            poly.extend(pts)
            prev, cur = cur, n
            if cur == start:
                break
            if cur in visited:
                ok = False
                break
        seen[visited] = True
        if ok and len(poly) >= 3:
            P = np.array(poly)
            if signed_area(P) < 0:
                P = P[::-1]
            polygons.append(P)
    if not polygons:
        return None, []
    polygons.sort(key=lambda p: -abs(polygon_area(p)))
    return polygons[0], polygons[1:]


# --------------------------------------------------------------------------- grid
def drop_corner_stubs(
    walls: Sequence[WallSegment], settings: WallMapSettings | None = None
) -> list[WallSegment]:
    """Remove short pieces lying across a corner of two longer walls (stereo smear at corners).

    A wall shorter than ``2 * corner_reach`` whose both end points lie within
    ``1.5 * corner_reach`` of a corner formed by two other, longer walls is an artefact, not a
    wall; so is a weak one (fewer than ``shadow_support`` times the points of the weaker corner
    wall) or a chord across the corner (each end within ``corner_reach / 2`` of one of the two
    walls' lines) with both ends within ``2.5 * corner_reach``: the rounded diagonal that the
    stereo matching window makes of a far corner (noisy there: the depth error grows as
    ``z^2``).
    """
    s = settings or WallMapSettings()
    walls = list(walls)
    corners = find_corners(walls, s)
    drop = set()
    for k, w in enumerate(walls):
        if w.length >= 2 * s.corner_reach:
            continue
        for c in corners:
            if k in c.walls or min(walls[c.walls[0]].length, walls[c.walls[1]].length) <= w.length:
                continue
            reach = max(np.linalg.norm(w.start - c.point), np.linalg.norm(w.end - c.point))
            a, b = walls[c.walls[0]], walls[c.walls[1]]
            weak = w.count < s.shadow_support * min(a.count, b.count)
            # a rounded corner: one end on each wall's line (a chord across the corner)
            ends = np.stack([w.start, w.end])
            da, db = np.abs(a.distance(ends)), np.abs(b.distance(ends))
            tol = 0.5 * s.corner_reach
            bridge = bool((da[0] <= tol and db[1] <= tol) or (db[0] <= tol and da[1] <= tol))
            if reach <= s.corner_reach * 1.5 or (
                (weak or bridge) and reach <= s.corner_reach * 2.5
            ):
                drop.add(k)
                break
    return [w for k, w in enumerate(walls) if k not in drop]


def drop_wall_shadows(
    walls: Sequence[WallSegment], settings: WallMapSettings | None = None
) -> list[WallSegment]:
    """Remove weak pieces running alongside a strong wall (stereo smear beside occluders).

    A wall is a shadow of a longer one when their directions differ by less than
    ``2 * merge_angle_deg``, both its ends lie within ``shadow_distance`` of the longer wall's
    line and inside its extent, and it has less than ``shadow_support`` of its points.
    """
    s = settings or WallMapSettings()
    walls = list(walls)
    if len(walls) < 2:
        return walls
    D = np.array([w.direction for w in walls])
    N = np.array([w.normal for w in walls])
    rho = np.array([w.rho for w in walls])
    S = np.array([w.start for w in walls])
    E = np.array([w.end for w in walls])
    n = np.array([w.count for w in walls], dtype=np.float64)
    half = 0.5 * np.linalg.norm(E - S, axis=1)
    mid = 0.5 * (S + E)
    # rows: candidate shadow i, columns: strong wall j
    par = np.abs(D @ D.T) >= np.cos(np.radians(2 * s.merge_angle_deg))
    dS = np.abs(S @ N.T - rho[None, :])
    dE = np.abs(E @ N.T - rho[None, :])
    near = np.maximum(dS, dE) <= s.shadow_distance
    tS = np.abs(np.einsum("ijk,jk->ij", S[:, None, :] - mid[None, :, :], D))
    tE = np.abs(np.einsum("ijk,jk->ij", E[:, None, :] - mid[None, :, :], D))
    inside = np.maximum(tS, tE) <= half[None, :] + s.merge_gap
    weak = n[:, None] < s.shadow_support * n[None, :]
    shadow = par & near & inside & weak
    np.fill_diagonal(shadow, False)
    keep = ~shadow.any(axis=1)
    return [w for w, k in zip(walls, keep, strict=True) if k]


def _finish(
    walls: list[WallSegment],
    s: WallMapSettings,
    rays: tuple[NDArray[np.float64], NDArray[np.float64]] | None,
    strongest_fraction: float = 0.0,
) -> WallMap:
    if walls:
        # support filter: a wall needs min_relative_support of the points of a well-supported
        # wall (the 75th percentile: robust to many stubs and to a few huge walls)
        counts = np.array([w.count for w in walls], dtype=np.float64)
        floor = np.full(len(walls), s.min_relative_support * float(np.percentile(counts, 75)))
        keep = counts >= floor
        if strongest_fraction > 0:
            # stereo clouds: support judged against the strongest wall's, for the wall's length,
            # and the density of points along the wall against the strongest wall's
            lengths = np.maximum([w.length for w in walls], 0.1)
            k = int(np.argmax(counts))
            share = np.minimum(1.0, lengths / lengths[k])
            keep &= counts >= strongest_fraction * counts[k] * share
            keep &= counts / lengths >= s.min_relative_density * counts[k] / lengths[k]
        walls = [w for w, ok in zip(walls, keep, strict=True) if ok]
    walls = drop_wall_shadows(walls, s)
    walls = drop_corner_stubs(walls, s)
    corners = find_corners(walls, s)
    outline, islands = find_outline(walls, corners, s)
    grid, origin = rasterize(
        walls,
        s.resolution,
        free_polygon=outline if rays is None else None,
        rays=rays,
        occupied_points=None if rays is None else rays[1],
    )
    return WallMap(
        walls=walls,
        corners=corners,
        outline=outline,
        islands=islands,
        occupancy=grid,
        resolution=s.resolution,
        origin=origin,
    )


def build_map(
    views: Sequence[ArrayLike],
    poses: ArrayLike | None = None,
    settings: WallMapSettings | None = None,
    *,
    ordered: bool = False,
    origins: ArrayLike | None = None,
) -> WallMap:
    """Build a wall map from 2D wall points of one or more views.

    Parameters
    ----------
    views : list of (N_k, 2) arrays
        Wall points of each view (e.g. stereo points of wall pixels projected on the floor),
        metres, in the view's frame (x forward, y left) - or in the world if ``poses`` is None.
    poses : (K, 3) array, optional
        ``(x, y, theta)`` of each view in the world (paper eq. 2: a rotation about z and a shift).
    settings : WallMapSettings, optional
    ordered : bool
        Points of each view are in scan order: use split-and-merge; else RANSAC.
    origins : (K, 2) array, optional
        The sensor's position of each view, in the views' frame (world points): with
        ``settings.range_sigma_coefficient > 0`` the walls are refitted by inverse-variance
        weighted TLS (:func:`refit_walls_weighted`). With ``poses`` the sensor sits at each
        view's origin and ``origins`` is not needed.

    Returns
    -------
    WallMap
    """
    s = settings or WallMapSettings()
    if not hasattr(views, "__len__") or (isinstance(views, np.ndarray) and views.ndim == 0):
        raise InputError(
            f"is {type(views).__name__}", field="views", expected="a list of (N, 2) arrays"
        )
    views = list(views)
    if poses is not None:
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        if len(poses) != len(views):
            raise InputError(
                f"has {len(poses)} rows for {len(views)} views",
                field="poses",
                expected="one (x, y, theta) per view",
            )
    segs: list[WallSegment] = []
    seg_fn = split_and_merge if ordered else ransac_walls
    for k, pts in enumerate(views):
        P = as_points(pts, 2, f"views[{k}]")
        local = seg_fn(P, s.segmentation)
        if poses is not None:
            T = se2_from_xytheta(*poses[k])
            local = [_transform(w, T) for w in local]
        segs.extend(local)
    walls = merge_segments(segs, s)
    if s.range_sigma_coefficient > 0 and (poses is not None or origins is not None):
        if poses is not None:
            world = [
                se2_apply(se2_from_xytheta(*poses[k]), as_points(v, 2)) for k, v in enumerate(views)
            ]
            sensor = poses[:, :2]
        else:
            world = [as_points(v, 2) for v in views]
            sensor = as_points(origins, 2, "origins")  # type: ignore[arg-type]
            if len(sensor) != len(views):
                raise InputError(
                    f"has {len(sensor)} rows for {len(views)} views",
                    field="origins",
                    expected="one sensor position (x, y) per view",
                )
        pts = np.concatenate(world)
        org = np.repeat(sensor, [len(w) for w in world], axis=0)
        walls = refit_walls_weighted(walls, pts, org, s.range_sigma_coefficient, s.sigma_floor)
        # a stray piece refitted onto a wall's points now lies on that wall: absorb it again
        walls = merge_segments(walls, s)
    # stereo clouds: stray pieces are also judged against the strongest wall (many stubs would
    # otherwise pull the percentile down)
    return _finish(walls, s, None, 0.0 if ordered else s.min_strongest_support)


def refit_walls_weighted(
    walls: Sequence[WallSegment],
    points: ArrayLike,
    origins: ArrayLike,
    range_sigma_coefficient: float,
    sigma_floor: float = 0.01,
    *,
    gate: float = 0.1,
    iterations: int = 3,
) -> list[WallSegment]:
    """Refit walls by inverse-variance weighted total least squares (stereo points).

    A stereo point's error lies along its viewing ray ``u`` with ``sigma_ray = k r^2`` (paper 3
    eq. 1 differentiated), so its error across a wall of normal ``n`` is
    ``sigma_i^2 = (k r_i^2)^2 (n . u_i)^2 + sigma_floor^2``. Plain TLS weighs every point the
    same: the far points of a wall seen obliquely (large, slanted errors) tilt its line. Here
    each wall's points (within ``gate`` of its line - the map's default merge distance - and of
    its extent, 0.1 m beyond its ends) get weights ``1 / sigma_i^2``; the line is the smallest eigenvector of
    the weighted scatter through the weighted centroid, iterated ``iterations`` times (the
    weights depend on the normal). The segment keeps its extent (ends projected on the new
    line); ``count`` stays the segmentation's support (the map's filters read it) and
    ``scatter`` is the weighted scatter scaled by ``count / sum w`` (so ``rms`` is the weighted
    RMS residual, metres). Decision: a fixed gate, not ``3 sigma_i``: far points' sigmas reach
    0.25 m, and a gate that wide pulls in the points of nearby walls and clutter.

    Parameters
    ----------
    walls : list of WallSegment
        World frame, metres.
    points : (N, 2) array
        All wall points, world frame, metres.
    origins : (N, 2) array
        The sensor position each point was seen from, metres.
    range_sigma_coefficient : float
        ``k``, 1/m.
    sigma_floor : float
        Metres.

    Returns
    -------
    list of WallSegment
        The same walls, refitted (a wall with fewer than 3 points kept as is).
    """
    P = as_points(points, 2)
    S0 = as_points(origins, 2, "origins")
    if len(S0) != len(P):
        raise InputError(
            f"has {len(S0)} rows for {len(P)} points",
            field="origins",
            expected="one sensor position per point",
        )
    ray = P - S0
    r = np.linalg.norm(ray, axis=1)
    u = ray / np.maximum(r, 1e-12)[:, None]
    sig_ray = range_sigma_coefficient * r**2
    out = []
    for w in walls:
        n, c = w.normal, w.centroid
        d = np.array([-n[1], n[0]])
        t = (P - c) @ d
        t0, t1 = sorted(((w.start - c) @ d, (w.end - c) @ d))
        near = (t >= t0 - 0.1) & (t <= t1 + 0.1)
        fitted = None
        for _ in range(iterations):
            sig2 = (sig_ray * (u @ n)) ** 2 + sigma_floor**2
            res = P @ n - float(n @ c)
            use = near & (np.abs(res) <= gate)
            if use.sum() < 3:
                break
            wt = 1.0 / sig2[use]
            Q = P[use]
            c = (wt @ Q) / wt.sum()
            D = Q - c
            S = (D * wt[:, None]).T @ D
            _, V = np.linalg.eigh(S)
            n = V[:, 0]
            # the segmentation's support is kept (the map's support filters read it)
            fitted = (w.count, c, S * (w.count / wt.sum()))
        if fitted is None:
            out.append(w)
            continue
        out.append(segment_from_stats(fitted[0], fitted[1], fitted[2], np.stack([w.start, w.end])))
    return out


def build_map_from_scans(
    ranges: ArrayLike,
    bearings: ArrayLike,
    poses: ArrayLike,
    settings: WallMapSettings | None = None,
    *,
    max_range: float = 30.0,
) -> WallMap:
    """Build a wall map from 2D laser scans with known (corrected) poses.

    Parameters
    ----------
    ranges : (K, B) array
        Ranges, metres; NaN, non-positive or ``>= max_range`` = no return.
    bearings : (B,) array
        Beam angles in the sensor frame, radians (0 = forward, positive to the left).
    poses : (K, 3) array
        Sensor poses ``(x, y, theta)`` in the world.
    settings : WallMapSettings, optional
    max_range : float
        Metres; readings at or above it are no return (they clear no free space either).

    Returns
    -------
    WallMap
        With the occupancy grid's free space traced along the beams.
    """
    s = settings or WallMapSettings()
    R = np.asarray(ranges, dtype=np.float64)
    b = np.asarray(bearings, dtype=np.float64).reshape(-1)
    X = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if R.ndim != 2 or R.shape[1] != len(b) or len(R) != len(X):
        raise InputError(
            f"ranges {R.shape}, bearings {b.shape}, poses {X.shape}",
            field="ranges",
            expected="(K, B) ranges, (B,) bearings, (K, 3) poses",
        )
    valid = np.isfinite(R) & (R > 0) & (R < max_range)  # no-return beams clear nothing
    local = np.stack([R * np.cos(b), R * np.sin(b)], axis=-1)  # (K, B, 2)
    segs: list[WallSegment] = []
    ends_world = []
    origins = []
    for k in range(len(R)):
        pts = local[k][valid[k]]
        T = se2_from_xytheta(*X[k])
        segs.extend(_transform(w, T) for w in split_and_merge(pts, s.segmentation))
        ok = valid[k]
        e = np.stack([R[k, ok] * np.cos(b[ok]), R[k, ok] * np.sin(b[ok])], axis=1)
        ends_world.append(se2_apply(T, e) if len(e) else np.zeros((0, 2)))
        origins.append(np.repeat(X[k, None, :2], len(e), axis=0))
    walls = merge_segments(segs, s)
    rays = (np.concatenate(origins), np.concatenate(ends_world))
    return _finish(walls, s, rays)


def _transform(w: WallSegment, T: NDArray[np.float64]) -> WallSegment:
    """The segment moved by the planar transform ``T`` (3, 3)."""
    R = T[:2, :2]
    c = R @ w.centroid + T[:2, 2]
    ends = se2_apply(T, np.stack([w.start, w.end]))
    return segment_from_stats(w.count, c, R @ w.scatter @ R.T, ends)


# --------------------------------------------------------------------------- evaluation
