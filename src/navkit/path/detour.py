"""Going round a blocked stretch of the stored path (the return of paper 4, extended).

Paper 4 returns along the stored path and says nothing about an obstacle that appears on it.
This module plans a detour on a 2D occupancy grid, from the robot to the first point of the
stored path beyond the blocked stretch that is free, so that the return controller can follow
the detour and then resume the stored path. The stages of :func:`plan_detour`:

1. **clearance** of every cell: the Euclidean distance transform of the free cells
   (:func:`scipy.ndimage.distance_transform_edt`), metres from the cell centre to the nearest
   occupied cell centre;
2. **inflation**: a cell is traversable when its clearance is at least ``robot_radius +
   margin`` (configuration space of a disc robot, plus a safety margin);
3. **the blocked stretch** of the stored path ahead: samples every half cell whose clearance is
   below ``robot_radius`` (a collision) and the samples around them closer than the inflated
   radius; the **rejoin candidates** are the traversable samples beyond it (at least
   ``rejoin_offset`` further on, so the controller's look-ahead does not cut back into the
   obstacle);
4. **shortest 8-connected path** with Dijkstra's algorithm (:func:`scipy.sparse.csgraph.dijkstra`
   on the grid graph built with array operations, edge weights ``resolution`` and
   ``sqrt(2) resolution``) from the robot's cell; the rejoin point is the first reachable
   candidate;
5. **shortcut smoothing**: from each kept vertex, jump to the farthest later vertex in line of
   sight (the straight segment, sampled every quarter cell, stays on traversable cells).

Nothing is found -> a returned :class:`DetourFailure` saying why: the way is closed, the
robot is enclosed, or nothing beyond the block is free within the searched length.

Decisions (the paper is silent, the issue says "go round"):

- cells outside the grid are not traversable; cells never observed are free (the optimistic
  assumption usual for a planner that replans as it sees more);
- a robot that already stands inside the inflated zone (it stopped closer to an obstacle than
  the margin) may leave it through the cells of that zone connected to it that are outside the
  hard radius ``robot_radius`` (and within ``escape_radius``), at ``escape_penalty`` times the
  cost, so the plan prefers to get out at once.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from navkit.domains import Domain, domain_field
from navkit.errors import InputError
from navkit.geometry._validate import check_settings
from navkit.path.spline import PathSpline

__all__ = [
    "Detour",
    "DetourFailure",
    "DetourSettings",
    "clearance_map",
    "grid_shortest_path",
    "plan_detour",
    "polyline_spline",
]

log = logging.getLogger(__name__)

_SQRT2 = float(np.sqrt(2.0))


@dataclass(frozen=True)
class DetourFailure:
    """No collision-free way round the blocked stretch exists on the grid (a returned value,
    like :class:`navkit.planes.MotionFailure`, not an exception).

    Attributes
    ----------
    reason : str
        ``"start enclosed"``, ``"no free path point beyond the block"``, ``"no path to the
        rejoin"`` (the way is closed) or ``"path not blocked"``.
    detail : str
        The numbers behind the reason.
    """

    reason: str
    detail: str = ""

    ok = False

    def __str__(self) -> str:
        return f"no detour: {self.reason}" + (f" ({self.detail})" if self.detail else "")


#: A length or distance, metres, that must be positive (a radius, a search length).
_METRES = Domain(lo=0.0, lo_open=True, note="metres")
#: A clearance or offset, metres, that may be 0.
_METRES_OR_0 = Domain(lo=0.0, note="metres")


@dataclass(frozen=True)
class DetourSettings:
    """Settings of the detour planner (SI units).

    Attributes
    ----------
    robot_radius : float
        Half the robot's width: a cell closer than this to an obstacle is a collision, metres.
    margin : float
        Extra clearance of the planned path: it keeps ``robot_radius + margin`` from every
        occupied cell centre, metres.
    rejoin_offset : float
        The rejoin point lies at least this far along the stored path beyond the blocked
        stretch (about the return controller's look-ahead), metres.
    search_length : float
        Length of stored path ahead that is searched for the block and the rejoin point, metres.
    window_pad : float
        The search area is the bounding box of the robot and that path stretch grown by this;
        it bounds how far the detour may swing out, metres.
    escape_radius : float
        How far a robot standing in the inflated zone may move inside it to get out, metres.
    escape_penalty : float
        Cost factor of a step inside the inflated zone (escape only).
    """

    robot_radius: float = domain_field(0.3, _METRES)
    margin: float = domain_field(0.1, _METRES_OR_0)
    rejoin_offset: float = domain_field(0.5, _METRES_OR_0)
    search_length: float = domain_field(8.0, _METRES)
    window_pad: float = domain_field(3.0, _METRES)
    escape_radius: float = domain_field(0.6, _METRES_OR_0)
    escape_penalty: float = domain_field(5.0, Domain(lo=1.0, note="a cost factor"))

    def __post_init__(self) -> None:
        check_settings(self)

    @property
    def inflation(self) -> float:
        """``robot_radius + margin``, metres."""
        return self.robot_radius + self.margin


@dataclass(frozen=True)
class Detour:
    """A planned way round a blocked stretch of the stored path.

    Attributes
    ----------
    points : (N, 2) array
        The smoothed detour, from the robot's position to the rejoin point, metres.
    raw_points : (K, 2) array
        The 8-connected grid path (cell centres) it was smoothed from, metres.
    length, raw_length : float
        Lengths of the two polylines, metres.
    rejoin_index : int
        Index of the rejoin point in the ``path_xy`` given to :func:`plan_detour`.
    rejoin_arclength : float
        Arc length of the rejoin point along ``path_xy``, metres.
    blocked_from, blocked_to : float
        Arc lengths along ``path_xy`` of the blocked stretch (inflated zone), metres.
    min_clearance : float
        Smallest distance from the smoothed detour (sampled every quarter cell) to an occupied
        cell centre, metres (``inf`` when nothing is occupied in the search window).
    """

    points: NDArray[np.float64]
    raw_points: NDArray[np.float64]
    length: float
    raw_length: float
    rejoin_index: int
    rejoin_arclength: float
    blocked_from: float
    blocked_to: float
    min_clearance: float

    @property
    def rejoin(self) -> NDArray[np.float64]:
        """``(2,)`` the rejoin point, metres."""
        return self.points[-1]


def _sample_polyline(P: NDArray[np.float64], step: float) -> NDArray[np.float64]:
    """Points ``(K, 2)`` along a polyline ``(N, 2)``: its vertices and at most ``step`` apart."""
    if len(P) < 2:
        return P.copy()
    d = np.diff(P, axis=0)
    n = np.maximum(np.ceil(np.hypot(*d.T) / step).astype(int), 1)
    i_seg = np.repeat(np.arange(len(n)), n)
    u = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n, n)
    return np.vstack([P[i_seg] + u[:, None] * d[i_seg], P[-1:]])


def _polyline_length(P: NDArray[np.float64]) -> float:
    return float(np.hypot(*np.diff(P, axis=0).T).sum()) if len(P) > 1 else 0.0


def clearance_map(occupied: NDArray[np.bool_], resolution: float) -> NDArray[np.float64]:
    """Distance ``(H, W)`` from each cell centre to the nearest occupied cell centre, metres.

    ``inf`` everywhere when nothing is occupied.
    """
    if not occupied.any():
        return np.full(occupied.shape, np.inf)
    return ndimage.distance_transform_edt(~occupied) * float(resolution)


def grid_shortest_path(
    allowed: NDArray[np.bool_],
    start: tuple[int, int],
    cost_factor: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.int32]]:
    """Dijkstra from ``start`` on the 8-connected graph of the ``allowed`` cells.

    Parameters
    ----------
    allowed : (H, W) bool array
        Traversable cells (row = y, column = x).
    start : (row, col)
    cost_factor : (H, W) array, optional
        Per-cell factor >= 1; an edge costs its length times the larger factor of its two cells.

    Returns
    -------
    dist : (H, W) array
        Path length in cells (straight step 1, diagonal ``sqrt 2``) times the cost factors;
        ``inf`` where unreachable.
    pred : (H * W,) int array
        Predecessor (flat index) of each cell on its shortest path; -9999 for none.
    """
    H, W = allowed.shape
    idx = np.arange(H * W).reshape(H, W)
    f = np.ones((H, W)) if cost_factor is None else cost_factor
    rows, cols, wts = [], [], []
    # the four "forward" neighbour directions; the graph is undirected
    for dr, dc, step in ((0, 1, 1.0), (1, 0, 1.0), (1, 1, _SQRT2), (1, -1, _SQRT2)):
        r0, r1 = slice(0, H - dr), slice(dr, H)
        c0, c1 = (slice(0, W - dc), slice(dc, W)) if dc >= 0 else (slice(-dc, W), slice(0, W + dc))
        ok = allowed[r0, c0] & allowed[r1, c1]
        if dr and dc:
            # no corner cutting: a diagonal step needs both orthogonal neighbours free
            ok &= allowed[r1, c0] & allowed[r0, c1]
        rows.append(idx[r0, c0][ok])
        cols.append(idx[r1, c1][ok])
        wts.append(step * np.maximum(f[r0, c0], f[r1, c1])[ok])
    graph = coo_matrix(
        (np.concatenate(wts), (np.concatenate(rows), np.concatenate(cols))), shape=(H * W, H * W)
    ).tocsr()
    s = int(idx[start])
    dist, pred = dijkstra(graph, directed=False, indices=s, return_predecessors=True)
    return dist.reshape(H, W), pred


def _segments_clear(
    a: NDArray[np.float64],
    B: NDArray[np.float64],
    allowed: NDArray[np.bool_],
    origin: NDArray[np.float64],
    resolution: float,
) -> NDArray[np.bool_]:
    """For segments from ``a (2,)`` to each of ``B (M, 2)``: do all their samples (every quarter
    cell) lie on allowed cells?"""
    L = np.hypot(*(B - a).T)
    n = np.maximum(np.ceil(L / (0.25 * resolution)).astype(int), 1) + 1
    seg = np.repeat(np.arange(len(B)), n)
    starts = np.concatenate([[0], np.cumsum(n)[:-1]])
    u = (np.arange(n.sum()) - np.repeat(starts, n)) / np.repeat(n - 1, n)
    P = a + u[:, None] * (B[seg] - a)
    ij = np.floor((P - origin) / resolution).astype(int)
    H, W = allowed.shape
    inside = (ij[:, 0] >= 0) & (ij[:, 1] >= 0) & (ij[:, 0] < W) & (ij[:, 1] < H)
    ok = np.zeros(len(P), dtype=bool)
    ok[inside] = allowed[ij[inside, 1], ij[inside, 0]]
    return np.minimum.reduceat(ok.astype(np.int8), starts).astype(bool)


def _shortcut(
    P: NDArray[np.float64],
    allowed: NDArray[np.bool_],
    origin: NDArray[np.float64],
    resolution: float,
) -> NDArray[np.float64]:
    """Greedy line-of-sight shortcutting of a polyline ``(K, 2)`` (a loop over kept vertices;
    each step tests all later vertices at once)."""
    keep = [0]
    i = 0
    while i < len(P) - 1:
        ok = _segments_clear(P[i], P[i + 1 :], allowed, origin, resolution)
        far = np.nonzero(ok)[0]
        i = i + 1 + (int(far[-1]) if len(far) else 0)
        keep.append(i)
    return P[keep]


def plan_detour(
    occupied: ArrayLike,
    resolution: float,
    origin: ArrayLike,
    start: ArrayLike,
    path_xy: ArrayLike,
    settings: DetourSettings | None = None,
    *,
    block_index: int | None = None,
) -> Detour | DetourFailure:
    """Plan a collision-free way from ``start`` round the blocked stretch of ``path_xy``.

    Parameters
    ----------
    occupied : (H, W) bool array
        Occupancy grid, row = y, column = x; cell ``(r, c)`` covers
        ``origin + [c, r] * resolution`` to ``origin + [c + 1, r + 1] * resolution``.
    resolution : float
        Cell size, metres.
    origin : (2,) array
        World position of the grid's lower-left corner, metres.
    start : (2,) array
        The robot's position, metres.
    path_xy : (M, 2) array
        The stored path still ahead of the robot, in the order it will be driven (towards home),
        metres; it is resampled every half cell up to ``settings.search_length``.
    settings : DetourSettings, optional
    block_index : int, optional
        Index into ``path_xy`` of a point known to be blocked (the caller's check); the blocked
        stretch is the one containing it. Default: the first sample closer than
        ``robot_radius`` to an occupied cell.

    Returns
    -------
    Detour or DetourFailure
        Smoothed polyline from ``start`` to the rejoin point on ``path_xy``, or why there is no
        way round within the searched area (see :class:`DetourFailure` for the reasons).

    Raises
    ------
    InputError
        Arrays of the wrong shape.
    """
    st = settings or DetourSettings()
    occ = np.asarray(occupied, dtype=bool)
    if occ.ndim != 2 or occ.size == 0:
        raise InputError(f"has shape {occ.shape}", field="occupied", expected="(H, W) bool grid")
    res = float(resolution)
    if not (np.isfinite(res) and res > 0):
        raise InputError(f"is {resolution}", field="resolution", expected="a positive cell size")
    org = np.asarray(origin, dtype=np.float64).reshape(-1)
    a = np.asarray(start, dtype=np.float64).reshape(-1)
    Q = np.asarray(path_xy, dtype=np.float64)
    if org.shape != (2,) or a.shape != (2,) or not np.isfinite(a).all():
        raise InputError(
            f"origin {org.shape}, start {a.shape}", field="start", expected="finite (2,) x, y"
        )
    if Q.ndim != 2 or Q.shape[1] != 2 or len(Q) < 2 or not np.isfinite(Q).all():
        raise InputError(
            f"has shape {Q.shape}", field="path_xy", expected="(M >= 2, 2) finite x, y in metres"
        )
    # 1. resample the path ahead every half cell (arc length s), up to the searched length
    cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(Q, axis=0).T))])
    s_end = min(float(cum[-1]), st.search_length)
    s = np.linspace(0.0, s_end, max(int(np.ceil(s_end / (0.5 * res))), 1) + 1)
    S = np.c_[np.interp(s, cum, Q[:, 0]), np.interp(s, cum, Q[:, 1])]
    # 2. the search window: robot and path stretch, grown by the pad, clipped to the grid
    H0, W0 = occ.shape
    lo = np.minimum(S.min(0), a) - st.window_pad
    hi = np.maximum(S.max(0), a) + st.window_pad
    c0, r0 = np.clip(np.floor((lo - org) / res).astype(int), 0, [W0, H0])
    c1, r1 = np.clip(np.ceil((hi - org) / res).astype(int) + 1, 0, [W0, H0])
    if c1 - c0 < 2 or r1 - r0 < 2:
        return DetourFailure("start enclosed", "the robot and the path lie outside the grid")
    sub = occ[r0:r1, c0:c1]
    o = org + res * np.array([c0, r0])
    H, W = sub.shape
    # 3. clearance and inflation (configuration space of a disc robot + margin)
    clear = clearance_map(sub, res)
    free = clear >= st.inflation

    def cell(
        p: NDArray[np.float64],
    ) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
        ij = np.floor((np.atleast_2d(p) - o) / res).astype(np.intp)
        ok = (ij[:, 0] >= 0) & (ij[:, 1] >= 0) & (ij[:, 0] < W) & (ij[:, 1] < H)
        return np.clip(ij[:, 1], 0, H - 1), np.clip(ij[:, 0], 0, W - 1), ok

    # clearance of the path samples and of the robot
    rs, cs, oks = cell(S)
    c_path = np.where(oks, clear[rs, cs], 0.0)
    rr, cc, oka = cell(a)
    if not oka[0]:
        return DetourFailure("start enclosed", "the robot lies outside the grid")
    start_rc = (int(rr[0]), int(cc[0]))
    # 4. the blocked stretch: a collision sample and the inflated-zone run around it
    if block_index is not None:
        bi = int(np.clip(block_index, 0, len(Q) - 1))
        k0 = int(np.clip(np.searchsorted(s, cum[bi]), 0, len(s) - 1))
        if c_path[k0] >= st.inflation:
            # the caller's blocked point: take the nearest sample in the inflated zone after it
            later = np.nonzero(c_path[k0:] < st.inflation)[0]
            if len(later) == 0:
                return DetourFailure("path not blocked", "no path sample within the inflated zone")
            k0 += int(later[0])
    else:
        hard = np.nonzero(c_path < st.robot_radius)[0]
        if len(hard) == 0:
            return DetourFailure("path not blocked", "no path sample closer than the robot radius")
        k0 = int(hard[0])
    free_path = c_path >= st.inflation
    after = np.nonzero(free_path[k0:])[0]
    if len(after) == 0:
        return DetourFailure(
            "no free path point beyond the block",
            f"the path stays blocked over the {s_end:.1f} m searched",
        )
    k1 = k0 + int(after[0])  # first free sample beyond the blocked stretch
    before = np.nonzero(free_path[: k0 + 1])[0]
    kb = int(before[-1]) + 1 if len(before) else 0
    cand = np.nonzero(free_path & (s >= s[k1] + st.rejoin_offset) & oks)[0]
    if len(cand) == 0:
        cand = np.nonzero(free_path & (np.arange(len(s)) >= k1) & oks)[0]
    # 5. the traversable cells; a robot standing in the inflated zone may escape it
    allowed = free.copy()
    factor = np.ones((H, W))
    if not free[start_rc]:
        yy, xx = np.mgrid[0:H, 0:W]
        near = np.hypot(yy - start_rc[0], xx - start_rc[1]) * res <= st.escape_radius
        zone = (clear >= st.robot_radius) & near & ~free
        zone[start_rc] = True
        lab, _ = ndimage.label(zone, structure=np.ones((3, 3), bool))
        escape = lab == lab[start_rc]
        allowed |= escape
        factor[escape] = st.escape_penalty
    # 6. Dijkstra from the robot; the rejoin point is the first reachable candidate
    dist, pred = grid_shortest_path(allowed, start_rc, factor)
    reach = np.isfinite(dist[rs[cand], cs[cand]])
    if not reach.any():
        if np.isfinite(dist).sum() <= 1:
            return DetourFailure("start enclosed", "no free cell around the robot")
        return DetourFailure(
            "no path to the rejoin",
            f"the way past the block ({s[k0]:.1f} m ahead) is closed within the searched area",
        )
    kr = int(cand[np.argmax(reach)])
    goal = int(rs[kr] * W + cs[kr])
    # walk the predecessors back to the start (a loop over the path's cells)
    chain = [goal]
    s_flat = start_rc[0] * W + start_rc[1]
    while chain[-1] != s_flat:
        chain.append(int(pred[chain[-1]]))
    chain_a = np.array(chain[::-1])
    raw = o + (np.c_[chain_a % W, chain_a // W] + 0.5) * res
    raw = np.vstack([a, raw[1:-1], S[kr]])
    # 7. shortcut smoothing on the traversable cells (with the escape zone)
    pts = _shortcut(raw, allowed, o, res)
    # clearance of the smoothed path: its samples (every quarter cell) to the occupied centres
    rows_o, cols_o = np.nonzero(sub)
    min_clear = (
        float(
            cKDTree(o + (np.c_[cols_o, rows_o] + 0.5) * res)
            .query(_sample_polyline(pts, 0.25 * res))[0]
            .min()
        )
        if len(rows_o)
        else float("inf")
    )
    rejoin_index = int(np.clip(np.searchsorted(cum, s[kr], side="right") - 1, 0, len(Q) - 1))
    det = Detour(
        points=pts,
        raw_points=raw,
        length=_polyline_length(pts),
        raw_length=_polyline_length(raw),
        rejoin_index=rejoin_index,
        rejoin_arclength=float(s[kr]),
        blocked_from=float(s[kb]),
        blocked_to=float(s[k1]),
        min_clearance=min_clear,
    )
    log.debug(
        "detour %.1f m (grid %.1f m) round the block at %.1f-%.1f m, rejoining at %.1f m",
        det.length,
        det.raw_length,
        det.blocked_from,
        det.blocked_to,
        det.rejoin_arclength,
    )
    return det


def polyline_spline(points: ArrayLike) -> PathSpline:
    """A :class:`PathSpline` made of the straight segments of a polyline ``(N, 2)``.

    Each segment is a degenerate cubic ``x(u) = x_k + u (x_{k+1} - x_k) / L_k`` over its arc
    length, so paper 4's return controller can follow a polyline; zero-length segments are
    dropped. The spline starts at ``points[0]``.
    """
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 2:
        raise InputError(f"has shape {P.shape}", field="points", expected="(N, 2) x, y in metres")
    d = np.diff(P, axis=0)
    L = np.hypot(*d.T)
    keep = L > 1e-9
    P0, d, L = P[:-1][keep], d[keep], L[keep]
    if len(L) == 0:
        raise InputError("has zero length", field="points", expected="a polyline of length > 0")
    z = np.zeros(len(L))
    ax = np.c_[P0[:, 0], d[:, 0] / L, z, z]
    ay = np.c_[P0[:, 1], d[:, 1] / L, z, z]
    return PathSpline.from_segments(L, ax, ay, tolerance=0.0, frame={"kind": "detour polyline"})
