"""Obstacle writers and georeferencing: obstacles.json keeps the detection to 1 mm, NaN as null;
local metres -> WGS84 exactly (against the ellipsoid's radii of curvature)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from navkit.errors import InputError
from navkit.io.maps import WGS84_A, WGS84_F, GeoOrigin, local_to_wgs84, parse_origin, write_geojson
from navkit.io.obstacles import _rounded, write_obstacles_json


def test_obstacles_json_keeps_the_detection_to_a_millimetre(tmp_path):
    from navkit.experiments.obstacles import run_experiment

    det = run_experiment("four", "tilting", 0.01, 0).detection
    write_obstacles_json(tmp_path / "o.json", det, source="four.npz", extra={"h": np.float32(1.5)})
    data = json.loads((tmp_path / "o.json").read_text())
    assert data["input"] == "four.npz" and data["h"] == 1.5 and len(data["obstacles"]) == 4
    for ob, written in zip(det.obstacles, data["obstacles"], strict=True):
        poly = np.array(written["boundary_polygon"])
        assert np.abs(poly - ob.polygon_xy).max() <= 5e-4 + 1e-12
        assert written["height"] == pytest.approx(ob.height, abs=5e-4)
        for name, shape in ob.shapes.items():
            for key, v in shape.params().items():
                w = written["shapes"][name][key]
                if isinstance(v, str):
                    assert w == v
                else:
                    assert np.allclose(w, v, atol=5e-4), (name, key)
    assert _rounded({"a": [float("nan"), 1.23456], "b": np.array([[np.inf, 2.0]])}, 2) == {
        "a": [None, 1.23],
        "b": [[None, 2.0]],
    }


def _radii(lat_deg):
    e2 = WGS84_F * (2 - WGS84_F)
    s2 = math.sin(math.radians(lat_deg)) ** 2
    meridian = WGS84_A * (1 - e2) / (1 - e2 * s2) ** 1.5
    normal = WGS84_A / math.sqrt(1 - e2 * s2)
    return meridian, normal


@pytest.mark.parametrize("lat", [0.0, 45.0, 60.0, -33.9])
def test_local_metres_to_wgs84(lat):
    M, N = _radii(lat)
    # heading 0: x north, y west; heading 90: x east
    ll = local_to_wgs84([[100.0, 0.0], [0.0, -100.0], [0.0, 0.0]], GeoOrigin(lat, 10.0, 0.0))
    assert ll[2] == pytest.approx([10.0, lat], abs=1e-12)
    assert math.radians(ll[0, 1] - lat) * M == pytest.approx(100.0, abs=1e-3)
    assert ll[0, 0] == pytest.approx(10.0, abs=1e-12)
    east = math.radians(ll[1, 0] - 10.0) * N * math.cos(math.radians(lat))
    assert east == pytest.approx(100.0, abs=1e-3)
    turned = local_to_wgs84([[100.0, 0.0]], GeoOrigin(lat, 10.0, 90.0))
    assert turned[0] == pytest.approx(ll[1], abs=1e-12)


def test_geojson_is_wgs84_only_with_an_origin(tmp_path):
    square = {"type": "Polygon", "coordinates": [[[0, 0], [10, 0], [10, 10], [0, 10], [0, 0]]]}
    write_geojson(tmp_path / "g.geojson", [square], origin=parse_origin("48.0, 11.0, 90"))
    gj = json.loads((tmp_path / "g.geojson").read_text())
    ring = np.array(gj["features"][0]["geometry"]["coordinates"][0])
    assert gj["properties"]["coordinates"].startswith("WGS84")
    assert np.all(ring[:, 0] >= 11.0) and np.all(ring[:, 1] >= 48.0)  # x east, y north
    assert ring[2, 0] - 11.0 == pytest.approx(
        10 / (_radii(48.0)[1] * math.cos(math.radians(48))) * 180 / math.pi, abs=1e-8
    )
    write_geojson(tmp_path / "l.geojson", [square])
    assert (
        "not RFC 7946"
        in json.loads((tmp_path / "l.geojson").read_text())["properties"]["coordinates"]
    )
    for bad in ("48.0", "91,0", "a,b", "1,2,3,4"):
        with pytest.raises(InputError, match="origin"):
            parse_origin(bad)
