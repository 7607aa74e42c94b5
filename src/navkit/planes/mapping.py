"""Sequences -> trajectory + merged plane map (paper 2, step 7 and figs. 8-9).

:class:`PlaneOdometry` reads like the paper's pipeline, one call per frame:

1. extract the frame's planes (done by the caller: a :class:`~navkit.planes.frame.PlaneObservation`);
2. predict the pose: the previous pose moved by the motion prior (:class:`~navkit.planes.motion.
   MotionPrior`, e.g. visual odometry) or, without one, by the last motion (constant velocity);
3. **frame-to-map**: associate the frame's planes with the *map* planes seen from the predicted
   pose (:class:`MapView`) and solve the correction with the case the geometry allows (>= 3, 2
   or 1 plane directions; the 1- and 2-plane texture steps run against the map's fused
   textures);
4. **frame-to-frame** against the previous frame when the map gives less (fewer plane
   directions, a texture step the depth check rejects, or nothing): the better-determined
   result wins (measured before prior-filled, then more plane directions, then the map);
5. **dense refinement and verification** (registered RGB-D frames, ``OdometrySettings.dense``):
   the plane solution - and the prediction when the planes give nothing or disagree with it
   - is refined by a dense photometric + point-to-plane alignment with the current keyframe
   (or an old keyframe the camera is back at, :meth:`PlaneOdometry._revisit`) and accepted
   only when it passes :class:`DenseGates`; otherwise the frame is an explicit failure
   (``FrameResult.reason``), never a silent pose;
6. chain onto the trajectory (``T_world_frame``; the first frame is the world);
7. merge the frame's planes into the map: the same physical plane (normal, distance and overlap
   agree in the world frame) becomes one map plane whose extent (a sample of its inlier points)
   and texture (running mean of brightness on a fixed lattice of the plane) are fused.

Tracking against the map bounds the drift: while a map plane stays in view, every frame is
referred to the same fused plane (and texture) instead of to the previous frame's noisy one.

When a motion cannot be determined the prediction is used for the trajectory, the frame is
flagged (``FrameResult.status``), never silently, and its planes are not merged into the map;
neither are the planes of a frame whose pose holds degrees of freedom filled from the prior
(``FrameResult.motion.prior_dof``).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import ConfigError, InputError, NavkitError
from navkit.geometry import Plane, canonical_plane, points_in_polygon, se3_inverse
from navkit.geometry._validate import check_settings
from navkit.geometry.linalg import rows_matmul
from navkit.planes.dense import DenseFrame, DenseResult, DenseSettings, dense_align, rigid
from navkit.planes.frame import PlaneObservation
from navkit.planes.motion import (
    MotionPrior,
    MotionSettings,
    as_prior,
    depth_consistency,
    estimate_motion,
)
from navkit.planes.segments import ExtractionResult, PlaneSegment, outline_from_points
from navkit.planes.solve import MotionEstimate, MotionFailure, normal_rank
from navkit.planes.texture import PlaneTexture

__all__ = [
    "DenseGates",
    "FrameResult",
    "MapPlane",
    "MapView",
    "OdometrySettings",
    "PlaneMap",
    "PlaneOdometry",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DenseGates:
    """When a densely refined motion (:func:`~navkit.planes.dense.dense_align`) is accepted.

    All must hold at the finest level, else the frame becomes an explicit failure (never a
    silent pose). The residual gates are in the sensor's own noise units
    (:mod:`navkit.planes.noise`): the point-to-plane RMS in sigmas of the depth noise at each
    point's depth (``sqrt(2) k z^2``), the brightness RMS in sigmas of the images' own
    brightness noise; overlap and inliers are fractions. One set serves every sequence.

    Calibration (``docs/planes.md``, "Gates in noise units"): the dense step was started from
    the reference motion perturbed by 0, 2, 10, 20, 40 and 80 cm (0-20 deg) on 20 pairs 1 and
    10 frames apart of the shared 7-Scenes frames. The 89 results within 3 cm / 1.5 deg had a
    geometric RMS <= 1.17 sigma (median 0.72), a photometric RMS <= 15.7 sigma (7-Scenes'
    colour is not registered with its depth: edges misalign by several pixels), overlap >=
    0.83 and inliers >= 0.86; each of the 31 off by more than 5 cm or 2 deg fails a gate (the
    closest: 1.78 sigma at overlap 0.76; 1.12 sigma at overlap 0.26). Checked, unchanged, on
    the TUM frames (``rgbd/tum-fr3-structure-notexture-far``, motion-capture reference): all
    107 right results pass (geometric <= 0.98 sigma, photometric <= 3.6 sigma, overlap >=
    0.90); 12 of the 13 wrong ones fail; one, started 80 cm / 20 deg off, ends 7.4 cm / 0.3
    deg off with 1.09 sigma, 5.1 brightness sigmas and overlap 0.83 and passes (the zig-zag
    structure repeats itself; no start of the odometry is that far off).

    Attributes
    ----------
    max_geometric_sigmas : float
        RMS of the inliers' point-to-plane residuals, in depth-noise sigmas.
    max_photometric_sigmas : float
        RMS of the inliers' brightness residuals, in brightness-noise sigmas.
    min_overlap : float
        Fraction of the frame's points landing on the reference frame with agreeing depth.
    min_inliers : float
        Fraction of those within 3 robust sigmas.
    """

    max_geometric_sigmas: float = 1.5
    max_photometric_sigmas: float = 20.0
    min_overlap: float = 0.3
    min_inliers: float = 0.6

    def __post_init__(self) -> None:
        check_settings(self)

    def check(self, r: DenseResult) -> str:
        """Empty when ``r`` passes, else the reason."""
        bad = []
        if not r.photometric_sigmas <= self.max_photometric_sigmas:
            bad.append(
                f"photometric rms {r.photometric_sigmas:.1f} sigma > "
                f"{self.max_photometric_sigmas} (brightness sigma {r.brightness_sigma:.4f})"
            )
        if not r.geometric_sigmas <= self.max_geometric_sigmas:
            bad.append(
                f"geometric rms {r.geometric_sigmas:.2f} sigma_depth > "
                f"{self.max_geometric_sigmas} ({100 * r.rms_geometric:.1f} cm)"
            )
        if not r.overlap >= self.min_overlap:
            bad.append(f"overlap {r.overlap:.2f} < {self.min_overlap}")
        if not r.inliers >= self.min_inliers:
            bad.append(f"inliers {r.inliers:.2f} < {self.min_inliers}")
        return "; ".join(bad)


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
        Pixel size of the fused map textures, metres. Keep it equal to the solver's ``nu``:
        the texture steps against the map compare the fused texture with the frame's at the
        solver's ``nu``, and a coarser map texture (2 cm, resampled to 1 cm) matched worse
        (D 0.57 instead of 0.28) and with a 4-6 mm bias on the simulated wall.
    map_points : int
        Inlier points kept per observation for the map plane's extent.
    min_map_plane_points : int
        Smallest frame plane (inliers) added to the map.
    frame_to_map : bool
        Track against the map (stage 3 of the module docstring); False = frame-to-frame only.
    map_texture_pixels : int
        Largest side of a map texture window handed to the texture steps, pixels of the
        solver's ``nu`` (the window is centred on where the frame sees the plane).
    dense : DenseSettings or None
        Dense photometric + geometric refinement and verification of every motion
        (:mod:`navkit.planes.dense`) when the frames are registered RGB-D images; None = the
        planes alone (the former behaviour).
    gates : DenseGates
        When a densely refined motion counts as measured (else the frame fails).
    keyframe_overlap : float
        The dense step aligns each frame with the current *keyframe* (not the previous
        frame: drift grows per keyframe, not per frame); a tracked frame whose overlap with
        the keyframe falls below this fraction becomes the next keyframe.
    revisit_distance, revisit_angle_deg : float
        **Revisits**: when the frame's start pose is within these (metres, degrees) of a
        keyframe at least 3 keyframes older than the current one, it is aligned with that old
        keyframe first: back where it started, the camera is measured against what it saw
        then, and the error does not grow with the way there and back.
    max_keyframes : int
        Keyframes kept for revisits (a pyramid is ~4 MB at 640 x 480; the first one is kept).
    max_history : int
        Poses and results kept (:attr:`PlaneOdometry.poses`, ``results``), and frame numbers
        kept per map plane (``MapPlane.observations``): the most recent ones; 0 = all (the
        default). Tracking only uses the last pose, so bounding it changes no pose; a long
        stream (``navkit run``) sets it so memory stays flat.
    max_map_planes : int
        Map planes kept: beyond, the one observed least recently is dropped; 0 = all (the
        default).
    """

    motion: MotionSettings = field(default_factory=MotionSettings)
    merge_angle_deg: float = 8.0
    merge_distance: float = 0.08
    merge_margin: float = 0.2
    map_nu: float = 0.01
    map_points: int = 3000
    min_map_plane_points: int = 3000
    frame_to_map: bool = True
    map_texture_pixels: int = 400
    dense: DenseSettings | None = field(default_factory=DenseSettings)
    gates: DenseGates = field(default_factory=lambda: DenseGates())
    keyframe_overlap: float = 0.85
    revisit_distance: float = 0.15
    revisit_angle_deg: float = 10.0
    max_keyframes: int = 200
    max_history: int = 0
    max_map_planes: int = 0

    def __post_init__(self) -> None:
        check_settings(self)
        for name in ("max_history", "max_map_planes"):
            if getattr(self, name) < 0:
                raise ConfigError(
                    f"is {getattr(self, name)}",
                    source="OdometrySettings",
                    field=name,
                    expected="0 (unbounded) or a positive count",
                )


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
class MapView(PlaneObservation):
    """The map's planes seen from a predicted pose, shaped like a frame for
    :func:`~navkit.planes.motion.estimate_motion` (the map plays frame 1).

    Segments are the map planes in the view frame (``T_world_view`` maps view coordinates to
    the world): fused normal and distance, world outline moved into the view, the fused point
    count. :meth:`texture` resamples the map's fused texture (bilinear, valid where every
    neighbour was seen) onto the lattice the solver asks for, cropped to a window around where
    the current frame sees the plane. There is no camera: the depth check of texture steps is
    made against the previous frame instead (:class:`PlaneOdometry`).

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
    source : str
        Where the motion came from: ``"map"`` (planes, frame-to-map), ``"frame"`` (planes,
        frame-to-frame), with ``"+dense"`` when the dense step refined and verified it;
        ``"prediction+dense"`` when the planes gave nothing the pixels agree with and the
        dense step started from the constant-velocity prediction (or the prior); ``""``
        (first frame, or failed: the pose is the prediction and is not a measurement).
    reason : str
        Why a frame failed; for a tracked frame a note (e.g. the dense check was
        inconclusive: too little overlap for the pixels to judge a large motion).
    dof_sources : dict
        For each degree of freedom (``tx ty tz rx ry rz``, frame axes): what fixed it -
        ``"planes"`` / ``"planes+texture"`` (plane geometry / texture, when no dense step
        ran) or the dense terms ``"depth"``, ``"image"``, ``"depth+image"``
        (:attr:`~navkit.planes.dense.DenseResult.dof_sources`).
    dense : DenseResult or None
        The accepted dense refinement (None without one).
    reference : int
        Index of the frame the dense step aligned with (keyframe or previous), -1 if none.
    """

    index: int
    T_world_frame: NDArray[np.float64]
    motion: MotionEstimate | MotionFailure | None
    status: str
    case: int
    ms: float
    n_planes: int
    source: str = ""
    reason: str = ""
    dof_sources: dict[str, str] = field(default_factory=dict)
    dense: DenseResult | None = None
    reference: int = -1

    @property
    def tracked(self) -> bool:
        """The pose is a measurement (first frame or a motion that passed every check)."""
        return self.status == "first" or self.status.startswith("ok")


