"""Scenes as TOML files: :func:`load_scene`, :func:`scene_to_toml`, :func:`builtin_scene_path`.

Format (all lengths in metres, angles in radians)::

    name = "yard"
    start = [0.0, 0.0, 0.0]          # optional robot start pose x, y, theta

    [[primitive]]
    type = "ground"                  # ground | box | prism | sphere | hemisphere | cylinder | wall
    name = "ground"
    height = 0.0
    hill_amplitude = 0.0
    hill_wavelength = 20.0
    [primitive.texture]              # optional; kind = bricks | tiles | noise | checker | solid
    kind = "noise"
    scale = 2.0
    seed = 7

    [[primitive]]
    type = "box"
    name = "crate"
    center = [6.0, -3.0, 0.5]
    size = [1.0, 1.0, 1.0]
    yaw = 0.3

Keys per type are the dataclass fields of :mod:`navkit.sim.primitives` (``Box(center, size,
yaw)``, ``Prism(center, size, yaw)``, ``Sphere(center, radius)``, ``Hemisphere(center, radius)``,
``Cylinder(center, radius, height)``, ``Wall(origin, u, v)``, ``Ground(height, hill_amplitude,
hill_wavelength)``). Unknown types, unknown or missing keys and out-of-range values raise a
:class:`~navkit.errors.ConfigError` naming the file, the table (``primitive[3] (box 'crate')``)
and the key.
"""

from __future__ import annotations

import dataclasses
import json
import os
import sys
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from navkit.errors import ConfigError, DataNotFoundError, FormatError
from navkit.sim.primitives import Box, Cylinder, Ground, Hemisphere, Primitive, Prism, Sphere, Wall
from navkit.sim.scene import Scene
from navkit.sim.texture import Texture

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = [
    "PRIMITIVE_TYPES",
    "builtin_scene_path",
    "builtin_scenes",
    "load_scene",
    "scene_from_dict",
    "scene_to_dict",
    "scene_to_toml",
]

PRIMITIVE_TYPES: dict[str, type[Primitive]] = {
    "ground": Ground,
    "box": Box,
    "prism": Prism,
    "sphere": Sphere,
    "hemisphere": Hemisphere,
    "cylinder": Cylinder,
    "wall": Wall,
}
_TOP_KEYS = {"name", "start", "primitive"}


def _fields(cls: type) -> tuple[list[str], list[str]]:
    """(required, optional) init field names of a dataclass."""
    req, opt = [], []
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            req.append(f.name)
        else:
            opt.append(f.name)
    return req, opt


def _texture(table: dict[str, Any], source: str | None, where: str) -> Texture:
    if not isinstance(table, dict):
        raise ConfigError(
            f"is {table!r}", source=source, field=f"{where}.texture", expected="a table"
        )
    req, opt = _fields(Texture)
    unknown = sorted(set(table) - set(req) - set(opt))
    if unknown:
        raise ConfigError(
            f"unknown keys {unknown}",
            source=source,
            field=f"{where}.texture",
            expected=f"keys among {req + opt}",
        )
    try:
        return Texture(**table)
    except ConfigError as exc:
        key = (exc.field or "").split(".")[-1]
        raise ConfigError(
            exc.message, source=source, field=f"{where}.texture.{key}", expected=exc.expected
        ) from None
    except (TypeError, ValueError) as exc:
        raise ConfigError(
            str(exc), source=source, field=f"{where}.texture", expected="a valid texture"
        ) from None


def scene_from_dict(data: dict[str, Any], source: str | os.PathLike[str] | None = None) -> Scene:
    """Build a scene from the parsed TOML structure (see the module docstring)."""
    src = None if source is None else str(source)
    if not isinstance(data, dict):
        raise ConfigError("is not a table", source=src, expected="a TOML document")
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise ConfigError(
            f"unknown top-level keys {unknown}",
            source=src,
            expected=f"keys among {sorted(_TOP_KEYS)}",
        )
    items = data.get("primitive", [])
    if not isinstance(items, list) or not items:
        raise ConfigError(
            "no [[primitive]] tables",
            source=src,
            field="primitive",
            expected="at least one [[primitive]] table",
        )
    prims: list[Primitive] = []
    for i, item in enumerate(items):
        where = f"primitive[{i}]"
        if not isinstance(item, dict):
            raise ConfigError(f"is {item!r}", source=src, field=where, expected="a table")
        kind = item.get("type")
        if kind is None:
            raise ConfigError(
                "missing key",
                source=src,
                field=f"{where}.type",
                expected=f"one of {sorted(PRIMITIVE_TYPES)}",
            )
        if kind not in PRIMITIVE_TYPES:
            raise ConfigError(
                f"unknown primitive type {kind!r}",
                source=src,
                field=f"{where}.type",
                expected=f"one of {sorted(PRIMITIVE_TYPES)}",
            )
        cls = PRIMITIVE_TYPES[kind]
        label = f"{where} ({kind} {item['name']!r})" if "name" in item else f"{where} ({kind})"
        req, opt = _fields(cls)
        args = {k: v for k, v in item.items() if k != "type"}
        unknown = sorted(set(args) - set(req) - set(opt))
        if unknown:
            raise ConfigError(
                f"unknown keys {unknown}",
                source=src,
                field=label,
                expected=f"keys among {['type', *req, *opt]}",
            )
        for key in req:
            if key not in args:
                raise ConfigError(
                    "missing key",
                    source=src,
                    field=f"{label}.{key}",
                    expected=f"{kind} needs {req}",
                )
        if "texture" in args:
            args["texture"] = _texture(args["texture"], src, label)
        try:
            prims.append(cls(**args))
        except ConfigError as exc:
            key = (exc.field or "").split(".")[-1]
            raise ConfigError(
                exc.message, source=src, field=f"{label}.{key}", expected=exc.expected
            ) from None
    try:
        start = tuple(float(c) for c in data.get("start", (0.0, 0.0, 0.0)))
        if len(start) != 3:
            raise ValueError
    except (TypeError, ValueError):
        raise ConfigError(
            f"is {data.get('start')!r}", source=src, field="start", expected="[x, y, theta]"
        ) from None
    try:
        return Scene(
            prims, name=str(data.get("name", Path(src).stem if src else "scene")), start=start
        )
    except ConfigError as exc:
        raise ConfigError(exc.message, source=src, field=exc.field, expected=exc.expected) from None


