"""6-DoF motion between two sensor positions from matched planes (paper 2).

Convention: the motion ``T_1_2`` maps points of the second frame (oxyz) into the first (OXYZ):
``X = A x + dT`` (the paper's ``A(dphi, dpsi, dtheta)`` maps oxyz to OXYZ). A plane seen as
``N1 . X = rho1`` and ``N2 . x = rho2`` then satisfies ``N1 = A N2`` (eq. 1) and
``N1 . dT = rho1 - rho2`` (eq. 2).

Cases (by how many independent normal directions the matched planes span):

- **>= 3**: closed form. Rotation: weighted orthogonal Procrustes (Kabsch) on the normal pairs;
  translation: least squares of eq. 2 written at the planes' centroids (see
  :func:`plane_translation`; all from geometry).
- **2**: rotation from the two normal directions (Procrustes on the normals and their cross
  product, the least-squares solution of eqs. 1 and 5); translation on the line of eqs. 2 and 6,
  the position along it ``mu`` from the 1D texture functional (eq. 7).
- **1**: the quaternion route: ``q1`` (eq. 8), the shift along ``N11`` (eq. 2), ``q2`` (eq. 9)
  fixing the in-plane axes, then ``(mu, eta, lambda)`` from the texture functional (eq. 4) with a
  global coarse stage, ``dT`` by eq. 10 and ``Q = q3 q1``.

When neither geometry nor texture can fix a degree of freedom the result is a
:class:`MotionFailure` naming the free degrees of freedom, never a guess.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from navkit.domains import NON_NEGATIVE, NON_NEGATIVE_INT, POSITIVE, Domain, domain_field
from navkit.errors import ConfigError, NavkitError
from navkit.geometry import se3_from_rt
from navkit.geometry._validate import check_settings
from navkit.geometry.fitting import Plane
from navkit.geometry.linalg import cross3
from navkit.geometry.rotations import matrix_to_quat, quat_to_matrix
from navkit.planes.align import Search1D, Search2D, search_1d, search_2d
from navkit.planes.quaternion import (
    compose_q3_q1,
    euler_zxy_from_quat,
    in_plane_axes,
    q1_normal_alignment,
    q2_to_optical_axis,
    q3_about_normal,
    translation_eq10,
)
from navkit.planes.texture import PlaneTexture
from navkit.results import Failure, Result

__all__ = [
    "MotionEstimate",
    "MotionFailure",
    "PartialMotion",
    "SolverSettings",
    "TextureFn",
    "normal_rank",
    "plane_translation",
    "solve_one_plane",
    "solve_three_planes",
    "solve_two_planes",
    "two_plane_geometry",
]

log = logging.getLogger(__name__)

TextureFn = Callable[[int, NDArray[np.float64], NDArray[np.float64], float], PlaneTexture]
"""``texture(k, axes (2, 3), ref (3,), nu) -> PlaneTexture`` of a frame's plane ``k``."""


@dataclass(frozen=True)
class SolverSettings:
    """Settings of the motion solvers.

    Attributes
    ----------
    parallel_deg : float
        Normals closer than this (degrees) count as one direction (degeneracy check).
    nu : float
        Texture pixel size, metres (the paper's nu).
    max_shift : float
        Largest texture shift searched (|mu|, |eta|), metres.
    max_turn_deg : float
        Largest turn lambda searched about the normal, degrees (1-plane case).
    min_overlap : int
        Fewest texture pixels compared for a match to count.
    min_contrast : float
        Smallest brightness std (0..1) for a texture to be usable.
    min_distinctness : float
        2-plane case: ``(median D - min D) / median D`` below this = flat functional = free DoF.
    min_peak : float
        1-plane case: best coarse normalised cross-correlation below this = no texture match.
    translation : str
        How eq. 2 is solved for the translation (:func:`plane_translation`): ``"centroid"``
        (default: each pair's equation evaluated where its points are, with both frames'
        normals) or ``"rho"`` (the paper's literal ``N1 . dT = rho1 - rho2``).
    """

    parallel_deg: float = domain_field(15.0, Domain(lo=0.0, hi=90.0, note="degrees"))
    nu: float = domain_field(0.01, POSITIVE)
    max_shift: float = domain_field(0.6, NON_NEGATIVE)
    max_turn_deg: float = domain_field(90.0, Domain(lo=0.0, hi=180.0, note="degrees"))
    min_overlap: int = domain_field(400, NON_NEGATIVE_INT)
    min_contrast: float = domain_field(0.01, Domain(lo=0.0, hi=1.0, note="brightness std"))
    min_distinctness: float = domain_field(0.1, NON_NEGATIVE)
    min_peak: float = domain_field(
        0.3, Domain(lo=-1.0, hi=1.0, note="a correlation, negative = accept anticorrelated")
    )
    translation: str = "centroid"

    def __post_init__(self) -> None:
        check_settings(self)