class PlaneOdometry:
    """Plane odometry over a sequence: frame-to-map tracking with a frame-to-frame fallback,
    an optional motion prior per frame, and the merged plane map (module docstring)."""

    def __init__(self, settings: OdometrySettings | None = None) -> None:
        self.settings = settings or OdometrySettings()
        self.map = PlaneMap(nu=self.settings.map_nu)
        self.poses: list[NDArray[np.float64]] = []
        self.results: list[FrameResult] = []
        self._prev: PlaneObservation | None = None
        self._velocity = np.eye(4)
        self._velocity_known = False  # a measured motion, not the start or a failure
        self._anchor: tuple[PlaneObservation, NDArray[np.float64]] | None = None  # last merged
        # dense step: (index, pyramid, T_world_frame) of the keyframe and of the last tracked
        self._keyframe: tuple[int, DenseFrame, NDArray[np.float64]] | None = None
        self._last_good: tuple[int, DenseFrame, NDArray[np.float64]] | None = None
        self._keyframes: list[tuple[int, DenseFrame, NDArray[np.float64]]] = []
        self._dense_reason = ""
        self._plane_overlap = 0.0
        self._depth_note = ""
        self.n_frames = 0  # frames registered (frame numbers: poses may keep only the last ones)
        self._next_plane_id = 0

    def register_frame(
        self, obs: PlaneObservation, prior: MotionPrior | ArrayLike | None = None
    ) -> FrameResult:
        """Track one frame (stages 2-6 of the module docstring).

        Parameters
        ----------
        obs : PlaneObservation
            The frame's planes.
        prior : MotionPrior or (4, 4) array, optional
            Predicted motion ``T_prev_curr`` from the previous frame to this one (e.g. visual
            odometry) with its uncertainty (a bare array gets
            :class:`~navkit.planes.motion.MotionPrior`'s default uncertainty). It replaces the
            constant-velocity prediction, sets the association gates, starts the texture
            searches and fills the degrees of freedom neither geometry nor texture fix
            (``FrameResult.motion.prior_dof``; such a frame is not merged into the map).
        """
        t0 = time.perf_counter()
        idx = self.n_frames
        self.n_frames += 1
        motion: MotionEstimate | MotionFailure | None = None
        source, reason = "", ""
        dof_sources: dict[str, str] = {}
        dense_res: DenseResult | None = None
        ref_idx = -1
        dframe = self._dense_frame(obs)
        if self._prev is None:
            T = np.eye(4)
            status, case = "first", 0
        else:
            mprior = None if prior is None else as_prior(prior)
            step_pred = self._velocity if mprior is None else mprior.T  # 2
            T_prev = self.poses[-1]
            T_pred = T_prev @ step_pred
            plane, failure = self._planes(obs, T_prev, T_pred, step_pred, mprior)  # 3-4
            if dframe is not None and self._keyframe is not None:  # dense: refine and verify
                T_plane = None if plane is None else plane[2]
                d = self._dense(dframe, T_plane, T_pred)
                if d is not None:
                    src, dense_res, T, ref_idx = d
                    source = ("prediction" if src == "prediction" else plane[0]) + "+dense"  # type: ignore[index]
                    base = plane[1] if (plane is not None and src != "prediction") else None
                    step = se3_inverse(T_prev) @ T
                    motion = (
                        replace(base, T=step, prior_dof=())
                        if base is not None
                        else MotionEstimate(step, 0, (), ())
                    )
                    status, case = "ok", (base.case if base is not None else 0)
                    dof_sources = dict(dense_res.dof_sources)
                elif (
                    plane is not None
                    and not plane[1].prior_dof
                    and self._plane_overlap < self.settings.gates.min_overlap
                    and self._depth_agrees(obs, plane[2])
                ):
                    # a large motion: the frames share too few pixels for the dense step to
                    # judge; the plane solution stands on the planes' own checks (depth
                    # consistency, association) and says so
                    reason = (
                        f"dense check inconclusive (overlap {self._plane_overlap:.2f}): "
                        f"planes only, depth check {self._depth_note}"
                    )
                else:
                    why = self._dense_reason
                    if plane is not None:
                        why = f"the {plane[0]} plane solution disagrees with the pixels ({why})"
                    elif failure is not None:
                        why = f"{failure.reason}; dense from the prediction: {why}"
                    failure = MotionFailure(
                        failure.case if failure is not None else 0,
                        ("rotation", "translation"),
                        why,
                    )
                    plane = None
            if motion is None and plane is not None:  # planes only (no dense data)
                source, est, T = plane
                step = se3_inverse(T_prev) @ T
                motion = replace(est, T=step)  # always reported as T_prev_curr
                status, case = "ok", est.case
                if est.prior_dof:
                    status = f"ok (from the prior: {', '.join(est.prior_dof)})"
                dof_sources = _plane_dof_sources(est)
            elif motion is None:
                assert failure is not None
                motion, step, T = failure, step_pred, T_pred
                status, case, reason = f"failed: {failure.reason}", failure.case, failure.reason
                log.warning(
                    "frame %d: motion not determined (%s); using the prediction",
                    idx,
                    failure.reason,
                )
            self._velocity = rigid(step)  # 5
            self._velocity_known = status.startswith("ok")
        T = rigid(T)  # chained products stay rotations
        self.poses.append(T)
        measured = isinstance(motion, MotionEstimate) and not motion.prior_dof
        if status == "first" or measured:  # a predicted pose is not good enough for the map
            self._merge(obs, T, idx)  # 6
            self._anchor = (obs, T)
            if dframe is not None:
                self._last_good = (idx, dframe, T)
                self._update_keyframe(idx, dframe, T, dense_res, ref_idx)
        self._prev = obs
        res = FrameResult(
            idx,
            T,
            motion,
            status,
            case,
            1000 * (time.perf_counter() - t0),
            len(obs.segments),
            source,
            reason,
            dof_sources,
            dense_res,
            ref_idx,
        )
        self.results.append(res)
        self._bound()
        return res

    def _bound(self) -> None:
        """Apply ``max_history`` and ``max_map_planes`` (:class:`OdometrySettings`)."""
        s = self.settings
        if s.max_history and len(self.poses) > s.max_history:
            del self.poses[: len(self.poses) - s.max_history]
            del self.results[: len(self.results) - s.max_history]
        if s.max_history:
            for mp in self.map.planes:
                if len(mp.observations) > s.max_history:
                    del mp.observations[: len(mp.observations) - s.max_history]
        if s.max_map_planes and len(self.map.planes) > s.max_map_planes:
            keep = sorted(self.map.planes, key=lambda mp: mp.observations[-1], reverse=True)
            kept = {id(mp) for mp in keep[: s.max_map_planes]}
            self.map.planes = [mp for mp in self.map.planes if id(mp) in kept]

    def _planes(
        self,
        obs: PlaneObservation,
        T_prev: NDArray[np.float64],
        T_pred: NDArray[np.float64],
        step_pred: NDArray[np.float64],
        mprior: MotionPrior | None,
    ) -> tuple[tuple[str, MotionEstimate, NDArray[np.float64]] | None, MotionFailure | None]:
        """Stages 3-4: the plane solution (source, estimate, ``T_world_frame``) or a failure."""
        # without a prior and a measured last motion (second frame, after a failure) the
        # prediction is weak: frame-to-frame then uses the global (prior-free) association,
        # whose solution is verified on the points; the map is still tried (it is what
        # recovers the pose after a failed frame)
        assert self._prev is not None
        predicted = mprior is not None or self._velocity_known
        f2f_prior: MotionPrior | NDArray[np.float64] | None = (
            mprior if mprior is not None else (step_pred if predicted else None)
        )
        # frame-to-frame against the last *tracked* frame: after a failure the previous
        # frame's pose is a prediction, and a motion from it would be chained onto a guess
        ref_obs, T_ref = self._prev, T_prev
        if self._anchor is not None and self._anchor[0] is not self._prev:
            ref_obs, T_ref = self._anchor
            if isinstance(f2f_prior, MotionPrior):
                f2f_prior = replace(f2f_prior, T=se3_inverse(T_ref) @ T_pred)
            elif f2f_prior is not None:
                f2f_prior = se3_inverse(T_ref) @ T_pred
        found: list[tuple[str, MotionEstimate, NDArray[np.float64]]] = []
        failure: MotionFailure | None = None
        if self.settings.frame_to_map and self.map.planes:  # 3
            r_map = self._track_map(obs, T_pred, mprior)
            if isinstance(r_map, MotionEstimate):
                found.append(("map", r_map, T_pred @ r_map.T))
            else:
                failure = r_map
        if not found or found[0][1].prior_dof or found[0][1].case < self._rank(obs):  # 4
            try:
                r_f = estimate_motion(ref_obs, obs, f2f_prior, self.settings.motion)
            except NavkitError as exc:
                r_f = MotionFailure(0, ("rotation", "translation"), f"frame-to-frame: {exc}")
            if isinstance(r_f, MotionEstimate):
                found.append(("frame", r_f, T_ref @ r_f.T))
            else:
                failure = r_f
        if not found:
            return None, failure
        best = max(found, key=lambda f: (not f[1].prior_dof, f[1].case, f[0] == "map"))
        return best, failure

    def _dense_frame(self, obs: PlaneObservation) -> DenseFrame | None:
        """The frame's dense pyramid, or None when the dense step cannot run (no dense
        settings, no camera image, not a registered organised RGB-D frame)."""
        ds = self.settings.dense
        P = np.asarray(obs.points)
        if (
            ds is None
            or obs.gray is None
            or obs.camera is None
            or obs.T_camera_sensor is not None
            or P.shape != (obs.camera.height, obs.camera.width, 3)
        ):
            return None
        return DenseFrame.build(obs.gray, P[..., 2], obs.camera, ds)

    def _depth_agrees(self, obs: PlaneObservation, T_world: NDArray[np.float64]) -> bool:
        """Does ``T_world`` put *all* the frame's points where the last tracked frame sees
        them (:func:`~navkit.planes.motion.depth_consistency`, same threshold as for texture
        steps)? The only evidence left for a large motion the dense step cannot judge."""
        if self._anchor is None:
            return False
        a_obs, a_T = self._anchor
        m = self.settings.motion
        chk = depth_consistency(a_obs, obs, se3_inverse(a_T) @ T_world, [])
        self._depth_note = f"{100 * chk.violation:.0f} % of {chk.tested} points in free space"
        return bool(chk.tested >= m.min_depth_points and chk.violation <= m.max_depth_violation)

    def _update_keyframe(self, idx, dframe, T, dense_res: DenseResult | None, ref_idx: int) -> None:
        """Keep the reference keyframe while the overlap lasts; a tracked frame whose overlap
        fell below ``keyframe_overlap`` becomes a new keyframe (and joins the list that
        :meth:`_revisit` searches); an old keyframe the frame was aligned with becomes the
        reference again when the overlap is good."""
        s = self.settings
        ref = next((k for k in self._keyframes if k[0] == ref_idx), None)
        if self._keyframe is None or dense_res is None:
            new = (idx, dframe, T)
        elif dense_res.overlap < s.keyframe_overlap:
            new = (idx, dframe, T)
        elif ref is not None:
            self._keyframe = ref
            return
        else:
            return
        self._keyframe = new
        self._keyframes.append(new)
        if len(self._keyframes) > s.max_keyframes:
            self._keyframes.pop(1)  # the first keyframe (the world frame) stays

    def _revisit(self, T_start: NDArray[np.float64]):
        """The oldest keyframe within ``revisit_distance`` / ``revisit_angle_deg`` of
        ``T_start`` that is at least 3 keyframes older than the current one (else None)."""
        s = self.settings
        if self._keyframe is None or len(self._keyframes) < 4:
            return None
        current = next(
            (n for n, k in enumerate(self._keyframes) if k[0] == self._keyframe[0]),
            len(self._keyframes),
        )
        for k in self._keyframes[: max(current - 2, 0)]:
            if not _differs(k[2], T_start, s.revisit_distance, s.revisit_angle_deg):
                return k
        return None

    def _dense(
        self,
        dframe: DenseFrame,
        T_plane: NDArray[np.float64] | None,
        T_pred: NDArray[np.float64],
    ) -> tuple[str, DenseResult, NDArray[np.float64], int] | None:
        """Dense refinement against the keyframe (then the last tracked frame), started from
        the plane solution and - when it is missing or disagrees with the prediction by more
        than 2 cm / 1 deg - from the prediction (constant velocity, or the prior) and from the
        previous pose; of the starts that pass the gates the lowest photometric RMS wins.
        None (and ``self._dense_reason``) when no start passes."""
        ds, gates = self.settings.dense, self.settings.gates
        assert ds is not None and self._keyframe is not None
        starts: list[tuple[str, NDArray[np.float64]]] = []
        if T_plane is not None:
            starts.append(("planes", T_plane))
        if T_plane is None or _differs(T_plane, T_pred, 0.02, 1.0):
            starts.append(("prediction", T_pred))
        # the previous pose (no motion since the last frame): inside the dense step's basin
        # for any hand-held motion at video rate, when both others are off
        T_still = self.poses[-1]
        if all(_differs(T0, T_still, 0.02, 1.0) for _, T0 in starts):
            starts.append(("prediction", T_still))
        refs = [self._keyframe]
        old = self._revisit(starts[0][1])
        if old is not None:  # the camera is back where an old keyframe was: align with it
            refs.insert(0, old)
        if self._last_good is not None and self._last_good[0] != self._keyframe[0]:
            refs.append(self._last_good)
        reasons = []
        self._plane_overlap = 0.0
        for ridx, rframe, T_ref in refs:
            best: tuple[str, DenseResult] | None = None
            for name, T0 in starts:
                r = dense_align(rframe, dframe, se3_inverse(T_ref) @ T0, ds)
                if name == "planes":
                    self._plane_overlap = max(self._plane_overlap, r.overlap)
                why = gates.check(r)
                if why:
                    reasons.append(f"from the {name} vs frame {ridx}: {why}")
                    continue
                if best is None or r.rms_photometric < best[1].rms_photometric:
                    # the plane start keeps the credit when both end in the same basin
                    if best is None or best[0] != "planes" or _differs(best[1].T, r.T, 0.01, 0.5):
                        best = (name, r)
            if best is not None:
                return best[0], best[1], T_ref @ best[1].T, ridx
        self._dense_reason = "; ".join(reasons) if reasons else "no reference frame"
        return None

    def _rank(self, obs: PlaneObservation) -> int:
        """Plane directions among the frame's own solver-sized planes: the most any solution
        can use (frame-to-frame is skipped when the map already reached it)."""
        m = self.settings.motion
        N = np.array([sg.normal for sg in obs.segments if sg.plane.count >= m.min_plane_points])
        return normal_rank(N.reshape(-1, 3), m.solver.parallel_deg)[0]

    def map_view(self, obs: PlaneObservation, T_world_view: NDArray[np.float64]) -> MapView:
        """The map planes seen from ``T_world_view``, with the texture windows centred on where
        the frame ``obs`` (placed at ``T_world_view``) sees each of them."""
        s = self.settings
        R, t = T_world_view[:3, :3], T_world_view[:3, 3]
        P = np.asarray(obs.points, dtype=np.float64).reshape(-1, 3)
        P = P[:: max(1, len(P) // 20_000)]
        P = P[np.all(np.isfinite(P), axis=1)]
        segs, focus, pts = [], [], []
        for mp in self.map.planes:
            nv = R.T @ mp.plane.normal
            n, rho = canonical_plane(nv, float(mp.plane.rho - mp.plane.normal @ t))
            c = R.T @ (mp.plane.centroid - t)
            plane = Plane(n, rho, c, mp.plane.rms, mp.plane.count)
            o_w, ax_w = mp.plane.rho * mp.plane.normal, mp.plane.basis()
            ov = (
                rows_matmul(o_w + mp.outline @ ax_w - t, R) if len(mp.outline) else np.zeros((0, 3))
            )
            outline = rows_matmul(ov - rho * n, plane.basis().T)
            segs.append(PlaneSegment(plane, np.zeros(0, np.int64), outline, mp.area))
            near = np.abs(P @ n - rho) < 3 * s.motion.association.max_distance
            focus.append(P[near])
            pts.append(rows_matmul(mp.points[:: max(1, len(mp.points) // 2000)] - t, R))
        X = np.concatenate(pts) if pts else np.zeros((0, 3))
        return MapView(
            ExtractionResult(tuple(segs), -np.ones(len(X), np.int64)),
            X,
            map_planes=tuple(self.map.planes),
            T_world_view=np.asarray(T_world_view, dtype=np.float64),
            nu_map=self.map.nu,
            focus=tuple(focus),
            margin=s.motion.solver.max_shift,
            max_pixels=s.map_texture_pixels,
        )

    def _track_map(
        self, obs: PlaneObservation, T_pred: NDArray[np.float64], prior: MotionPrior | None
    ) -> MotionEstimate | MotionFailure:
        """Stage 3: the correction ``T_pred_frame`` against the map (identity = the prediction).

        A texture step (1 or 2 plane directions) against the map is checked against the depth
        of the last frame merged into the map (:func:`~navkit.planes.motion.depth_consistency`;
        its pose is measured, unlike that of a failed previous frame), the map view having no
        camera of its own.
        """
        s = self.settings
        view = self.map_view(obs, T_pred)
        ms = replace(s.motion, global_search=False)
        p: MotionPrior | NDArray[np.float64] = np.eye(4)
        if prior is not None:
            p = MotionPrior(np.eye(4), prior.sigma_rotation_deg, prior.sigma_translation)
        try:
            res = estimate_motion(view, obs, p, ms)
        except NavkitError as exc:
            return MotionFailure(0, ("rotation", "translation"), f"map tracking: {exc}")
        if isinstance(res, MotionEstimate) and res.texture_dof and self._anchor is not None:
            a_obs, a_T = self._anchor
            T_a_curr = se3_inverse(a_T) @ T_pred @ res.T
            chk = depth_consistency(a_obs, obs, T_a_curr, [j for _, j in res.pairs])
            if chk.tested >= ms.min_depth_points and chk.violation > ms.max_depth_violation:
                log.info(
                    "map texture step rejected: %.0f %% of %d points in free space",
                    100 * chk.violation,
                    chk.tested,
                )
                return MotionFailure(
                    res.case, res.texture_dof, "map texture step rejected by the depth check"
                )
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
                    self._next_plane_id,
                    plane,
                    pts,
                    np.zeros((0, 2)),
                    0.0,
                    [frame],
                    tex_ref=rho * n,
                    tex_axes=plane.basis(),
                )
                self.map.planes.append(mp)
                self._next_plane_id += 1
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
    def tracked(self) -> NDArray[np.bool_]:
        """``(N,)`` True where the pose is a measurement (see :attr:`FrameResult.tracked`)."""
        return np.array([r.tracked for r in self.results], dtype=bool)

    @property
    def trajectory(self) -> NDArray[np.float64]:
        """``(N, 4, 4)`` poses ``T_world_frame``."""
        return np.array(self.poses).reshape(-1, 4, 4)

    def relative(self, i: int, j: int) -> NDArray[np.float64]:
        """``T_i_j`` from the chained poses."""
        return se3_inverse(self.poses[i]) @ self.poses[j]


def _differs(Ta: NDArray[np.float64], Tb: NDArray[np.float64], dist: float, deg: float) -> bool:
    """Poses further apart than ``dist`` metres or ``deg`` degrees."""
    E = se3_inverse(Ta) @ Tb
    c = np.clip((np.trace(E[:3, :3]) - 1) / 2, -1.0, 1.0)
    return bool(np.linalg.norm(E[:3, 3]) > dist or np.degrees(np.arccos(c)) > deg)


def _plane_dof_sources(est: MotionEstimate) -> dict[str, str]:
    """What fixed each DoF of a plane-only estimate: ``planes``, ``texture`` or ``prior``
    (the solver names DoFs in its own terms; listed as the solver gives them)."""
    out = {d: "planes" for d in est.geometry_dof}
    out.update({d: "texture" for d in est.texture_dof})
    out.update({d: "prior" for d in est.prior_dof})
    return out
