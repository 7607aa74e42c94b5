"""A scene of primitives and vectorised ray casting against it."""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import ConfigError, InputError
from navkit.geometry.fitting import Plane, canonical_plane
from navkit.geometry.linalg import rows_dot, rows_norm
from navkit.sim.primitives import Ground, Primitive

__all__ = ["RayHits", "Scene"]

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RayHits:
    """What each ray hit (the truth of a render).

    Attributes
    ----------
    distance : (N,) float64
        Distance along the (unit) ray to the first hit, metres; NaN on a miss.
    index : (N,) int64
        Index of the primitive hit in ``Scene.primitives``; -1 on a miss.
    point : (N, 3) float64
        World hit points; NaN on a miss.
    normal : (N, 3) float64
        Unit surface normals at the hits, oriented to face the ray (``normal . d <= 0``); NaN on
        a miss.
    color : (N, 3) float64
        Surface (albedo) colour from the primitive's texture, RGB in ``[0, 1]``; NaN on a miss.
    """

    distance: FloatArray
    index: NDArray[np.int64]
    point: FloatArray
    normal: FloatArray
    color: FloatArray

    @property
    def hit(self) -> NDArray[np.bool_]:
        """``(N,)`` True where the ray hit something."""
        return self.index >= 0


def _as_rays(origins: ArrayLike, directions: ArrayLike) -> tuple[FloatArray, FloatArray]:
    try:
        D = np.asarray(directions, dtype=np.float64)
        Or = np.asarray(origins, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"not numeric: {exc}", field="origins/directions", expected="float arrays"
        ) from exc
    if D.ndim != 2 or D.shape[1] != 3:
        raise InputError(f"has shape {D.shape}", field="directions", expected="(N, 3) array")
    if Or.shape == (3,):
        Or = Or[None, :]
    if Or.ndim != 2 or Or.shape[1] != 3 or Or.shape[0] not in (1, D.shape[0]):
        raise InputError(
            f"has shape {Or.shape}", field="origins", expected=f"(3,) or ({D.shape[0]}, 3) array"
        )
    if not (np.all(np.isfinite(Or)) and np.all(np.isfinite(D))):
        raise InputError(
            "contains NaN or inf", field="origins/directions", expected="finite values"
        )
    norm = rows_norm(D)
    if np.any(norm == 0):
        raise InputError(
            "contains a zero vector", field="directions", expected="non-zero directions"
        )
    return Or, D / norm[:, None]


