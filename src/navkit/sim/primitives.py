"""Scene primitives and their analytic ray intersections, vectorised over rays.

Every primitive is a frozen dataclass with its geometric parameters (metres, radians), a ``name``
and an optional :class:`~navkit.sim.texture.Texture`. The ray-casting interface used by
:class:`navkit.sim.Scene` is private to the package:

- ``_intersect(Or, D) -> (t, face)``: for rays ``Or + t D`` (``(M, 3)`` origins, unit directions)
  the smallest ``t > T_MIN`` on the surface (``inf`` on a miss) and which face was hit;
- ``_surface(P, face) -> (normal, s, t)``: the outward unit normal at the hit points and the
  point's 2D surface coordinates in metres (where textures are evaluated);
- ``_bound()``: a bounding sphere ``(center, radius)`` for cheap rejection (``None`` = unbounded);
- ``_faces()``: the planar faces, for :meth:`navkit.sim.Scene.true_planes`.

All surfaces are two-sided (a ray from inside a box hits the face it leaves through).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from navkit.errors import ConfigError
from navkit.geometry.linalg import rows_dot, rows_matmul, rows_norm
from navkit.sim.texture import Texture

__all__ = [
    "T_MIN",
    "Box",
    "Cylinder",
    "Ground",
    "Hemisphere",
    "Primitive",
    "Prism",
    "Sphere",
    "Wall",
]

T_MIN = 1e-9
"""Hits closer than this along a ray (metres) are ignored (self-intersection guard)."""

Vec3 = tuple[float, float, float]
FloatArray = NDArray[np.float64]


def _vec3(kind: str, field: str, value: object) -> Vec3:
    try:
        v = tuple(float(c) for c in value)  # type: ignore[attr-defined]
    except (TypeError, ValueError) as exc:
        raise ConfigError(
            f"is {value!r}", field=f"{kind}.{field}", expected="three numbers"
        ) from exc
    if len(v) != 3 or not all(np.isfinite(v)):
        raise ConfigError(f"is {value!r}", field=f"{kind}.{field}", expected="three finite numbers")
    return v  # type: ignore[return-value]


def _scalar(
    kind: str, field: str, value: object, *, positive: bool = False, nonnegative: bool = False
) -> float:
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"is {value!r}", field=f"{kind}.{field}", expected="a number") from exc
    if not np.isfinite(v):
        raise ConfigError(f"is {v}", field=f"{kind}.{field}", expected="a finite number")
    if positive and v <= 0:
        raise ConfigError(f"is {v}", field=f"{kind}.{field}", expected="a positive number (metres)")
    if nonnegative and v < 0:
        raise ConfigError(f"is {v}", field=f"{kind}.{field}", expected="a number >= 0 (metres)")
    return v


def _rot_z(yaw: float) -> FloatArray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _dot(a: FloatArray, b: FloatArray) -> FloatArray:
    return np.einsum("ij,ij->i", a, b)


class Primitive:
    """Common interface of the scene primitives (see the module docstring)."""

    name: str
    texture: Texture | None
    kind: ClassVar[str] = "primitive"
    is_ground: ClassVar[bool] = False
    default_texture: ClassVar[Texture] = Texture("solid", color=(0.55, 0.55, 0.55))

    def _bound(self) -> tuple[FloatArray, float] | None:
        raise NotImplementedError

    def _intersect(self, Or: FloatArray, D: FloatArray) -> tuple[FloatArray, NDArray[np.int64]]:
        raise NotImplementedError

    def _surface(
        self, P: FloatArray, face: NDArray[np.int64]
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        raise NotImplementedError

    def _faces(self) -> list[tuple[str, FloatArray, FloatArray]]:
        """Planar faces as ``(suffix, outward unit normal, a point on the face)``."""
        return []

    @property
    def effective_texture(self) -> Texture:
        """The texture, or the primitive type's default when none was given."""
        return self.texture if self.texture is not None else self.default_texture


def _check_common(p: Primitive) -> None:
    if not isinstance(p.name, str):
        raise ConfigError(f"is {p.name!r}", field=f"{p.kind}.name", expected="a string")
    if p.texture is not None and not isinstance(p.texture, Texture):
        raise ConfigError(
            f"is {type(p.texture).__name__}",
            field=f"{p.kind}.texture",
            expected="a navkit.sim.Texture or None",
        )


