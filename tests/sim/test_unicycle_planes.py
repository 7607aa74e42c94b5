"""Unicycle integration and the scene's true planes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from navkit.errors import InputError
from navkit.sim import (
    Box,
    Cylinder,
    Ground,
    Prism,
    Scene,
    SpinningLidar,
    Wall,
    render_scan,
    simulate_unicycle,
)
from navkit.sim.unicycle import unicycle_step


def test_constant_turn_is_a_circle():
    v, w, dt, n = 1.0, 0.5, 0.1, 200
    poses = simulate_unicycle(np.full(n, v), np.full(n, w), dt, start=(1.0, 2.0, 0.3))
    assert poses.shape == (n + 1, 3)
    # centre of the circle of radius v / w to the left of the start heading
    c = np.array([1.0, 2.0]) + (v / w) * np.array([-np.sin(0.3), np.cos(0.3)])
    np.testing.assert_allclose(np.linalg.norm(poses[:, :2] - c, axis=1), v / w, atol=1e-12)
    np.testing.assert_allclose(poses[-1, 2], 0.3 + w * dt * n, atol=1e-12)


def test_matches_step_loop_and_ode_solution(rng):
    n, dt = 300, 0.1
    v = rng.uniform(0.0, 1.5, n)
    w = rng.uniform(-1.0, 1.0, n)
    w[::7] = 0.0  # straight segments: the sinc form must be exact there too
    poses = simulate_unicycle(v, w, dt)
    state = np.zeros(3)
    for k in range(n):
        state = unicycle_step(state, v[k], w[k], dt)
        np.testing.assert_allclose(state, poses[k + 1], atol=1e-9)

    # reference: adaptive ODE integration of the piecewise-constant inputs
    def f(t, s):
        k = min(int(t / dt), n - 1)
        return [v[k] * np.cos(s[2]), v[k] * np.sin(s[2]), w[k]]

    ref = solve_ivp(
        f,
        (0, n * dt),
        [0, 0, 0],
        t_eval=np.arange(n + 1) * dt,
        rtol=1e-10,
        atol=1e-10,
        max_step=dt / 4,
    )
    np.testing.assert_allclose(poses, ref.y.T, atol=1e-6)  # ODE solver tolerance ~1e-10/step
    # batched: a (2, 3) state advances both
    two = unicycle_step(np.zeros((2, 3)), np.array([1.0, 2.0]), np.array([0.0, 0.0]), 1.0)
    np.testing.assert_allclose(two[:, 0], [1.0, 2.0])
    with pytest.raises(InputError):
        simulate_unicycle([1.0, 2.0], [0.0], 0.1)


def test_true_planes_contain_the_hits_on_planar_primitives():
    scene = Scene(
        [
            Ground(name="ground"),
            Box((5.0, 1.0, 0.6), (1.0, 2.0, 1.2), yaw=0.3, name="box"),
            Prism((-4.0, 2.0, 0.5), (2.0, 1.5, 1.0), yaw=-0.7, name="ramp"),
            Wall((-8.0, -8.0, 0.0), (16.0, 0.0, 0.0), (0.0, 0.0, 3.0), name="wall"),
            Cylinder((2.0, -3.0, 0.0), 0.3, 1.0, name="post"),
        ]
    )
    planes = scene.true_planes()
    names = [n for n, _ in planes]
    assert "ground" in names and "wall" in names and "box:top" in names and "ramp:slope" in names
    assert "box:bottom" not in names  # resting on the ground: decision documented
    for _, p in planes:
        assert p.rho >= 0 and abs(np.linalg.norm(p.normal) - 1) < 1e-12
    sim = render_scan(
        scene,
        SpinningLidar(n_beams=32, n_columns=720),
        np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1.6], [0, 0, 0, 1.0]]),
    )
    pts, idx = sim.points_world, sim.hit_index
    for prim in ("ground", "box", "ramp", "wall"):
        P = pts[idx == scene.index_of(prim)]
        assert len(P) > 20, prim
        own = [p for n, p in planes if n == prim or n.startswith(prim + ":")]
        dist = np.min(np.abs(np.stack([p.distance(P) for p in own])), axis=0)
        np.testing.assert_allclose(dist, 0.0, atol=1e-9)
    # the cylinder's hits on its top lie on post:top; its side is not planar
    top = dict(planes)["post:top"]
    np.testing.assert_allclose(top.rho, 1.0)
