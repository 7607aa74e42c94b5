"""Map building: merging views, corners, outline, grid, JSON - against the known floor plan."""

from __future__ import annotations

import json

import numpy as np
import pytest

from navkit.errors import FormatError
from navkit.geometry import polygon_area
from navkit.localization import (
    MapSettings,
    WallMap,
    build_map,
    build_map_from_scans,
    evaluate_map,
    rasterize,
)
from tests.localization.helpers import LSHAPE, LSHAPE_POLY, RECT, cast, scan_points


def _views(segments, poses, rng, noise=0.01):
    return [scan_points(segments, p, n=720, noise=noise, rng=rng) for p in poses]


def test_map_of_an_l_shaped_room_from_several_views(rng):
    poses = np.array([[2.5, 2.0, 0.0], [7.5, 2.0, 1.0], [2.5, 6.0, -2.0]])
    m = build_map(_views(LSHAPE, poses, rng), poses, ordered=True)
    acc = evaluate_map(m, LSHAPE, LSHAPE_POLY)
    # every wall seen from >= 1 view, merged: exactly the 6 true walls
    assert acc["walls_found"] == 6 and len(m.walls) == 6
    # 1 cm noise, >= 100 points per wall: angle error ~ 0.01/sqrt(n L^2 / 12) < 0.05 deg;
    # corner error ~ sigma_offset / sin(90) ~ 1 mm; allow 0.2 deg and 1 cm.
    assert acc["wall_angle_error_deg_max"] < 0.2
    assert acc["corners_found"] == 6
    assert acc["corner_error_m_max"] < 0.01
    assert m.outline is not None
    assert abs(polygon_area(m.outline)) == pytest.approx(abs(polygon_area(LSHAPE_POLY)), rel=0.01)
    # the reported corner uncertainty is of the same order as the measured error
    assert all(c.sigma < 0.01 for c in m.corners)


def test_the_same_wall_seen_twice_is_merged(rng):
    # two views of the same room: without merging there would be about 8 segments
    poses = np.array([[2.0, 2.0, 0.0], [6.0, 4.0, 2.0]])
    m = build_map(_views(RECT, poses, rng), poses, ordered=True)
    assert len(m.walls) == 4
    assert sum(w.count for w in m.walls) > 1000  # pooled support from both views


def test_doorway_is_crossed_by_the_outline(rng):
    door = np.array(
        [
            [[0, 0], [8, 0]],
            [[8, 0], [8, 2.5]],
            [[8, 3.5], [8, 6]],
            [[8, 6], [0, 6]],
            [[0, 6], [0, 0]],
        ],
        float,
    )
    poses = np.array([[3.0, 3.0, 0.0], [5.0, 2.0, 1.5]])
    m = build_map(_views(door, poses, rng), poses, ordered=True)
    assert len(m.walls) == 5
    assert m.outline is not None and abs(polygon_area(m.outline)) == pytest.approx(48.0, rel=0.01)


def test_build_from_scans_traces_free_space(rng):
    poses = np.array([[2.0, 2.0, 0.0], [6.0, 4.0, 2.0]])
    b = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    ranges = np.stack([cast(RECT, p, b) for p in poses])
    m = build_map_from_scans(ranges, b, poses, MapSettings(resolution=0.1))
    g, o, r = m.occupancy, m.origin, m.resolution

    def cell(x, y):
        return g[int((y - o[1]) // r), int((x - o[0]) // r)]

    assert cell(4.0, 3.0) == 0  # the middle of the room was crossed by beams
    assert cell(4.0, 0.0) == 100 and cell(8.0, 3.0) == 100  # walls occupied
    assert cell(4.0, -0.7) == -1  # behind the wall: unknown


def test_json_round_trip_and_errors(rng, tmp_path):
    poses = np.array([[3.0, 3.0, 0.0]])
    m = build_map(_views(RECT, poses, rng), poses, ordered=True)
    text = json.dumps(m.to_dict())
    back = WallMap.from_dict(json.loads(text))
    assert len(back.walls) == len(m.walls)
    for a, b in zip(m.walls, back.walls, strict=True):
        np.testing.assert_allclose(a.start, b.start, atol=1e-12)
        np.testing.assert_allclose(a.normal, b.normal, atol=1e-12)
    with pytest.raises(FormatError, match="format"):
        WallMap.from_dict({"walls": []}, source="x.json")
    bad = m.to_dict()
    del bad["walls"][0]["scatter"]  # type: ignore[index]
    with pytest.raises(FormatError, match="walls"):
        WallMap.from_dict(bad, source="x.json")


def test_rasterize_marks_walls_and_inside():
    from navkit.localization import segment_from_points

    walls = [
        segment_from_points(np.stack([np.linspace(s[0], e[0], 50), np.linspace(s[1], e[1], 50)], 1))
        for s, e in RECT
    ]
    g, _ = rasterize(walls, 0.1, free_polygon=RECT[:, 0])
    assert (g == 100).sum() >= 2 * (80 + 60) - 4  # every 0.1 m of the 28 m perimeter
    assert (g == 0).sum() == pytest.approx(80 * 60, rel=0.05)