# --------------------------------------------------------------------------- convex polyhedra
def _convex_intersect(
    Ol: FloatArray, Dl: FloatArray, N: FloatArray, d: FloatArray
) -> tuple[FloatArray, NDArray[np.int64]]:
    """Cyrus-Beck clipping of rays against the convex set ``{x : N x <= d}`` (local frame).

    Returns the first surface crossing ``t > T_MIN`` (``inf`` on a miss) and the index of the
    face crossed (the entering face, or the exiting face for a ray that starts inside).
    """
    num = d[None, :] - rows_matmul(Ol, N.T)  # (M, K): >= 0 where the origin is inside half-space k
    den = rows_matmul(Dl, N.T)
    with np.errstate(divide="ignore", invalid="ignore"):
        tk = num / den
    entering = den < 0
    exiting = den > 0
    parallel_out = (den == 0) & (num < 0)
    t_in_k = np.where(entering, tk, -np.inf)
    t_out_k = np.where(exiting, tk, np.inf)
    f_in = np.argmax(t_in_k, axis=1)
    f_out = np.argmin(t_out_k, axis=1)
    rows = np.arange(Dl.shape[0])
    t_in = t_in_k[rows, f_in]
    t_out = t_out_k[rows, f_out]
    ok = (t_in <= t_out) & ~parallel_out.any(axis=1)
    use_in = t_in > T_MIN
    t = np.where(use_in, t_in, t_out)
    face = np.where(use_in, f_in, f_out)
    ok &= t > T_MIN
    return np.where(ok, t, np.inf), face