@dataclass(frozen=True)
class MotionEstimate(Result):
    """A recovered motion ``T_1_2`` (frame 2 -> frame 1).

    Attributes
    ----------
    T : (4, 4) array
        ``X1 = R X2 + t``.
    quaternion : (4,) array
        ``(x, y, z, w)`` of ``R`` (the paper's ``Q``).
    euler_zxy : (3,) array
        ``(dphi, dpsi, dtheta)``, radians, ``R = A_Z(dphi) A_X(dpsi) A_Y(dtheta)`` (eq. 11).
    case : int
        1, 2 or 3 (= ">= 3") independent plane normals used.
    geometry_dof, texture_dof : tuple of str
        Which degrees of freedom geometry fixed and which the texture fixed.
    residuals : dict
        ``normal_deg`` (RMS angle between ``N1`` and ``R N2``), ``rho_m`` (RMS of eq. 2),
        and for texture cases ``texture_D`` (eq. 4 / 7), ``texture_overlap`` (pixels), ...
    pairs : tuple of (int, int)
        The plane matches used (frame-1 index, frame-2 index).
    prior_dof : tuple of str
        Degrees of freedom neither geometry nor texture fixed, taken from a motion prior
        (:class:`navkit.planes.motion.MotionPrior`); empty when everything was measured.
    """

    T: NDArray[np.float64]
    case: int
    geometry_dof: tuple[str, ...]
    texture_dof: tuple[str, ...]
    residuals: dict[str, float] = field(default_factory=dict)
    pairs: tuple[tuple[int, int], ...] = ()
    prior_dof: tuple[str, ...] = ()

    @property
    def rotation(self) -> NDArray[np.float64]:
        return self.T[:3, :3]

    @property
    def translation(self) -> NDArray[np.float64]:
        return self.T[:3, 3]

    @property
    def quaternion(self) -> NDArray[np.float64]:
        return matrix_to_quat(self.T[:3, :3])

    @property
    def euler_zxy(self) -> NDArray[np.float64]:
        return euler_zxy_from_quat(self.quaternion)


@dataclass(frozen=True)
class MotionFailure(Failure):
    """No motion: the input leaves degrees of freedom free.

    Returned by the solvers and :func:`~navkit.planes.motion.estimate_motion` for a pair of
    frames, and by :meth:`~navkit.planes.odometry.PlaneOdometry.update` for a frame of a
    sequence, which also fills the frame fields.

    Attributes
    ----------
    case : int
        Independent normal directions available (0 = no matched plane).
    free_dof : tuple of str
        The degrees of freedom neither geometry nor texture fixed.
    reason : str
        Why (no overlap, uniform texture, flat functional, ...).
    index : int
        The frame's number in the sequence (-1 outside ``PlaneOdometry``).
    T_world_frame : (4, 4) array or None
        The pose the trajectory carries for the frame: the prediction, not a measurement (None
        outside ``PlaneOdometry``).
    ms : float
        Wall time of the odometry's update, milliseconds (NaN outside it).
    n_planes : int
        The frame's planes (0 outside ``PlaneOdometry``).
    """

    case: int
    free_dof: tuple[str, ...]
    reason: str
    index: int = -1
    T_world_frame: NDArray[np.float64] | None = None
    ms: float = float("nan")
    n_planes: int = 0


