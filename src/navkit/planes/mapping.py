"""Sequences -> trajectory + merged plane map (paper 2, step 7 and figs. 8-9).

:class:`PlaneOdometry` reads like the paper's pipeline, one call per frame:

1. extract the frame's planes (done by the caller: a :class:`~navkit.planes.frame.PlaneObservation`);
2. associate them with the previous frame's planes, predicted by the last motion (constant
   velocity);
3. solve the motion with the case the geometry allows (>= 3, 2 or 1 plane directions);
4. chain the motion onto the trajectory (``T_world_frame``; the first frame is the world);
5. merge the frame's planes into the map: the same physical plane (normal, distance and overlap
   agree in the world frame) becomes one map plane whose extent (a sample of its inlier points)
   and texture (running mean of brightness on a fixed lattice of the plane) are fused.

When a motion cannot be determined the constant-velocity prediction is used for the trajectory,
the frame is flagged (``FrameResult.status``), never silently, and its planes are not merged into
the map.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from navkit.errors import NavkitError
from navkit.geometry import Plane, canonical_plane, points_in_polygon, se3_inverse
from navkit.geometry.linalg import rows_matmul
from navkit.planes.frame import PlaneObservation
from navkit.planes.motion import MotionSettings, estimate_motion
from navkit.planes.segments import outline_from_points
from navkit.planes.solve import MotionEstimate, MotionFailure

__all__ = ["FrameResult", "MapPlane", "OdometrySettings", "PlaneMap", "PlaneOdometry"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class OdometrySettings:
    """Settings of :class:`PlaneOdometry`.

    Attributes
    ----------
    motion : MotionSettings
    merge_angle_deg, merge_distance, merge_margin : float
        A frame plane joins a map plane when normals agree within ``merge_angle_deg``, distances
        within ``merge_distance`` metres and their outlines come within ``merge_margin`` metres.
    map_nu : float
        Pixel size of the fused map textures, metres.
    map_points : int
        Inlier points kept per observation for the map plane's extent.
    min_map_plane_points : int
        Smallest frame plane (inliers) added to the map.
    """

    motion: MotionSettings = field(default_factory=MotionSettings)
    merge_angle_deg: float = 8.0
    merge_distance: float = 0.08
    merge_margin: float = 0.2
    map_nu: float = 0.02
    map_points: int = 3000
    min_map_plane_points: int = 3000


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


@dataclass(frozen=True)
class FrameResult:
    """What :meth:`PlaneOdometry.register_frame` did with one frame.

    Attributes
    ----------
    index : int
    T_world_frame : (4, 4) array
    motion : MotionEstimate, MotionFailure or None
        None for the first frame.
    status : str
        ``"first"``, ``"ok"`` or ``"failed: <reason>"`` (then the pose is the constant-velocity
        prediction).
    case : int
        Solver case used (3 = >= 3 planes, 2, 1; 0 = none).
    ms : float
        Wall time of association + motion + map update, milliseconds.
    n_planes : int
    """

    index: int
    T_world_frame: NDArray[np.float64]
    motion: MotionEstimate | MotionFailure | None
    status: str
    case: int
    ms: float
    n_planes: int


class PlaneOdometry:
    """Frame-to-frame plane odometry with a merged plane map."""

    def __init__(self, settings: OdometrySettings | None = None) -> None:
        self.settings = settings or OdometrySettings()
        self.map = PlaneMap(nu=self.settings.map_nu)
        self.poses: list[NDArray[np.float64]] = []
        self.results: list[FrameResult] = []
        self._prev: PlaneObservation | None = None
        self._velocity = np.eye(4)

    def register_frame(self, obs: PlaneObservation) -> FrameResult:
        """Track one frame (stages 2-5 of the module docstring)."""
        t0 = time.perf_counter()
        idx = len(self.poses)
        motion: MotionEstimate | MotionFailure | None = None
        if self._prev is None:
            T = np.eye(4)
            status, case = "first", 0
        else:
            motion = estimate_motion(self._prev, obs, self._velocity, self.settings.motion)  # 2-3
            if isinstance(motion, MotionEstimate):
                step = motion.T
                status, case = "ok", motion.case
            else:
                step = self._velocity
                status, case = f"failed: {motion.reason}", motion.case
                log.warning(
                    "frame %d: motion not determined (%s); using the prediction", idx, motion.reason
                )
            self._velocity = step
            T = self.poses[-1] @ step  # 4
        self.poses.append(T)
        if not status.startswith("failed"):  # a predicted pose is not good enough for the map
            self._merge(obs, T, idx)  # 5
        self._prev = obs
        res = FrameResult(
            idx, T, motion, status, case, 1000 * (time.perf_counter() - t0), len(obs.segments)
        )
        self.results.append(res)
        return res

    def _merge(self, obs: PlaneObservation, T: NDArray[np.float64], frame: int) -> None:
        s = self.settings
        R, t = T[:3, :3], T[:3, 3]
        rng = np.random.default_rng(frame)
        P = obs.points.reshape(-1, 3)
        for k, seg in enumerate(obs.segments):
            if seg.plane.count < s.min_map_plane_points:
                continue
            n, rho = canonical_plane(R @ seg.normal, float(seg.rho + (R @ seg.normal) @ t))
            pick = (
                seg.inliers
                if len(seg.inliers) <= s.map_points
                else rng.choice(seg.inliers, s.map_points, replace=False)
            )
            pts = rows_matmul(P[pick], R.T) + t
            target = self._find(n, rho, pts)
            if target is None:
                plane = Plane(n, rho, pts.mean(0), seg.rms, seg.plane.count)
                mp = MapPlane(
                    len(self.map.planes),
                    plane,
                    pts,
                    np.zeros((0, 2)),
                    0.0,
                    [frame],
                    tex_ref=rho * n,
                    tex_axes=plane.basis(),
                )
                self.map.planes.append(mp)
            else:
                mp = target
                mp.points = np.vstack([mp.points, pts])
                if len(mp.points) > 20 * s.map_points:
                    mp.points = mp.points[
                        rng.choice(len(mp.points), 20 * s.map_points, replace=False)
                    ]
                mp.observations.append(frame)
            self._refit(mp)
            if obs.has_texture:
                axes_c = mp.tex_axes @ R  # world axes seen in the frame
                ref_c = R.T @ (mp.tex_ref - t)
                try:
                    tex = obs.texture(k, axes_c, ref_c, s.map_nu)
                except NavkitError as exc:  # texture is optional for the map
                    log.debug("map texture of plane %d skipped: %s", k, exc)
                    continue
                mp.add_texture(tex.image, tex.mask, tex.index0)

    def _find(self, n, rho, pts) -> MapPlane | None:
        s = self.settings
        best, best_d = None, np.inf
        for mp in self.map.planes:
            ang = np.degrees(np.arccos(np.clip(n @ mp.plane.normal, -1, 1)))
            d = abs(rho - mp.plane.rho)
            if ang > s.merge_angle_deg or d > s.merge_distance:
                continue
            if len(mp.outline) >= 3:
                o, ax = mp.plane.rho * mp.plane.normal, mp.plane.basis()
                sub = pts[:: max(1, len(pts) // 300)]
                if not points_in_polygon(
                    (sub - o) @ ax.T, mp.outline, tolerance=s.merge_margin
                ).any():
                    continue
            if d < best_d:
                best, best_d = mp, d
        return best

    def _refit(self, mp: MapPlane) -> None:
        X = mp.points
        c = X.mean(0)
        w, V = np.linalg.eigh(np.einsum("ni,nj->ij", X - c, X - c))
        n, rho = canonical_plane(V[:, 0], float(V[:, 0] @ c))
        mp.plane = Plane(n, rho, c, float(np.sqrt(max(w[0], 0) / len(X))), len(X))
        o, ax = rho * n, mp.plane.basis()
        uv = rows_matmul(X - o, ax.T)
        mp.outline, _ = outline_from_points(uv, 0.05)
        _, mp.area = outline_from_points(uv, 0.1)

    @property
    def trajectory(self) -> NDArray[np.float64]:
        """``(N, 4, 4)`` poses ``T_world_frame``."""
        return np.array(self.poses).reshape(-1, 4, 4)

    def relative(self, i: int, j: int) -> NDArray[np.float64]:
        """``T_i_j`` from the chained poses."""
        return se3_inverse(self.poses[i]) @ self.poses[j]
