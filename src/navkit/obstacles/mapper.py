"""The global 2D obstacle map: paper 1's per-scan obstacles fused over time (online).

:class:`ObstacleMapper` is the online object of paper 1 (kiss-icp shaped): built from frozen
:class:`ObstacleMapperSettings` and the mapped area, it takes one detection at a time
(:meth:`ObstacleMapper.update`, an :class:`~navkit.obstacles.ObstacleDetection` and the
sensor's pose in the map frame) and keeps the evidence grid.

Fusion: every scan's obstacle vertices (class ``OBSTACLE`` with ``vertex_obstacle > 0``, i.e.
the obstacle's own vertices, not the shadows it owns) and all its valid points within
``max_range`` of the sensor are moved into the map frame and counted per cell, once per scan:
``hits`` (an obstacle was seen in the cell) and ``seen`` (anything was seen there). A cell is an
obstacle when ``hits >= min_hits`` and ``hits / seen >= min_ratio`` - one-scan noise and cells
that later scans see as ground are dropped. Obstacles are the 8-connected components of those
cells (with a one-cell closing so a face seen in stripes stays one obstacle).

The map frame is 2D: ``T_world_sensor`` may be a planar ``(3, 3)`` transform (the points' x, y
are moved with it, z is ignored) or a ``(4, 4)`` one (the points are moved in 3D, then
projected). Decision: the grid covers a fixed area given at construction (the mission knows its
world's bounds); points outside it are dropped, not an error.

Scoring the map against true footprints is evaluation, not mapping:
:func:`navkit.obstacles.evaluate.score_obstacle_map`.
"""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage
from scipy.spatial import cKDTree

from navkit.domains import POSITIVE_INT, Domain, domain_field
from navkit.errors import InputError
from navkit.geometry._validate import check_grid_size, check_settings
from navkit.jit import kernels_enabled
from navkit.obstacles.detector import ObstacleDetection
from navkit.obstacles.rules import OBSTACLE
from navkit.results import Result, deprecated_alias

__all__ = [
    "MapUpdate",
    "MappedObstacle",
    "ObstacleGrid",
    "ObstacleMapper",
    "ObstacleMapperSettings",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ObstacleMapperSettings:
    """Settings of :class:`ObstacleMapper` (SI units).

    Attributes
    ----------
    resolution : float
        Cell size, metres.
    min_hits : int
        Scans that must see an obstacle in a cell before it counts.
    min_ratio : float
        ... and the fraction of the scans that saw the cell at all that saw an obstacle there.
    recent_scans : int
        Length of the short memory used to check the way ahead (:meth:`ObstacleMapper.blocked`).
    max_range : float
        Points farther than this from the sensor (horizontally) are not fused, metres.
    """

    resolution: float = domain_field(0.1, Domain(lo=0.0, lo_open=True, note="metres"))
    min_hits: int = domain_field(2, POSITIVE_INT)
    min_ratio: float = domain_field(0.3, Domain(lo=0.0, hi=1.0, note="a fraction"))
    recent_scans: int = domain_field(4, POSITIVE_INT)
    max_range: float = domain_field(15.0, Domain(lo=0.0, lo_open=True, note="metres"))

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class MappedObstacle:
    """One obstacle of the map: a connected component of obstacle cells.

    Attributes
    ----------
    id : int
        Component label (1..n) in :meth:`ObstacleGrid.components`.
    cells : int
    centre : (2,) array
        Mean of the cell centres, metres.
    area_m2 : float
    """

    id: int
    cells: int
    centre: NDArray[np.float64]
    area_m2: float


@dataclass(frozen=True)
class ObstacleGrid:
    """A snapshot of the evidence grid (rows = y, columns = x).

    Attributes
    ----------
    origin : (2,) array
        World position of the lower-left corner of cell ``(0, 0)``, metres.
    resolution : float
        Cell size, metres.
    hits, seen : (H, W) int32 arrays
        Scans that saw an obstacle / anything in each cell.
    occupied : (H, W) bool array
        Confirmed obstacle cells.
    """

    origin: NDArray[np.float64]
    resolution: float
    hits: NDArray[np.int32]
    seen: NDArray[np.int32]
    occupied: NDArray[np.bool_]

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.hits.shape[0]), int(self.hits.shape[1]))

    def centres(self, rows: ArrayLike, cols: ArrayLike) -> NDArray[np.float64]:
        """World centres ``(N, 2)`` of cells."""
        return _centres(self.origin, self.resolution, rows, cols)

    def components(self) -> tuple[NDArray[np.int32], int]:
        """Labels ``(H, W)`` (0 = free) of the obstacles and their number."""
        return _components(self.occupied)