def _kabsch(
    a: NDArray[np.float64], b: NDArray[np.float64], w: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Rotation ``R`` minimising ``sum w |a_i - R b_i|^2`` (rows are vectors)."""
    H = (b * w[:, None]).T @ a
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    return Vt.T @ np.diag([1.0, 1.0, d]) @ U.T


def _on_plane(p: Plane) -> NDArray[np.float64]:
    """The plane's centroid projected onto it (a centroid left at the origin becomes the foot
    point ``rho n``)."""
    c = np.asarray(p.centroid, dtype=np.float64).reshape(3)
    return c - (p.normal @ c - p.rho) * p.normal


def plane_translation(
    R: NDArray[np.float64],
    p1: Sequence[Plane],
    p2: Sequence[Plane],
    w: NDArray[np.float64],
    method: str = "centroid",
    basis: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Translation ``t`` of ``T_1_2 = (R, t)`` from matched planes by weighted least squares.

    ``method="rho"`` is the paper's eq. 2 as written, ``N1i . t = rho1i - rho2i``.
    ``method="centroid"`` (default) writes the same constraint where the planes were measured:
    the centroid ``c2`` of frame 2's points, moved into frame 1, lies on frame 1's plane, and
    ``c1`` on frame 2's plane moved into frame 1::

        N1i . (R c2i + t - c1i) = 0,     (R N2i) . (R c2i + t - c1i) = 0.

    Both are eq. 2 exactly for noise-free planes (``rho = N . c``). Why: a TLS plane's ``rho``
    is ``N . c`` - its distance is measured at the centroid and *extrapolated* to the origin,
    so a normal error ``dN`` (covariance ``sigma^2 sum_k e_k e_k^T / (n lambda_k)`` over the
    in-plane eigenpairs of the points' scatter matrix) moves ``rho`` by ``dN . c``:
    ``var(rho) = c^T C_N c + sigma^2 / n``. A Kinect plane whose centroid is 3 m away (a side
    wall at grazing incidence, ``rho`` 0.5 m) turns a 5 deg normal error into a 16 cm distance
    error. At the centroids the lever is ``|R c2 + t - c1|`` (how far apart the two views'
    centroids are), not ``|c|``. Using both frames' normals averages their errors.

    Parameters
    ----------
    R : (3, 3) array
        Rotation of the motion (frame 2 -> frame 1).
    p1, p2 : sequences of Plane
        Matched planes (same order); centroids are projected onto their planes first.
    w : (K,) array
        Weights of the pairs (both equations of a pair get the same weight).
    method : {"centroid", "rho"}
    basis : (m, 3) array, optional
        Solve only within the span of these orthonormal rows (``t = basis^T u``; the 2-plane
        case: the two directions across the planes' intersection line).

    Returns
    -------
    (3,) array
        ``t``, metres.
    """
    N1 = np.array([p.normal for p in p1], dtype=np.float64).reshape(-1, 3)
    w = np.asarray(w, dtype=np.float64)
    if method == "rho":
        A = N1
        b = np.array([a.rho - c.rho for a, c in zip(p1, p2, strict=True)])
        ww = w
    elif method == "centroid":
        N2r = np.array([p.normal for p in p2], dtype=np.float64).reshape(-1, 3) @ R.T
        N2r *= np.where(np.einsum("ij,ij->i", N1, N2r) < 0, -1.0, 1.0)[:, None]
        D = np.array([_on_plane(a) for a in p1]) - np.array([_on_plane(c) for c in p2]) @ R.T
        A = np.vstack([N1, N2r])
        b = np.concatenate([np.einsum("ij,ij->i", N1, D), np.einsum("ij,ij->i", N2r, D)])
        ww = np.concatenate([w, w])
    else:
        raise ConfigError(
            f"unknown translation method {method!r}",
            source="SolverSettings",
            field="translation",
            expected="'centroid' or 'rho'",
        )
    B = np.eye(3) if basis is None else np.asarray(basis, dtype=np.float64)
    u = np.linalg.lstsq((A @ B.T) * ww[:, None], b * ww, rcond=None)[0]
    return np.asarray(B.T @ u, dtype=np.float64)


def normal_rank(normals: NDArray[np.float64], parallel_deg: float) -> tuple[int, list[int]]:
    """How many independent directions the unit normals ``(K, 3)`` span, and the indices chosen.

    Normals within ``parallel_deg`` of each other (or of the plane of two chosen ones, for the
    third) do not add a direction. Input order = priority (put the largest planes first).
    """
    if len(normals) == 0:
        return 0, []
    s = np.sin(np.radians(parallel_deg))
    chosen = [0]
    cr = np.linalg.norm(np.cross(normals[0], normals), axis=1)
    if cr.max() < s:
        return 1, chosen
    b = int(np.argmax(cr > s))  # first (largest) non-parallel one
    chosen.append(b)
    axis = np.cross(normals[0], normals[b])
    axis /= np.linalg.norm(axis)
    off = np.abs(normals @ axis)
    if off.max() < s:
        return 2, chosen
    chosen.append(int(np.argmax(off > s)))
    return 3, chosen


