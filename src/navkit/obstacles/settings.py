"""Settings of the obstacle detector (paper 1), with their defaults in one place."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from navkit.domains import (
    NON_NEGATIVE,
    NON_NEGATIVE_INT,
    POSITIVE,
    POSITIVE_INT,
    Domain,
    domain_field,
)
from navkit.errors import ConfigError
from navkit.geometry._validate import check_settings

__all__ = ["DEFAULT_SHAPES", "ObstacleSettings"]

DEFAULT_SHAPES = ("A1", "A2", "A3", "A4", "A5", "A6", "MEC", "MVEE")

#: A slope or tilt threshold, degrees: 0 and 90 would make every face (or none) steep.
_DEGREES_OPEN = Domain(lo=0.0, hi=90.0, lo_open=True, hi_open=True, note="degrees")


@dataclass(frozen=True)
class ObstacleSettings:
    """Thresholds and options of the eight stages (the implementation, compiled kernels or their
    NumPy twins, is no setting: :mod:`navkit.jit` chooses it, with the same results).


    Attributes
    ----------
    c0_deg : float
        Largest slope the robot can climb and descend (deg); a face steeper than this is an
        obstacle even without a height jump (paper 1, "Setting" and the prism example).
    c1_deg : float or None
        Tilt of the normal from the vertical above which rule P1 holds (deg). ``None`` = ``c0_deg``
        **[reading: the paper keeps c0 and c1 apart but gives no values; P1 is the rule that makes
        a face steeper than c0 an obstacle, so c1 = c0 unless set]**.
    c2 : float
        Co-directionality threshold on the cosine between the horizontal projections of the normal
        and of the ray: P2 (zone II, behind) when ``cos > c2``, P3 (zone I, front) when
        ``cos < -c2``, zone III (sides) otherwise. 0.5 = within 60 deg.
    jump_height_m, jump_range_fraction : float
        Rule P4 (no height jump): a triangle *has* a height jump when the vertical extent of its
        three vertices exceeds ``jump_height_m + jump_range_fraction * d`` with ``d`` its mean
        range (m). **[reading: the paper does not define the jump; the vertical extent is used
        because on level ground the height noise is about ``relative_noise * sensor_height``
        whatever the range, while the range term absorbs gentle hills seen at grazing angles]**.
    jump_range_ratio : float
        Rule P4, second test: a triangle also has a jump when the ranges at the two ends of its
        azimuth edge differ by more than this fraction of the smaller one **[reading: the spec
        allows "the range discontinuity between neighbouring beams"; along azimuth, smooth
        ground gives about equal ranges, so this catches the occlusion edges beside an obstacle
        where the height difference is small - they become side shadows, not obstacles]**.
        ``inf`` disables the test.
    chain_min_height_m : float
        Rule P5 (previous triangle along the ray is an obstacle) carries the obstacle label only
        over triangles at least this much above the lowest point of the face that started the
        chain **[reading: P5 is meant to carry the label "over the flat top of a box"; a top is
        above the obstacle's foot, and this keeps one noisy triangle on flat ground from
        labelling the rest of its column]**.
    normal_support_m : float
        Metric support (m) of the robust normals used by the tilt test P1
        (:func:`navkit.obstacles.mesh.robust_cell_normals`); 0 = the paper's per-triangle normals.
        Larger values suppress phantom obstacles under range noise at the cost of about
        ``normal_support_m / 2`` of boundary growth.
    normal_support : int
        Half-size (cells) of an extra window over which the normals are averaged before P1
        (0 = none). Jump and unreliable triangles are left out of the average.
    merge_distance_m, merge_gap_cells : float, int
        Obstacle zones whose vertices come within ``merge_distance_m`` (3D) across at most
        ``merge_gap_cells`` grid cells are one obstacle (a missing return or a small jump inside
        one object splits its mesh zone; see
        :func:`navkit.obstacles.segment.merge_close_components`). ``0`` disables.
    min_obstacle_triangles : int
        Connected obstacle zones with fewer triangles are returned to ground.
    min_obstacle_height_m : float
        Obstacle zones whose vertical extent (max z - min z of their vertices) is below this are
        returned to ground (noise and curbs, not obstacles); so are zones whose robust extent
        (90th - 10th percentile of their triangles' mid heights) and mean height over the ground
        triangles around them are both below half of it (a patch of range noise on the ground).
    ground_refine : bool
        Re-label points by their height above the local ground after stage 7 (beyond the paper;
        :mod:`navkit.obstacles.ground`): within ``ground_band_m`` -> ground, labelled ground but
        more than ``ground_above_m`` above -> obstacle; the ground height is a low quantile per
        ``ground_cell_m`` cell of the points of the main ground zones (ground components on the
        mesh with >= 10 % of the largest one's triangles: the ground around the robot, not a
        terrace cut off by its steep sides). Only the per-point classes change (triangles,
        obstacles and shapes do not).
    ground_band_m, ground_above_m, ground_cell_m : float
        See ``ground_refine``.
    wrap_azimuth : bool or None
        Close the mesh across the azimuth seam (a 360 deg spinning lidar). ``None`` = when the
        azimuth span plus one step reaches 2 pi.
    build_map : bool
        Stage 8: an :class:`~navkit.obstacles.Obstacle` record per obstacle - its outline (the
        convex hull of its boundary vertices), heights, shadow and bounding shapes. ``False``
        stops after stage 7: the per-point classes, obstacle ids and boundary flags are all in
        the detection (what a ground segmenter such as Patchwork++ gives, and what a per-frame
        costmap needs), its ``obstacles`` is empty.
    shapes : tuple of str
        Bounding-shape methods of :mod:`navkit.geometry.shapes` computed on each obstacle's
        boundary vertices (stage 8).
    guaranteed_shapes : tuple of str
        Shapes recomputed over the obstacle together with its shadows: the paper's A7.
    """

    c0_deg: float = domain_field(20.0, _DEGREES_OPEN)
    c1_deg: float | None = domain_field(None, _DEGREES_OPEN)
    c2: float = domain_field(0.5, Domain(lo=0.0, hi=1.0, hi_open=True, note="a cosine"))
    jump_height_m: float = domain_field(0.3, POSITIVE)
    jump_range_fraction: float = domain_field(0.01, NON_NEGATIVE)
    jump_range_ratio: float = domain_field(0.2, Domain(lo=0.0, lo_open=True, allow_inf=True))
    chain_min_height_m: float = domain_field(0.2, NON_NEGATIVE)
    normal_support_m: float = domain_field(1.0, NON_NEGATIVE)
    normal_support: int = domain_field(0, NON_NEGATIVE_INT)
    merge_distance_m: float = domain_field(0.5, NON_NEGATIVE)
    merge_gap_cells: int = domain_field(2, NON_NEGATIVE_INT)
    min_obstacle_triangles: int = domain_field(4, POSITIVE_INT)
    min_obstacle_height_m: float = domain_field(0.2, NON_NEGATIVE)
    ground_refine: bool = True
    ground_band_m: float = domain_field(0.1, NON_NEGATIVE)
    ground_above_m: float = domain_field(0.3, POSITIVE)
    ground_cell_m: float = domain_field(2.0, POSITIVE)
    wrap_azimuth: bool | None = None
    build_map: bool = True
    shapes: tuple[str, ...] = DEFAULT_SHAPES
    guaranteed_shapes: tuple[str, ...] = ("A1", "MEC")

    def __post_init__(self) -> None:
        check_settings(self)

        def check(name: str, ok: bool, expected: str) -> None:
            if not ok:
                raise ConfigError(f"= {getattr(self, name)!r}", field=name, expected=expected)

        object.__setattr__(self, "shapes", tuple(self.shapes))
        object.__setattr__(self, "guaranteed_shapes", tuple(self.guaranteed_shapes))
        from navkit.geometry.shapes import SHAPES

        for name in ("shapes", "guaranteed_shapes"):
            bad = [s for s in getattr(self, name) if s not in SHAPES]
            check(name, not bad, f"names among {sorted(SHAPES)}")

    @property
    def c1_rad(self) -> float:
        """The P1 tilt threshold in radians."""
        return math.radians(self.c0_deg if self.c1_deg is None else self.c1_deg)

    @classmethod
    def from_dict(cls, data: dict[str, object], source: str = "settings") -> ObstacleSettings:
        """Build from a mapping (e.g. a TOML table), rejecting unknown keys."""
        if "backend" in data:
            raise ConfigError(
                "has `backend`, which is no setting any more",
                source=source,
                field="backend",
                expected="no `backend` key: the compiled kernels and their NumPy twins give the "
                "same results, and the environment variable NAVKIT_JIT (or navkit.jit.use) "
                "chooses between them",
            )
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConfigError(
                f"unknown keys {unknown}", source=source, expected=f"keys among {sorted(known)}"
            )
        return cls(**data)  # type: ignore[arg-type]
