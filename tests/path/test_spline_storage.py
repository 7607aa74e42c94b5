"""PathSpline evaluation and search, and the path.json format."""

from __future__ import annotations

import json

import numpy as np
import pytest

from navkit.errors import DataNotFoundError, FormatError
from navkit.io.pathjson import read_path_json, write_path_json
from navkit.path import ApproximatorSettings, PathSpline, approximate


@pytest.fixture
def wavy() -> PathSpline:
    t = np.linspace(0.0, 12.0, 1200)
    P = np.c_[t, np.sin(t) + 0.3 * np.sin(3.1 * t)]
    return approximate(P, ApproximatorSettings(tolerance=0.01), timed=False).spline


def test_evaluation_accepts_any_shape(wavy):
    s = np.linspace(0.0, wavy.total_length, 24).reshape(2, 3, 4)
    assert wavy.position(s).shape == (2, 3, 4, 2)
    assert wavy.heading(s).shape == (2, 3, 4)
    assert wavy.curvature(s).shape == (2, 3, 4)
    np.testing.assert_allclose(wavy.position(0.0), wavy.start)
    # positions are continuous at the knots (segments start where the previous one ends)
    k = wavy.s0[1:]
    np.testing.assert_allclose(wavy.position(k - 1e-9), wavy.position(k), atol=1e-6)


def test_nearest_matches_brute_force(wavy, rng):
    q = np.c_[rng.uniform(0, 12, 300), rng.uniform(-2, 2, 300)]
    s, d = wavy.nearest(q)
    _ss, xy = wavy.sample(0.0005)  # brute force: 0.5 mm samples, distance error <= 0.25 mm
    dd = np.hypot(xy[None, :, 0] - q[:, None, 0], xy[None, :, 1] - q[:, None, 1]).min(1)
    assert np.all(d <= dd + 1e-9)  # never worse than the dense samples
    np.testing.assert_allclose(d, dd, atol=3e-4)
    np.testing.assert_allclose(np.hypot(*(wavy.position(s) - q).T), d, atol=1e-12)


def test_nearest_in_window(wavy):
    p = wavy.position(6.0) + np.array([0.0, 0.05])
    s, _ = wavy.nearest(p[None, :], s_min=np.array([0.0]), s_max=np.array([3.0]))
    assert 0.0 <= s[0] <= 3.0


def test_path_json_round_trip(tmp_path, wavy):
    f = write_path_json(
        tmp_path / "path.json",
        PathSpline.from_segments(
            wavy.length, wavy.ax, wavy.ay, tolerance=0.01, frame={"kind": "plane", "method": "xy"}
        ),
    )
    data = json.loads(f.read_text())
    assert set(data) >= {"tolerance", "length", "segments", "frame"}
    assert set(data["segments"][0]) == {"s0", "length", "x", "y"}
    back = read_path_json(f)
    np.testing.assert_array_equal(back.ax, wavy.ax)
    np.testing.assert_array_equal(back.length, wavy.length)
    assert back.tolerance == 0.01 and back.frame["method"] == "xy"
    # the documented formula reproduces the curve: x(s) = a0 + a1 u + a2 u^2 + a3 u^3, u = s - s0
    seg = data["segments"][2]
    u = 0.3 * seg["length"]
    x = sum(a * u**i for i, a in enumerate(seg["x"]))
    y = sum(b * u**i for i, b in enumerate(seg["y"]))
    np.testing.assert_allclose(wavy.position(seg["s0"] + u), [x, y], atol=1e-12)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("not json", "not valid JSON"),
        ("[1, 2]", "top level"),
        ('{"segments": 3}', "segments"),
        ('{"segments": [{"s0": 0, "length": 1, "x": [0, 1, 0], "y": [0, 0, 0, 0]}]}', "4 numbers"),
        (
            '{"segments": [{"s0": 0, "length": -1, "x": [0, 1, 0, 0], "y": [0, 0, 0, 0]}]}',
            "negative",
        ),
        ('{"segments": [{"s0": 0, "x": [0, 1, 0, 0], "y": [0, 0, 0, 0]}]}', "missing key"),
        (
            '{"segments": [{"s0": 0, "length": 1, "x": ["a", 1, 0, 0], "y": [0, 0, 0, 0]}]}',
            "non-numeric",
        ),
        (
            '{"segments": [{"s0": 0, "length": 1, "x": [0, 1, 0, 0], "y": [0, 0, 0, 0]},'
            ' {"s0": 5, "length": 1, "x": [1, 1, 0, 0], "y": [0, 0, 0, 0]}]}',
            "running sum",
        ),
    ],
)
def test_bad_path_json_names_the_field(tmp_path, text, match):
    f = tmp_path / "bad.json"
    f.write_text(text)
    with pytest.raises(FormatError, match=match) as info:
        read_path_json(f)
    assert str(f) in str(info.value)


def test_missing_path_json(tmp_path):
    with pytest.raises(DataNotFoundError):
        read_path_json(tmp_path / "nope.json")


def test_failed_write_leaves_no_file(tmp_path, wavy, monkeypatch):
    import navkit.io.atomic as atomic

    def boom(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(atomic.json, "dump", boom)
    with pytest.raises(RuntimeError):
        write_path_json(tmp_path / "path.json", wavy)
    assert list(tmp_path.iterdir()) == []
