"""path.Return, the online object of the way back: home along the stored path, round a box on the
obstacle map, or a ReturnFailure naming why when a wall closes the way."""

from __future__ import annotations

import numpy as np

from navkit.obstacles import ObstacleMapper, ObstacleMapperSettings
from navkit.path import Return, ReturnFailure, ReturnStep, ReturnTripSettings, approximate
from navkit.path.control import PathFollowerSettings
from navkit.sim.unicycle import unicycle_step

DT = 0.1


def stored_path():
    """Recorded from the operator at x = 0 out to x = 10."""
    return approximate(np.c_[np.linspace(0.0, 10.0, 201), np.zeros(201)]).spline


def mapper_with(points):
    m = ObstacleMapper((-3, -5), (13, 5), ObstacleMapperSettings(0.1, min_hits=1, min_ratio=0.0))
    m.add_points(points, points)
    return m


def drive(ret, mapper, pose, t_max=80.0):
    """Closed loop on the true pose (no estimation error): the map is checked every 0.5 s."""
    t, got, poses = 0.0, None, [pose]
    while t < t_max:
        got = ret.update(pose, t)
        if isinstance(got, ReturnFailure) or got.home:
            break
        pose = unicycle_step(pose, got.v, got.omega, DT)
        poses.append(pose)
        t += DT
        if round(t / DT) % 5 == 0:
            ret.update(pose, t, mapper)
    return got, np.array(poses)


def settings(detour=True):
    ctrl = PathFollowerSettings(delta=0.8, v_max=0.6, stop_radius=0.25, approach_radius=0.5)
    return ReturnTripSettings(controller=ctrl, half_width=0.3, detour=detour, wait=2.0)


def test_return_goes_round_a_box_and_reaches_home():
    xx, yy = np.meshgrid(np.arange(4.6, 5.41, 0.05), np.arange(-0.4, 0.41, 0.05))
    box = np.c_[xx.ravel(), yy.ravel()]
    mapper = mapper_with(box)
    ret = Return(stored_path(), settings())
    got, poses = drive(ret, mapper, np.array([10.0, 0.0, np.pi]))
    assert isinstance(got, ReturnStep) and got.home
    assert np.hypot(*poses[-1, :2]) <= 0.25 + 0.6 * DT  # stop radius + one step
    assert len(ret.detours) >= 1 and ret.detours[0]["completed_time"] is not None
    # the robot's centre kept the half-width from every box point
    d = np.hypot(*(poses[:, None, :2] - box[None]).transpose(2, 0, 1)).min(axis=1)
    assert d.min() >= 0.3


def test_a_wall_across_the_way_is_a_failure_naming_why():
    wall = np.c_[np.full(200, 5.0), np.linspace(-5.0, 5.0, 200)]
    for detour in (True, False):
        ret = Return(stored_path(), settings(detour))
        got, poses = drive(ret, mapper_with(wall), np.array([10.0, 0.0, np.pi]))
        assert isinstance(got, ReturnFailure) and got.reason == "blocked"
        assert got.detail.startswith("no detour") if detour else got.detail == "detours disabled"
        assert poses[:, 0].min() > 5.0 + 0.3  # stopped in front of it
        assert ret.blocked is not None and ret.blocked["active"]
