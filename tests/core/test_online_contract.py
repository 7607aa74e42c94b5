"""The online objects' contract (docs/architecture.md, "Online objects"; navkit.results): one verb
``update``, typed results and failures, the former verbs as deprecated aliases that still
answer the same, and a table in the docs that names what the code has."""

import re
from pathlib import Path

import numpy as np
import pytest

from navkit.localization import LocalizationFailure, Localizer
from navkit.localization.localizer import Fix
from navkit.obstacles import MapUpdate, ObstacleMapper
from navkit.path import (
    OnlineApproximator,
    PathUpdate,
    Return,
    ReturnFailure,
    ReturnStep,
    Skipped,
    WayAhead,
    WayBlocked,
    approximate,
)
from navkit.planes import FrameMotion, MotionEstimate, MotionFailure, PlaneOdometry
from navkit.results import Failure, Result

ROOT = Path(__file__).resolve().parents[2]
OBJECTS = {
    "planes.PlaneOdometry": PlaneOdometry,
    "localization.Localizer": Localizer,
    "path.OnlineApproximator": OnlineApproximator,
    "path.Return": Return,
    "obstacles.ObstacleMapper": ObstacleMapper,
}


@pytest.mark.parametrize(
    "cls", [FrameMotion, MotionEstimate, Fix, PathUpdate, ReturnStep, WayAhead, MapUpdate]
)
def test_results_are_results(cls):
    assert issubclass(cls, Result) and not issubclass(cls, Failure) and cls.ok


@pytest.mark.parametrize(
    "cls", [MotionFailure, LocalizationFailure, Skipped, ReturnFailure, WayBlocked]
)
def test_failures_name_a_reason_and_the_free_dof(cls):
    assert issubclass(cls, Failure) and not cls.ok
    fields = cls.__dataclass_fields__
    assert "reason" in fields and "free_dof" in fields


def test_the_architecture_table_names_the_code():
    """Every object the table says is on the contract has ``update``; every verb in its column
    exists on the object."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    table = text[text.index("## Online objects") :].split("\n## ")[0]
    rows = [r for r in table.splitlines() if r.startswith("| `") and "update(" in r]
    named = {re.match(r"\| `([\w.]+)`", r).group(1) for r in rows}
    assert named == set(OBJECTS)
    for name, cls in OBJECTS.items():
        assert callable(cls.update), name


def test_approximator_update_and_its_deprecated_alias():
    rec = OnlineApproximator()
    got = [rec.update(p) for p in ([0.0, 0.0], [np.nan, 1.0], [0.0, 0.0], [1.0, 0.0])]
    assert [type(r) for r in got] == [PathUpdate, Skipped, Skipped, PathUpdate]
    assert [r.index for r in got] == [0, 1, 2, 3]
    assert (got[1].reason, got[2].reason) == ("not finite", "repeat")
    assert got[1].free_dof == () and not got[1].ok
    with pytest.warns(DeprecationWarning, match="OnlineApproximator.add"):
        assert rec.add([2.0, 0.0]) is True
    with pytest.warns(DeprecationWarning):
        assert rec.add([2.0, 0.0]) is False  # a repeat, as before
    assert rec.n_input == 6 and rec.n_repeated == 2 and rec.n_nonfinite == 1


def test_approximator_reports_the_segments_a_point_freezes():
    """A right-angle corner cannot be one cubic within 1 cm: the points after it freeze the
    segment before it; the frozen count adds up to the result's segments."""
    pts = np.r_[
        np.c_[np.linspace(0, 2, 21), np.zeros(21)], np.c_[np.full(20, 2.0), np.linspace(0.1, 2, 20)]
    ]
    rec = OnlineApproximator()
    got = [rec.update(p) for p in pts]
    assert all(isinstance(r, PathUpdate) for r in got)
    frozen = sum(r.frozen for r in got)
    assert frozen >= 1 and got[-1].segments == frozen
    assert rec.finish().spline.n_segments >= frozen


class _Map:
    """An obstacle map blocking everything (no way round)."""

    resolution = 0.1
    origin = np.zeros(2)

    def blocked(self, path_xy, half_width):
        return np.ones(len(path_xy), dtype=bool)

    def planning_grid(self):
        return np.ones((20, 20), dtype=bool)


def test_return_update_and_its_deprecated_aliases():
    path = approximate(np.c_[np.linspace(0, 3, 31), np.zeros(31)]).spline
    ret = Return(path)
    pose = np.array([3.0, 0.0, np.pi])
    assert isinstance(ret.update(pose, 0.0), ReturnStep)
    way = ret.update(pose, 0.0, _Map())
    assert isinstance(way, WayBlocked) and way.reason and way.free_dof == ()
    with pytest.warns(DeprecationWarning, match="Return.observe"):
        assert Return(path).observe(pose, 0.0, _Map()) == "blocked"
    with pytest.warns(DeprecationWarning, match="Return.step"):
        assert isinstance(Return(path).step(pose, 0.0), ReturnStep)


def test_localizer_update_and_its_deprecated_alias():
    t = np.linspace(0, 4, 81)
    room = np.r_[
        np.c_[t, 0 * t], np.c_[t, 0 * t + 3], np.c_[0 * t, 0.75 * t], np.c_[0 * t + 4, 0.75 * t]
    ]
    few = np.full((5, 2), np.nan)  # no valid point: a failure naming what is free
    r = Localizer.from_points(room).update(few)
    assert isinstance(r, LocalizationFailure) and r.reason == "too few points"
    assert set(r.free_dof) == {"x", "y", "theta"}
    with pytest.warns(DeprecationWarning, match="Localizer.register"):
        r2 = Localizer.from_points(room).register(few)
    assert isinstance(r2, LocalizationFailure) and r2.reason == r.reason


def test_plane_odometry_register_frame_is_a_deprecated_alias(monkeypatch):
    seen = []
    monkeypatch.setattr(
        PlaneOdometry, "update", lambda self, obs, prior=None: seen.append((obs, prior)) or "r"
    )
    with pytest.warns(DeprecationWarning, match="PlaneOdometry.register_frame"):
        assert PlaneOdometry().register_frame("obs", "prior") == "r"
    assert seen == [("obs", "prior")]


def test_obstacle_mapper_update_and_its_deprecated_alias():
    """The mapper's update counts the scan's distinct cells inside the mapped area; the
    deprecated verb warns and fuses the same."""
    from navkit.obstacles import detect_obstacles
    from navkit.sim import Box, Ground, Scene, SpinningLidar, render_scan

    T = np.eye(4)
    T[2, 3] = 1.0
    det = detect_obstacles(
        render_scan(Scene([Ground(), Box((4, 0, 0.5), (1, 1, 1))]), SpinningLidar(16, 360), T).scan
    )
    a, b = ObstacleMapper([-10, -10], [10, 10]), ObstacleMapper([-10, -10], [10, 10])
    r = a.update(det, T)
    assert isinstance(r, MapUpdate) and r.ok and r.scan == 0
    assert 0 < r.obstacle_cells <= r.seen_cells == int((a.seen > 0).sum())
    assert r.obstacle_cells == int((a.hits > 0).sum())
    with pytest.warns(DeprecationWarning, match="ObstacleMapper.update"):
        b.add_scan(det, T)
    assert np.array_equal(a.hits, b.hits) and np.array_equal(a.seen, b.seen)
