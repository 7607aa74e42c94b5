"""Plane odometry: sequences -> trajectory + merged plane map (paper 2, step 7 and figs. 8-9).

:meth:`PlaneOdometry.update` reads like the paper's pipeline, one call per frame and one named
step per stage:

1. extract the frame's planes (done by the caller: a :class:`~navkit.planes.frame.PlaneObservation`);
2. predict the pose: the previous pose moved by the motion prior (:class:`~navkit.planes.motion.
   MotionPrior`, e.g. visual odometry) or, without one, by the last motion (constant velocity);
3. **frame-to-map**: associate the frame's planes with the *map* planes seen from the predicted
   pose (:class:`~navkit.planes.plane_map.MapView`) and solve the correction with the case the geometry allows (>= 3, 2
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
   (:class:`~navkit.planes.solve.MotionFailure`), never a silent pose;
6. chain onto the trajectory (``T_world_frame``; the first frame is the world);
7. merge the frame's planes into the map (:meth:`~navkit.planes.plane_map.PlaneMap.merge`):
   the same physical plane (normal, distance and overlap agree in the world frame) becomes one
   map plane whose extent (a sample of its inlier points) and texture (running mean of
   brightness on a fixed lattice of the plane) are fused.

Tracking against the map bounds the drift: while a map plane stays in view, every frame is
referred to the same fused plane (and texture) instead of to the previous frame's noisy one.

Where the dense step will run, stages 3-4 first run without the planes' texture searches:
the planes fix what they can, the prior (or the constant-velocity prediction) fills the free
degrees of freedom and the dense step measures them (:meth:`PlaneOdometry._measure`); the
texture searches run only when that fails. A frame that no reference overlaps restarts the
tracking (:meth:`PlaneOdometry._restart`).

A tracked frame is a :class:`FrameMotion`. When a motion cannot be determined the frame is a
:class:`~navkit.planes.solve.MotionFailure` naming its reason and free degrees of freedom, the
prediction is used for the trajectory, and its planes are not merged into the map; neither are
the planes of a frame whose pose holds degrees of freedom filled from the prior
(``FrameMotion.prior_dof``).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.domains import (
    NON_NEGATIVE,
    NON_NEGATIVE_INT,
    POSITIVE,
    POSITIVE_INT,
    Domain,
    domain_field,
)
from navkit.errors import NavkitError
from navkit.geometry import se3_inverse
from navkit.geometry._validate import check_settings
from navkit.geometry.transforms import se3_adjoint
from navkit.jit import kernels_enabled
from navkit.planes.dense import (
    DenseFrame,
    DenseGates,
    DenseResult,
    DenseSettings,
    _dense_align,
    rigid,
)
from navkit.planes.frame import PlaneObservation
from navkit.planes.motion import (
    MotionPrior,
    MotionSettings,
    as_prior,
    depth_consistency,
    estimate_motion,
)
from navkit.planes.noise import DOF_NAMES, DepthNoise, free_directions, segments_information
from navkit.planes.plane_map import MapView, PlaneMap
from navkit.planes.solve import MotionEstimate, MotionFailure, normal_rank
from navkit.results import Result, deprecated_alias

__all__ = ["DenseGates", "FrameMotion", "OdometrySettings", "PlaneOdometry", "ros_pose_covariance"]

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
        planes alone.
    gates : DenseGates
        When a densely refined motion counts as measured (else the frame fails).
    keyframe_overlap : float
        The dense step aligns each frame with the current *keyframe* (not the previous
        frame: drift grows per keyframe, not per frame); a tracked frame whose overlap with
        the keyframe falls below this fraction of the best overlap a frame had with it becomes
        the next keyframe. Relative, because part of every view never overlaps whatever the
        motion (sky, missing depth, depth edges): 0.7 of a view with much sky is full overlap.
    revisit_distance, revisit_angle_deg : float
        **Revisits**: when the frame's start pose is within these (metres, degrees) of a
        keyframe at least 2 keyframes older than the current one, it is aligned with that old
        keyframe first: back where it started, the camera is measured against what it saw
        then, and the error does not grow with the way there and back.
    max_keyframes : int
        Keyframes kept for revisits (a pyramid is ~4 MB at 640 x 480; the first one is kept).
    map_keyframe_distance, map_keyframe_angle_deg : float
        A measured frame merges into the map's planes only once it is this far (metres,
        degrees) from the last frame that did (:meth:`PlaneOdometry._is_map_keyframe`); in
        between a frame adds only its planes the map does not have. Between such *map
        keyframes* a frame
        sees the same surfaces from nearly the same place: merging it adds CPU (the map
        update is the costliest step after the dense one), not information. 5 cm / 5 deg:
        at 1-4 m the view then shifts by 1-9 % of a 58 deg field of view, so new parts of the
        surfaces enter at each merge; 0 / 0 merges every frame.
    covariance_scale : float
        Factor on the dense step's standard deviations (``FrameMotion.covariance``): its
        Gauss-Newton information treats every pixel as independent, and the errors of
        neighbouring pixels are not (normals, colour offset, the depth camera's correlation
        window). Measured step errors against the references were 4.6x (TUM, motion capture;
        median over the frames) and 17.5x (7-Scenes; its KinectFusion reference errs by about
        as much) the uninflated sigma; 10 is between.
    plane_free_translation, plane_free_rotation_deg : float
        The degeneracy analysis of the plane constraints (``FrameMotion.plane_free_dof``): a
        direction whose 3-sigma, from the information of the matched planes' noise-weighted
        fits, exceeds this many metres (degrees) is one the planes leave free. 5 cm / 2 deg:
        the bound of a wrong motion (a frame tracked but off by more is an error).
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
    merge_angle_deg: float = domain_field(8.0, Domain(lo=0.0, hi=90.0, note="degrees"))
    merge_distance: float = domain_field(0.08, NON_NEGATIVE)
    merge_margin: float = domain_field(0.2, NON_NEGATIVE)
    map_nu: float = domain_field(0.01, POSITIVE)
    map_points: int = domain_field(3000, POSITIVE_INT)
    min_map_plane_points: int = domain_field(3000, NON_NEGATIVE_INT)
    frame_to_map: bool = True
    map_texture_pixels: int = domain_field(400, POSITIVE_INT)
    dense: DenseSettings | None = field(default_factory=DenseSettings)
    gates: DenseGates = field(default_factory=lambda: DenseGates())
    keyframe_overlap: float = domain_field(0.85, Domain(lo=0.0, hi=1.0, note="a fraction"))
    revisit_distance: float = domain_field(0.15, NON_NEGATIVE)
    revisit_angle_deg: float = domain_field(10.0, Domain(lo=0.0, hi=180.0, note="degrees"))
    max_keyframes: int = domain_field(200, POSITIVE_INT)
    map_keyframe_distance: float = domain_field(0.05, NON_NEGATIVE)
    map_keyframe_angle_deg: float = domain_field(5.0, Domain(lo=0.0, hi=180.0, note="degrees"))
    covariance_scale: float = domain_field(10.0, POSITIVE)
    plane_free_translation: float = domain_field(0.05, POSITIVE)
    plane_free_rotation_deg: float = domain_field(2.0, Domain(lo=0.0, lo_open=True, note="degrees"))
    max_history: int = domain_field(0, Domain(integer=True, lo=0, note="0 = all"))
    max_map_planes: int = domain_field(0, Domain(integer=True, lo=0, note="0 = all"))

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class FrameMotion(Result):
    """A tracked frame: what :meth:`PlaneOdometry.update` measured (the pose is a measurement).

    A frame whose motion cannot be measured is a :class:`~navkit.planes.solve.MotionFailure`
    instead, with its reason, its free degrees of freedom and the same frame fields
    (``index``, ``T_world_frame`` - there the prediction -, ``ms``, ``n_planes``).

    Attributes
    ----------
    index : int
        Frame number (0 = the first frame, which defines the world).
    T_world_frame : (4, 4) array
    motion : MotionEstimate or None
        ``T_prev_curr`` and how it was found; None for the first frame.
    case : int
        Solver case used (3 = >= 3 planes, 2, 1; 0 = none: the first frame, or a motion the
        dense step found from the prediction).
    ms : float
        Wall time of :meth:`PlaneOdometry.update`, milliseconds.
    n_planes : int
        The frame's planes.
    source : str
        Where the motion came from: ``"first"``; ``"map"`` (planes, frame-to-map) or
        ``"frame"`` (planes, frame-to-frame), with ``"+dense"`` when the dense step refined and
        verified it; ``"prediction+dense"`` when the planes gave nothing the pixels agree with
        and the dense step started from the constant-velocity prediction (or the prior).
    note : str
        What a reader of the frame should know, e.g. the dense check was inconclusive (too
        little overlap for the pixels to judge a large motion); empty otherwise.
    dof_sources : dict
        For each degree of freedom (``tx ty tz rx ry rz``, frame axes): what fixed it -
        ``"planes"`` / ``"texture"`` / ``"prior"`` (plane geometry, texture, the motion prior,
        when no dense step ran) or the dense terms ``"depth"``, ``"image"``, ``"depth+image"``
        (:attr:`~navkit.planes.dense.DenseResult.dof_sources`).
    dense : DenseResult or None
        The accepted dense refinement (None without one).
    reference : int
        Index of the frame the dense step aligned with (keyframe or previous), -1 if none.
    covariance : (6, 6) array or None
        Covariance of ``T_world_frame`` as a left perturbation ``exp(d) T`` with ``d = (v, w)``
        in world axes (:func:`ros_pose_covariance` converts it to ROS's position /
        fixed-axis rotation form): the reference frame's covariance plus the dense step's
        (:attr:`~navkit.planes.dense.DenseResult.information` inverted, moved to world axes,
        times ``OdometrySettings.covariance_scale`` squared). It grows per keyframe, as the
        drift does. None for a motion without a dense step.
    plane_information : (6, 6) array
        What the matched planes alone say about the motion: the information (inverse
        covariance, perturbation ``(v, w)`` in frame axes) of their constraints, each plane's
        fit weighted by the depth noise (:func:`~navkit.planes.noise.fit_plane`,
        :func:`~navkit.planes.noise.plane_pair_information`; the frame's fit stands for both
        sides of a pair). Zero when no plane was matched (a motion the dense step found from
        the prediction) and for the first frame. It counts the depth noise only: the plane
        solutions' actual errors on the shared sequences are about 100 times its sigmas (the
        fits' systematic errors - segmentation edges, depth distortion - are not noise),
        which is why the dense step refines all six degrees of freedom rather than only the
        free ones (docs/planes.md).
    plane_free_dof : tuple of str
        **Degeneracy analysis**: the degrees of freedom (``tx ty tz rx ry rz``, the frame axes
        each free direction leans on most) that ``plane_information`` leaves free
        (:func:`~navkit.planes.noise.free_directions`, limits
        ``OdometrySettings.plane_free_translation`` / ``plane_free_rotation_deg``): e.g. the
        translation along a corridor's walls and floor. What fixed them is in
        ``dof_sources`` (texture, image, prior).
    """

    index: int
    T_world_frame: NDArray[np.float64]
    motion: MotionEstimate | None
    case: int
    ms: float
    n_planes: int
    source: str
    note: str = ""
    dof_sources: dict[str, str] = field(default_factory=dict)
    dense: DenseResult | None = None
    reference: int = -1
    covariance: NDArray[np.float64] | None = None
    plane_information: NDArray[np.float64] = field(default_factory=lambda: np.zeros((6, 6)))
    plane_free_dof: tuple[str, ...] = DOF_NAMES

    @property
    def prior_dof(self) -> tuple[str, ...]:
        """Degrees of freedom taken from the motion prior (empty when all were measured)."""
        return () if self.motion is None else self.motion.prior_dof


@dataclass(frozen=True)
class _Prediction:
    """Stage 2: where the frame is expected, before any measurement."""

    T_prev: NDArray[np.float64]  # T_world_prev (the last pose on the trajectory)
    step: NDArray[np.float64]  # T_prev_curr predicted (constant velocity or the prior)
    T: NDArray[np.float64]  # T_world_curr predicted
    prior: MotionPrior | None


@dataclass(frozen=True)
class _Measured:
    """Stages 3-5 for one frame: the pose and how it was found (or the failure)."""

    T: NDArray[np.float64]  # T_world_frame (the prediction for a failure)
    step: NDArray[np.float64]  # T_prev_frame (becomes the constant-velocity prediction)
    motion: MotionEstimate | MotionFailure | None
    case: int
    source: str = ""
    note: str = ""
    dof_sources: dict[str, str] = field(default_factory=dict)
    dense: DenseResult | None = None
    reference: int = -1


_Plane = tuple[str, MotionEstimate, NDArray[np.float64]]  # (source, estimate, T_world_frame)


class PlaneOdometry:
    """Plane odometry over a sequence: frame-to-map tracking with a frame-to-frame fallback,
    an optional motion prior per frame, and the merged plane map (module docstring)."""

    def __init__(self, settings: OdometrySettings | None = None) -> None:
        self.settings = settings or OdometrySettings()
        self.compiled = kernels_enabled()  # kernels or twins, for this object's life
        self.map = PlaneMap(nu=self.settings.map_nu)
        self.poses: list[NDArray[np.float64]] = []
        self.results: list[FrameMotion | MotionFailure] = []
        self._prev: PlaneObservation | None = None
        self._velocity = np.eye(4)
        self._velocity_known = False  # a measured motion, not the start or a failure
        self._anchor: tuple[PlaneObservation, NDArray[np.float64]] | None = None  # last measured
        self._merged_at: NDArray[np.float64] | None = None  # pose of the last map keyframe
        # dense step: (index, pyramid, T_world_frame) of the keyframe and of the last tracked
        self._keyframe: tuple[int, DenseFrame, NDArray[np.float64]] | None = None
        self._last_good: tuple[int, DenseFrame, NDArray[np.float64]] | None = None
        self._keyframes: list[tuple[int, DenseFrame, NDArray[np.float64]]] = []
        self._keyframe_best_overlap: dict[int, float] = {}  # keyframe index -> best overlap
        self._covariances: dict[int, NDArray[np.float64]] = {}  # reference frames' covariance
        self._dense_reason = ""
        self._plane_overlap = 0.0
        self._depth_note = ""
        self.n_frames = 0  # frames registered (frame numbers: poses may keep only the last ones)

    def update(
        self, obs: PlaneObservation, prior: MotionPrior | ArrayLike | None = None
    ) -> FrameMotion | MotionFailure:
        """Track one frame (stages 2-7 of the module docstring).

        Parameters
        ----------
        obs : PlaneObservation
            The frame's planes (stage 1).
        prior : MotionPrior or (4, 4) array, optional
            Predicted motion ``T_prev_curr`` from the previous frame to this one (e.g. visual
            odometry) with its uncertainty (a bare array gets
            :class:`~navkit.planes.motion.MotionPrior`'s default uncertainty). It replaces the
            constant-velocity prediction, sets the association gates, starts the texture
            searches and fills the degrees of freedom neither geometry nor texture fix
            (``FrameMotion.prior_dof``; such a frame is not merged into the map).

        Returns
        -------
        FrameMotion or MotionFailure
            The measured pose, or why there is none and which degrees of freedom are free
            (the trajectory then carries the prediction, ``MotionFailure.T_world_frame``).
        """
        t0 = time.perf_counter()
        idx = self.n_frames
        self.n_frames += 1
        dframe = self._dense_frame(obs)  # the frame's image pyramid (None: no dense step)
        if self._prev is None:
            m = _Measured(np.eye(4), np.eye(4), None, 0, source="first")  # the world frame
        else:
            pred = self._predict(prior)  # 2
            m = self._measure(idx, obs, dframe, pred)  # 3-5
            self._velocity = rigid(m.step)
            self._velocity_known = isinstance(m.motion, MotionEstimate)
        T = rigid(m.T)  # 6: chained products stay rotations
        self.poses.append(T)
        cov = None if isinstance(m.motion, MotionFailure) else self._covariance(idx, m)
        if m.motion is None or (isinstance(m.motion, MotionEstimate) and not m.motion.prior_dof):
            self._update_map(idx, obs, dframe, T, m)  # 7: only measured poses
        elif isinstance(m.motion, MotionFailure) and prior is not None and dframe is not None:
            m = replace(m, motion=self._restart(idx, obs, dframe, T, m.motion))
        self._prev = obs
        res = self._result(idx, obs, T, m, t0, cov)
        self.results.append(res)
        self._bound()
        return res

    def register_frame(
        self, obs: PlaneObservation, prior: MotionPrior | ArrayLike | None = None
    ) -> FrameMotion | MotionFailure:
        """Deprecated alias of :meth:`update` (removed in the next release)."""
        deprecated_alias("PlaneOdometry.register_frame", "PlaneOdometry.update")
        return self.update(obs, prior)

    def _predict(self, prior: MotionPrior | ArrayLike | None) -> _Prediction:
        """Stage 2: the previous pose moved by the prior, or by the last motion."""
        mprior = None if prior is None else as_prior(prior)
        step = self._velocity if mprior is None else mprior.T
        T_prev = self.poses[-1]
        return _Prediction(T_prev, step, T_prev @ step, mprior)

    def _measure(
        self, idx: int, obs: PlaneObservation, dframe: DenseFrame | None, pred: _Prediction
    ) -> _Measured:
        """Stages 3-5. With the dense step to come, the planes' texture searches are left out
        first: the planes fix what they can, the prior or the prediction starts the rest and
        the dense alignment measures it (the image solves what the planes leave free). Only
        when that fails - e.g. too little overlap for the pixels to judge - are the texture
        searches run and the frame measured again."""
        if dframe is not None and self._keyframe is not None:
            m = self._verify(idx, obs, dframe, pred, *self._planes(obs, pred, texture=False))
            if not isinstance(m.motion, MotionFailure):
                return m
        m = self._verify(idx, obs, dframe, pred, *self._planes(obs, pred))
        if isinstance(m.motion, MotionFailure):
            log.warning(
                "frame %d: motion not determined (%s); using the prediction", idx, m.motion.reason
            )
        return m

    def _verify(
        self,
        idx: int,
        obs: PlaneObservation,
        dframe: DenseFrame | None,
        pred: _Prediction,
        plane: _Plane | None,
        failure: MotionFailure | None,
    ) -> _Measured:
        """Stage 5: the dense refinement and verification of the plane solution (or of the
        prediction when the planes give nothing the pixels agree with); without dense data the
        plane solution stands on its own checks. Else the frame fails, at the prediction."""
        note = ""
        if dframe is not None and self._keyframe is not None:
            d = self._dense(dframe, None if plane is None else plane[2], pred)
            if d is not None:
                return _dense_measured(pred, plane, *d)
            if (
                plane is not None
                and not plane[1].prior_dof
                and pred.prior is None
                and self._plane_overlap < self.settings.gates.min_overlap
                and self._depth_agrees(obs, plane[2])
            ):
                # a large motion: the frames share too few pixels for the dense step to
                # judge; the plane solution stands on the planes' own checks (depth
                # consistency, association) and says so. Not with a motion prior: that
                # measured the motion already, and the frame fails to it (and restarts from
                # it) rather than rest on an unverified plane solution
                note = (
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
                    failure.case if failure is not None else 0, ("rotation", "translation"), why
                )
                plane = None
        if plane is not None:  # the planes alone
            source, est, T = plane
            step = se3_inverse(pred.T_prev) @ T
            motion = replace(est, T=step)  # always reported as T_prev_curr
            return _Measured(T, step, motion, est.case, source, note, _plane_dof_sources(est))
        assert failure is not None
        return _Measured(pred.T, pred.step, failure, failure.case)

    def _restart(
        self,
        idx: int,
        obs: PlaneObservation,
        dframe: DenseFrame,
        T: NDArray[np.float64],
        failure: MotionFailure,
    ) -> MotionFailure:
        """Tracking restarts from a failed frame that has a motion prior: it becomes the
        keyframe and the frame-to-frame reference at the pose the prior put it (it stays a
        failure, not merged into the map, and its covariance is unknown), so the next frames'
        motions are measured against it - their steps are right, their poses carry the prior's
        error of this one step - instead of failing against references the view has left
        (the older keyframes stay for revisits). Without a prior the pose would be a
        constant-velocity guess, and every later pose would be off by that guess while
        reported tracked: such a frame stays failed, and the next frames keep trying the old
        references."""
        log.info("frame %d: motion failed; tracking restarts from the prior's pose", idx)
        self._anchor = (obs, T)
        self._last_good = (idx, dframe, T)
        self._keyframe = (idx, dframe, T)
        self._keyframes.append(self._keyframe)
        if len(self._keyframes) > self.settings.max_keyframes:
            dropped = self._keyframes.pop(1)
            self._keyframe_best_overlap.pop(dropped[0], None)
        return replace(
            failure, reason=f"{failure.reason}; tracking restarts from this frame's prediction"
        )

    def _update_map(
        self,
        idx: int,
        obs: PlaneObservation,
        dframe: DenseFrame | None,
        T: NDArray[np.float64],
        m: _Measured,
    ) -> None:
        """Stage 7: a measured frame becomes the reference of the next frame-to-frame step and,
        with dense data, of the keyframes; a *map keyframe* (:meth:`_is_map_keyframe`) merges
        all its planes into the map, any other frame only its planes the map does not have."""
        s = self.settings
        key = self._is_map_keyframe(T)
        self.map.merge(
            obs,
            T,
            idx,
            min_points=s.min_map_plane_points,
            sample=s.map_points,
            angle_deg=s.merge_angle_deg,
            distance_m=s.merge_distance,
            margin_m=s.merge_margin,
            only_new=not key,
        )
        if key:
            self.map.consolidate(
                angle_deg=s.merge_angle_deg,
                distance_m=s.merge_distance,
                margin_m=s.merge_margin,
                max_points=20 * s.map_points,
            )
            self._merged_at = T
        self._anchor = (obs, T)
        if dframe is not None:
            self._last_good = (idx, dframe, T)
            self._update_keyframe(idx, dframe, T, m.dense, m.reference)

    def _is_map_keyframe(self, T: NDArray[np.float64]) -> bool:
        """Does the measured frame merge into the map's existing planes? The first frame, and
        a frame ``map_keyframe_distance`` / ``map_keyframe_angle_deg`` from the last such
        frame, however it was tracked (a frame the map planes did not track - frame-to-frame,
        or dense from the prediction in a view of 1-2 plane directions - still adds the
        planes the map lacks). Any other frame adds only its new planes."""
        s = self.settings
        if self._merged_at is None:
            return True
        return _differs(self._merged_at, T, s.map_keyframe_distance, s.map_keyframe_angle_deg)

    def _result(
        self,
        idx: int,
        obs: PlaneObservation,
        T: NDArray[np.float64],
        m: _Measured,
        t0: float,
        cov: NDArray[np.float64] | None,
    ) -> FrameMotion | MotionFailure:
        ms = 1000 * (time.perf_counter() - t0)
        n = len(obs.segments)
        if isinstance(m.motion, MotionFailure):
            return replace(m.motion, index=idx, T_world_frame=T, ms=ms, n_planes=n)
        return FrameMotion(
            idx,
            T,
            m.motion,
            m.case,
            ms,
            n,
            m.source,
            m.note,
            m.dof_sources,
            m.dense,
            m.reference,
            cov,
            *self._plane_information(obs, m.motion),
        )

    def _plane_information(
        self, obs: PlaneObservation, motion: MotionEstimate | None
    ) -> tuple[NDArray[np.float64], tuple[str, ...]]:
        """``FrameMotion.plane_information`` and ``plane_free_dof`` of a measured motion."""
        s = self.settings
        H = np.zeros((6, 6))
        if motion is not None and motion.pairs:
            noise = s.dense.noise if s.dense is not None else DepthNoise()
            inliers = [obs.segments[j].inliers for _, j in motion.pairs]
            H = segments_information(np.asarray(obs.points).reshape(-1, 3), inliers, noise)
        if not H.any():
            return H, DOF_NAMES
        free, _, _ = free_directions(H, s.plane_free_translation, s.plane_free_rotation_deg)
        return H, free

    def _covariance(self, idx: int, m: _Measured) -> NDArray[np.float64] | None:
        """``FrameMotion.covariance`` of frame ``idx``; kept while the frame can be a reference
        (the first frame: zero, it defines the world)."""
        if m.motion is None:
            cov: NDArray[np.float64] | None = np.zeros((6, 6))
        elif m.dense is None or m.reference not in self._covariances:
            cov = None
        else:
            H = m.dense.information
            try:
                C = np.linalg.inv(H + 1e-12 * max(float(np.trace(H)), 1e-300) * np.eye(6))
            except np.linalg.LinAlgError:
                C = np.full((6, 6), np.inf)
            T_ref = self._reference_pose(m.reference)
            Ad = se3_adjoint(T_ref)
            cov = self._covariances[m.reference] + self.settings.covariance_scale**2 * (
                Ad @ C @ Ad.T
            )
        if cov is not None:
            # kept for the frames that can still be a reference: the keyframes, the last
            # tracked frame and this one (it may become either)
            keep = {k[0] for k in self._keyframes} | {idx}
            if self._last_good is not None:
                keep.add(self._last_good[0])
            for k in [k for k in self._covariances if k not in keep]:
                del self._covariances[k]
            self._covariances[idx] = cov
        return cov

    def _reference_pose(self, ref: int) -> NDArray[np.float64]:
        for k in self._keyframes:
            if k[0] == ref:
                return k[2]
        assert self._last_good is not None and self._last_good[0] == ref
        return self._last_good[2]

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
        self, obs: PlaneObservation, pred: _Prediction, texture: bool = True
    ) -> tuple[_Plane | None, MotionFailure | None]:
        """Stages 3-4: the plane solution (source, estimate, ``T_world_frame``) - frame-to-map
        first, frame-to-frame when the map gives less - and the last failure met (``texture``:
        run the 1-2 plane texture searches, :attr:`MotionSettings.texture`)."""
        T_prev, T_pred, step_pred, mprior = pred.T_prev, pred.T, pred.step, pred.prior
        ms = self.settings.motion if texture else replace(self.settings.motion, texture=False)
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
        found: list[_Plane] = []
        failure: MotionFailure | None = None
        if self.settings.frame_to_map and self.map.planes:  # 3
            r_map = self._track_map(obs, T_pred, mprior, ms)
            if isinstance(r_map, MotionEstimate):
                found.append(("map", r_map, T_pred @ r_map.T))
            else:
                failure = r_map
        if not found or found[0][1].prior_dof or found[0][1].case < self._rank(obs):  # 4
            try:
                r_f = estimate_motion(ref_obs, obs, f2f_prior, ms)
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
        fell below ``keyframe_overlap`` times the best overlap any frame had with that keyframe
        becomes a new keyframe (and joins the list that
        :meth:`_revisit` searches), as does a frame the keyframes failed (aligned with the last
        tracked frame instead); an old keyframe the frame was aligned with becomes the
        reference again when the overlap is good."""
        s = self.settings
        ref = next((k for k in self._keyframes if k[0] == ref_idx), None)
        if self._keyframe is None or dense_res is None or ref is None:
            # the first, a frame without a dense result, or one the keyframes failed (it was
            # aligned with the last tracked frame): a new keyframe
            new = (idx, dframe, T)
        else:
            best = max(self._keyframe_best_overlap.get(ref_idx, 0.0), dense_res.overlap)
            self._keyframe_best_overlap[ref_idx] = best
            if dense_res.overlap >= s.keyframe_overlap * best:
                self._keyframe = ref  # (an old keyframe, after a revisit)
                return
            new = (idx, dframe, T)
        self._keyframe = new
        self._keyframes.append(new)
        if len(self._keyframes) > s.max_keyframes:
            dropped = self._keyframes.pop(1)  # the first keyframe (the world frame) stays
            self._keyframe_best_overlap.pop(dropped[0], None)

    def _revisit(self, T_start: NDArray[np.float64]):
        """The oldest keyframe within ``revisit_distance`` / ``revisit_angle_deg`` of
        ``T_start`` that is at least 2 keyframes older than the current one (else None): the
        one just before the current was left for lack of overlap."""
        s = self.settings
        if self._keyframe is None or len(self._keyframes) < 3:
            return None
        current = next(
            (n for n, k in enumerate(self._keyframes) if k[0] == self._keyframe[0]),
            len(self._keyframes),
        )
        for k in self._keyframes[: max(current - 1, 0)]:
            if not _differs(k[2], T_start, s.revisit_distance, s.revisit_angle_deg):
                return k
        return None

    def _dense(
        self,
        dframe: DenseFrame,
        T_plane: NDArray[np.float64] | None,
        pred: _Prediction,
    ) -> tuple[str, DenseResult, NDArray[np.float64], int] | None:
        """Dense refinement against the keyframe (then the last tracked frame), started from
        the plane solution and - when it is missing or disagrees with the prediction by more
        than 2 cm / 1 deg - from the prediction (constant velocity, or the prior) and from the
        previous pose (not with a motion prior); of the starts that pass the gates, and agree
        with the motion prior when one is given, the lowest photometric RMS wins. A
        start within 2 cm / 1 deg of a result already accepted is not run: it lies in that
        result's basin and ends there. None (and ``self._dense_reason``) when no start
        passes."""
        ds, gates = self.settings.dense, self.settings.gates
        assert ds is not None and self._keyframe is not None
        T_pred = pred.T
        starts: list[tuple[str, NDArray[np.float64]]] = []
        if T_plane is not None:
            starts.append(("planes", T_plane))
        if T_plane is None or _differs(T_plane, T_pred, 0.02, 1.0):
            starts.append(("prediction", T_pred))
        # the previous pose (no motion since the last frame): inside the dense step's basin
        # for any hand-held motion at video rate, when both others are off; not with a motion
        # prior, which measured the motion
        T_still = self.poses[-1]
        if pred.prior is None and all(_differs(T0, T_still, 0.02, 1.0) for _, T0 in starts):
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
                T1 = se3_inverse(T_ref) @ T0
                if best is not None and not _differs(best[1].T, T1, 0.02, 1.0):
                    continue  # starts within 2 cm / 1 deg of an accepted result end there
                r = _dense_align(rframe, dframe, T1, ds, compiled=self.compiled)
                if name == "planes":
                    self._plane_overlap = max(self._plane_overlap, r.overlap)
                why = gates.check(r) or self._outside_prior(pred, T_ref @ r.T)
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

    @staticmethod
    def _outside_prior(pred: _Prediction, T_world: NDArray[np.float64]) -> str:
        """Why the pose ``T_world`` contradicts the motion prior (empty when it does not, or
        without a prior): its motion since the last pose is more than 3 sigma of the prior's
        uncertainty (plus the association's 3 deg / 5 cm) from the prior's."""
        if pred.prior is None:
            return ""
        p = pred.prior
        E = se3_inverse(p.T) @ (se3_inverse(pred.T_prev) @ T_world)
        dt = float(np.linalg.norm(E[:3, 3]))
        dr = float(np.degrees(np.arccos(np.clip((np.trace(E[:3, :3]) - 1) / 2, -1.0, 1.0))))
        lim_t, lim_r = 3 * p.sigma_translation + 0.05, 3 * p.sigma_rotation_deg + 3.0
        if dt <= lim_t and dr <= lim_r:
            return ""
        return f"{100 * dt:.0f} cm / {dr:.1f} deg from the prior (> {100 * lim_t:.0f} cm / {lim_r:.0f} deg)"

    def map_view(self, obs: PlaneObservation, T_world_view: NDArray[np.float64]) -> MapView:
        """The map planes seen from ``T_world_view``, with the texture windows centred on where
        the frame ``obs`` (placed at ``T_world_view``) sees each of them."""
        s = self.settings
        return self.map.view(
            obs,
            T_world_view,
            near_m=3 * s.motion.association.max_distance,
            margin_m=s.motion.solver.max_shift,
            max_pixels=s.map_texture_pixels,
        )

    def _rank(self, obs: PlaneObservation) -> int:
        """Plane directions among the frame's own solver-sized planes: the most any solution
        can use (frame-to-frame is skipped when the map already reached it)."""
        m = self.settings.motion
        N = np.array([sg.normal for sg in obs.segments if sg.plane.count >= m.min_plane_points])
        return normal_rank(N.reshape(-1, 3), m.solver.parallel_deg)[0]

    def _track_map(
        self,
        obs: PlaneObservation,
        T_pred: NDArray[np.float64],
        prior: MotionPrior | None,
        motion: MotionSettings | None = None,
    ) -> MotionEstimate | MotionFailure:
        """Stage 3: the correction ``T_pred_frame`` against the map (identity = the prediction).

        A texture step (1 or 2 plane directions) against the map is checked against the depth
        of the last frame merged into the map (:func:`~navkit.planes.motion.depth_consistency`;
        its pose is measured, unlike that of a failed previous frame), the map view having no
        camera of its own.
        """
        view = self.map_view(obs, T_pred)
        ms = replace(motion or self.settings.motion, global_search=False)
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

    @property
    def tracked(self) -> NDArray[np.bool_]:
        """``(N,)`` True where the pose is a measurement (a :class:`FrameMotion`)."""
        return np.array([isinstance(r, FrameMotion) for r in self.results], dtype=bool)

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


def _dense_measured(
    pred: _Prediction,
    plane: _Plane | None,
    start: str,
    dense: DenseResult,
    T: NDArray[np.float64],
    reference: int,
) -> _Measured:
    """The pose the dense step verified: the plane estimate it refined (its geometry and
    texture cases kept, nothing left to the prior), or a bare estimate when it started from
    the prediction."""
    base = plane[1] if (plane is not None and start != "prediction") else None
    source = ("prediction" if base is None else plane[0]) + "+dense"  # type: ignore[index]
    step = se3_inverse(pred.T_prev) @ T
    motion = (
        replace(base, T=step, prior_dof=()) if base is not None else MotionEstimate(step, 0, (), ())
    )
    case = base.case if base is not None else 0
    return _Measured(T, step, motion, case, source, "", dict(dense.dof_sources), dense, reference)


def ros_pose_covariance(cov: NDArray[np.float64], point: ArrayLike) -> NDArray[np.float64]:
    """A :attr:`FrameMotion.covariance` (left perturbation, world axes) as ROS's pose covariance
    of a frame at ``point`` (world): position, then rotation about the fixed world axes
    (``geometry_msgs/PoseWithCovariance``). A left perturbation ``(v, w)`` moves ``point`` by
    ``v + w x point``."""
    p = np.asarray(point, dtype=np.float64)
    J = np.eye(6)
    J[:3, 3:] = -np.array([[0.0, -p[2], p[1]], [p[2], 0.0, -p[0]], [-p[1], p[0], 0.0]])
    return J @ np.asarray(cov, dtype=np.float64) @ J.T