def _centres(
    origin: NDArray[np.float64], resolution: float, rows: ArrayLike, cols: ArrayLike
) -> NDArray[np.float64]:
    return origin + (np.c_[cols, rows] + 0.5) * resolution


def _components(occ: NDArray[np.bool_]) -> tuple[NDArray[np.int32], int]:
    closed = ndimage.binary_closing(occ, structure=np.ones((3, 3), bool)) | occ
    labels, _ = ndimage.label(closed, structure=np.ones((3, 3), bool))
    labels = np.where(occ, labels, 0).astype(np.int32)
    present = np.unique(labels[labels > 0])
    remap = np.zeros(int(labels.max()) + 1, dtype=np.int32)
    remap[present] = np.arange(1, len(present) + 1, dtype=np.int32)
    return remap[labels], len(present)


def scan_points_2d(
    detection: ObstacleDetection, T_world_sensor: ArrayLike, max_range: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The obstacle points and all valid points of one detection within ``max_range``, in the
    map frame: two ``(N, 2)`` arrays (see the module docstring for the transform)."""
    P = detection.points
    r2 = P[..., 0] ** 2 + P[..., 1] ** 2
    near = detection.valid & (r2 <= max_range**2)
    # obstacle vertices only (vertex_obstacle also marks the shadows an obstacle owns)
    is_obst = (detection.vertex_labels == OBSTACLE) & (detection.vertex_obstacle > 0)
    T = np.asarray(T_world_sensor, dtype=np.float64)
    if T.shape == (3, 3):
        R, t = T[:2, :2], T[:2, 2]
        obst = P[near & is_obst][:, :2] @ R.T + t
        seen = P[near][:, :2] @ R.T + t
    elif T.shape == (4, 4):
        R3, t3 = T[:3, :3], T[:3, 3]
        obst = (P[near & is_obst] @ R3.T + t3)[:, :2]
        seen = (P[near] @ R3.T + t3)[:, :2]
    else:
        raise InputError(
            f"has shape {T.shape}",
            field="T_world_sensor",
            expected="a (3, 3) planar or (4, 4) rigid transform",
        )
    return obst, seen


def _scan_flat(
    P: NDArray[np.float64],
    valid: NDArray[np.bool_],
    vlab: NDArray[np.int8],
    vobs: NDArray[np.int32],
    S: NDArray[np.float64],
    o: NDArray[np.float64],
    max_r2: float,
    H: int,
    W: int,
) -> tuple[NDArray[np.intp], NDArray[np.bool_]]:
    """The flat cells (row-major, with repeats, in point order) of the valid points within
    ``sqrt(max_r2)`` of the sensor that fall inside the ``(H, W)`` grid, and which of them are
    obstacle vertices. A point's column / row: ``floor(((x S[j, 0] + y S[j, 1]) + z S[j, 2]) +
    o[j])``, each operation rounded in this order (``map_cells_kernel``'s)."""
    x, y, z = P[:, 0], P[:, 1], P[:, 2]
    near = np.flatnonzero(valid & (x * x + y * y <= max_r2))
    xn, yn, zn = x[near], y[near], z[near]
    with np.errstate(invalid="ignore", over="ignore"):
        cr = []
        for j in range(2):
            c = xn * S[j, 0]
            c += yn * S[j, 1]
            c += zn * S[j, 2]
            c += o[j]
            cr.append(np.floor(c, out=c))
        cols, rows = cr
        # decided on the floats (NaN fails), converted in range: a far point's index may not
        # fit an integer
        ok = (cols >= 0) & (rows >= 0) & (cols < W) & (rows < H)
    flat = rows[ok].astype(np.intp) * W + cols[ok].astype(np.intp)
    k = near[ok]
    return flat, (vlab[k] == OBSTACLE) & (vobs[k] > 0)


def count_scan_cells(
    P: NDArray[np.float64],
    valid: NDArray[np.bool_],
    vlab: NDArray[np.int8],
    vobs: NDArray[np.int32],
    S: NDArray[np.float64],
    o: NDArray[np.float64],
    max_r2: float,
    H: int,
    W: int,
    hits: NDArray[np.int32],
    seen: NDArray[np.int32],
    mark: NDArray[np.uint8],
    box: NDArray[np.int64],
) -> tuple[NDArray[np.intp], int]:
    """Count one scan into the flat ``(H * W,)`` grids ``hits`` and ``seen`` (in place): each
    cell an obstacle vertex fell in once in ``hits``, each cell any counted point fell in once
    in ``seen`` (points as :func:`_scan_flat`). ``mark`` ``(H * W,)`` uint8 is scratch, zero on
    entry and on return; ``box`` ``(4,)`` (row min, row max, column min, column max) grows in
    place to hold every cell seen. Returns the scan's obstacle cells (ascending, each once) and
    the number of distinct cells seen. NumPy's buffered fancy-index increment counts a repeated
    index once; the NumPy twin of ``map_cells_kernel``."""
    flat, is_obst = _scan_flat(P, valid, vlab, vobs, S, o, max_r2, H, W)
    obst = flat[is_obst]
    hits[obst] += 1
    seen[flat] += 1
    _grow_box(box, flat, W)
    mark[obst] = 1  # the scan's obstacle cells, once each
    cells = np.flatnonzero(mark)
    mark[flat] = 1  # and the seen ones
    n_seen = int(np.count_nonzero(mark))
    mark[flat] = 0
    return cells, n_seen


def _grow_box(box: NDArray[np.int64], flat: NDArray[np.intp], W: int) -> None:
    """Grow ``box`` (row min, row max, column min, column max; in place) to hold the flat
    (row-major, width ``W``) cells ``flat``."""
    if flat.size:
        rows, cols = np.divmod(flat, W)
        box[:] = (
            min(box[0], rows.min()),
            max(box[1], rows.max()),
            min(box[2], cols.min()),
            max(box[3], cols.max()),
        )


def _empty_box(shape: tuple[int, int]) -> NDArray[np.int64]:
    """The box of no cell: minima past the grid's end, maxima before its start."""
    return np.array([shape[0], -1, shape[1], -1], dtype=np.int64)


@dataclass(frozen=True)
class MapUpdate(Result):
    """What one :meth:`ObstacleMapper.update` fused.

    Attributes
    ----------
    scan : int
        The scan's index (0 = the first fused).
    obstacle_cells : int
        Distinct cells the scan saw an obstacle in, inside the mapped area.
    seen_cells : int
        Distinct cells the scan's valid points fell in, inside the mapped area.
    """

    scan: int
    obstacle_cells: int
    seen_cells: int


class ObstacleMapper:
    """Fuses obstacle detections into a 2D evidence grid (the online object of paper 1).

    Parameters
    ----------
    lo, hi : (2,) arrays
        Corners of the mapped area, metres.
    settings : ObstacleMapperSettings, optional

    Examples
    --------
    >>> mapper = ObstacleMapper([-10, -10], [10, 10])            # doctest: +SKIP
    >>> for scan, T in stream:                                    # doctest: +SKIP
    ...     mapper.update(detect_obstacles(scan), T)
    >>> grid, obstacles = mapper.grid(), mapper.obstacles()       # doctest: +SKIP
    """

    def __init__(
        self, lo: ArrayLike, hi: ArrayLike, settings: ObstacleMapperSettings | None = None
    ):
        self.settings = st = settings or ObstacleMapperSettings()
        self.origin = np.asarray(lo, dtype=np.float64)
        self.resolution = float(st.resolution)
        with np.errstate(invalid="ignore", over="ignore"):
            fsize = np.ceil((np.asarray(hi, dtype=np.float64) - self.origin) / self.resolution) + 1
        if fsize.shape != (2,) or not (fsize >= 1).all() or not np.isfinite(fsize).all():
            raise InputError(
                f"lo={lo!r}, hi={hi!r}", field="lo/hi", expected="finite, hi >= lo, (2,) each"
            )
        # the grid's size before it is allocated (a clear error, not a MemoryError)
        check_grid_size((fsize[1], fsize[0]), setting="resolution", source="ObstacleMapper lo/hi")
        size = fsize.astype(int)
        self.shape = (int(size[1]), int(size[0]))  # rows = y, columns = x
        self.hits = np.zeros(self.shape, dtype=np.int32)
        self.seen = np.zeros(self.shape, dtype=np.int32)
        self.n_scans = 0
        self.recent: deque[NDArray[np.intp]] = deque(maxlen=int(st.recent_scans))
        self.known: NDArray[np.bool_] | None = None
        self._mark: NDArray[np.uint8] | None = None
        # rows and columns (min, max) holding every cell any scan fell in: outside it hits and
        # seen are zero, so the map's read-outs scan this window, not the whole area
        self._box = _empty_box(self.shape)

    def __getstate__(self) -> dict[str, object]:
        state = dict(self.__dict__)
        state["_mark"] = None  # scratch (all zero): not part of the map
        return state

    # --- the online interface ------------------------------------------------------------------
    def update(self, detection: ObstacleDetection, T_world_sensor: ArrayLike) -> MapUpdate:
        """Fuse one detection seen from ``T_world_sensor`` (``(3, 3)`` or ``(4, 4)``): the
        online object's one verb (``docs/architecture.md``, "Online objects").

        The same counts as :meth:`add_points` on :func:`scan_points_2d`'s points, in one pass
        over the cloud (:func:`count_scan_cells`; compiled: ``map_cells_kernel``, one loop that
        computes each point's cell and counts it once per scan). Points outside the mapped area
        are dropped (counted in the result), never an error."""
        args = self._scan_args(detection, T_world_sensor)
        hits, seen = self.hits.reshape(-1), self.seen.reshape(-1)  # views: counted in place
        mark = getattr(self, "_mark", None)  # per-scan scratch, kept zero between scans
        if mark is None or mark.size != hits.size:
            mark = self._mark = np.zeros(hits.size, dtype=np.uint8)
        box = self._window_box()
        if kernels_enabled():
            from navkit.obstacles._kernels_grid import map_cells_kernel

            cells, n_seen = map_cells_kernel(*args, hits, seen, mark, box)
        else:
            cells, n_seen = count_scan_cells(*args, hits, seen, mark, box)
        self.recent.append(cells)
        self.n_scans += 1
        return MapUpdate(self.n_scans - 1, len(cells), int(n_seen))

    def add_scan(self, detection: ObstacleDetection, T_world_sensor: ArrayLike) -> None:
        """Deprecated alias of :meth:`update` (kept for one release)."""
        deprecated_alias("ObstacleMapper.add_scan", "ObstacleMapper.update")
        self.update(detection, T_world_sensor)

    def scan_cells(
        self, detection: ObstacleDetection, T_world_sensor: ArrayLike
    ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Flat grid indices (row-major, with repeats) of one detection's obstacle points and of
        all its valid points within ``max_range``, inside the grid (see :func:`scan_points_2d`
        for which points and the transform)."""
        flat, is_obst = _scan_flat(*self._scan_args(detection, T_world_sensor))
        return flat[is_obst], flat

    def _scan_args(
        self, detection: ObstacleDetection, T_world_sensor: ArrayLike
    ) -> tuple[
        NDArray[np.float64],
        NDArray[np.bool_],
        NDArray[np.int8],
        NDArray[np.int32],
        NDArray[np.float64],
        NDArray[np.float64],
        float,
        int,
        int,
    ]:
        """The arguments of :func:`count_scan_cells` but the counts: the detection's points,
        validity, classes and obstacle ids flattened (contiguous, one dtype each, so the kernel
        has one signature), and the map-cell transform ``S (2, 3)``, ``o (2,)`` (a point ``p``'s
        column and row are ``floor(S p + o)``)."""
        T = np.asarray(T_world_sensor, dtype=np.float64)
        if T.shape == (3, 3):
            A = np.zeros((2, 4))
            A[:, :2], A[:, 3] = T[:2, :2], T[:2, 2]
        elif T.shape == (4, 4):
            A = T[:2]
        else:
            raise InputError(
                f"has shape {T.shape}",
                field="T_world_sensor",
                expected="a (3, 3) planar or (4, 4) rigid transform",
            )
        S = np.ascontiguousarray(A[:, :3] / self.resolution)
        o = (A[:, 3] - self.origin) / self.resolution
        return (
            np.ascontiguousarray(detection.points, dtype=np.float64).reshape(-1, 3),
            np.ascontiguousarray(detection.valid, dtype=np.bool_).reshape(-1),
            np.ascontiguousarray(detection.vertex_labels, dtype=np.int8).reshape(-1),
            np.ascontiguousarray(detection.vertex_obstacle, dtype=np.int32).reshape(-1),
            S,
            o,
            float(self.settings.max_range) ** 2,
            self.shape[0],
            self.shape[1],
        )

    def _window_box(self) -> NDArray[np.int64]:
        """The box of the cells seen so far (see ``__init__``); a state restored without one
        gets it from ``seen``."""
        box = getattr(self, "_box", None)
        if box is None:
            box = self._box = _empty_box(self.shape)
            _grow_box(box, np.flatnonzero(self.seen), self.shape[1])
        return box

    def window(self) -> tuple[slice, slice]:
        """Rows and columns of the smallest box holding every cell any scan fell in (empty
        before the first): ``hits`` and ``seen`` are zero outside it."""
        r0, r1, c0, c1 = self._window_box().tolist()
        if r1 < r0:
            return slice(0, 0), slice(0, 0)
        return slice(r0, r1 + 1), slice(c0, c1 + 1)

    def occupancy(self) -> NDArray[np.int8]:
        """The map as an occupancy grid ``(H, W)`` int8: -1 never seen, 0 seen and not an
        obstacle, 100 a confirmed obstacle cell (:meth:`occupied_cells`)."""
        occ = np.full(self.shape, -1, dtype=np.int8)
        rows, cols = self.window()
        # 1 seen, 0 never: minus 1 gives 0 / -1
        np.subtract((self.seen[rows, cols] > 0).view(np.int8), 1, out=occ[rows, cols])
        occ.reshape(-1)[self.occupied_cells()] = 100
        return occ

    def grid(self) -> ObstacleGrid:
        """A snapshot of the grid (copies: later scans do not change it)."""
        return ObstacleGrid(
            self.origin.copy(), self.resolution, self.hits.copy(), self.seen.copy(), self.occupied
        )

    def obstacles(self) -> list[MappedObstacle]:
        """The obstacles of the map (connected components of the confirmed cells)."""
        labels, n = self.components()
        rows, cols = np.nonzero(labels)
        lab = labels[rows, cols]
        C = self.centres(rows, cols)
        out = []
        for k in range(1, n + 1):
            m = lab == k
            out.append(
                MappedObstacle(
                    k, int(m.sum()), C[m].mean(axis=0), float(m.sum() * self.resolution**2)
                )
            )
        return out

    # --- the grid ------------------------------------------------------------------------------
    def add_points(self, obstacle_xy: ArrayLike, seen_xy: ArrayLike) -> None:
        """Count one scan given as map-frame points: obstacle points and all valid points, both
        ``(N, 2)``."""
        obstacle_xy = np.asarray(obstacle_xy, dtype=np.float64).reshape(-1, 2)
        seen_xy = np.asarray(seen_xy, dtype=np.float64).reshape(-1, 2)
        self.recent.append(self._count(self.hits, obstacle_xy))
        flat = self._count(self.seen, np.vstack([seen_xy, obstacle_xy]))
        _grow_box(self._window_box(), flat, self.shape[1])
        self.n_scans += 1

    def cells(
        self, xy: NDArray[np.float64]
    ) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
        """Row, column and in-grid flag of points ``(N, 2)``."""
        with np.errstate(invalid="ignore", over="ignore"):
            f = np.floor((xy - self.origin) / self.resolution)
            # decided on the floats (NaN fails), converted once in range: a far point's index
            # may not fit an integer
            ok = (
                (f[:, 0] >= 0)
                & (f[:, 1] >= 0)
                & (f[:, 0] < self.shape[1])
                & (f[:, 1] < self.shape[0])
            )
        ij = np.where(ok[:, None], f, 0.0).astype(np.intp)
        return ij[:, 1], ij[:, 0], ok

    def centres(self, rows: ArrayLike, cols: ArrayLike) -> NDArray[np.float64]:
        """World centres ``(N, 2)`` of cells."""
        return _centres(self.origin, self.resolution, rows, cols)

    def _count(self, grid: NDArray[np.int32], xy: NDArray[np.float64]) -> NDArray[np.intp]:
        r, c, ok = self.cells(xy)
        flat = np.unique(r[ok] * self.shape[1] + c[ok])  # once per scan
        grid.reshape(-1)[flat] += 1
        return flat

    @property
    def occupied(self) -> NDArray[np.bool_]:
        """Confirmed obstacle cells ``(H, W)``."""
        occ = np.zeros(self.shape[0] * self.shape[1], dtype=bool)
        occ[self.occupied_cells()] = True
        return occ.reshape(self.shape)

    def occupied_cells(self) -> NDArray[np.intp]:
        """Flat (row-major) indices of the confirmed obstacle cells, ascending: ``hits >=
        min_hits`` and ``hits / max(seen, 1) >= min_ratio``."""
        # within the window of the cells seen (hits are zero outside it); the ratio only where
        # there are enough hits (a few cells of the grid)
        rows, cols = self.window()
        h = self.hits[rows, cols]
        r, c = np.nonzero(h >= self.settings.min_hits)
        ratio = h[r, c] / np.maximum(self.seen[rows, cols][r, c], 1)
        ok = ratio >= self.settings.min_ratio
        # row-major in the window is row-major in the grid: ascending flat indices
        return (r[ok] + rows.start) * self.shape[1] + (c[ok] + cols.start)

    @property
    def recent_occupied(self) -> NDArray[np.bool_]:
        """Cells ``(H, W)`` that at least ``min_hits`` of the recent scans saw as obstacle."""
        count = np.zeros(self.shape[0] * self.shape[1], dtype=np.int32)
        for flat in self.recent:
            count[flat] += 1
        need = min(self.settings.min_hits, max(len(self.recent), 1))
        return (count >= need).reshape(self.shape)

    def components(self) -> tuple[NDArray[np.int32], int]:
        """Labels ``(H, W)`` (0 = free) of the obstacles and their number."""
        return _components(self.occupied)

    # --- what the return needs -----------------------------------------------------------------
    def freeze_known(self, margin: float) -> None:
        """Remember the obstacles mapped so far, grown by ``margin`` metres, as *known*.

        Called when the link is lost: the robot drove the stored path on the way out, so what
        was mapped then did not block it. During the return the same structure, seen again with
        a drifted estimate, can land within the corridor (a doorway's jambs); cells within
        ``margin`` (about the estimate's inconsistency between the two passes) of a known
        obstacle are then not a reason to stop - a *new* obstacle is.
        """
        r = int(np.ceil(margin / self.resolution))
        yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
        disk = xx**2 + yy**2 <= r**2
        self.known = ndimage.binary_dilation(self.occupied, structure=disk)

    def planning_grid(self) -> NDArray[np.bool_]:
        """Cells ``(H, W)`` a detour must avoid: the confirmed ones and those of the recent scans."""
        return self.occupied | self.recent_occupied

    def blocked(
        self, path_xy: NDArray[np.float64], half_width: float, recent: bool = True
    ) -> NDArray[np.bool_]:
        """Which path points ``(M, 2)`` have an obstacle cell within ``half_width``.

        With ``recent`` (the default) the cells are those of the last scans
        (:attr:`recent_occupied`): they were placed with the *current* pose estimate, the frame
        in which the robot will actually follow the path ahead - older cells carry the estimate's
        error of their own time and would block or clear the way in the wrong place. After
        :meth:`freeze_known`, cells near obstacles known from the way out do not count.
        """
        cells = self.recent_occupied if recent else self.occupied
        if self.known is not None:
            cells = cells & ~self.known
        rows, cols = np.nonzero(cells)
        if len(rows) == 0 or len(path_xy) == 0:
            return np.zeros(len(path_xy), dtype=bool)
        C = self.centres(rows, cols)
        lo, hi = (
            path_xy.min(0) - half_width - self.resolution,
            path_xy.max(0) + half_width + self.resolution,
        )
        near = np.all((C >= lo) & (C <= hi), axis=1)
        if not near.any():
            return np.zeros(len(path_xy), dtype=bool)
        d, _ = cKDTree(C[near]).query(path_xy, k=1)
        # a cell counts when any part of it is within the corridor: centre distance minus half a
        # cell diagonal
        return d - 0.5 * np.sqrt(2.0) * self.resolution <= half_width