@dataclass(frozen=True)
class Ground(Primitive):
    """The ground: ``z = height + A sin(2 pi x / L) sin(2 pi y / L)``, infinite in x and y.

    ``A = hill_amplitude`` (metres, 0 = flat: intersected exactly), ``L = hill_wavelength``
    (metres). Hills are intersected by marching along the ray inside the slab
    ``|z - height| <= A``: each step is the larger of the Lipschitz-safe step ``|f| / K`` (``f`` =
    ray height above the surface, ``K`` a bound of ``|df/dt|``) and the step over which the
    surface's curvature lets the ray dip under a crest by at most ``max_missed_dip`` = 1 um; the
    first bracketed crossing is refined by a safeguarded Newton iteration to ``|f| < 1e-12`` m.
    So a hit is exact to 1e-12 m and no crossing deeper than 1 um is skipped. Surface
    coordinates are world ``(x, y)``.
    """

    height: float = 0.0
    hill_amplitude: float = 0.0
    hill_wavelength: float = 20.0
    name: str = ""
    texture: Texture | None = None

    kind: ClassVar[str] = "ground"
    is_ground: ClassVar[bool] = True
    default_texture: ClassVar[Texture] = Texture(
        "noise", scale=2.0, seed=7, color=(0.55, 0.52, 0.42), color2=(0.28, 0.30, 0.22)
    )
    max_missed_dip: ClassVar[float] = 1e-6
    max_march_distance: ClassVar[float] = 2000.0

    def __post_init__(self) -> None:
        _check_common(self)
        object.__setattr__(self, "height", _scalar("ground", "height", self.height))
        object.__setattr__(
            self,
            "hill_amplitude",
            _scalar("ground", "hill_amplitude", self.hill_amplitude, nonnegative=True),
        )
        object.__setattr__(
            self,
            "hill_wavelength",
            _scalar("ground", "hill_wavelength", self.hill_wavelength, positive=True),
        )

    @property
    def is_flat(self) -> bool:
        return self.hill_amplitude == 0.0

    def height_at(self, x: FloatArray, y: FloatArray) -> FloatArray:
        """Ground height ``z(x, y)`` (metres) at world positions."""
        k = 2.0 * np.pi / self.hill_wavelength
        return self.height + self.hill_amplitude * np.sin(k * np.asarray(x)) * np.sin(
            k * np.asarray(y)
        )

    def _bound(self) -> None:
        return None

    def _intersect(
        self, Or: FloatArray, D: FloatArray, t_far: FloatArray | None = None
    ) -> tuple[FloatArray, NDArray[np.int64]]:
        M = D.shape[0]
        Or = np.broadcast_to(Or, (M, 3))
        face = np.zeros(M, dtype=np.int64)
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.is_flat:
                t = (self.height - Or[:, 2]) / D[:, 2]
                return np.where(np.isfinite(t) & (t > T_MIN), t, np.inf), face
            return self._intersect_hills(Or, D, t_far), face

    def _f(self, Or: FloatArray, D: FloatArray, t: FloatArray) -> FloatArray:
        P = Or + t[:, None] * D
        return P[:, 2] - self.height_at(P[:, 0], P[:, 1])

    def _df(self, Or: FloatArray, D: FloatArray, t: FloatArray) -> FloatArray:
        k = 2.0 * np.pi / self.hill_wavelength
        P = Or + t[:, None] * D
        sx, cx = np.sin(k * P[:, 0]), np.cos(k * P[:, 0])
        sy, cy = np.sin(k * P[:, 1]), np.cos(k * P[:, 1])
        return D[:, 2] - self.hill_amplitude * k * (cx * sy * D[:, 0] + sx * cy * D[:, 1])

    def _intersect_hills(
        self, Or: FloatArray, D: FloatArray, t_far: FloatArray | None
    ) -> FloatArray:
        M = D.shape[0]
        A, h = self.hill_amplitude, self.height
        zlo, zhi = h - A, h + A
        Oz, Dz = Or[:, 2], D[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            t_lo = (zlo - Oz) / Dz
            t_hi = (zhi - Oz) / Dz
        t_lo = np.where(Dz == 0, np.where((Oz >= zlo) & (Oz <= zhi), -np.inf, np.nan), t_lo)
        t_hi = np.where(Dz == 0, np.where((Oz >= zlo) & (Oz <= zhi), np.inf, np.nan), t_hi)
        t_in = np.maximum(np.fmin(t_lo, t_hi), 0.0)
        t_out = np.fmax(t_lo, t_hi)
        limit = (
            np.full(M, self.max_march_distance)
            if t_far is None
            else np.minimum(t_far, self.max_march_distance)
        )
        t_out = np.minimum(t_out, limit)
        result = np.full(M, np.inf)
        idx = np.flatnonzero(np.isfinite(t_in) & np.isfinite(t_out) & (t_out > t_in))
        if idx.size == 0:
            return result
        # march (sphere tracing with a floor): |f'| <= K = |Dz| + A k (|Dx| + |Dy|), so no root
        # lies within |f| / K of a sample; steps never go below s_min, the length over which
        # the curvature bound C = A k^2 (|Dx| + |Dy|)^2 lets f dip by at most C s^2 / 8 = DIP.
        k = 2.0 * np.pi / self.hill_wavelength
        Oi, Di = Or[idx], D[idx]
        l1 = np.abs(Di[:, 0]) + np.abs(Di[:, 1])
        K = np.abs(Di[:, 2]) + A * k * l1
        with np.errstate(divide="ignore"):
            s_min = np.sqrt(8.0 * self.max_missed_dip / (A * k * k * l1 * l1))
        tend = t_out[idx]
        ta = t_in[idx]
        fa = self._f(Oi, Di, ta)
        lo = np.full(idx.size, np.nan)
        hi = np.full(idx.size, np.nan)
        exact = fa == 0
        lo[exact] = hi[exact] = ta[exact]
        active = np.flatnonzero(~exact)
        while active.size:
            step = np.maximum(np.abs(fa[active]) / K[active], s_min[active])
            tb = np.minimum(ta[active] + step, tend[active])
            fb = self._f(Oi[active], Di[active], tb)
            crossed = np.sign(fb) != np.sign(fa[active])
            c = active[crossed]
            lo[c], hi[c] = ta[active][crossed], tb[crossed]
            ta[active], fa[active] = tb, fb
            active = active[~crossed & (tb < tend[active])]
        found = np.flatnonzero(np.isfinite(lo))
        if found.size == 0:
            return result
        # safeguarded Newton on [lo, hi] (bisection when the Newton step leaves the bracket)
        a, b = lo[found], hi[found]
        Of, Df = Oi[found], Di[found]
        fa_ = self._f(Of, Df, a)
        t = 0.5 * (a + b)
        todo = np.flatnonzero(a != b)
        t[a == b] = a[a == b]
        for _ in range(100):
            if todo.size == 0:
                break
            tt = t[todo]
            ft = self._f(Of[todo], Df[todo], tt)
            same = np.sign(ft) == np.sign(fa_[todo])
            a[todo] = np.where(same, tt, a[todo])
            fa_[todo] = np.where(same, ft, fa_[todo])
            b[todo] = np.where(same, b[todo], tt)
            dft = self._df(Of[todo], Df[todo], tt)
            with np.errstate(divide="ignore", invalid="ignore"):
                tn = tt - ft / dft
            bad = (
                ~np.isfinite(tn)
                | (tn <= np.minimum(a[todo], b[todo]))
                | (tn >= np.maximum(a[todo], b[todo]))
            )
            tn = np.where(bad, 0.5 * (a[todo] + b[todo]), tn)
            t[todo] = tn
            done = (np.abs(ft) < 1e-12) | (np.abs(b[todo] - a[todo]) < 1e-13)
            t[todo[done]] = tt[done]
            todo = todo[~done]
        t = np.where(t > T_MIN, t, np.inf)
        result[idx[found]] = t
        return result

    def _surface(
        self, P: FloatArray, face: NDArray[np.int64]
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        k = 2.0 * np.pi / self.hill_wavelength
        A = self.hill_amplitude
        gx = A * k * np.cos(k * P[:, 0]) * np.sin(k * P[:, 1])
        gy = A * k * np.sin(k * P[:, 0]) * np.cos(k * P[:, 1])
        n = np.stack([-gx, -gy, np.ones_like(gx)], axis=1)
        n /= rows_norm(n)[:, None]
        return n, P[:, 0].copy(), P[:, 1].copy()

    def _faces(self) -> list[tuple[str, FloatArray, FloatArray]]:
        if not self.is_flat:
            return []
        return [("", np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, self.height]))]