def _residuals(R, t, p1: Sequence[Plane], p2: Sequence[Plane]) -> dict[str, float]:
    N1 = np.array([p.normal for p in p1])
    N2 = np.array([p.normal for p in p2])
    cosang = np.clip(np.einsum("ij,ij->i", N1, N2 @ R.T), -1, 1)
    drho = np.array([a.rho - b.rho for a, b in zip(p1, p2, strict=True)])
    return {
        "normal_deg": float(np.degrees(np.sqrt(np.mean(np.arccos(cosang) ** 2)))),
        "rho_m": float(np.sqrt(np.mean((N1 @ t - drho) ** 2))),
    }


def solve_three_planes(
    p1: Sequence[Plane],
    p2: Sequence[Plane],
    settings: SolverSettings | None = None,
    weights: NDArray[np.float64] | None = None,
) -> MotionEstimate | MotionFailure:
    """Closed form from >= 3 matched planes spanning three directions.

    Parameters
    ----------
    p1, p2 : sequences of Plane
        Matched planes, frame 1 and frame 2 (same order).
    weights : (K,) array, optional
        Per-pair weights (default: ``sqrt`` of the smaller inlier count).

    Returns
    -------
    MotionEstimate (case 3), or MotionFailure when the normals do not span three directions
    (``case`` = the directions found, ``free_dof`` the translation directions left free).
    """
    s = settings or SolverSettings()
    N1 = np.array([p.normal for p in p1], dtype=np.float64).reshape(-1, 3)
    N2 = np.array([p.normal for p in p2], dtype=np.float64).reshape(-1, 3)
    rank, _ = normal_rank(N1, s.parallel_deg)
    if rank < 3:
        free = {0: ("rotation", "translation"), 1: ("lambda", "mu", "eta"), 2: ("mu",)}[rank]
        return MotionFailure(rank, free, f"the normals span {rank} direction(s), 3 needed")
    w = (
        np.asarray(weights, float)
        if weights is not None
        else np.sqrt(
            np.minimum([max(p.count, 1) for p in p1], [max(p.count, 1) for p in p2]).astype(float)
        )
    )
    R = _kabsch(N1, N2, w)
    t = plane_translation(R, p1, p2, w, s.translation)
    return MotionEstimate(
        se3_from_rt(R, t), 3, ("rotation", "translation"), (), _residuals(R, t, p1, p2)
    )


@dataclass(frozen=True)
class PartialMotion:
    """What geometry alone fixes when the matched planes span two normal directions.

    The rotation (3 DoF) and the translation across the planes' intersection line (2 DoF);
    the position ``mu`` along the line (direction ``d`` in frame 1) is free:
    ``T_1_2 = (R, t0 + mu d)`` for any ``mu``.

    Attributes
    ----------
    R : (3, 3) array
        Rotation, least squares of eqs. 1 and 5.
    t0 : (3,) array
        Minimum-norm translation of eqs. 2 and 6 (``t0 . d = 0``), metres.
    d : (3,) array
        Unit direction of the intersection line, frame 1.
    free_dof : tuple of str
        ``("mu",)``.
    """

    R: NDArray[np.float64]
    t0: NDArray[np.float64]
    d: NDArray[np.float64]
    free_dof: tuple[str, ...] = ("mu",)


