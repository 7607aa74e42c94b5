"""Test rooms for the stereo map and localization evaluation, with their true floor plans.

Each room is returned as a scene *description* (the dictionary :func:`navkit.sim.scene_io.scene_from_dict`
reads - this module does not import the simulator) plus its truth: the inner faces of the walls
as 2D segments and the true corners. Walls are textured with value noise (different seed per
wall, so stereo matching has texture and no two walls look alike); the floor is textured too.

Rooms: ``"rectangle"`` (8 x 6 m), ``"lshape"`` (10 x 8 m L), ``"column"`` (the rectangle with a
0.6 m square column), ``"doorway"`` (the rectangle with a 1 m doorway in the east wall and a
corridor wall 2 m beyond it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from navkit.errors import ConfigError

__all__ = ["ROOM_KINDS", "RoomTruth", "room", "sample_poses"]

ROOM_KINDS = ("rectangle", "lshape", "column", "doorway")
WALL_HEIGHT = 2.5


@dataclass(frozen=True)
class RoomTruth:
    """A room's scene description and its true floor plan.

    Attributes
    ----------
    scene : dict
        For :func:`navkit.sim.scene_io.scene_from_dict`.
    walls : (K, 2, 2) array
        Inner wall faces as segments ``[[x0, y0], [x1, y1]]``, metres.
    corners : (C, 2) array
        True corners (where two walls meet), metres.
    outline : (P, 2) array
        The room polygon (counter-clockwise).
    size : float
        Metres; the room's diagonal (errors are reported relative to it).
    survey : (S, 3) array
        Poses ``(x, y, theta)`` to build the map from (turning in place at one or two spots).
    """

    scene: dict[str, object]
    walls: NDArray[np.float64]
    corners: NDArray[np.float64]
    outline: NDArray[np.float64]
    size: float
    survey: NDArray[np.float64]

    def free_space(self) -> NDArray[np.float64]:
        """The outline polygon (poses are drawn inside it, away from the walls and the column)."""
        return self.outline


def _wall(
    a: tuple[float, float], b: tuple[float, float], seed: int, name: str
) -> dict[str, object]:
    return {
        "type": "wall",
        "name": name,
        "origin": [a[0], a[1], 0.0],
        "u": [b[0] - a[0], b[1] - a[1], 0.0],
        "v": [0.0, 0.0, WALL_HEIGHT],
        "texture": {
            "kind": "noise",
            "scale": 0.6,
            "seed": seed,
            "color": [0.85, 0.8, 0.7],
            "color2": [0.15, 0.12, 0.1],
        },
    }


def _ground() -> dict[str, object]:
    return {
        "type": "ground",
        "name": "floor",
        "height": 0.0,
        "texture": {
            "kind": "noise",
            "scale": 0.8,
            "seed": 3,
            "color": [0.5, 0.45, 0.4],
            "color2": [0.2, 0.2, 0.2],
        },
    }


def _survey(points: list[tuple[float, float]], n: int = 12) -> NDArray[np.float64]:
    th = np.arange(n) * 2 * np.pi / n
    return np.concatenate([np.stack([np.full(n, x), np.full(n, y), th], 1) for x, y in points])


def room(kind: str) -> RoomTruth:
    """The scene and truth of a test room (see the module docstring).

    Raises
    ------
    ConfigError
        If ``kind`` is not one of :data:`ROOM_KINDS`.
    """
    if kind not in ROOM_KINDS:
        raise ConfigError(f"unknown room {kind!r}", field="room", expected=" | ".join(ROOM_KINDS))
    prims: list[dict[str, object]] = [_ground()]
    extra_corners: list[tuple[float, float]] = []
    if kind == "lshape":
        poly = [(0.0, 0.0), (10.0, 0.0), (10.0, 4.0), (5.0, 4.0), (5.0, 8.0), (0.0, 8.0)]
        survey = _survey([(2.5, 2.0), (7.5, 2.0), (2.5, 6.0)])
    else:
        poly = [(0.0, 0.0), (8.0, 0.0), (8.0, 6.0), (0.0, 6.0)]
        survey = (
            _survey([(2.0, 1.5), (6.0, 1.5), (6.0, 4.5), (2.0, 4.5)], 8)
            if kind == "column"
            else _survey([(4.0, 3.0)])
        )
    segs = []
    for k, (a, b) in enumerate(zip(poly, poly[1:] + poly[:1], strict=True)):
        if kind == "doorway" and k == 1:  # east wall (8,0)-(8,6) with a door from y=2.5 to 3.5
            for j, (p, q) in enumerate([(a, (8.0, 2.5)), ((8.0, 3.5), b)]):
                prims.append(_wall(p, q, 100 + 10 * k + j, f"wall{k}{'ab'[j]}"))
                segs.append([p, q])
            continue
        prims.append(_wall(a, b, 100 + 10 * k, f"wall{k}"))
        segs.append([a, b])
    if kind == "doorway":
        prims.append(_wall((10.0, -2.0), (10.0, 8.0), 190, "corridor"))
    if kind == "column":
        c, h = np.array([4.0, 3.0]), 0.3
        prims.append(
            {
                "type": "box",
                "name": "column",
                "center": [4.0, 3.0, WALL_HEIGHT / 2],
                "size": [0.6, 0.6, WALL_HEIGHT],
                "yaw": 0.0,
                "texture": {
                    "kind": "noise",
                    "scale": 0.3,
                    "seed": 77,
                    "color": [0.8, 0.8, 0.8],
                    "color2": [0.1, 0.1, 0.15],
                },
            }
        )
        sq = [c + np.array(o) for o in ([-h, -h], [h, -h], [h, h], [-h, h])]
        for a, b in zip(sq, sq[1:] + sq[:1], strict=True):
            segs.append([tuple(a), tuple(b)])
        extra_corners = [tuple(p) for p in sq]
    P = np.array(poly)
    return RoomTruth(
        scene={"name": f"room-{kind}", "primitive": prims},
        walls=np.array(segs, dtype=np.float64),
        corners=np.array(list(poly) + extra_corners, dtype=np.float64),
        outline=P,
        size=float(np.linalg.norm(P.max(0) - P.min(0))),
        survey=survey,
    )


def sample_poses(
    truth: RoomTruth, count: int, rng: np.random.Generator, clearance: float = 0.8
) -> NDArray[np.float64]:
    """``count`` random poses ``(x, y, theta)`` inside the room, ``clearance`` metres from every wall.

    Rejection sampling in the bounding box (vectorised per batch); headings uniform.
    """
    from navkit.geometry.polygons import points_in_polygon

    lo, hi = truth.outline.min(axis=0), truth.outline.max(axis=0)
    S, E = truth.walls[:, 0], truth.walls[:, 1]
    out: list[NDArray[np.float64]] = []
    n = 0
    while n < count:
        P = lo + rng.random((4 * count, 2)) * (hi - lo)
        inside = points_in_polygon(P, truth.outline)
        # distance of each point to each wall segment
        d = E - S
        t = np.clip(
            np.einsum("pwk,wk->pw", P[:, None, :] - S[None], d) / np.einsum("wk,wk->w", d, d), 0, 1
        )
        dist = np.linalg.norm(P[:, None, :] - (S[None] + t[..., None] * d[None]), axis=2).min(
            axis=1
        )
        keep = P[inside & (dist >= clearance)]
        out.append(keep)
        n += len(keep)
    P = np.concatenate(out)[:count]
    return np.column_stack([P, rng.uniform(-np.pi, np.pi, count)])