class _Polyhedron(Primitive):
    """Boxes and prisms: a yawed convex polyhedron given by local half-spaces ``N x <= d``."""

    center: Vec3
    size: Vec3
    yaw: float
    _face_names: ClassVar[tuple[str, ...]] = ()
    _face_axes: ClassVar[tuple[tuple[int, int], ...]] = ()
    _slope_face: ClassVar[int | None] = None

    def _local_planes(self) -> tuple[FloatArray, FloatArray]:
        raise NotImplementedError

    def _R(self) -> FloatArray:
        return _rot_z(self.yaw)

    def _bound(self) -> tuple[FloatArray, float]:
        return np.asarray(self.center), 0.5 * float(np.linalg.norm(self.size))

    def _intersect(self, Or: FloatArray, D: FloatArray) -> tuple[FloatArray, NDArray[np.int64]]:
        R = self._R()
        N, d = self._local_planes()
        Ol = rows_matmul(Or - np.asarray(self.center), R)  # world -> local: R^T p
        Dl = rows_matmul(D, R)
        return _convex_intersect(Ol, Dl, N, d)

    def _surface(
        self, P: FloatArray, face: NDArray[np.int64]
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        R = self._R()
        N, _ = self._local_planes()
        n = rows_matmul(N[face], R.T)
        # local coordinates measured from the lower corner (metres)
        Pl = rows_matmul(P - np.asarray(self.center), R) + 0.5 * np.asarray(self.size)
        axes = np.asarray(self._face_axes)[face]  # (M, 2): local axes of (s, t) per face
        rows = np.arange(len(P))
        s = Pl[rows, axes[:, 0]]
        t = Pl[rows, axes[:, 1]]
        if self._slope_face is not None:  # distance up the ramp
            up = face == self._slope_face
            t = np.where(up, np.hypot(Pl[:, 0], Pl[:, 2]), t)
        return n, s, t

    def _faces(self) -> list[tuple[str, FloatArray, FloatArray]]:
        R = self._R()
        N, d = self._local_planes()
        c = np.asarray(self.center)
        out = []
        for name, n, dk in zip(self._face_names, N, d, strict=True):
            out.append((name, R @ n, c + R @ self._face_point(name, n, dk)))
        return out

    def _face_point(self, name: str, n: FloatArray, d: float) -> FloatArray:
        return n * d


@dataclass(frozen=True)
class Box(_Polyhedron):
    """A box: ``center`` (its centre), ``size`` = full extents ``(x, y, z)``, turned by ``yaw``.

    Faces: ``+x, -x, +y, -y, top, bottom`` (local axes). Surface coordinates: metres across the
    face from its lower corner (``(y, z)`` on x faces, ``(x, z)`` on y faces, ``(x, y)`` on top).
    """

    center: Vec3
    size: Vec3
    yaw: float = 0.0
    name: str = ""
    texture: Texture | None = None

    kind: ClassVar[str] = "box"
    default_texture: ClassVar[Texture] = Texture("solid", color=(0.62, 0.45, 0.30))
    _face_names: ClassVar[tuple[str, ...]] = ("+x", "-x", "+y", "-y", "top", "bottom")
    _face_axes: ClassVar[tuple[tuple[int, int], ...]] = (
        (1, 2),
        (1, 2),
        (0, 2),
        (0, 2),
        (0, 1),
        (0, 1),
    )

    def __post_init__(self) -> None:
        _check_common(self)
        object.__setattr__(self, "center", _vec3("box", "center", self.center))
        size = _vec3("box", "size", self.size)
        if min(size) <= 0:
            raise ConfigError(
                f"is {size}", field="box.size", expected="three positive extents (metres)"
            )
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "yaw", _scalar("box", "yaw", self.yaw))

    def _local_planes(self) -> tuple[FloatArray, FloatArray]:
        hx, hy, hz = 0.5 * np.asarray(self.size)
        N = np.array([[1.0, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]])
        return N, np.array([hx, hx, hy, hy, hz, hz])

    def _intersect(self, Or: FloatArray, D: FloatArray) -> tuple[FloatArray, NDArray[np.int64]]:
        """Kay-Kajiya slab test in the box frame (3 slabs instead of 6 half-spaces)."""
        R = self._R()
        h = 0.5 * np.asarray(self.size)
        Ol = rows_matmul(Or - np.asarray(self.center), R)
        Dl = rows_matmul(D, R)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / Dl
            t1 = (-h - Ol) * inv
            t2 = (h - Ol) * inv
        # a ray parallel to a slab and outside it: NaN (0 * inf) or +-inf, caught below
        lo = np.minimum(t1, t2)
        hi = np.maximum(t1, t2)
        lo = np.where(np.isnan(lo), -np.inf, lo)
        hi = np.where(np.isnan(hi), np.inf, hi)
        outside_parallel = (Dl == 0) & (np.abs(np.broadcast_to(Ol, Dl.shape)) > h)
        ax_in = np.argmax(lo, axis=1)
        ax_out = np.argmin(hi, axis=1)
        rows = np.arange(D.shape[0])
        t_in = lo[rows, ax_in]
        t_out = hi[rows, ax_out]
        use_in = t_in > T_MIN
        t = np.where(use_in, t_in, t_out)
        ok = (t_in <= t_out) & (t > T_MIN) & ~outside_parallel.any(axis=1)
        # face index as in _local_planes: axis a -> 2a for +, 2a + 1 for -; the entering face
        # is the one facing the ray (sign opposite to D), the exiting one along D
        ax = np.where(use_in, ax_in, ax_out)
        d_ax = Dl[rows, ax]
        positive = np.where(use_in, d_ax < 0, d_ax > 0)
        face = 2 * ax + np.where(positive, 0, 1)
        return np.where(ok, t, np.inf), face


