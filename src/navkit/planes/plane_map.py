"""The merged plane map of paper 2 (step 7, figs. 8-9): one :class:`MapPlane` per physical
plane (world frame), fused over the frames that saw it - a sample of its inlier points, its
outline and a running mean of its brightness on a fixed lattice of the plane - and the
:class:`MapView` that shows the map to the motion solver as if it were a frame."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError, NavkitError
from navkit.geometry.fitting import Plane, canonical_plane
from navkit.geometry.linalg import rows_matmul
from navkit.geometry.polygons import points_in_polygon
from navkit.planes.frame import PlaneObservation
from navkit.planes.segments import ExtractionResult, PlaneSegment, outline_from_points
from navkit.planes.texture import PlaneTexture

__all__ = ["MapPlane", "MapView", "PlaneMap"]

log = logging.getLogger(__name__)


@dataclass
class MapPlane:
    """One plane of the map (world frame), fused over the frames that saw it.

    Attributes
    ----------
    id : int
    plane : Plane
        TLS fit over all kept points (world frame).
    points : (N, 3) array
        Sample of inlier points (world frame).
    outline : (M, 2) array
        Outline in the plane's own frame (``plane.rho * plane.normal``, ``plane.basis()``).
    area : float
        m^2.
    observations : list of int
        Frame indices that saw the plane.
    tex_sum, tex_count : (h, w) arrays
        Running brightness sum and count on the lattice ``tex_ref + (i0 + i) nu u + (j0 + j) nu v``.
    tex_ref : (3,) array; tex_axes : (2, 3) array; tex_index0 : (2,) int array
    """

    id: int
    plane: Plane
    points: NDArray[np.float64]
    outline: NDArray[np.float64]
    area: float
    observations: list[int]
    tex_ref: NDArray[np.float64]
    tex_axes: NDArray[np.float64]
    tex_index0: NDArray[np.int64] = field(default_factory=lambda: np.zeros(2, np.int64))
    tex_sum: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 0)))
    tex_count: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 0)))

    @property
    def texture(self) -> NDArray[np.float64]:
        """Fused brightness ``(h, w)`` in [0, 1], NaN where never seen."""
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(
                self.tex_count > 0, self.tex_sum / np.maximum(self.tex_count, 1), np.nan
            )

    def add_texture(
        self, image: NDArray[np.float32], mask: NDArray[np.bool_], index0: NDArray[np.int64]
    ) -> None:
        """Accumulate a texture sampled on this plane's lattice (window at ``index0``)."""
        if self.tex_sum.size == 0:
            self.tex_index0 = np.asarray(index0, np.int64).copy()
            self.tex_sum = np.zeros(image.shape)
            self.tex_count = np.zeros(image.shape)
        lo = np.minimum(self.tex_index0, index0)
        hi = np.maximum(
            self.tex_index0 + self.tex_sum.shape[::-1], np.asarray(index0) + image.shape[::-1]
        )
        if np.any(lo != self.tex_index0) or np.any(
            hi != self.tex_index0 + self.tex_sum.shape[::-1]
        ):
            S = np.zeros((hi[1] - lo[1], hi[0] - lo[0]))
            C = np.zeros_like(S)
            o = self.tex_index0 - lo
            S[o[1] : o[1] + self.tex_sum.shape[0], o[0] : o[0] + self.tex_sum.shape[1]] = (
                self.tex_sum
            )
            C[o[1] : o[1] + self.tex_sum.shape[0], o[0] : o[0] + self.tex_sum.shape[1]] = (
                self.tex_count
            )
            self.tex_sum, self.tex_count, self.tex_index0 = S, C, lo
        o = np.asarray(index0) - self.tex_index0
        win = (slice(o[1], o[1] + image.shape[0]), slice(o[0], o[0] + image.shape[1]))
        self.tex_sum[win] += np.where(mask, image, 0.0)
        self.tex_count[win] += mask