class Scene:
    """A world made of primitives (see :mod:`navkit.sim.primitives`).

    Parameters
    ----------
    primitives : sequence of primitives
        Ground, Box, Prism, Sphere, Hemisphere, Cylinder, Wall. Unnamed primitives are named
        ``<kind><index>``; names must be unique.
    name : str
        A name for the scene (used in figures and the TOML file).
    start : (3,) floats
        A suggested robot start pose ``(x, y, theta)`` in the world (metres, radians).
    """

    def __init__(
        self,
        primitives: Iterable[Primitive],
        name: str = "scene",
        start: Sequence[float] = (0.0, 0.0, 0.0),
    ) -> None:
        prims = list(primitives)
        named: list[Primitive] = []
        for i, p in enumerate(prims):
            if not isinstance(p, Primitive):
                raise ConfigError(
                    f"item {i} is a {type(p).__name__}",
                    field="primitives",
                    expected="navkit.sim primitives (Ground, Box, Prism, ...)",
                )
            if not p.name:
                p = dataclasses.replace(p, name=f"{p.kind}{i}")  # type: ignore[type-var]
            named.append(p)
        names = [p.name for p in named]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ConfigError(
                f"duplicate primitive names {dup}", field="name", expected="unique names"
            )
        self.primitives: tuple[Primitive, ...] = tuple(named)
        self.name = name
        try:
            st = tuple(float(c) for c in start)
        except (TypeError, ValueError):
            st = ()
        if len(st) != 3 or not np.all(np.isfinite(st)):
            raise ConfigError(f"is {start!r}", field="start", expected="(x, y, theta) finite")
        self.start: tuple[float, float, float] = st  # type: ignore[assignment]
        self._ground_mask = np.array([p.is_ground for p in named] + [False], dtype=bool)
        self._bounds = [p._bound() for p in named]

    def __repr__(self) -> str:
        return f"Scene({self.name!r}, {len(self.primitives)} primitives)"

    def __len__(self) -> int:
        return len(self.primitives)

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, Scene)
            and other.primitives == self.primitives
            and other.name == self.name
        )

    __hash__ = None  # type: ignore[assignment]

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.primitives]

    def index_of(self, name: str) -> int:
        """Index of the primitive called ``name``."""
        try:
            return self.names.index(name)
        except ValueError:
            raise InputError(
                f"no primitive named {name!r}", field="name", expected=f"one of {self.names}"
            ) from None

    def is_ground_index(self, index: ArrayLike) -> NDArray[np.bool_]:
        """True where ``index`` (any shape, -1 = miss) refers to a ground primitive."""
        idx = np.asarray(index, dtype=np.int64)
        return self._ground_mask[np.where(idx >= 0, idx, len(self.primitives))]

    @property
    def ground(self) -> Ground | None:
        """The first ground primitive, if any."""
        for p in self.primitives:
            if isinstance(p, Ground):
                return p
        return None

    def ground_height(self, x: ArrayLike, y: ArrayLike) -> FloatArray:
        """Height of the ground (metres) at world ``(x, y)``; 0 where the scene has no ground."""
        g = self.ground
        xb, yb = np.broadcast_arrays(
            np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        )
        if g is None:
            return np.zeros(xb.shape)
        return g.height_at(xb, yb)

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """``(lo, hi)`` corners of the axis-aligned box holding every bounded primitive."""
        spheres = [b for b in self._bounds if b is not None]
        if not spheres:
            return np.zeros(3), np.zeros(3)
        c = np.array([b[0] for b in spheres])
        r = np.array([b[1] for b in spheres])[:, None]
        return (c - r).min(axis=0), (c + r).max(axis=0)

    # ------------------------------------------------------------------------------ casting
    def cast(
        self,
        origins: ArrayLike,
        directions: ArrayLike,
        max_range: float = np.inf,
        with_color: bool = True,
    ) -> RayHits:
        """Cast rays and return the first hit of each (vectorised over rays).

        Each primitive is intersected analytically with all the rays at once, after rejecting the
        rays that miss its bounding sphere or whose bounding-sphere entry is beyond the nearest
        hit found so far; the nearest hit wins. Unbounded primitives (the ground) go last, so
        their (possibly iterative) intersection is limited to the distance already found.

        Parameters
        ----------
        origins : (N, 3) or (3,) array
            Ray origins, world frame, metres.
        directions : (N, 3) array
            Ray directions (normalised here); ``distance`` is measured along the unit ray.
        max_range : float
            Hits at or beyond this distance are misses.
        with_color : bool
            Evaluate the textures (``color``); ``False`` leaves ``color`` NaN and saves the
            texture cost (range sensors do not need it).

        Returns
        -------
        RayHits
        """
        Or, D = _as_rays(origins, directions)
        N = D.shape[0]
        single = Or.shape[0] == 1
        best = np.full(N, float(max_range) if max_range > 0 else 0.0)
        index = np.full(N, -1, dtype=np.int64)
        face = np.zeros(N, dtype=np.int64)
        # bounded primitives nearest first (their hits prune the later ones), the ground last
        ref = Or.mean(axis=0)

        def _key(k: int) -> tuple[bool, float]:
            b = self._bounds[k]
            return (True, 0.0) if b is None else (False, float(np.linalg.norm(b[0] - ref)) - b[1])

        order = sorted(range(len(self.primitives)), key=_key)
        for k in order:
            prim = self.primitives[k]
            bound = self._bounds[k]
            if bound is None:
                cand = np.arange(N)
                Oc = Or if single else Or[cand]
                t, f = (
                    prim._intersect(Oc, D[cand], best[cand])
                    if isinstance(prim, Ground)
                    else prim._intersect(Oc, D[cand])
                )
            else:
                c, r = bound
                r = r * (1 + 1e-9) + 1e-9  # conservative: never reject a grazing hit
                if single:
                    # cone test: a unit ray from outside the sphere hits it iff
                    # d . (c - o) >= sqrt(|c - o|^2 - r^2) (angle within asin(r / |c - o|))
                    oc = c - Or[0]
                    dist2 = float(oc @ oc)
                    if dist2 <= r * r:
                        cand = np.flatnonzero(best > 0)
                    else:
                        tca = rows_dot(D, oc)
                        lim = np.sqrt(dist2 - r * r)
                        cand = np.flatnonzero((tca >= lim) & (tca - r < best))
                else:
                    oc = c[None, :] - Or
                    tca = np.einsum("ij,ij->i", D, oc)
                    d2 = np.einsum("ij,ij->i", oc, oc) - tca * tca
                    cand = np.flatnonzero((d2 <= r * r) & (tca + r > 0) & (tca - r < best))
                if cand.size == 0:
                    continue
                Oc = Or if single else Or[cand]
                t, f = prim._intersect(Oc, D[cand])
            closer = t < best[cand]
            w = cand[closer]
            best[w] = t[closer]
            index[w] = k
            face[w] = f[closer]
        return self._finish(Or, D, best, index, face, with_color)

    def _finish(
        self,
        Or: FloatArray,
        D: FloatArray,
        best: FloatArray,
        index: NDArray[np.int64],
        face: NDArray[np.int64],
        with_color: bool = True,
    ) -> RayHits:
        """Hit points, normals (facing the rays) and texture colours of the winning hits."""
        N = D.shape[0]
        hit = index >= 0
        distance = np.where(hit, best, np.nan)
        point = np.full((N, 3), np.nan)
        normal = np.full((N, 3), np.nan)
        color = np.full((N, 3), np.nan)
        Ob = np.broadcast_to(Or, (N, 3))
        point[hit] = Ob[hit] + best[hit, None] * D[hit]
        for k in np.unique(index[hit]):
            sel = np.flatnonzero(index == k)
            prim = self.primitives[int(k)]
            n, s, t = prim._surface(point[sel], face[sel])
            n = np.where((np.einsum("ij,ij->i", n, D[sel]) > 0)[:, None], -n, n)
            normal[sel] = n
            if with_color:
                color[sel] = prim.effective_texture.evaluate(s, t)
        return RayHits(distance, index, point, normal, color)

    def cast_on(self, index: ArrayLike, origins: ArrayLike, directions: ArrayLike) -> RayHits:
        """Intersect each ray only with the primitive ``index[i]`` (-1: no primitive, a miss).

        Much cheaper than :meth:`cast` (one primitive per ray); used for sub-pixel colour samples
        that are assumed to land on the primitive seen by the pixel centre.
        """
        Or, D = _as_rays(origins, directions)
        N = D.shape[0]
        idx = np.asarray(index, dtype=np.int64).reshape(-1)
        if idx.shape != (N,):
            raise InputError(f"has shape {idx.shape}", field="index", expected=f"({N},) indices")
        best = np.full(N, np.inf)
        out_index = np.full(N, -1, dtype=np.int64)
        face = np.zeros(N, dtype=np.int64)
        for k in np.unique(idx[idx >= 0]):
            sel = np.flatnonzero(idx == k)
            Oc = Or if Or.shape[0] == 1 else Or[sel]
            t, f = self.primitives[int(k)]._intersect(Oc, D[sel])
            ok = np.isfinite(t)
            best[sel[ok]] = t[ok]
            out_index[sel[ok]] = k
            face[sel[ok]] = f[ok]
        return self._finish(Or, D, best, out_index, face)

    # ------------------------------------------------------------------------------ truth
    def true_planes(self) -> list[tuple[str, Plane]]:
        """The planar faces of the scene as ``(name, Plane)``, ``n . x = rho`` with ``rho >= 0``.

        Names are ``<primitive>`` for a flat ground or a wall, ``<primitive>:<face>`` for box,
        prism and cylinder faces (``+x, -x, +y, -y, top`` / ``slope, +x, +y, -y`` / ``top``).
        ``centroid`` is the face's centre. Decision: bottom faces resting on a flat ground (and
        the bottom of a cylinder standing on it) are left out - no sensor above the ground can
        see them and they coincide with the ground plane. A ground with hills has no plane.
        """
        g = self.ground
        ground_z = g.height if (g is not None and g.is_flat) else None
        out: list[tuple[str, Plane]] = []
        for p in self.primitives:
            for suffix, n, point in p._faces():
                if suffix == "bottom" and ground_z is not None and abs(point[2] - ground_z) < 1e-6:
                    continue
                unit, rho = canonical_plane(n, float(np.dot(n, point)))
                out.append(
                    (
                        f"{p.name}:{suffix}" if suffix else p.name,
                        Plane(unit, rho, np.asarray(point, dtype=np.float64), 0.0, 0),
                    )
                )
        return out

    def primitive_names(self, index: ArrayLike) -> NDArray[np.str_]:
        """Names of the primitives for an index array (``""`` for -1)."""
        idx = np.asarray(index, dtype=np.int64)
        names = np.array([*self.names, ""])
        return names[np.where(idx >= 0, idx, len(self.primitives))]

    def with_primitives(self, primitives: Sequence[Primitive]) -> Scene:
        """A new scene with these primitives added."""
        return Scene([*self.primitives, *primitives], name=self.name, start=self.start)