@dataclass(frozen=True)
class Prism(_Polyhedron):
    """A ramp (wedge) with a rectangular footprint ``size[0] x size[1]``.

    ``center`` is the centre of its bounding box (as for :class:`Box`); the top rises linearly
    from 0 at local ``-x`` to ``size[2]`` at local ``+x``, so the slope angle is
    ``atan(size[2] / size[0])``. Faces: ``slope``, ``bottom``, ``+x`` (the vertical back),
    ``+y``, ``-y`` (triangles).
    """

    center: Vec3
    size: Vec3
    yaw: float = 0.0
    name: str = ""
    texture: Texture | None = None

    kind: ClassVar[str] = "prism"
    default_texture: ClassVar[Texture] = Texture("solid", color=(0.50, 0.55, 0.62))
    _face_names: ClassVar[tuple[str, ...]] = ("slope", "bottom", "+x", "+y", "-y")
    _face_axes: ClassVar[tuple[tuple[int, int], ...]] = ((1, 0), (0, 1), (1, 2), (0, 2), (0, 2))
    _slope_face: ClassVar[int | None] = 0

    def __post_init__(self) -> None:
        _check_common(self)
        object.__setattr__(self, "center", _vec3("prism", "center", self.center))
        size = _vec3("prism", "size", self.size)
        if min(size) <= 0:
            raise ConfigError(
                f"is {size}", field="prism.size", expected="three positive extents (metres)"
            )
        object.__setattr__(self, "size", size)
        object.__setattr__(self, "yaw", _scalar("prism", "yaw", self.yaw))

    @property
    def slope_angle(self) -> float:
        """Angle of the sloped face to the horizontal, radians."""
        return float(np.arctan2(self.size[2], self.size[0]))

    def _local_planes(self) -> tuple[FloatArray, FloatArray]:
        hx, hy, hz = 0.5 * np.asarray(self.size)
        # top: z <= -hz + (x + hx) hz / hx  <=>  -(hz/hx) x + z <= 0
        ns = np.array([-hz / hx, 0.0, 1.0])
        ns /= np.linalg.norm(ns)
        N = np.array([ns, [0, 0, -1.0], [1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0]])
        return N, np.array([0.0, hz, hx, hy, hy])

    def _face_point(self, name: str, n: FloatArray, d: float) -> FloatArray:
        hx, hy, hz = 0.5 * np.asarray(self.size)
        return {
            "slope": np.array([0.0, 0.0, 0.0]),
            "bottom": np.array([0.0, 0.0, -hz]),
            "+x": np.array([hx, 0.0, 0.0]),
            "+y": np.array([hx / 3, hy, -hz / 3]),
            "-y": np.array([hx / 3, -hy, -hz / 3]),
        }[name]