def two_plane_geometry(
    p1: Sequence[Plane], p2: Sequence[Plane], settings: SolverSettings | None = None
) -> PartialMotion | MotionFailure:
    """The geometric part of the 2-plane case: rotation and translation across the line.

    Parameters
    ----------
    p1, p2 : sequences of Plane
        Matched planes (largest first); their normals must span exactly two directions.

    Returns
    -------
    PartialMotion, or MotionFailure when the normals do not span two directions.
    """
    s = settings or SolverSettings()
    N1 = np.array([p.normal for p in p1], dtype=np.float64).reshape(-1, 3)
    N2 = np.array([p.normal for p in p2], dtype=np.float64).reshape(-1, 3)
    rank, chosen = normal_rank(N1, s.parallel_deg)
    if rank != 2:
        free = {0: ("rotation", "translation"), 1: ("lambda", "mu", "eta"), 3: ()}[min(rank, 3)]
        return MotionFailure(rank, free, f"the normals span {rank} direction(s), 2 expected")
    a, b = chosen
    # rotation: least squares of eqs. 1 and 5 (normals and their cross product)
    c1 = cross3(N1[a], N1[b])
    c2 = cross3(N2[a], N2[b])
    R = _kabsch(
        np.stack([N1[a], N1[b], c1 / np.linalg.norm(c1)]),
        np.stack([N2[a], N2[b], c2 / np.linalg.norm(c2)]),
        np.ones(3),
    )
    # translation across the line: eqs. 2 and 6 (all planes, weighted by sqrt of the smaller
    # inlier count as in the closed form, at the centroids: plane_translation), solved in the
    # two directions across the line so t0 . d = 0; free along the line
    d = c1 / np.linalg.norm(c1)
    w = np.sqrt(np.minimum([max(x.count, 1) for x in p1], [max(y.count, 1) for y in p2]))
    across = np.stack([N1[a], cross3(d, N1[a])])
    t0 = plane_translation(R, p1, p2, w, s.translation, basis=across)
    return PartialMotion(R, t0, d)


def solve_two_planes(
    p1: Sequence[Plane],
    p2: Sequence[Plane],
    tex1: TextureFn,
    tex2: TextureFn,
    settings: SolverSettings | None = None,
    prior_translation: NDArray[np.float64] | None = None,
) -> MotionEstimate | MotionFailure:
    """Two normal directions: rotation from geometry, the position on the line from texture (eq. 7).

    Parameters
    ----------
    p1, p2 : sequences of Plane
        Matched planes (first two must be non-parallel; further ones parallel to either also
        contribute their texture).
    tex1, tex2 : TextureFn
        Texture samplers of frame 1 and frame 2.
    prior_translation : (3,) array, optional
        Predicted translation; its component along the line centres the search.

    Returns
    -------
    MotionEstimate (case 2) or MotionFailure naming ``mu`` (the position along the planes'
    intersection line) when the textures do not overlap or do not vary along it.
    """
    s = settings or SolverSettings()
    N1 = np.array([p.normal for p in p1])
    rank, _ = normal_rank(N1, s.parallel_deg)
    if rank != 2:
        return MotionFailure(rank, ("mu",), f"the normals span {rank} direction(s), 2 expected")
    # rotation (eqs. 1, 5) and translation across the line (eqs. 2, 6); mu along d is free
    geo = two_plane_geometry(p1, p2, s)
    assert isinstance(geo, PartialMotion)  # rank 2 checked above
    R, t0, d = geo.R, geo.t0, geo.d
    prior_shift = (
        0.0 if prior_translation is None else float(np.asarray(prior_translation, float) @ d)
    )
    # textures on a common lattice per plane: columns along d, frame 2 seen through (R, t0)
    pairs = []
    low_contrast = 0
    for k in range(len(p1)):
        n = N1[k]
        if abs(n @ d) > np.sin(np.radians(s.parallel_deg)):
            continue  # not containing the line direction
        u = d - (d @ n) * n
        u /= np.linalg.norm(u)
        axes1 = np.stack([u, cross3(n, u)])
        ref1 = p1[k].rho * n
        axes2 = axes1 @ R  # R^T applied to each row
        ref2 = R.T @ (ref1 - t0)
        # centre the search on the prior shift: shift ref2 so the prior is at zero shift
        ref2 = ref2 - prior_shift * (R.T @ u)
        try:
            e1 = tex1(k, axes1, ref1, s.nu)
            e2 = tex2(k, axes2, ref2, s.nu)
        except NavkitError as exc:  # a plane without texture is skipped, the others decide
            log.debug("plane %d: no texture (%s)", k, exc)
            continue
        if e1.contrast() < s.min_contrast or e2.contrast() < s.min_contrast:
            low_contrast += 1
            continue
        pairs.append((e1, e2))
    if not pairs:
        why = "uniform texture" if low_contrast else "no textured plane"
        return MotionFailure(
            2, ("mu",), f"{why}: the position along the planes' intersection line is free"
        )
    res: Search1D = search_1d(pairs, int(np.ceil(s.max_shift / s.nu)), s.min_overlap)
    if not np.isfinite(res.shift):
        return MotionFailure(
            2,
            ("mu",),
            "the textures do not overlap: the position along the intersection line is free",
        )
    if res.distinctness < s.min_distinctness:
        return MotionFailure(
            2,
            ("mu",),
            f"the texture functional D(mu) is flat (distinctness {res.distinctness:.3f}): "
            "the position along the intersection line is free",
        )
    mu = prior_shift + res.shift * s.nu
    t = t0 + mu * d
    resid = _residuals(R, t, p1, p2)
    resid.update(
        texture_D=float(np.nanmin(res.D)),
        texture_overlap=float(res.overlap),
        texture_distinctness=float(res.distinctness),
        mu_m=float(mu),
    )
    return MotionEstimate(
        se3_from_rt(R, t), 2, ("rotation", "translation across the line"), ("mu",), resid
    )