def load_scene(path: str | os.PathLike[str]) -> Scene:
    """Read a scene from a TOML file (or a built-in scene name such as ``"yard"``).

    Raises
    ------
    DataNotFoundError
        The file does not exist (and is not a built-in scene name).
    FormatError
        The file is not valid TOML.
    ConfigError
        A table or key is unknown, missing or out of range (the message names which).
    """
    p = Path(path)
    if not p.exists() and p.suffix == "" and p.name in builtin_scenes():
        p = builtin_scene_path(p.name)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: no such scene file (built-in scenes: {builtin_scenes()})")
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise FormatError(
            f"not valid TOML: {exc}", source=p, expected="a TOML scene file"
        ) from None
    return scene_from_dict(data, source=p)


def scene_to_dict(scene: Scene) -> dict[str, Any]:
    """The TOML structure of a scene (inverse of :func:`scene_from_dict`)."""
    kinds = {cls: name for name, cls in PRIMITIVE_TYPES.items()}
    items = []
    for p in scene.primitives:
        d: dict[str, Any] = {"type": kinds[type(p)], "name": p.name}
        for f in dataclasses.fields(p):  # type: ignore[arg-type]
            v = getattr(p, f.name)
            if f.name == "name":
                continue
            if f.name == "texture":
                if v is not None:
                    d["texture"] = {
                        g.name: (
                            list(getattr(v, g.name))
                            if isinstance(getattr(v, g.name), tuple)
                            else getattr(v, g.name)
                        )
                        for g in dataclasses.fields(v)
                    }
                continue
            d[f.name] = list(v) if isinstance(v, tuple) else v
        items.append(d)
    return {"name": scene.name, "start": list(scene.start), "primitive": items}


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return (
            repr(v)
            if isinstance(v, int) or np.isfinite(v)
            else ("nan" if v != v else ("inf" if v > 0 else "-inf"))
        )
    if isinstance(v, str):
        return json.dumps(v)  # JSON string escapes are valid TOML basic-string escapes
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def scene_to_toml(scene: Scene) -> str:
    """TOML text of a scene (the format of :func:`load_scene`, which gives an equal scene back)."""
    d = scene_to_dict(scene)
    lines = [f"name = {_toml_value(d['name'])}", f"start = {_toml_value(d['start'])}", ""]
    for item in d["primitive"]:
        lines.append("[[primitive]]")
        lines += [f"{k} = {_toml_value(v)}" for k, v in item.items() if k != "texture"]
        if "texture" in item:
            lines.append("[primitive.texture]")
            lines += [f"{k} = {_toml_value(v)}" for k, v in item["texture"].items()]
        lines.append("")
    return "\n".join(lines)


def builtin_scenes() -> list[str]:
    """Names of the scenes shipped with navkit (``navkit/data/*.toml`` with ``[[primitive]]``).

    Other TOML files in that folder (e.g. mission routes) are not scenes and are not listed.
    """
    root = resources.files("navkit").joinpath("data")
    names = []
    for entry in root.iterdir():
        if not str(entry.name).endswith(".toml"):
            continue
        try:
            data = tomllib.loads(entry.read_text(encoding="utf-8"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError, OSError):
            continue
        if isinstance(data.get("primitive"), list):
            names.append(Path(str(entry.name)).stem)
    return sorted(names)


def builtin_scene_path(name: str = "yard") -> Path:
    """Path of a built-in scene file, e.g. ``builtin_scene_path("yard")``."""
    path = Path(str(resources.files("navkit").joinpath("data", f"{name}.toml")))
    if not path.is_file():
        raise DataNotFoundError(f"no built-in scene {name!r} (available: {builtin_scenes()})")
    return path
