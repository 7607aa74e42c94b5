"""Procedural surface textures, deterministic from a seed.

Every texture is a function of a primitive's own 2D surface coordinates ``(s, t)`` in metres (for
a wall: along its ``u`` edge and up its ``v`` edge; for the ground: world ``x, y``), so a pattern
keeps its physical size wherever the primitive is placed and however it is seen. Colours are RGB
floats in ``[0, 1]``. Randomness comes from an integer hash of the lattice cell and the seed
(no global RNG state), so the same seed gives the same colours on any machine.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from navkit.errors import ConfigError

__all__ = ["TEXTURE_KINDS", "Texture", "hash_uniform"]

TEXTURE_KINDS = ("bricks", "tiles", "noise", "checker", "solid")

_M1 = np.uint64(0x9E3779B97F4A7C15)
_M2 = np.uint64(0xBF58476D1CE4E5B9)
_M3 = np.uint64(0x94D049BB133111EB)


def hash_uniform(
    i: NDArray[np.int64], j: NDArray[np.int64], seed: int, salt: int = 0
) -> NDArray[np.float64]:
    """Uniform floats in ``[0, 1)`` from integer lattice coordinates (splitmix64 finaliser).

    Parameters
    ----------
    i, j : int arrays (broadcastable)
        Lattice cell indices.
    seed, salt : int
        Texture seed and a per-use salt (different salts give independent streams).
    """
    with np.errstate(over="ignore"):
        h = (
            np.asarray(i, dtype=np.int64).astype(np.uint64) * _M1
            ^ np.asarray(j, dtype=np.int64).astype(np.uint64) * _M2
            ^ np.uint64((seed * 1000003 + salt * 7919) & 0xFFFFFFFFFFFFFFFF) * _M3
        )
        h ^= h >> np.uint64(30)
        h *= _M2
        h ^= h >> np.uint64(27)
        h *= _M3
        h ^= h >> np.uint64(31)
    return (h >> np.uint64(11)).astype(np.float64) / float(1 << 53)


def _value_noise(
    s: NDArray[np.float64], t: NDArray[np.float64], cell: float, seed: int, salt: int
) -> NDArray[np.float64]:
    """Smooth value noise in ``[0, 1]`` with lattice spacing ``cell`` metres (smoothstep blend)."""
    x, y = s / cell, t / cell
    i0, j0 = np.floor(x), np.floor(y)
    fx, fy = x - i0, y - j0
    i0, j0 = i0.astype(np.int64), j0.astype(np.int64)
    wx, wy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    v00 = hash_uniform(i0, j0, seed, salt)
    v10 = hash_uniform(i0 + 1, j0, seed, salt)
    v01 = hash_uniform(i0, j0 + 1, seed, salt)
    v11 = hash_uniform(i0 + 1, j0 + 1, seed, salt)
    return (v00 * (1 - wx) + v10 * wx) * (1 - wy) + (v01 * (1 - wx) + v11 * wx) * wy


def _as_rgb(name: str, value: object) -> tuple[float, float, float]:
    try:
        rgb = tuple(float(c) for c in value)  # type: ignore[attr-defined]
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"is {value!r}", field=name, expected="three floats in [0, 1]") from exc
    if len(rgb) != 3 or not all(0.0 <= c <= 1.0 for c in rgb):
        raise ConfigError(f"is {value!r}", field=name, expected="three floats in [0, 1]")
    return rgb  # type: ignore[return-value]


@dataclass(frozen=True)
class Texture:
    """A procedural texture evaluated in surface coordinates (metres).

    Attributes
    ----------
    kind : {"bricks", "tiles", "noise", "checker", "solid"}
        ``bricks``: running-bond courses of ``scale`` x ``scale/3`` bricks with mortar joints
        (each brick's shade drawn from the seed); ``tiles``: square tiles of side ``scale`` with
        grout lines, shade per tile; ``noise``: five octaves of value noise, coarsest cell
        ``scale``, finest ``scale / 81``; ``checker``: squares of side ``scale`` alternating ``color`` / ``color2``;
        ``solid``: ``color`` everywhere.
    scale : float
        Size of the pattern's unit, metres (brick length, tile side, noise cell, checker square).
    seed : int
        Seed of the per-cell random shades.
    color, color2 : (3,) floats in [0, 1]
        Main colour (bricks, tiles) and secondary colour (mortar / grout, second checker colour,
        the dark end of the noise).
    variation : float
        Relative shade variation between bricks / tiles (0 = uniform).
    """

    kind: str = "solid"
    scale: float = 0.25
    seed: int = 0
    color: tuple[float, float, float] = (0.6, 0.6, 0.6)
    color2: tuple[float, float, float] = (0.3, 0.3, 0.3)
    variation: float = 0.25

    def __post_init__(self) -> None:
        if self.kind not in TEXTURE_KINDS:
            raise ConfigError(
                f"unknown texture kind {self.kind!r}",
                field="kind",
                expected=" | ".join(TEXTURE_KINDS),
            )
        if not (np.isfinite(self.scale) and self.scale > 0):
            raise ConfigError(
                f"is {self.scale}", field="scale", expected="a positive size in metres"
            )
        if not (0.0 <= self.variation <= 1.0):
            raise ConfigError(
                f"is {self.variation}", field="variation", expected="a float in [0, 1]"
            )
        object.__setattr__(self, "scale", float(self.scale))
        object.__setattr__(self, "seed", int(self.seed))
        object.__setattr__(self, "color", _as_rgb("color", self.color))
        object.__setattr__(self, "color2", _as_rgb("color2", self.color2))

    def evaluate(self, s: NDArray[np.float64], t: NDArray[np.float64]) -> NDArray[np.float64]:
        """RGB colours ``(M, 3)`` in ``[0, 1]`` at surface coordinates ``s, t`` ``(M,)`` metres."""
        s = np.asarray(s, dtype=np.float64)
        t = np.asarray(t, dtype=np.float64)
        c1, c2 = np.asarray(self.color), np.asarray(self.color2)
        k = self.kind
        if k == "solid":
            return np.broadcast_to(c1, (*s.shape, 3)).copy()
        if k == "checker":
            parity = (np.floor(s / self.scale) + np.floor(t / self.scale)) % 2 == 1
            return np.where(parity[..., None], c2, c1)
        if k == "noise":
            # five octaves, cell scale / 3^i, amplitude 0.75^i (normalised): detail down to
            # scale / 81, so close-up views (stereo on the ground) still see texture
            v = np.zeros(s.shape)
            for i in range(5):
                v += 0.75**i * _value_noise(s, t, self.scale / 3.0**i, self.seed, 1 + i)
            v /= sum(0.75**i for i in range(5))
            return c2 + (c1 - c2) * v[..., None]
        if k == "bricks":
            length, height = self.scale, self.scale / 3.0
            mortar = 0.04 * self.scale
            row = np.floor(t / height)
            offset = 0.5 * length * (row % 2)
            col = np.floor((s + offset) / length)
            fs = (s + offset) - col * length
            ft = t - row * height
            joint = (fs < mortar) | (ft < mortar)
            shade = (
                1.0
                + self.variation
                * (hash_uniform(col.astype(np.int64), row.astype(np.int64), self.seed) - 0.5)
                * 2.0
            )
            fine = 0.9 + 0.2 * _value_noise(s, t, self.scale / 12.0, self.seed, 5)
            brick = np.clip(c1 * (shade * fine)[..., None], 0.0, 1.0)
            return np.where(joint[..., None], c2, brick)
        # tiles
        grout = 0.05 * self.scale
        ti, tj = np.floor(s / self.scale), np.floor(t / self.scale)
        fs, ft = s - ti * self.scale, t - tj * self.scale
        joint = (fs < grout) | (ft < grout)
        shade = (
            1.0
            + self.variation
            * (hash_uniform(ti.astype(np.int64), tj.astype(np.int64), self.seed) - 0.5)
            * 2.0
        )
        tile = np.clip(c1 * shade[..., None], 0.0, 1.0)
        return np.where(joint[..., None], c2, tile)
