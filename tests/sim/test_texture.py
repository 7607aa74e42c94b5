"""Procedural textures: deterministic from the seed, patterns of the stated physical size."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.errors import ConfigError
from navkit.sim import Texture


@pytest.fixture
def st(rng):
    n = 200_000
    return rng.uniform(-50, 50, n), rng.uniform(-50, 50, n)


def _share(mask):
    p = mask.mean()
    return p, 5 * np.sqrt(p * (1 - p) / mask.size)  # 5 sigma of a binomial share


def test_bricks_mortar_share_and_brick_size(st):
    s, t = st
    tex = Texture("bricks", scale=0.25, color=(0.6, 0.3, 0.2), color2=(0.9, 0.9, 0.9))
    c = tex.evaluate(s, t)
    mortar = np.all(c == np.array(tex.color2), axis=1)
    # mortar strips 0.04 * scale wide along both axes of a scale x scale/3 brick:
    # share = 1 - (1 - 0.04) (1 - 0.12)
    p, tol = _share(mortar)
    assert abs(p - (1 - 0.96 * 0.88)) < tol
    # running bond: rows alternate by half a brick, so the vertical joints of row 0 and row 1
    # (t in [0.01, 0.08) and [0.0933, 0.16)) are half a brick apart
    xs = np.linspace(0, 1, 4001)
    row0 = np.all(tex.evaluate(xs, np.full_like(xs, 0.05)) == tex.color2, axis=1)
    row1 = np.all(tex.evaluate(xs, np.full_like(xs, 0.13)) == tex.color2, axis=1)
    starts0 = xs[1:][row0[1:] & ~row0[:-1]]
    starts1 = xs[1:][row1[1:] & ~row1[:-1]]
    np.testing.assert_allclose(np.diff(starts0), 0.25, atol=1e-3)
    np.testing.assert_allclose((starts1[0] - starts0[0]) % 0.25, 0.125, atol=1e-3)


def test_tiles_checker_solid(st):
    s, t = st
    tiles = Texture("tiles", scale=0.5, color2=(0.1, 0.1, 0.1)).evaluate(s, t)
    p, tol = _share(np.all(tiles == 0.1, axis=1))
    assert abs(p - (1 - 0.95**2)) < tol  # grout 0.05 * scale on two sides of each tile
    chk = Texture("checker", scale=0.3, color=(1, 1, 1), color2=(0, 0, 0)).evaluate(s, t)
    p, tol = _share(chk[:, 0] == 0)
    assert abs(p - 0.5) < tol
    solid = Texture("solid", color=(0.2, 0.4, 0.6)).evaluate(s[:10], t[:10])
    np.testing.assert_array_equal(solid, np.tile([0.2, 0.4, 0.6], (10, 1)))


def test_noise_is_deterministic_smooth_and_seeded(st):
    s, t = st
    a = Texture("noise", scale=1.0, seed=1).evaluate(s, t)
    b = Texture("noise", scale=1.0, seed=1).evaluate(s, t)
    c = Texture("noise", scale=1.0, seed=2).evaluate(s, t)
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).mean() > 0.02
    lo, hi = np.array(Texture().color2), np.array(Texture().color)
    assert np.all(a >= lo - 1e-12) and np.all(a <= hi + 1e-12)
    # value noise is continuous: 0.1 mm apart, colours differ by far less than across the range
    d = Texture("noise", scale=1.0, seed=1).evaluate(s + 1e-4, t)
    assert np.abs(d - a).max() < 0.01 * (hi - lo).max()


def test_bad_textures():
    with pytest.raises(ConfigError, match="kind"):
        Texture("marble")
    with pytest.raises(ConfigError, match="scale"):
        Texture("bricks", scale=0)
    with pytest.raises(ConfigError, match="color"):
        Texture("solid", color=(1.2, 0, 0))
