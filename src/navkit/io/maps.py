"""Map exports: ROS ``map_server`` occupancy grids (PGM + YAML) and GeoJSON.

Occupancy grids
---------------
In memory an occupancy grid is an ``(H, W)`` int8 array with -1 unknown, 0 free, 100 occupied
(values in between are occupancy probabilities in percent), laid out like the
``nav_msgs/OccupancyGrid`` message: **row 0 is the lowest y**, column 0 the lowest x; cell
``(row, col)`` covers ``x in origin_x + [col, col + 1) * resolution``,
``y in origin_y + [row, row + 1) * resolution``. On disk (ROS ``map_server`` format) the PGM image
is flipped so that **image row 0 is the highest y**; pixels are 0 occupied, 254 free, 205 unknown,
and the YAML next to it holds ``image, resolution, origin [x, y, yaw], negate 0,
occupied_thresh 0.65, free_thresh 0.196``. Reading applies map_server's trinary rule:
``p = (255 - pixel) / 255``; ``p > occupied_thresh`` -> 100, ``p < free_thresh`` -> 0, else -1.

GeoJSON
-------
:func:`write_geojson` writes a ``FeatureCollection``. RFC 7946 GeoJSON means WGS84 longitude /
latitude, so a map in local metres is georeferenced first: given a :class:`GeoOrigin` (the
latitude and longitude of the local frame's origin and the compass heading of its x axis),
every position is converted exactly (:func:`local_to_wgs84`: local x, y -> east, north on the
tangent plane at the origin -> ECEF -> geodetic latitude / longitude on the WGS84 ellipsoid,
heights on the ellipsoid dropped) and written as ``[lon, lat]`` with 8 decimals (about 1 mm).
Without an origin the coordinates stay local metres, which RFC 7946 does not allow; the
collection says so in its ``properties`` (commands write GeoJSON only when georeferenced, and
keep local maps as map_server grids and JSON). Polygon rings must be closed (first position ==
last) with at least 4 positions; :func:`polygon_geometry` builds closed, counter-clockwise rings
from ``(N, 2)`` vertices.
"""

from __future__ import annotations

import json
import logging
import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import DataNotFoundError, FormatError, InputError
from navkit.io.atomic import atomic_write, to_jsonable, write_text

__all__ = [
    "WGS84_A",
    "WGS84_F",
    "GeoOrigin",
    "OccupancyGrid",
    "line_geometry",
    "local_to_wgs84",
    "parse_origin",
    "point_geometry",
    "polygon_geometry",
    "read_occupancy_grid",
    "write_geojson",
    "write_occupancy_grid",
]

log = logging.getLogger(__name__)

PathLike = str | os.PathLike[str]

OCCUPIED_THRESH = 0.65
FREE_THRESH = 0.196
PIXEL_OCCUPIED, PIXEL_FREE, PIXEL_UNKNOWN = 0, 254, 205


WGS84_A = 6378137.0
"""WGS84 semi-major axis (m)."""
WGS84_F = 1.0 / 298.257223563
"""WGS84 flattening."""
_E2 = WGS84_F * (2.0 - WGS84_F)


@dataclass(frozen=True)
class GeoOrigin:
    """Where a local map frame sits on the Earth.

    Attributes
    ----------
    lat_deg, lon_deg : float
        WGS84 latitude and longitude of the local origin (deg).
    heading_deg : float
        Compass bearing of the local x axis (deg clockwise from true north): 0 = x points north,
        90 = x points east. The local y axis is 90 deg counter-clockwise from x (to its left).
    """

    lat_deg: float
    lon_deg: float
    heading_deg: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lat_deg) and -90.0 < self.lat_deg < 90.0):
            raise InputError(
                f"latitude {self.lat_deg!r}", field="origin", expected="-90 < LAT < 90 (deg)"
            )
        if not (math.isfinite(self.lon_deg) and -180.0 <= self.lon_deg <= 180.0):
            raise InputError(
                f"longitude {self.lon_deg!r}", field="origin", expected="-180 <= LON <= 180 (deg)"
            )
        if not math.isfinite(self.heading_deg):
            raise InputError(
                f"heading {self.heading_deg!r}", field="origin", expected="finite degrees"
            )