@dataclass(frozen=True)
class Sphere(Primitive):
    """A sphere. Surface coordinates: ``(radius * azimuth, radius * elevation)`` metres."""

    center: Vec3
    radius: float
    name: str = ""
    texture: Texture | None = None

    kind: ClassVar[str] = "sphere"
    default_texture: ClassVar[Texture] = Texture(
        "noise", scale=0.3, seed=3, color=(0.60, 0.58, 0.55), color2=(0.35, 0.33, 0.30)
    )

    def __post_init__(self) -> None:
        _check_common(self)
        object.__setattr__(self, "center", _vec3(self.kind, "center", self.center))
        object.__setattr__(self, "radius", _scalar(self.kind, "radius", self.radius, positive=True))

    def _bound(self) -> tuple[FloatArray, float]:
        return np.asarray(self.center), self.radius

    def _roots(self, Or: FloatArray, D: FloatArray) -> tuple[FloatArray, FloatArray]:
        oc = Or - np.asarray(self.center)
        b = _dot(oc, D) if oc.shape == D.shape else rows_dot(D, oc[0])
        c = np.einsum("ij,ij->i", oc, oc) - self.radius**2
        disc = b * b - c
        sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
        # numerically stable pair: q = -(b + sign(b) sq); t0 = q, t1 = c / q
        q = -(b + np.copysign(sq, b))
        with np.errstate(divide="ignore", invalid="ignore"):
            r1, r2 = q, c / q
        t0, t1 = np.fmin(r1, r2), np.fmax(r1, r2)
        return t0, t1  # NaN on a miss

    def _intersect(self, Or: FloatArray, D: FloatArray) -> tuple[FloatArray, NDArray[np.int64]]:
        t0, t1 = self._roots(Or, D)
        t = np.where(t0 > T_MIN, t0, np.where(t1 > T_MIN, t1, np.inf))
        return t, np.zeros(D.shape[0], dtype=np.int64)

    def _surface(
        self, P: FloatArray, face: NDArray[np.int64]
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        v = (P - np.asarray(self.center)) / self.radius
        v /= rows_norm(v)[:, None]
        az = np.arctan2(v[:, 1], v[:, 0])
        el = np.arcsin(np.clip(v[:, 2], -1.0, 1.0))
        return v, self.radius * az, self.radius * el


@dataclass(frozen=True)
class Hemisphere(Sphere):
    """The upper half of a sphere (a dome, e.g. a rock): ``center`` on the ground, dome up.

    Only the dome ``z >= center.z`` is a surface; the flat base is left open (it lies on the
    ground), so a ray below ``center.z`` passes under the dome.
    """

    kind: ClassVar[str] = "hemisphere"

    def _bound(self) -> tuple[FloatArray, float]:
        return np.asarray(self.center), self.radius

    def _intersect(self, Or: FloatArray, D: FloatArray) -> tuple[FloatArray, NDArray[np.int64]]:
        t0, t1 = self._roots(Or, D)
        Ob = np.broadcast_to(Or, D.shape)
        cz = self.center[2]
        up0 = Ob[:, 2] + t0 * D[:, 2] >= cz
        up1 = Ob[:, 2] + t1 * D[:, 2] >= cz
        t = np.where((t0 > T_MIN) & up0, t0, np.where((t1 > T_MIN) & up1, t1, np.inf))
        return t, np.zeros(D.shape[0], dtype=np.int64)


@dataclass(frozen=True)
class Cylinder(Primitive):
    """A vertical closed cylinder (a post): ``center`` = centre of the base, axis +z.

    Faces: 0 side, 1 top, 2 bottom. Surface coordinates: ``(radius * angle, z above the base)``
    on the side, local ``(x, y)`` on the caps.
    """

    center: Vec3
    radius: float
    height: float
    name: str = ""
    texture: Texture | None = None

    kind: ClassVar[str] = "cylinder"
    default_texture: ClassVar[Texture] = Texture("solid", color=(0.35, 0.38, 0.42))

    def __post_init__(self) -> None:
        _check_common(self)
        object.__setattr__(self, "center", _vec3("cylinder", "center", self.center))
        object.__setattr__(
            self, "radius", _scalar("cylinder", "radius", self.radius, positive=True)
        )
        object.__setattr__(
            self, "height", _scalar("cylinder", "height", self.height, positive=True)
        )

    def _bound(self) -> tuple[FloatArray, float]:
        c = np.asarray(self.center) + np.array([0.0, 0.0, 0.5 * self.height])
        return c, float(np.hypot(self.radius, 0.5 * self.height))

    def _intersect(self, Or: FloatArray, D: FloatArray) -> tuple[FloatArray, NDArray[np.int64]]:
        M = D.shape[0]
        Ol = np.broadcast_to(Or - np.asarray(self.center), (M, 3))
        R, H = self.radius, self.height
        a = D[:, 0] ** 2 + D[:, 1] ** 2
        b = Ol[:, 0] * D[:, 0] + Ol[:, 1] * D[:, 1]
        c = Ol[:, 0] ** 2 + Ol[:, 1] ** 2 - R * R
        disc = b * b - a * c
        with np.errstate(divide="ignore", invalid="ignore"):
            sq = np.sqrt(np.where(disc >= 0, disc, np.nan))
            q = -(b + np.copysign(sq, b))
            r1, r2 = q / a, c / q
            cand = np.empty((M, 4))
            cand[:, 0], cand[:, 1] = np.fmin(r1, r2), np.fmax(r1, r2)
            cand[:, 2] = (H - Ol[:, 2]) / D[:, 2]
            cand[:, 3] = -Ol[:, 2] / D[:, 2]
        fin = np.where(np.isfinite(cand), cand, 0.0)
        z0 = Ol[:, 2, None] + fin[:, :2] * D[:, 2, None]
        side_ok = (z0 >= 0) & (z0 <= H)
        Pc = Ol[:, None, :2] + fin[:, 2:, None] * D[:, None, :2]
        cap_ok = np.einsum("mkj,mkj->mk", Pc, Pc) <= R * R
        ok = np.concatenate([side_ok, cap_ok], axis=1) & (cand > T_MIN) & np.isfinite(cand)
        cand = np.where(ok, cand, np.inf)
        k = np.argmin(cand, axis=1)
        t = cand[np.arange(M), k]
        face = np.array([0, 0, 1, 2])[k]
        return t, face

    def _surface(
        self, P: FloatArray, face: NDArray[np.int64]
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        Pl = P - np.asarray(self.center)
        radial = np.stack([Pl[:, 0], Pl[:, 1], np.zeros(len(P))], axis=1)
        radial /= np.maximum(rows_norm(radial), 1e-300)[:, None]
        n = np.where(
            (face == 0)[:, None],
            radial,
            np.where((face == 1)[:, None], np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])),
        )
        ang = np.arctan2(Pl[:, 1], Pl[:, 0])
        s = np.where(face == 0, self.radius * ang, Pl[:, 0])
        t = np.where(face == 0, Pl[:, 2], Pl[:, 1])
        return n, s, t

    def _faces(self) -> list[tuple[str, FloatArray, FloatArray]]:
        c = np.asarray(self.center)
        return [
            ("top", np.array([0.0, 0.0, 1.0]), c + np.array([0.0, 0.0, self.height])),
            ("bottom", np.array([0.0, 0.0, -1.0]), c.copy()),
        ]


