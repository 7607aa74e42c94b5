"""The settings of the unorganised-cloud path (:mod:`navkit.obstacles.unorganised`): one object
for every cloud, its thresholds in the data's units (spacings, its height noise)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from navkit.domains import NON_NEGATIVE, POSITIVE, POSITIVE_INT, Domain, domain_field
from navkit.errors import ConfigError
from navkit.geometry._validate import check_settings
from navkit.obstacles.settings import _DEGREES_OPEN, DEFAULT_SHAPES

__all__ = ["UnorganisedSettings"]

#: A length in multiples of the data's point spacing.
_SPACINGS = Domain(lo=0.0, lo_open=True, note="point spacings")


@dataclass(frozen=True)
class UnorganisedSettings:
    """Settings of the unorganised path: one object for every cloud.

    Lengths are either multiples of the data's point spacing ``s`` (median horizontal
    nearest-neighbour distance, measured per cloud) or metres of the scene (object sizes).

    Attributes
    ----------
    c0_deg : float
        Steepest terrain slope (deg). An edge of the ground TIN rising faster than this plus the
        ground band is a height jump (rule P4), and a triangle tilted more than ``c1`` is steep
        (P1). Natural terrain in the data may reach it (hillsides, embankments); walls exceed it.
    c1_deg : float or None
        Tilt threshold of P1 (deg); ``None`` = ``c0_deg`` (as on the scan path).
    grid_spacings : float
        Cell of the minimum surface used by the opening, in point spacings (1: the surface
        resolves what the data resolve; the cells left empty take their nearest full cell's
        height).
    thin_spacings : float
        Thinning cell of the mesh, in point spacings (the lowest point per cell is a vertex).
    max_object_m : float
        Half-width of the largest object the opening removes (m): the largest window radius. An
        object wider than twice this is left to the jump rule on the TIN.
    opening_slope : float
        Terrain slope (rise over run) the opening tolerates between two window sizes: a cell
        whose opened height drops by more than ``opening_slope * window`` is an object cell.
    band_noise : float
        Ground band = ``max(band_min_m, band_noise * noise)`` with ``noise`` the measured height
        noise of the cloud (:func:`height_noise`): a point within the band of the ground surface
        is ground.
    band_min_m : float
        Floor of the ground band (m): below it the data cannot separate low objects (grass,
        kerbs) from the ground whatever the noise.
    slope_scale_m : float
        The band grows by ``slope_scale_m * tan(slope)`` of the ground surface: on a slope an
        error in x-y of a fraction of the spacing is a height error.
    low_factor : float
        A point more than ``low_factor`` bands below the ground surface is a low outlier
        (multipath, a wrong echo), not ground.
    gap_spacings : float
        A mesh triangle with an edge longer than this many spacings spans a hole in the data
        (water, an occlusion): unreliable (-1).
    tile_m, overlap_m : float
        Square tiles processed one at a time (m) and how far each tile's working area reaches
        past its own square (m). ``overlap_m`` must hold the largest opening window.
    min_obstacle_triangles : int
        Connected obstacle zones with fewer triangles are not reported as obstacles (their
        points keep their per-point label).
    min_obstacle_height_m : float
        Obstacle zones lower than this over the ground surface are not reported.
    build_map, shapes, guaranteed_shapes : see :class:`~navkit.obstacles.ObstacleSettings`.
    """

    c0_deg: float = domain_field(35.0, _DEGREES_OPEN)
    c1_deg: float | None = domain_field(None, _DEGREES_OPEN)
    grid_spacings: float = domain_field(1.0, _SPACINGS)
    thin_spacings: float = domain_field(1.0, _SPACINGS)
    max_object_m: float = domain_field(18.0, POSITIVE)
    opening_slope: float = domain_field(0.15, Domain(lo=0.0, lo_open=True, note="rise over run"))
    band_noise: float = domain_field(
        3.0, Domain(lo=0.0, lo_open=True, note="multiples of the height noise")
    )
    band_min_m: float = domain_field(0.5, POSITIVE)
    slope_scale_m: float = domain_field(1.25, POSITIVE)
    low_factor: float = domain_field(
        3.0, Domain(lo=0.0, lo_open=True, note="multiples of the ground band")
    )
    gap_spacings: float = domain_field(20.0, _SPACINGS)
    tile_m: float = domain_field(512.0, POSITIVE)
    overlap_m: float = domain_field(48.0, NON_NEGATIVE)
    min_obstacle_triangles: int = domain_field(4, POSITIVE_INT)
    min_obstacle_height_m: float = domain_field(1.0, POSITIVE)
    build_map: bool = True
    shapes: tuple[str, ...] = DEFAULT_SHAPES
    guaranteed_shapes: tuple[str, ...] = ("A1", "MEC")

    def __post_init__(self) -> None:
        check_settings(self)

        def check(name: str, ok: bool, expected: str) -> None:
            if not ok:
                raise ConfigError(
                    f"is {getattr(self, name)!r}",
                    source=type(self).__name__,
                    field=name,
                    expected=expected,
                )

        check(
            "overlap_m",
            self.overlap_m >= self.max_object_m,
            f"metres >= max_object_m ({self.max_object_m}): a tile must hold the widest window",
        )
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
