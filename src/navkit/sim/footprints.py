"""Footprints of the simulator's primitives on the ground: simulator truth, in one place.

Every evaluation that needs "where is this obstacle on the map" (the mission's obstacle-map
score, paper 1's shape experiments, the figures) takes it from :func:`footprint`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["Footprint", "footprint", "room_walls", "true_footprints"]


@dataclass(frozen=True)
class Footprint:
    """A true obstacle's outline on the ground.

    Attributes
    ----------
    index : int
        Primitive index in the scene (-1 when made from a lone primitive).
    name, kind : str
    polygon : (K, 2) array
        Counter-clockwise outline, metres (a circle as a 32-gon; a wall as its base segment
        thickened to the wall thickness).
    height : float
        Top above the ground under the primitive, metres.
    extent : float
        Largest horizontal extent, metres.
    circle : (3,) array or None
        ``(cx, cy, r)`` of round primitives (spheres, hemispheres, cylinders), exact.
    """

    index: int
    name: str
    kind: str
    polygon: NDArray[np.float64]
    height: float
    extent: float
    circle: NDArray[np.float64] | None = None


def _circle(c: Any, r: float, n: int = 32) -> NDArray[np.float64]:
    a = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.c_[c[0] + r * np.cos(a), c[1] + r * np.sin(a)]


def _rect(c: Any, size: Any, yaw: float) -> NDArray[np.float64]:
    hx, hy = 0.5 * size[0], 0.5 * size[1]
    local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    cy, sy = np.cos(yaw), np.sin(yaw)
    return local @ np.array([[cy, sy], [-sy, cy]]) + np.asarray(c[:2])


def footprint(
    p: Any, scene: Any = None, *, index: int = -1, wall_thickness: float = 0.1
) -> Footprint | None:
    """The footprint of one primitive (None for the ground).

    Boxes and prisms: their rotated rectangle; cylinders, spheres, hemispheres: their circle;
    walls: their base segment thickened to ``wall_thickness`` metres; anything else: its
    bounding circle. Heights are measured from ``scene.ground_height`` under the primitive
    (from z = 0 without a scene).
    """
    if p.is_ground:
        return None

    def ground(x: float, y: float) -> float:
        return float(scene.ground_height(x, y)) if scene is not None else 0.0

    kind = p.kind
    circle = None
    if kind in ("box", "prism"):
        c, size = np.asarray(p.center), np.asarray(p.size)
        poly = _rect(c, size, float(p.yaw))
        top = c[2] + 0.5 * size[2] - ground(c[0], c[1])  # the box top / the prism's high edge
    elif kind in ("sphere", "hemisphere", "cylinder"):
        c = np.asarray(p.center)
        poly = _circle(c, float(p.radius))
        circle = np.array([c[0], c[1], float(p.radius)])
        up = float(p.height) if kind == "cylinder" else float(p.radius)
        top = c[2] + up - ground(c[0], c[1])
    elif kind == "wall":
        o, u, v = (np.asarray(a, dtype=np.float64) for a in (p.origin, p.u, p.v))
        corners = np.array([o, o + u, o + v, o + u + v])
        xy = corners[:, :2]
        d = xy.max(0) - xy.min(0)
        ends = xy[np.argsort(xy @ (d / max(np.hypot(*d), 1e-12)))][[0, -1]]
        along = ends[1] - ends[0]
        n = np.array([-along[1], along[0]]) / max(np.hypot(*along), 1e-12) * 0.5 * wall_thickness
        poly = np.array([ends[0] - n, ends[1] - n, ends[1] + n, ends[0] + n])
        top = float(corners[:, 2].max() - ground(*xy.mean(0)))
    else:  # an unknown kind: its bounding circle
        c, r = p._bound()
        poly = _circle(c, float(r))
        top = float(c[2] + r)
    if kind in ("box", "prism"):
        extent = float(max(p.size[0], p.size[1]))
    else:
        extent = float(max(poly.max(0) - poly.min(0)))
    return Footprint(index, p.name, kind, poly, float(top), extent, circle)


def true_footprints(scene: Any, wall_thickness: float = 0.1) -> list[Footprint]:
    """Footprints of every non-ground primitive of a :class:`navkit.sim.Scene`."""
    out = []
    for k, p in enumerate(scene.primitives):
        f = footprint(p, scene, index=k, wall_thickness=wall_thickness)
        if f is not None:
            out.append(f)
    return out


def room_walls(
    scene: Any, room: tuple[float, float, float, float] | None, margin: float = 0.3
) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """The true room walls: base segments ``(start, end)`` of the scene's walls inside the room."""
    if room is None:
        return []
    x0, y0, x1, y1 = room
    out = []
    for p in scene.primitives:
        if p.kind != "wall":
            continue
        o, u = np.asarray(p.origin, float)[:2], np.asarray(p.u, float)[:2]
        a, b = o, o + u
        if np.hypot(*u) < 1e-9:  # vertical u: the base runs along v
            b = o + np.asarray(p.v, float)[:2]
        inside = all(
            x0 - margin <= q[0] <= x1 + margin and y0 - margin <= q[1] <= y1 + margin
            for q in (a, b)
        )
        if inside:
            out.append((a, b))
    return out