@dataclass(frozen=True)
class Wall(Primitive):
    """A planar parallelogram ``origin + a u + b v``, ``a, b`` in ``[0, 1]`` (two-sided).

    For a vertical wall give ``u`` horizontal along the wall and ``v`` up. Surface coordinates:
    ``(a |u|, b |v|)`` metres (bricks run along ``u``). Normal: ``u x v`` (flipped to face a ray).
    """

    origin: Vec3
    u: Vec3
    v: Vec3
    name: str = ""
    texture: Texture | None = None

    kind: ClassVar[str] = "wall"
    default_texture: ClassVar[Texture] = Texture(
        "bricks", scale=0.25, seed=11, color=(0.62, 0.28, 0.20), color2=(0.80, 0.78, 0.72)
    )

    def __post_init__(self) -> None:
        _check_common(self)
        for f in ("origin", "u", "v"):
            object.__setattr__(self, f, _vec3("wall", f, getattr(self, f)))
        if np.linalg.norm(np.cross(self.u, self.v)) < 1e-9:
            raise ConfigError(
                f"u={self.u} and v={self.v} are parallel or zero",
                field="wall.u",
                expected="two non-parallel edge vectors (metres)",
            )

    @property
    def normal(self) -> FloatArray:
        n = np.cross(self.u, self.v)
        return n / np.linalg.norm(n)

    def _bound(self) -> tuple[FloatArray, float]:
        u, v = np.asarray(self.u), np.asarray(self.v)
        r = 0.5 * max(np.linalg.norm(u + v), np.linalg.norm(u - v))
        return np.asarray(self.origin) + 0.5 * (u + v), float(r)

    def _dual(self) -> tuple[FloatArray, FloatArray]:
        """Dual edge vectors ``u*, v*`` with ``a = (P - origin) . u*``, ``b = (P - origin) . v*``."""
        u, v = np.asarray(self.u), np.asarray(self.v)
        Ginv = np.linalg.inv(np.array([[u @ u, u @ v], [u @ v, v @ v]]))
        return Ginv[0, 0] * u + Ginv[0, 1] * v, Ginv[1, 0] * u + Ginv[1, 1] * v

    def _ab(self, P: FloatArray) -> tuple[FloatArray, FloatArray]:
        us, vs = self._dual()
        w = P - np.asarray(self.origin)
        return rows_dot(w, us), rows_dot(w, vs)

    def _intersect(self, Or: FloatArray, D: FloatArray) -> tuple[FloatArray, NDArray[np.int64]]:
        # t = (origin - O) . n / (D . n); the hit's a = (O - origin) . u* + t D . u* (same for b)
        n = self.normal
        us, vs = self._dual()
        w0 = Or - np.asarray(self.origin)  # (1, 3) or (M, 3)
        den = rows_dot(D, n)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -rows_dot(w0, n) / den
            a = rows_dot(w0, us) + t * rows_dot(D, us)
            b = rows_dot(w0, vs) + t * rows_dot(D, vs)
        ok = (t > T_MIN) & (a >= 0) & (a <= 1) & (b >= 0) & (b <= 1) & np.isfinite(t)
        return np.where(ok, t, np.inf), np.zeros(D.shape[0], dtype=np.int64)

    def _surface(
        self, P: FloatArray, face: NDArray[np.int64]
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        a, b = self._ab(P)
        n = np.broadcast_to(self.normal, P.shape).copy()
        return n, a * float(np.linalg.norm(self.u)), b * float(np.linalg.norm(self.v))

    def _faces(self) -> list[tuple[str, FloatArray, FloatArray]]:
        u, v = np.asarray(self.u), np.asarray(self.v)
        return [("", self.normal, np.asarray(self.origin) + 0.5 * (u + v))]
