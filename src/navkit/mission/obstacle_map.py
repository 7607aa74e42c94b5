"""The global 2D obstacle map (paper 1's per-scan obstacles fused over the mission) and its score.

Fusion: every scan's obstacle vertices (``vertex_obstacle > 0`` of
:func:`navkit.obstacles.detector.detect_obstacles`) and all its valid points are moved into the
map frame with the robot's *current pose estimate* and counted per cell, once per scan: ``hits``
(an obstacle was seen in the cell) and ``seen`` (anything was seen there). A cell is an obstacle
when ``hits >= min_hits`` and ``hits / seen >= min_ratio`` - one-scan noise and cells that later
scans see as ground are dropped. Obstacles are the 8-connected components of those cells (with a
one-cell closing so a face seen in stripes stays one obstacle).

Score against the simulator's truth (:func:`true_footprints`): a true obstacle is *found* when a
map component comes within ``match_tolerance`` of its footprint; a component matching nothing is a
*phantom*. Recall is counted over the obstacles the lidar actually hit during the mission (the
truth of every ray is known), so an obstacle never in view is not held against the detector.
"""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.spatial import cKDTree

__all__ = ["Footprint", "ObstacleGrid", "score_obstacles", "true_footprints"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Footprint:
    """A true obstacle's outline on the ground.

    Attributes
    ----------
    index : int
        Primitive index in the scene.
    name, kind : str
    polygon : (K, 2) array
        Counter-clockwise outline, metres.
    height : float
        Top above the ground, metres.
    extent : float
        Largest horizontal extent, metres.
    """

    index: int
    name: str
    kind: str
    polygon: NDArray[np.float64]
    height: float
    extent: float


def _circle(c: Any, r: float, n: int = 32) -> NDArray[np.float64]:
    a = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.c_[c[0] + r * np.cos(a), c[1] + r * np.sin(a)]


def _rect(c: Any, size: Any, yaw: float) -> NDArray[np.float64]:
    hx, hy = 0.5 * size[0], 0.5 * size[1]
    local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    cy, sy = np.cos(yaw), np.sin(yaw)
    return local @ np.array([[cy, sy], [-sy, cy]]) + np.asarray(c[:2])


def true_footprints(scene: Any, wall_thickness: float = 0.1) -> list[Footprint]:
    """Footprints of every non-ground primitive of a :class:`navkit.sim.Scene`.

    Boxes and prisms: their rotated rectangle; cylinders, spheres, hemispheres: their circle;
    walls: their base segment thickened to ``wall_thickness`` metres. Heights are measured from
    the flat-ground height under the primitive.
    """
    out = []
    for k, p in enumerate(scene.primitives):
        if p.is_ground:
            continue
        kind = p.kind
        if kind in ("box", "prism"):
            c, size = np.asarray(p.center), np.asarray(p.size)
            poly = _rect(c, size, float(p.yaw))
            g = float(scene.ground_height(c[0], c[1]))
            top = c[2] + 0.5 * size[2] - g  # the box top / the prism's high edge
        elif kind in ("sphere", "hemisphere"):
            c = np.asarray(p.center)
            poly = _circle(c, float(p.radius))
            top = c[2] + float(p.radius) - float(scene.ground_height(c[0], c[1]))
        elif kind == "cylinder":
            c = np.asarray(p.center)
            poly = _circle(c, float(p.radius))
            top = c[2] + float(p.height) - float(scene.ground_height(c[0], c[1]))
        elif kind == "wall":
            o, u, v = (np.asarray(a, dtype=np.float64) for a in (p.origin, p.u, p.v))
            corners = np.array([o, o + u, o + v, o + u + v])
            xy = corners[:, :2]
            d = xy.max(0) - xy.min(0)
            ends = xy[np.argsort(xy @ (d / max(np.hypot(*d), 1e-12)))][[0, -1]]
            along = ends[1] - ends[0]
            n = (
                np.array([-along[1], along[0]])
                / max(np.hypot(*along), 1e-12)
                * 0.5
                * wall_thickness
            )
            poly = np.array([ends[0] - n, ends[1] - n, ends[1] + n, ends[0] + n])
            top = float(corners[:, 2].max() - scene.ground_height(*xy.mean(0)))
        else:  # an unknown kind: its bounding circle
            c, r = p._bound()
            poly = _circle(c, float(r))
            top = float(c[2] + r)
        ext = poly.max(0) - poly.min(0)
        if kind in ("box", "prism"):
            extent = float(max(p.size[0], p.size[1]))
        else:
            extent = float(max(ext))
        out.append(Footprint(k, p.name, kind, poly, float(top), extent))
    return out


def _distance_to_polygon(
    points: NDArray[np.float64], poly: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Distance ``(N,)`` of points to a polygon (0 inside), metres."""
    from navkit.geometry import points_in_polygon

    A, B = poly, np.roll(poly, -1, axis=0)
    AB = B - A
    L2 = np.maximum((AB**2).sum(1), 1e-12)
    t = np.clip(np.einsum("nkd,kd->nk", points[:, None, :] - A[None], AB) / L2, 0.0, 1.0)
    proj = A[None] + t[..., None] * AB[None]
    d = np.hypot(*(points[:, None, :] - proj).transpose(2, 0, 1)).min(axis=1)
    inside = points_in_polygon(points, poly)
    return np.where(inside, 0.0, d)


class ObstacleGrid:
    """Evidence grid of obstacles in the map frame.

    Parameters
    ----------
    lo, hi : (2,) arrays
        Corners of the mapped area, metres.
    resolution : float
        Cell size, metres.
    min_hits : int
    min_ratio : float
        See :class:`navkit.mission.settings.ObstacleMapSettings`.
    recent_scans : int
        Length of the short memory used to check the way ahead (:meth:`blocked`): the obstacle
        cells of the last ``recent_scans`` scans.
    """

    def __init__(
        self,
        lo: Any,
        hi: Any,
        resolution: float,
        min_hits: int = 2,
        min_ratio: float = 0.3,
        recent_scans: int = 4,
    ) -> None:
        self.origin = np.asarray(lo, dtype=np.float64)
        self.resolution = float(resolution)
        size = (
            np.ceil((np.asarray(hi, dtype=np.float64) - self.origin) / self.resolution).astype(int)
            + 1
        )
        self.shape = (int(size[1]), int(size[0]))  # rows = y, columns = x
        self.hits = np.zeros(self.shape, dtype=np.int32)
        self.seen = np.zeros(self.shape, dtype=np.int32)
        self.min_hits, self.min_ratio = int(min_hits), float(min_ratio)
        self.n_scans = 0
        self.recent: deque[NDArray[np.intp]] = deque(maxlen=int(recent_scans))
        self.known: NDArray[np.bool_] | None = None

    def cells(
        self, xy: NDArray[np.float64]
    ) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.bool_]]:
        """Row, column and in-grid flag of points ``(N, 2)``."""
        ij = np.floor((xy - self.origin) / self.resolution).astype(np.intp)
        ok = (
            (ij[:, 0] >= 0)
            & (ij[:, 1] >= 0)
            & (ij[:, 0] < self.shape[1])
            & (ij[:, 1] < self.shape[0])
        )
        return ij[:, 1], ij[:, 0], ok

    def centres(self, rows: NDArray[np.intp], cols: NDArray[np.intp]) -> NDArray[np.float64]:
        """World centres ``(N, 2)`` of cells."""
        return self.origin + (np.c_[cols, rows] + 0.5) * self.resolution

    def _count(self, grid: NDArray[np.int32], xy: NDArray[np.float64]) -> NDArray[np.intp]:
        r, c, ok = self.cells(xy)
        flat = np.unique(r[ok] * self.shape[1] + c[ok])  # once per scan
        grid.reshape(-1)[flat] += 1
        return flat

    def add_scan(self, obstacle_xy: NDArray[np.float64], seen_xy: NDArray[np.float64]) -> None:
        """Count one scan: obstacle points and all valid points, both ``(N, 2)`` in the map frame."""
        self.recent.append(self._count(self.hits, obstacle_xy))
        self._count(self.seen, np.vstack([seen_xy, obstacle_xy]))
        self.n_scans += 1

    @property
    def recent_occupied(self) -> NDArray[np.bool_]:
        """Cells ``(H, W)`` that at least ``min_hits`` of the recent scans saw as obstacle."""
        count = np.zeros(self.shape[0] * self.shape[1], dtype=np.int32)
        for flat in self.recent:
            count[flat] += 1
        return (count >= min(self.min_hits, max(len(self.recent), 1))).reshape(self.shape)

    @property
    def occupied(self) -> NDArray[np.bool_]:
        """Confirmed obstacle cells ``(H, W)``."""
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = self.hits / np.maximum(self.seen, 1)
        return (self.hits >= self.min_hits) & (ratio >= self.min_ratio)

    def components(self) -> tuple[NDArray[np.int32], int]:
        """Labels ``(H, W)`` (0 = free) of the obstacles and their number."""
        occ = self.occupied
        closed = ndimage.binary_closing(occ, structure=np.ones((3, 3), bool)) | occ
        labels, _ = ndimage.label(closed, structure=np.ones((3, 3), bool))
        labels = np.where(occ, labels, 0).astype(np.int32)
        present = np.unique(labels[labels > 0])
        remap = np.zeros(int(labels.max()) + 1, dtype=np.int32)
        remap[present] = np.arange(1, len(present) + 1, dtype=np.int32)
        return remap[labels], len(present)

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


def score_obstacles(
    grid: ObstacleGrid,
    footprints: list[Footprint],
    seen_indices: set[int],
    *,
    min_height: float,
    robot_width: float,
    tolerance: float,
) -> dict[str, Any]:
    """Recall, precision and phantoms of the fused map against the true footprints.

    Parameters
    ----------
    grid : ObstacleGrid
    footprints : list of Footprint
        From :func:`true_footprints`.
    seen_indices : set of int
        Primitives the lidar actually hit during the mission.
    min_height : float
        True obstacles lower than this (a curb) are traversable: not expected, and a component on
        them counts as a phantom.
    robot_width : float
        "Larger than the robot": largest horizontal extent at least this, metres.
    tolerance : float
        Matching distance, metres.

    Returns
    -------
    dict
        ``recall``, ``recall_larger_than_robot``, ``precision``, ``phantoms``, per-obstacle rows
        (``obstacles``), per-component rows (``components``), and ``cell_error_*``: distances of
        obstacle cells of matched components to the true footprint (map error), metres.
    """
    labels, n = grid.components()
    rows, cols = np.nonzero(labels)
    lab = labels[rows, cols]
    C = grid.centres(rows, cols)
    expected = [f for f in footprints if f.height >= min_height]
    D = (
        np.stack([_distance_to_polygon(C, f.polygon) for f in expected], axis=1)
        if expected and len(C)
        else np.zeros((len(C), 0))
    )
    comp_rows = []
    matched_comp = np.zeros(n + 1, dtype=bool)
    cell_err: list[NDArray[np.float64]] = []
    for k in range(1, n + 1):
        m = lab == k
        if D.shape[1]:
            dmin = D[m].min(axis=0)  # closest approach of the component to each footprint
            j = int(np.argmin(dmin))
            ok = bool(dmin[j] <= tolerance)
        else:
            ok, j = False, -1
        matched_comp[k] = ok
        if ok:
            cell_err.append(D[m].min(axis=1))
        centre = C[m].mean(axis=0)
        comp_rows.append(
            {
                "id": k,
                "cells": int(m.sum()),
                "centre": centre.tolist(),
                "area_m2": float(m.sum() * grid.resolution**2),
                "matches": expected[j].name if ok else None,
            }
        )
    obst_rows = []
    for j, f in enumerate(expected):
        found = bool(D.shape[1] and len(C) and (D[:, j] <= tolerance).any())
        obst_rows.append(
            {
                "name": f.name,
                "kind": f.kind,
                "height_m": f.height,
                "extent_m": f.extent,
                "seen": f.index in seen_indices,
                "found": found,
                "larger_than_robot": f.extent >= robot_width,
            }
        )
    seen_rows = [r for r in obst_rows if r["seen"]]
    large = [r for r in seen_rows if r["larger_than_robot"]]
    n_found = sum(1 for r in seen_rows if r["found"])
    n_found_large = sum(1 for r in large if r["found"])
    errs = np.concatenate(cell_err) if cell_err else np.zeros(0)
    return {
        "true_obstacles": len(expected),
        "seen_obstacles": len(seen_rows),
        "found": n_found,
        "recall": n_found / len(seen_rows) if seen_rows else float("nan"),
        "recall_larger_than_robot": n_found_large / len(large) if large else float("nan"),
        "larger_than_robot_missed": [r["name"] for r in large if not r["found"]],
        "components": n,
        "precision": float(matched_comp[1:].sum() / n) if n else float("nan"),
        "phantoms": int(n - matched_comp[1:].sum()),
        "cell_error_median_m": float(np.median(errs)) if len(errs) else float("nan"),
        "cell_error_p95_m": float(np.percentile(errs, 95)) if len(errs) else float("nan"),
        "obstacles": obst_rows,
        "component_list": comp_rows,
    }