def parse_origin(text: str, source: str = "--origin") -> GeoOrigin:
    """``"LAT,LON"`` or ``"LAT,LON,HEADING"`` (deg) -> :class:`GeoOrigin`.

    Raises
    ------
    InputError
        Naming ``source`` and the expected form.
    """
    parts = [p for p in text.replace(" ", "").split(",") if p]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        vals = []
    if len(vals) not in (2, 3):
        raise InputError(
            f"= {text!r}", source=source, expected="LAT,LON or LAT,LON,HEADING in degrees"
        )
    return GeoOrigin(*vals)


def local_to_wgs84(xy: ArrayLike, origin: GeoOrigin) -> NDArray[np.float64]:
    """Local metres ``(N, 2)`` -> WGS84 ``(N, 2)`` longitude, latitude (deg), exactly.

    The local frame is the tangent plane of the WGS84 ellipsoid at ``origin``, its x axis at
    compass bearing ``origin.heading_deg``. Each point goes local -> east, north (``e = x sin h
    - y cos h``, ``n = x cos h + y sin h``) -> ECEF (origin + ENU axes) -> geodetic latitude and
    longitude (Bowring's closed form, refined by two fixed-point steps: below 1e-9 deg within
    hundreds of kilometres). Points on the tangent plane sit slightly above the ellipsoid away
    from the origin (x^2 / 2R: 8 cm at 1 km); the height is dropped, the horizontal position
    kept.
    """
    p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    h = math.radians(origin.heading_deg)
    e = p[:, 0] * math.sin(h) - p[:, 1] * math.cos(h)
    n = p[:, 0] * math.cos(h) + p[:, 1] * math.sin(h)
    lat0, lon0 = math.radians(origin.lat_deg), math.radians(origin.lon_deg)
    sl, cl, so, co = math.sin(lat0), math.cos(lat0), math.sin(lon0), math.cos(lon0)
    N0 = WGS84_A / math.sqrt(1.0 - _E2 * sl * sl)
    x0, y0, z0 = N0 * cl * co, N0 * cl * so, N0 * (1.0 - _E2) * sl
    # ENU -> ECEF (up component 0: the point lies on the tangent plane)
    X = x0 - so * e - sl * co * n
    Y = y0 + co * e - sl * so * n
    Z = z0 + cl * n
    lon = np.arctan2(Y, X)
    r = np.hypot(X, Y)
    b = WGS84_A * (1.0 - WGS84_F)
    ep2 = (WGS84_A**2 - b**2) / b**2
    beta = np.arctan2(WGS84_A * Z, b * r)
    lat = np.arctan2(Z + ep2 * b * np.sin(beta) ** 3, r - _E2 * WGS84_A * np.cos(beta) ** 3)
    for _ in range(2):  # fixed-point refinement of the geodetic latitude
        sin_lat = np.sin(lat)
        Nl = WGS84_A / np.sqrt(1.0 - _E2 * sin_lat**2)
        hgt = r / np.cos(lat) - Nl
        lat = np.arctan2(Z, r * (1.0 - _E2 * Nl / (Nl + hgt)))
    return np.column_stack([np.degrees(lon), np.degrees(lat)])


