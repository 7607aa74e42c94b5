"""Scene TOML files: round trip, validation messages, the shipped worlds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from navkit.errors import ConfigError, DataNotFoundError, FormatError
from navkit.sim import (
    Box,
    Cylinder,
    Ground,
    Hemisphere,
    Prism,
    Scene,
    Sphere,
    Texture,
    Wall,
    builtin_scene_path,
    builtin_scenes,
    load_scene,
)
from navkit.sim.scene_io import scene_to_toml


def test_round_trip_of_every_primitive_type(tmp_path):
    scene = Scene(
        [
            Ground(
                height=0.1,
                hill_amplitude=0.2,
                hill_wavelength=9.5,
                name="g",
                texture=Texture("noise", scale=1.1, seed=3),
            ),
            Box((1.0, 2.0, 0.5), (1.0, 2.0, 1.0), yaw=0.25, name="b"),
            Prism(
                (3.0, -1.0, 0.3),
                (1.5, 1.0, 0.6),
                yaw=-1.0,
                name="p",
                texture=Texture("checker", color=(1.0, 0.0, 0.0)),
            ),
            Sphere((0.0, 4.0, 1.0), 0.5, name="s"),
            Hemisphere((5.0, 5.0, 0.0), 0.7, name="h", texture=Texture("tiles", variation=0.0)),
            Cylinder((-2.0, 0.0, 0.0), 0.2, 2.5, name="c"),
            Wall(
                (0.0, -5.0, 0.0),
                (4.0, 0.0, 0.0),
                (0.0, 0.0, 2.0),
                name="w",
                texture=Texture("bricks", seed=9, scale=0.3),
            ),
        ],
        name="all kinds",
        start=(1.0, -2.0, 0.5),
    )
    path = tmp_path / "scene.toml"
    path.write_text(scene_to_toml(scene))
    again = load_scene(path)
    assert again == scene
    # and it renders identically
    D = np.random.default_rng(0).normal(size=(500, 3))
    a, b = scene.cast([0.0, 0.0, 1.0], D), again.cast([0.0, 0.0, 1.0], D)
    np.testing.assert_array_equal(a.index, b.index)
    np.testing.assert_array_equal(a.color, b.color)


def _write(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "bad.toml"
    path.write_text('name = "bad"\n' + body)
    return path


@pytest.mark.parametrize(
    ("body", "fragments"),
    [
        ('[[primitive]]\ntype = "pyramid"\n', ["bad.toml", "primitive[0].type", "pyramid", "box"]),
        (
            '[[primitive]]\ntype = "ground"\n[[primitive]]\ntype = "box"\nname = "crate"\ncenter = [0, 0, 0]\n',
            ["bad.toml", "primitive[1] (box 'crate').size", "missing"],
        ),
        (
            '[[primitive]]\ntype = "sphere"\ncenter = [0, 0, 1]\nradius = -0.5\n',
            ["bad.toml", "primitive[0] (sphere).radius", "-0.5", "positive"],
        ),
        (
            '[[primitive]]\ntype = "box"\ncenter = [0, 0, 1]\nsize = [1, 1]\n',
            ["primitive[0] (box).size", "three"],
        ),
        (
            '[[primitive]]\ntype = "cylinder"\ncenter = [0, 0, 0]\nradius = 1\nheight = 1\ncolour = 3\n',
            ["primitive[0] (cylinder)", "unknown keys ['colour']"],
        ),
        (
            '[[primitive]]\ntype = "wall"\norigin = [0, 0, 0]\nu = [1, 0, 0]\nv = [0, 0, 1]\n'
            '[primitive.texture]\nkind = "marble"\n',
            ["primitive[0] (wall).texture.kind", "marble", "bricks"],
        ),
        ("", ["bad.toml", "primitive", "at least one"]),
    ],
)
def test_validation_names_file_table_and_key(tmp_path, body, fragments):
    with pytest.raises(ConfigError) as info:
        load_scene(_write(tmp_path, body))
    for frag in fragments:
        assert frag in str(info.value)


def test_unreadable_and_missing_files(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[[primitive]\ntype = ")
    with pytest.raises(FormatError, match=r"broken\.toml"):
        load_scene(path)
    with pytest.raises(DataNotFoundError, match=r"nowhere\.toml"):
        load_scene(tmp_path / "nowhere.toml")
    with pytest.raises(DataNotFoundError, match="yard"):
        builtin_scene_path("no-such-world")


def test_shipped_yard_has_what_the_mission_needs():
    assert {"yard", "hills"} <= set(builtin_scenes())
    yard = load_scene(builtin_scene_path("yard"))
    assert load_scene("yard") == yard
    kinds = {p.kind for p in yard.primitives}
    assert kinds >= {"ground", "wall", "box", "prism", "hemisphere", "cylinder"}
    walls = [p for p in yard.primitives if p.kind == "wall"]
    assert any(w.texture is not None and w.texture.kind == "bricks" for w in walls)
    ramp = next(p for p in yard.primitives if isinstance(p, Prism))
    assert np.degrees(ramp.slope_angle) > 20.0
    curb = yard.primitives[yard.index_of("sidewalk")]
    assert isinstance(curb, Box) and 0.05 < curb.size[2] < 0.3
    # the room: a ray through the doorway reaches the far wall; beside it, it stops at the door wall
    hits = yard.cast([19.0, -2.0, 1.0], [[0.0, -1.0, 0.0], [-0.3, -1.0, 0.0]])
    assert list(yard.primitive_names(hits.index)) == ["room_south", "room_north_west"]
    # hills: the rock's dome stands on the hilly ground (no gap under it)
    hills = load_scene("hills")
    rock = hills.primitives[hills.index_of("rock")]
    assert abs(rock.center[2] - float(hills.ground_height(*rock.center[:2]))) < 1e-3
    # every world toml round-trips
    for name in builtin_scenes():
        scene = load_scene(builtin_scene_path(name))
        assert load_scene_from_text(scene_to_toml(scene)) == scene


def load_scene_from_text(text: str) -> Scene:
    import tomllib

    from navkit.sim.scene_io import scene_from_dict

    return scene_from_dict(tomllib.loads(text))