def solve_one_plane(
    p1: Plane,
    p2: Plane,
    tex1: TextureFn,
    tex2: TextureFn,
    k1: int,
    k2: int,
    settings: SolverSettings | None = None,
) -> MotionEstimate | MotionFailure:
    """One plane: the paper's quaternion route with the 3-parameter texture search (eqs. 3, 4, 8-10).

    Steps: ``q1`` turns ``N21`` onto ``N11`` (eq. 8); the shift ``(rho11 - rho21) N11`` puts the
    second texture into plane P1 (eq. 2); ``q2`` (eq. 9) fixes the in-plane axes ``mu``, ``eta``;
    :func:`~navkit.planes.align.search_2d` finds ``(mu0, eta0, lambda0)`` (eq. 4); then eq. 10 and
    ``Q = q3 q1``.

    Returns
    -------
    MotionEstimate (case 1) or MotionFailure naming ``lambda``, ``mu``, ``eta``.
    """
    s = settings or SolverSettings()
    n1, n2 = p1.normal, p2.normal
    q1 = q1_normal_alignment(n2, n1)
    q2 = q2_to_optical_axis(n1)
    axes1 = in_plane_axes(q2)  # (mu, eta) axes, u x v = N11
    R1 = quat_to_matrix(q1)
    axes2 = axes1 @ R1  # q1^-1 applied: frame-2 axes that q1 maps onto axes1
    free = ("lambda", "mu", "eta")
    try:
        e1 = tex1(k1, axes1, p1.rho * n1, s.nu)
        e2 = tex2(k2, axes2, p2.rho * n2, s.nu)
    except NavkitError as exc:
        return MotionFailure(1, free, f"no texture: {exc}")
    if min(e1.contrast(), e2.contrast()) < s.min_contrast:
        return MotionFailure(
            1, free, "uniform texture: the turn about the normal and the in-plane shift are free"
        )
    res: Search2D = search_2d(
        e1,
        e2,
        max_angle=np.radians(s.max_turn_deg),
        max_shift=s.max_shift,
        min_overlap=s.min_overlap,
    )
    if not np.isfinite(res.lam) or not np.isfinite(res.D):
        return MotionFailure(1, free, "the textures do not overlap")
    if res.peak < s.min_peak:
        return MotionFailure(
            1, free, f"the textures do not match (best correlation {res.peak:.2f})"
        )
    q3 = q3_about_normal(n1, res.lam)
    Q = compose_q3_q1(q3, q1)
    t = translation_eq10(n1, p1.rho, p2.rho, q2, float(res.t[0]), float(res.t[1]))
    R = quat_to_matrix(Q)
    resid = _residuals(R, t, [p1], [p2])
    resid.update(
        texture_D=res.D,
        texture_overlap=float(res.overlap),
        texture_peak=res.peak,
        texture_distinctness=res.distinctness,
        lambda_rad=res.lam,
        mu_m=float(res.t[0]),
        eta_m=float(res.t[1]),
    )
    return MotionEstimate(
        se3_from_rt(R, t),
        1,
        ("rotation aligning the normal", "translation along the normal"),
        free,
        resid,
    )