def _georeference(geom: Any, origin: GeoOrigin, decimals: int) -> Any:
    """A geometry with every position converted to rounded ``[lon, lat]``."""
    if geom is None:
        return None
    if geom["type"] == "GeometryCollection":
        return {
            **geom,
            "geometries": [_georeference(g, origin, decimals) for g in geom["geometries"]],
        }
    depth = _GEOMETRY_DEPTH[geom["type"]]

    def conv(c: Any, d: int) -> Any:
        if d == 2:  # a list of positions: one vectorised call
            ll = np.round(local_to_wgs84(np.asarray(c, dtype=np.float64)[:, :2], origin), decimals)
            return ll.tolist()
        return [conv(x, d - 1) for x in c]

    if depth == 1:
        return {**geom, "coordinates": conv([geom["coordinates"]], 2)[0]}
    return {**geom, "coordinates": conv(geom["coordinates"], depth)}


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """An occupancy grid read from (or to be written as) a map_server map.

    Attributes
    ----------
    occupancy : (H, W) int8
        -1 unknown, 0 free, 100 occupied; row 0 = lowest y (nav_msgs/OccupancyGrid layout).
    resolution : float
        Cell size, metres.
    origin_xy : (2,) float64
        World position of the corner of cell (0, 0) (its lowest x and y), metres.
    origin_yaw : float
        Rotation of the grid about z, radians (map_server's third origin number; usually 0).
    """

    occupancy: NDArray[np.int8]
    resolution: float
    origin_xy: NDArray[np.float64]
    origin_yaw: float = 0.0

    def cell_centers(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(W,)`` x and ``(H,)`` y of the cell centres (for yaw 0), metres."""
        h, w = self.occupancy.shape
        x = self.origin_xy[0] + (np.arange(w) + 0.5) * self.resolution
        y = self.origin_xy[1] + (np.arange(h) + 0.5) * self.resolution
        return x, y


def _validate_grid(
    occupancy: ArrayLike, resolution: float, origin_xy: ArrayLike
) -> tuple[NDArray[np.int8], float, NDArray[np.float64]]:
    occ = np.asarray(occupancy)
    if occ.ndim != 2 or occ.size == 0:
        raise InputError(
            f"occupancy has shape {occ.shape}",
            field="occupancy",
            expected="a non-empty (H, W) array",
        )
    if not np.issubdtype(occ.dtype, np.integer):
        raise InputError(
            f"occupancy has dtype {occ.dtype}",
            field="occupancy",
            expected="integers -1 (unknown) or 0..100 (percent occupied)",
        )
    bad = (occ < -1) | (occ > 100)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise InputError(
            f"cell ({r}, {c}) holds {occ[r, c]}",
            field="occupancy",
            expected="-1 (unknown) or 0..100",
        )
    if not (math.isfinite(resolution) and resolution > 0):
        raise InputError(
            f"{resolution!r}", field="resolution", expected="a positive cell size in metres"
        )
    org = np.asarray(origin_xy, dtype=np.float64).ravel()
    if org.size != 2 or not np.isfinite(org).all():
        raise InputError(f"{origin_xy!r}", field="origin_xy", expected="two finite numbers (x, y)")
    return occ.astype(np.int8), float(resolution), org


def write_occupancy_grid(
    path_stem: PathLike,
    occupancy: ArrayLike,
    resolution: float,
    origin_xy: ArrayLike = (0.0, 0.0),
    *,
    origin_yaw: float = 0.0,
) -> tuple[Path, Path]:
    """Write an occupancy grid as ROS map_server ``<stem>.pgm`` + ``<stem>.yaml`` (atomically).

    Parameters
    ----------
    path_stem : str or path
        Output path without suffix (``out/map`` -> ``out/map.pgm``, ``out/map.yaml``).
    occupancy : (H, W) int array
        -1 unknown, 0 free, 100 occupied, or percentages; row 0 = lowest y.
    resolution : float
        Metres per cell.
    origin_xy : (2,) float
        World x, y of the lower-left corner of cell (0, 0), metres.

    Returns
    -------
    (pgm_path, yaml_path)

    Notes
    -----
    Percentages are thresholded with the thresholds written to the YAML (``p > 0.65`` occupied,
    ``p < 0.196`` free, else unknown), so reading back gives exactly -1 / 0 / 100.
    """
    occ, res, org = _validate_grid(occupancy, resolution, origin_xy)
    stem = Path(path_stem)
    if stem.suffix.lower() in (".pgm", ".yaml", ".yml"):
        stem = stem.with_suffix("")
    pgm = stem.with_name(stem.name + ".pgm")
    yaml = stem.with_name(stem.name + ".yaml")
    p = occ.astype(np.float64) / 100.0
    img = np.full(occ.shape, PIXEL_UNKNOWN, dtype=np.uint8)
    img[(occ >= 0) & (p > OCCUPIED_THRESH)] = PIXEL_OCCUPIED
    img[(occ >= 0) & (p < FREE_THRESH)] = PIXEL_FREE
    img = img[::-1]  # image row 0 = highest y
    h, w = np.shape(occ)
    with atomic_write(pgm, "wb") as fh:
        fh.write(f"P5\n# navkit occupancy grid, {res} m/cell\n{w} {h}\n255\n".encode("ascii"))
        fh.write(np.ascontiguousarray(img).tobytes())
    write_text(
        yaml,
        f"image: {pgm.name}\n"
        "mode: trinary\n"
        f"resolution: {float(res)!r}\n"
        f"origin: [{float(org[0])!r}, {float(org[1])!r}, {float(origin_yaw)!r}]\n"
        "negate: 0\n"
        f"occupied_thresh: {OCCUPIED_THRESH}\n"
        f"free_thresh: {FREE_THRESH}\n",
    )
    log.debug("wrote occupancy grid %s (%d x %d cells)", yaml, w, h)
    return pgm, yaml


def _parse_simple_yaml(p: Path) -> dict[str, Any]:
    """The flat ``key: value`` YAML of map_server files (scalars and ``[a, b, c]`` lists)."""
    out: dict[str, Any] = {}
    for k, raw in enumerate(p.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        if ":" not in line:
            raise FormatError(
                f"line {k} is not 'key: value': {raw!r}",
                source=p,
                field=f"line {k}",
                expected="map_server YAML (image, resolution, origin, ...)",
            )
        key, value = (s.strip() for s in line.split(":", 1))
        if value.startswith("[") and value.endswith("]"):
            out[key] = [v.strip() for v in value[1:-1].split(",") if v.strip()]
        else:
            out[key] = value.strip("'\"")
    return out


def read_occupancy_grid(yaml_path: PathLike) -> OccupancyGrid:
    """Read a ROS map_server map (YAML + its image) into an :class:`OccupancyGrid`.

    Applies ``negate`` and the file's thresholds (trinary mode); the image is flipped so that row
    0 is the lowest y.
    """
    from navkit.io.images import read_image

    p = Path(yaml_path)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: no such file")
    meta = _parse_simple_yaml(p)

    def number(key: str, default: float | None = None) -> float:
        if key not in meta:
            if default is None:
                raise FormatError("missing", source=p, field=key, expected="a number")
            return default
        try:
            value = float(meta[key])
        except (TypeError, ValueError):
            value = float("nan")
        if not np.isfinite(value):
            raise FormatError(f"{meta[key]!r}", source=p, field=key, expected="a finite number")
        return value

    if "image" not in meta:
        raise FormatError("missing", source=p, field="image", expected="the map image file name")
    res = number("resolution")
    origin = meta.get("origin")
    try:
        ox, oy, oyaw = (float(v) for v in origin)  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise FormatError(f"{origin!r}", source=p, field="origin", expected="[x, y, yaw]") from None
    if not res > 0:
        raise FormatError(f"{res}", source=p, field="resolution", expected="metres per cell > 0")
    if not all(np.isfinite(v) for v in (ox, oy, oyaw)):
        raise FormatError(f"{origin!r}", source=p, field="origin", expected="finite [x, y, yaw]")
    negate = number("negate", 0.0)
    if negate not in (0.0, 1.0):
        raise FormatError(f"{negate:g}", source=p, field="negate", expected="0 or 1")
    occ_t = number("occupied_thresh", OCCUPIED_THRESH)
    free_t = number("free_thresh", FREE_THRESH)
    if not 0.0 <= free_t < occ_t <= 1.0:
        raise FormatError(
            f"free_thresh {free_t:g}, occupied_thresh {occ_t:g}",
            source=p,
            field="occupied_thresh",
            expected="0 <= free_thresh < occupied_thresh <= 1",
        )
    mode = str(meta.get("mode", "trinary"))
    if mode not in ("trinary", "scale", "raw"):
        raise FormatError(f"{mode!r}", source=p, field="mode", expected="trinary, scale or raw")
    img_path = Path(meta["image"])
    if not img_path.is_absolute():
        img_path = p.parent / img_path
    img = read_image(img_path)
    if img.ndim == 3:  # map_server averages the colour channels (alpha ignored)
        img = img[..., :3].mean(axis=2)
    img = img.astype(np.float64)
    if mode == "raw":
        occ = np.where(img > 100, -1, img).astype(np.int8)
    else:
        prob = img / 255.0 if negate else (255.0 - img) / 255.0
        occ = np.full(img.shape, -1, dtype=np.int8)
        occ[prob > occ_t] = 100
        occ[prob < free_t] = 0
        if mode == "scale":
            mid = (prob >= free_t) & (prob <= occ_t)
            occ[mid] = np.round(99.0 * (prob[mid] - free_t) / (occ_t - free_t)).astype(np.int8)
    return OccupancyGrid(occ[::-1].copy(), res, np.array([ox, oy]), oyaw)


# --------------------------------------------------------------------------- GeoJSON
_GEOMETRY_DEPTH = {
    "Point": 1,
    "MultiPoint": 2,
    "LineString": 2,
    "MultiLineString": 3,
    "Polygon": 3,
    "MultiPolygon": 4,
}


def point_geometry(xy: ArrayLike) -> dict[str, Any]:
    """A GeoJSON Point from ``(2,)`` or ``(3,)`` coordinates."""
    return {"type": "Point", "coordinates": np.asarray(xy, dtype=np.float64).tolist()}


def line_geometry(xy: ArrayLike) -> dict[str, Any]:
    """A GeoJSON LineString from ``(N, 2)`` vertices (N >= 2)."""
    return {"type": "LineString", "coordinates": np.asarray(xy, dtype=np.float64).tolist()}


def polygon_geometry(exterior: ArrayLike, holes: Iterable[ArrayLike] = ()) -> dict[str, Any]:
    """A GeoJSON Polygon from ``(N, 2)`` vertices: rings closed, exterior CCW, holes CW (RFC 7946)."""

    def ring(xy: ArrayLike, ccw: bool) -> list[list[float]]:
        r = np.asarray(xy, dtype=np.float64)
        if r.ndim != 2 or r.shape[1] != 2 or len(r) < 3:
            raise InputError(
                f"ring has shape {r.shape}", field="polygon", expected="(N >= 3, 2) vertices"
            )
        if np.array_equal(r[0], r[-1]):
            r = r[:-1]
        area2 = np.sum(r[:, 0] * np.roll(r[:, 1], -1) - np.roll(r[:, 0], -1) * r[:, 1])
        if (area2 > 0) != ccw:
            r = r[::-1]
        return np.vstack([r, r[:1]]).tolist()

    return {
        "type": "Polygon",
        "coordinates": [ring(exterior, True)] + [ring(h, False) for h in holes],
    }


def _check_positions(coords: Any, depth: int, where: str) -> None:
    if depth == 1:
        if not (
            isinstance(coords, list)
            and len(coords) in (2, 3)
            and all(isinstance(v, (int, float)) and math.isfinite(v) for v in coords)
        ):
            raise InputError(
                f"bad position {str(coords)[:60]}", field=where, expected="2 or 3 finite numbers"
            )
        return
    if not isinstance(coords, list):
        raise InputError(f"coordinates {str(coords)[:60]}", field=where, expected="a list")
    for k, c in enumerate(coords):
        _check_positions(c, depth - 1, f"{where}[{k}]")


def _check_geometry(geom: Any, where: str) -> None:
    if geom is None:
        return
    if not isinstance(geom, Mapping) or "type" not in geom:
        raise InputError(
            f"geometry {str(geom)[:60]}",
            field=where,
            expected="a GeoJSON geometry object with 'type'",
        )
    kind = geom["type"]
    if kind == "GeometryCollection":
        for k, g in enumerate(geom.get("geometries", [])):
            _check_geometry(g, f"{where}.geometries[{k}]")
        return
    if kind not in _GEOMETRY_DEPTH:
        raise InputError(
            f"geometry type {kind!r}",
            field=where,
            expected=", ".join(_GEOMETRY_DEPTH) + " or GeometryCollection",
        )
    coords: Any = geom.get("coordinates")
    _check_positions(coords, _GEOMETRY_DEPTH[kind], f"{where}.coordinates")
    if kind == "LineString" and len(coords) < 2:
        raise InputError("LineString with < 2 positions", field=where, expected=">= 2 positions")
    rings: list[tuple[str, Any]] = []
    if kind == "Polygon":
        rings = [(f"{where}.coordinates[{i}]", r) for i, r in enumerate(coords)]
    elif kind == "MultiPolygon":
        rings = [
            (f"{where}.coordinates[{j}][{i}]", r)
            for j, poly in enumerate(coords)
            for i, r in enumerate(poly)
        ]
    for name, r in rings:
        if len(r) < 4:
            raise InputError(
                f"ring has {len(r)} positions",
                field=name,
                expected="a closed ring of >= 4 positions",
            )
        if r[0] != r[-1]:
            raise InputError(
                f"ring is not closed: first {r[0]} != last {r[-1]}",
                field=name,
                expected="a closed ring (last position == first)",
            )


def write_geojson(
    path: PathLike,
    features: Iterable[Mapping[str, Any] | tuple[Mapping[str, Any], Mapping[str, Any] | None]],
    *,
    properties: Mapping[str, Any] | None = None,
    origin: GeoOrigin | None = None,
    decimals: int = 8,
) -> None:
    """Write a GeoJSON FeatureCollection atomically (compact: no indentation).

    Parameters
    ----------
    path : str or path
        Output ``.geojson`` file.
    features : iterable
        Each a Feature dict (``{"type": "Feature", "geometry": ..., "properties": ...}``), a bare
        geometry dict, or a ``(geometry, properties)`` pair. NumPy values are converted.
    properties : dict, optional
        Extra members of the collection's ``properties`` (e.g. the frame name).
    origin : GeoOrigin, optional
        Georeference: positions are local metres and are written as WGS84 ``[lon, lat]``
        (:func:`local_to_wgs84`), as RFC 7946 requires. Without it they are written as they
        are (local metres, flagged in the collection's ``properties``: not RFC 7946).
    decimals : int
        Decimals of the written longitudes / latitudes (8: about 1 mm).

    Raises
    ------
    InputError
        A geometry of unknown type, non-finite or malformed coordinates, an open polygon ring;
        the message names the feature index (``features[3].geometry.coordinates[0]``).
    """
    out = []
    for k, item in enumerate(features):
        if isinstance(item, tuple):
            if len(item) != 2:
                raise InputError(
                    f"tuple of {len(item)}",
                    source=path,
                    field=f"features[{k}]",
                    expected="(geometry, properties)",
                )
            geom, props = item
            feat: dict[str, Any] = {"type": "Feature", "geometry": geom, "properties": props or {}}
        elif isinstance(item, Mapping) and item.get("type") == "Feature":
            feat = {
                "type": "Feature",
                "geometry": item.get("geometry"),
                "properties": item.get("properties") or {},
            }
            if "id" in item:
                feat["id"] = item["id"]
        elif isinstance(item, Mapping):
            feat = {"type": "Feature", "geometry": item, "properties": {}}
        else:
            raise InputError(
                f"{type(item).__name__}",
                source=path,
                field=f"features[{k}]",
                expected="a Feature dict, a geometry dict or (geometry, properties)",
            )
        feat = to_jsonable(feat)
        try:
            _check_geometry(feat["geometry"], f"features[{k}].geometry")
        except InputError as exc:
            raise InputError(
                exc.message, source=path, field=exc.field, expected=exc.expected
            ) from None
        if origin is not None:
            feat["geometry"] = _georeference(feat["geometry"], origin, decimals)
        out.append(feat)
    if origin is None:
        frame: dict[str, Any] = {
            "coordinates": "local metres in the map frame (x east/forward, y north/left), "
            "not WGS84: not RFC 7946 GeoJSON"
        }
    else:
        frame = {
            "coordinates": "WGS84 longitude, latitude (deg), RFC 7946",
            "origin": {
                "lat_deg": origin.lat_deg,
                "lon_deg": origin.lon_deg,
                "heading_deg": origin.heading_deg,
            },
        }
    coll = {
        "type": "FeatureCollection",
        "properties": {**frame, **to_jsonable(dict(properties or {}))},
        "features": out,
    }
    text = json.dumps(coll, separators=(",", ":"), allow_nan=False)  # C encoder; dump() is not
    with atomic_write(path) as fh:
        fh.write(text + "\n")
