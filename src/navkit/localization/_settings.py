"""Settings dataclasses from mappings (TOML tables): nested tables for nested settings, unknown
keys rejected with the file and the table named."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from navkit.errors import ConfigError

__all__ = ["settings_from_dict"]


def settings_from_dict(cls: Any, data: Mapping[str, Any], source: str, where: str) -> Any:
    """A frozen settings dataclass from a mapping, nested dataclass fields from sub-tables."""
    if not isinstance(data, Mapping):
        raise ConfigError(
            f"is a {type(data).__name__}", source=source, field=where, expected="a table"
        )
    known = {f.name: f for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - set(known))
    if unknown:
        raise ConfigError(
            f"unknown keys {unknown}",
            source=source,
            field=where,
            expected=f"keys among {sorted(known)}",
        )
    kwargs: dict[str, Any] = {}
    for name, value in data.items():
        f = known[name]
        default = f.default_factory() if f.default_factory is not dataclasses.MISSING else f.default
        if dataclasses.is_dataclass(default) and isinstance(value, Mapping):
            value = settings_from_dict(type(default), value, source, f"{where}.{name}")
        kwargs[name] = value
    try:
        return cls(**kwargs)
    except TypeError as exc:
        raise ConfigError(str(exc), source=source, field=where, expected="valid settings") from None
