"""Occupancy grids (ROS map_server) and GeoJSON."""

from __future__ import annotations

import json

import numpy as np
import pytest

from navkit.errors import InputError
from navkit.io.images import read_image
from navkit.io.maps import (
    line_geometry,
    point_geometry,
    polygon_geometry,
    read_occupancy_grid,
    write_geojson,
    write_occupancy_grid,
)


def test_occupancy_roundtrip_and_ros_convention(tmp_path, rng):
    occ = rng.choice(np.array([-1, 0, 100], dtype=np.int8), size=(20, 30))
    occ[-1, :] = 100  # the highest-y row is a wall
    occ[0, :] = 0  # the lowest-y row is free
    pgm, yaml = write_occupancy_grid(tmp_path / "map", occ, 0.05, (-1.5, 2.0))
    assert pgm.name == "map.pgm" and yaml.name == "map.yaml"
    grid = read_occupancy_grid(yaml)
    np.testing.assert_array_equal(grid.occupancy, occ)
    assert grid.resolution == 0.05
    np.testing.assert_array_equal(grid.origin_xy, [-1.5, 2.0])
    # the file: P5, image row 0 = highest y (the wall, pixel 0), last row free (254)
    img = read_image(pgm)
    assert pgm.read_bytes().startswith(b"P5")
    assert img.shape == (20, 30)
    assert np.all(img[0] == 0) and np.all(img[-1] == 254)
    assert set(np.unique(img).tolist()) <= {0, 205, 254}
    text = yaml.read_text()
    for line in (
        "image: map.pgm",
        "resolution: 0.05",
        "origin: [-1.5, 2.0, 0.0]",
        "negate: 0",
        "occupied_thresh: 0.65",
        "free_thresh: 0.196",
    ):
        assert line in text
    x, y = grid.cell_centers()
    assert x[0] == pytest.approx(-1.475) and y[-1] == pytest.approx(2.0 + 19.5 * 0.05)


def test_occupancy_percentages_thresholded(tmp_path):
    occ = np.array([[0, 19, 20, 50, 65, 66, 100, -1]], dtype=np.int8)
    _, yaml = write_occupancy_grid(tmp_path / "p", occ, 0.1)
    # p < 0.196 free, p > 0.65 occupied, else unknown (map_server's trinary rule)
    np.testing.assert_array_equal(
        read_occupancy_grid(yaml).occupancy, [[0, 0, -1, -1, -1, 100, 100, -1]]
    )


def test_occupancy_reads_negated_map(tmp_path):
    # a hand-written map_server map with negate: 1 (white = occupied)
    img = np.array([[255, 0], [205, 0]], dtype=np.uint8)
    (tmp_path / "n.pgm").write_bytes(b"P5\n2 2\n255\n" + img.tobytes())
    (tmp_path / "n.yaml").write_text(
        "image: n.pgm\nresolution: 0.5\norigin: [0.0, 0.0, 0.0]\nnegate: 1\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    grid = read_occupancy_grid(tmp_path / "n.yaml")
    # flipped: file row 1 (205 -> p 0.80 occupied with negate) is grid row 0
    np.testing.assert_array_equal(grid.occupancy, [[100, 0], [100, 0]])


def test_occupancy_bad_input(tmp_path):
    with pytest.raises(InputError, match=r"occupancy.*cell \(0, 1\) holds 101"):
        write_occupancy_grid(tmp_path / "m", np.array([[0, 101]]), 0.1)
    with pytest.raises(InputError, match="resolution"):
        write_occupancy_grid(tmp_path / "m", np.zeros((2, 2), np.int8), 0.0)
    assert not (tmp_path / "m.pgm").exists()
    (tmp_path / "bad.yaml").write_text("image: x.pgm\norigin: [0, 0, 0]\n")
    with pytest.raises(InputError, match=r"bad\.yaml.*'resolution'"):
        read_occupancy_grid(tmp_path / "bad.yaml")


def test_geojson(tmp_path):
    square = np.array([[0, 0], [0, 1], [1, 1], [1, 0]], dtype=float)  # clockwise
    feats = [
        (polygon_geometry(square), {"kind": "obstacle", "height_m": np.float64(0.5)}),
        {
            "type": "Feature",
            "geometry": line_geometry([[0, 0], [2, 0]]),
            "properties": {"kind": "wall"},
            "id": 7,
        },
        point_geometry([3.0, 4.0]),
    ]
    write_geojson(tmp_path / "m.geojson", feats, properties={"frame": "map"})
    data = json.loads((tmp_path / "m.geojson").read_text())
    assert data["type"] == "FeatureCollection" and data["properties"]["frame"] == "map"
    ring = np.array(data["features"][0]["geometry"]["coordinates"][0])
    assert np.array_equal(ring[0], ring[-1]) and len(ring) == 5
    # exterior ring made counter-clockwise (RFC 7946): positive shoelace area
    area = 0.5 * np.sum(ring[:-1, 0] * ring[1:, 1] - ring[1:, 0] * ring[:-1, 1])
    assert area == pytest.approx(1.0)
    assert data["features"][0]["properties"]["height_m"] == 0.5
    assert data["features"][1]["id"] == 7
    assert data["features"][2]["geometry"] == {"type": "Point", "coordinates": [3.0, 4.0]}


def test_geojson_open_ring_and_bad_coordinates(tmp_path):
    open_ring = {"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 1]]]}
    with pytest.raises(
        InputError, match=r"g\.geojson.*features\[1\]\.geometry\.coordinates\[0\].*not closed"
    ):
        write_geojson(tmp_path / "g.geojson", [point_geometry([0, 0]), open_ring])
    nan_point = {"type": "Point", "coordinates": [0.0, float("nan")]}
    with pytest.raises(InputError, match=r"features\[0\]"):
        write_geojson(tmp_path / "g.geojson", [nan_point])
    with pytest.raises(InputError, match="geometry type 'Circle'"):
        write_geojson(tmp_path / "g.geojson", [{"type": "Circle", "coordinates": [0, 0]}])
    assert not (tmp_path / "g.geojson").exists()