@dataclass
class PlaneMap:
    """The merged plane map (world frame = first frame's sensor frame)."""

    planes: list[MapPlane] = field(default_factory=list)
    nu: float = 0.02
    next_id: int = 0

    def mesh(self) -> tuple[NDArray[np.float64], NDArray[np.uint8], NDArray[np.int64]]:
        """Textured triangle mesh of all map planes: vertices ``(V, 3)`` at the texture pixel
        centres, gray colours ``(V, 3)`` uint8, faces ``(F, 3)`` (two per 2 x 2 block of valid
        texture pixels)."""
        verts, cols, faces = [], [], []
        base = 0
        for mp in self.planes:
            tex = mp.texture
            if tex.size == 0:
                continue
            h, w = tex.shape
            valid = np.isfinite(tex)
            i = (mp.tex_index0[0] + np.arange(w)) * self.nu
            j = (mp.tex_index0[1] + np.arange(h)) * self.nu
            P = mp.tex_ref + i[None, :, None] * mp.tex_axes[0] + j[:, None, None] * mp.tex_axes[1]
            idx = -np.ones((h, w), np.int64)
            idx[valid] = base + np.arange(valid.sum())
            verts.append(P[valid])
            g = np.clip(np.rint(tex[valid] * 255), 0, 255).astype(np.uint8)
            cols.append(np.repeat(g[:, None], 3, axis=1))
            a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
            ok = (a >= 0) & (b >= 0) & (c >= 0) & (d >= 0)
            faces.append(
                np.concatenate(
                    [np.stack([a[ok], c[ok], b[ok]], 1), np.stack([b[ok], c[ok], d[ok]], 1)]
                )
            )
            base += int(valid.sum())
        if not verts:
            return np.zeros((0, 3)), np.zeros((0, 3), np.uint8), np.zeros((0, 3), np.int64)
        return np.concatenate(verts), np.concatenate(cols), np.concatenate(faces)

    def to_dict(self) -> dict:
        """JSON-ready description (normals, rho, area, outline in world coordinates, observations)."""
        out = []
        for mp in self.planes:
            o, ax = mp.plane.rho * mp.plane.normal, mp.plane.basis()
            out.append(
                {
                    "id": mp.id,
                    "normal": mp.plane.normal,
                    "rho": mp.plane.rho,
                    "rms": mp.plane.rms,
                    "area_m2": mp.area,
                    "points": len(mp.points),
                    "outline_world": o + mp.outline @ ax if len(mp.outline) else np.zeros((0, 3)),
                    "observations": mp.observations,
                    "texture_shape": list(mp.tex_sum.shape),
                    "texture_nu": self.nu,
                }
            )
        return {"frame": "world = sensor frame of the first frame", "planes": out}

    def merge(
        self,
        obs: PlaneObservation,
        T: NDArray[np.float64],
        frame: int,
        *,
        min_points: int,
        sample: int,
        angle_deg: float,
        distance_m: float,
        margin_m: float,
        only_new: bool = False,
    ) -> None:
        """Merge the planes of frame ``obs`` (number ``frame``, placed at ``T = T_world_frame``)
        into the map: a frame plane of at least ``min_points`` inliers joins the map plane whose
        normal agrees within ``angle_deg``, distance within ``distance_m`` and outline within
        ``margin_m`` (the nearest in distance), else it starts a new map plane; ``sample``
        inlier points per observation extend it (at most ``20 sample`` kept), and the frame's
        texture is fused into the plane's running mean. ``only_new``: add only the planes that
        join no map plane, without their texture (the next full merge fuses it: texture
        fusion is the costliest part of a merge)."""
        R, t = T[:3, :3], T[:3, 3]
        rng = np.random.default_rng(frame)
        P = obs.points.reshape(-1, 3)
        for k, seg in enumerate(obs.segments):
            if seg.plane.count < min_points:
                continue
            n, rho = canonical_plane(R @ seg.normal, float(seg.rho + (R @ seg.normal) @ t))
            probe = rows_matmul(P[seg.inliers[:: max(1, len(seg.inliers) // 300)]], R.T) + t
            target = self._find(n, rho, probe, angle_deg, distance_m, margin_m)
            if only_new and target is not None:
                continue
            pick = (
                seg.inliers
                if len(seg.inliers) <= sample
                else rng.choice(seg.inliers, sample, replace=False)
            )
            pts = rows_matmul(P[pick], R.T) + t
            if target is None:
                plane = Plane(n, rho, pts.mean(0), seg.rms, seg.plane.count)
                mp = MapPlane(
                    self.next_id,
                    plane,
                    pts,
                    np.zeros((0, 2)),
                    0.0,
                    [frame],
                    tex_ref=rho * n,
                    tex_axes=plane.basis(),
                )
                self.planes.append(mp)
                self.next_id += 1
            else:
                mp = target
                mp.points = np.vstack([mp.points, pts])
                if len(mp.points) > 20 * sample:
                    mp.points = mp.points[rng.choice(len(mp.points), 20 * sample, replace=False)]
                mp.observations.append(frame)
            _refit(mp)
            if obs.has_texture and not only_new:
                axes_c = mp.tex_axes @ R  # world axes seen in the frame
                ref_c = R.T @ (mp.tex_ref - t)
                try:
                    tex = obs.texture(k, axes_c, ref_c, self.nu)
                except NavkitError as exc:  # texture is optional for the map
                    log.debug("map texture of plane %d skipped: %s", k, exc)
                    continue
                mp.add_texture(tex.image, tex.mask, tex.index0)

    def consolidate(
        self, *, angle_deg: float, distance_m: float, margin_m: float, max_points: int
    ) -> int:
        """Join map planes that are one surface: two map planes the merge rule would join
        (:meth:`_find`: normals within ``angle_deg``, distances within ``distance_m``, one's
        points within ``margin_m`` of the other's outline) become one. Such duplicates appear
        when a surface is first seen in parts - split by an occluder or a segmentation
        (over-segmentation), or its new part more than ``margin_m`` beyond the map plane's
        outline - and the parts grow together. The plane observed more often keeps its id and
        texture (the other's lattice differs; its texture is rebuilt by the next merges),
        gains the other's points (a random ``max_points`` of both at most) and observations,
        and is refitted. Returns the number of planes joined away."""
        joined = 0
        k = 0
        while k < len(self.planes):
            mp = self.planes[k]
            rest = PlaneMap(self.planes[k + 1 :], self.nu)
            other = rest._find(
                mp.plane.normal,
                mp.plane.rho,
                mp.points[:: max(1, len(mp.points) // 300)],
                angle_deg,
                distance_m,
                margin_m,
            )
            if other is None:
                k += 1
                continue
            keep, drop = (
                (mp, other) if len(mp.observations) >= len(other.observations) else (other, mp)
            )
            pts = np.vstack([keep.points, drop.points])
            if len(pts) > max_points:
                rng = np.random.default_rng(keep.id)
                pts = pts[rng.choice(len(pts), max_points, replace=False)]
            keep.points = pts
            keep.observations = sorted(set(keep.observations) | set(drop.observations))
            if keep.tex_sum.size == 0 and drop.tex_sum.size:
                keep.tex_ref, keep.tex_axes = drop.tex_ref, drop.tex_axes
                keep.tex_index0, keep.tex_sum, keep.tex_count = (
                    drop.tex_index0,
                    drop.tex_sum,
                    drop.tex_count,
                )
            _refit(keep)
            self.planes = [p for p in self.planes if p is not drop]
            joined += 1  # k stays: the joined plane may now meet another
        return joined

    def _find(
        self,
        n: NDArray[np.float64],
        rho: float,
        pts: NDArray[np.float64],
        angle_deg: float,
        distance_m: float,
        margin_m: float,
    ) -> MapPlane | None:
        """The map plane the world plane ``(n, rho)`` with points ``pts`` joins, or None: of
        the map planes within ``angle_deg`` and ``distance_m`` whose outline comes within
        ``margin_m`` of the points, the nearest in distance."""
        if not self.planes:
            return None
        N = np.array([mp.plane.normal for mp in self.planes])
        r = np.array([mp.plane.rho for mp in self.planes])
        ang = np.degrees(np.arccos(np.clip(N @ n, -1, 1)))
        d = np.abs(rho - r)
        for k in np.argsort(d, kind="stable"):
            if not (ang[k] <= angle_deg and d[k] <= distance_m):
                continue
            mp = self.planes[k]
            if len(mp.outline) >= 3:
                o, ax = mp.plane.rho * mp.plane.normal, mp.plane.basis()
                if not points_in_polygon((pts - o) @ ax.T, mp.outline, tolerance=margin_m).any():
                    continue
            return mp
        return None

    def view(
        self,
        obs: PlaneObservation,
        T_world_view: NDArray[np.float64],
        *,
        near_m: float,
        margin_m: float,
        max_pixels: int,
    ) -> MapView:
        """The map planes seen from ``T_world_view``, with the texture windows centred on where
        the frame ``obs`` (placed at ``T_world_view``) sees each of them: its points within
        ``near_m`` of the plane, plus ``margin_m``, at most ``max_pixels`` a side. A map plane
        none of whose kept points falls in the frame's view (:func:`_in_view`) is left out:
        the solver's association would only reject it, at a cost that grows with the map."""
        R, t = T_world_view[:3, :3], T_world_view[:3, 3]
        P = np.asarray(obs.points).reshape(-1, 3)
        P = np.asarray(P[:: max(1, len(P) // 4_000)], dtype=np.float64)
        P = P[np.all(np.isfinite(P), axis=1)]
        seen = [(mp, _in_view(mp, obs, P, R, t, near_m)) for mp in self.planes]
        planes = [mp for mp, X in seen if X is not None]
        pts = [X for _, X in seen if X is not None]
        segs, focus = [], []
        if planes:
            # the frame's points near each map plane (view frame), all planes at once
            Nw = np.array([mp.plane.normal for mp in planes])
            rw = np.array([mp.plane.rho for mp in planes])
            near_all = np.abs(rows_matmul(P, R.T @ Nw.T) - (rw - Nw @ t)) < near_m
        for k, mp in enumerate(planes):
            nv = R.T @ mp.plane.normal
            n, rho = canonical_plane(nv, float(mp.plane.rho - mp.plane.normal @ t))
            c = R.T @ (mp.plane.centroid - t)
            plane = Plane(n, rho, c, mp.plane.rms, mp.plane.count)
            # the outline in the view plane's own 2-D frame: the map plane's outline moved
            # in-plane (a 2 x 2 rotation and an offset between the two planes' frames)
            o_w, ax_w, ax_v = mp.plane.rho * mp.plane.normal, mp.plane.basis(), plane.basis()
            M2 = ax_w @ R @ ax_v.T
            offset = ((o_w - t) @ R - rho * n) @ ax_v.T
            outline = mp.outline @ M2 + offset if len(mp.outline) else np.zeros((0, 2))
            segs.append(PlaneSegment(plane, np.zeros(0, np.int64), outline, mp.area))
            focus.append(P[near_all[:, k]])
        X = np.concatenate(pts) if pts else np.zeros((0, 3))
        return MapView(
            ExtractionResult(tuple(segs), -np.ones(len(X), np.int64)),
            X,
            map_planes=tuple(planes),
            T_world_view=np.asarray(T_world_view, dtype=np.float64),
            nu_map=self.nu,
            focus=tuple(focus),
            margin=margin_m,
            max_pixels=max_pixels,
        )


@dataclass(frozen=True)
class MapView(PlaneObservation):
    """The map's planes seen from a predicted pose, shaped like a frame for
    :func:`~navkit.planes.motion.estimate_motion` (the map plays frame 1).

    Segments are the map planes in the view frame (``T_world_view`` maps view coordinates to
    the world): fused normal and distance, world outline moved into the view, the fused point
    count. :meth:`texture` resamples the map's fused texture (bilinear, valid where every
    neighbour was seen) onto the lattice the solver asks for, cropped to a window around where
    the current frame sees the plane. There is no camera: the depth check of texture steps is
    made against the last merged frame instead
    (:class:`~navkit.planes.odometry.PlaneOdometry`).

    Attributes
    ----------
    map_planes : tuple of MapPlane
        ``map_planes[k]`` is segment ``k``.
    T_world_view : (4, 4) array
    nu_map : float
        Pixel size of the fused textures, metres.
    focus : tuple of (K_k, 3) arrays
        Per segment, view-frame points of the current frame near the plane (where the
        texture window is centred; empty = the whole fused texture).
    margin : float
        Window margin around ``focus``, metres (the solver's search range).
    max_pixels : int
        Largest window side, pixels.
    """

    map_planes: tuple[MapPlane, ...] = ()
    T_world_view: NDArray[np.float64] = field(default_factory=lambda: np.eye(4))
    nu_map: float = 0.02
    focus: tuple[NDArray[np.float64], ...] = ()
    margin: float = 0.6
    max_pixels: int = 400

    @property
    def has_texture(self) -> bool:
        return any(mp.tex_sum.size > 0 for mp in self.map_planes)

    def texture(
        self, k: int, axes: ArrayLike | None = None, ref: ArrayLike | None = None, nu: float = 0.01
    ) -> PlaneTexture:
        """Fused texture of map plane ``k`` on the lattice ``ref + (i0 + i) nu u + (j0 + j) nu v``
        (view frame; default: the plane's own frame), see :mod:`navkit.planes.texture`."""
        mp, seg = self.map_planes[k], self.segments[k]
        if mp.tex_sum.size == 0 or not np.any(mp.tex_count > 0):
            raise InputError(
                f"map plane {mp.id} has no fused texture", field="texture", expected="a seen plane"
            )
        ax = seg.plane.basis() if axes is None else np.asarray(axes, dtype=np.float64)
        o = seg.plane.rho * seg.plane.normal if ref is None else np.asarray(ref, dtype=np.float64)
        R, t = self.T_world_view[:3, :3], self.T_world_view[:3, 3]
        # the fused texture's valid extent, in the requested lattice
        jj, ii = np.nonzero(mp.tex_count > 0)
        corners = np.array([[ii.min(), jj.min()], [ii.max(), jj.max()]]) + mp.tex_index0
        Cw = (
            mp.tex_ref
            + (corners[[0, 1, 0, 1], 0, None] * self.nu_map) * mp.tex_axes[0]
            + (corners[[0, 0, 1, 1], 1, None] * self.nu_map) * mp.tex_axes[1]
        )
        uv = rows_matmul(rows_matmul(Cw - t, R) - o, ax.T)
        lo = np.floor(uv.min(0) / nu).astype(np.int64) - 1
        hi = np.ceil(uv.max(0) / nu).astype(np.int64) + 1
        F = self.focus[k] if k < len(self.focus) else np.zeros((0, 3))
        if len(F):
            fuv = rows_matmul(F - o, ax.T)
            flo = np.floor((fuv.min(0) - self.margin) / nu).astype(np.int64)
            fhi = np.ceil((fuv.max(0) + self.margin) / nu).astype(np.int64)
            lo, hi = np.maximum(lo, flo), np.minimum(hi, fhi)
            mid = np.rint(np.median(fuv, axis=0) / nu).astype(np.int64)
        else:
            mid = (lo + hi) // 2
        half = self.max_pixels // 2
        lo, hi = np.maximum(lo, mid - half), np.minimum(hi, mid + half)
        size = np.maximum(hi - lo + 1, 1)
        # lattice points -> world -> the map texture's pixel coordinates (inverse mapping)
        i = (lo[0] + np.arange(size[0])) * nu
        j = (lo[1] + np.arange(size[1])) * nu
        Pv = o + i[None, :, None] * ax[0] + j[:, None, None] * ax[1]
        Pw = Pv @ R.T + t
        d = Pw - mp.tex_ref
        mx = ((d @ mp.tex_axes[0]) / self.nu_map - mp.tex_index0[0]).astype(np.float32)
        my = ((d @ mp.tex_axes[1]) / self.nu_map - mp.tex_index0[1]).astype(np.float32)
        seen = mp.tex_count > 0
        tex = np.where(seen, mp.tex_sum / np.maximum(mp.tex_count, 1), 0.0).astype(np.float32)
        bc = cv2.BORDER_CONSTANT
        img = np.asarray(cv2.remap(tex, mx, my, cv2.INTER_LINEAR, borderMode=bc, borderValue=0))
        seen_f = seen.astype(np.float32)
        msk = (
            np.asarray(cv2.remap(seen_f, mx, my, cv2.INTER_LINEAR, borderMode=bc, borderValue=0))
            > 0.999
        )
        return PlaneTexture(
            np.where(msk, img, np.nan).astype(np.float32),
            msk,
            o,
            ax,
            lo.astype(np.int64),
            nu,
            seg.plane,
        )


def _in_view(
    mp: MapPlane,
    obs: PlaneObservation,
    P: NDArray[np.float64],
    R: NDArray[np.float64],
    t: NDArray[np.float64],
    margin_m: float,
) -> NDArray[np.float64] | None:
    """A sample of map plane ``mp``'s kept points (200) in the view frame of ``obs`` placed at
    ``(R, t)``, or None when the frame cannot see the plane: none of them projects into the
    camera's image in front of it; without a camera, none falls within the box of the frame's
    points ``P`` grown by ``margin_m``."""
    X = rows_matmul(mp.points[:: max(1, len(mp.points) // 200)] - t, R)
    cam = obs.camera
    if cam is not None and obs.T_camera_sensor is None:
        z = X[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = cam.fx * X[:, 0] / z + cam.cx
            v = cam.fy * X[:, 1] / z + cam.cy
        seen = bool(np.any((z > 0) & (u >= 0) & (u < cam.width) & (v >= 0) & (v < cam.height)))
    elif len(P) == 0:
        seen = True
    else:
        lo, hi = P.min(0) - margin_m, P.max(0) + margin_m
        seen = bool(np.any(np.all((X >= lo) & (X <= hi), axis=1)))
    return X if seen else None


def _refit(mp: MapPlane) -> None:
    """Refit the map plane to its kept points (total least squares) and redraw its outline,
    from at most 10 000 of them (a regular subsample: the normal's error from 10 000 points of
    a Kinect plane is ~1e-4 rad, and a 5 cm outline raster of a few m^2 has ~1000 cells)."""
    X = mp.points[:: max(1, len(mp.points) // 10_000)]
    c = X.mean(0)
    w, V = np.linalg.eigh(np.einsum("ni,nj->ij", X - c, X - c))
    n, rho = canonical_plane(V[:, 0], float(V[:, 0] @ c))
    mp.plane = Plane(n, rho, c, float(np.sqrt(max(w[0], 0) / len(X))), len(mp.points))
    o, ax = rho * n, mp.plane.basis()
    uv = rows_matmul(X - o, ax.T)
    mp.outline, _ = outline_from_points(uv, 0.05)
    _, mp.area = outline_from_points(uv, 0.1)
