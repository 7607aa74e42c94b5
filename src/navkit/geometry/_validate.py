"""Array checks shared by the geometry functions (clear errors instead of NumPy tracebacks)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.domains import MAX_MAGNITUDE as _MAX_MAGNITUDE
from navkit.errors import InputError


def as_points(
    points: ArrayLike, dim: int, name: str = "points", min_count: int = 0
) -> NDArray[np.float64]:
    """Return ``points`` as a float64 ``(N, dim)`` array, or raise :class:`InputError`."""
    try:
        arr = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"cannot be read as numbers: {exc}", field=name, expected=f"(N, {dim}) array of floats"
        ) from exc
    if arr.ndim == 1 and arr.shape[0] == dim:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise InputError(f"has shape {arr.shape}", field=name, expected=f"(N, {dim}) array")
    if arr.shape[0] < min_count:
        raise InputError(
            f"has {arr.shape[0]} rows", field=name, expected=f"at least {min_count} points"
        )
    return arr


def as_matrices(T: ArrayLike, size: int, name: str = "T") -> NDArray[np.float64]:
    """Return ``T`` as float64 ``(..., size, size)``, or raise :class:`InputError`."""
    arr = np.asarray(T, dtype=np.float64)
    if arr.ndim < 2 or arr.shape[-2:] != (size, size):
        raise InputError(
            f"has shape {arr.shape}",
            field=name,
            expected=f"({size}, {size}) or (N, {size}, {size}) array",
        )
    return arr


#: Default bound on the cells of any grid navkit allocates from a setting (50 M cells: 50 MB
#: of int8, 400 MB of float64). The environment variable ``NAVKIT_MAX_GRID_CELLS`` raises it.
MAX_GRID_CELLS = 50_000_000


def max_grid_cells() -> int:
    """The grid-size bound in force: ``NAVKIT_MAX_GRID_CELLS`` if set, else :data:`MAX_GRID_CELLS`."""
    import os

    raw = os.environ.get("NAVKIT_MAX_GRID_CELLS")
    if raw is None:
        return MAX_GRID_CELLS
    try:
        value = int(float(raw))
    except ValueError:
        raise InputError(
            f"is {raw!r}", source="NAVKIT_MAX_GRID_CELLS", expected="a positive integer"
        ) from None
    if value <= 0:
        raise InputError(f"is {raw!r}", source="NAVKIT_MAX_GRID_CELLS", expected="> 0")
    return value


def check_grid_size(shape: tuple[float, ...], *, setting: str, source: str | None = None) -> None:
    """Refuse a grid whose cell count exceeds :func:`max_grid_cells`, before allocating it.

    Parameters
    ----------
    shape : tuple of numbers
        The grid's dimensions (floats are accepted: they may be huge or not finite).
    setting : str
        The setting(s) that decide the size, named in the error (``"resolution"``).
    source : str, optional
        Where the input came from.

    Raises
    ------
    InputError
        Naming the size, the setting and how to raise the bound.
    """
    dims = [float(d) for d in shape]
    if not all(np.isfinite(d) and d >= 0 for d in dims):
        raise InputError(
            f"grid of {' x '.join(map(str, dims))} cells is not finite",
            source=source,
            field=setting,
            expected="finite coordinates and a positive cell size",
        )
    cells = float(np.prod(dims)) if dims else 0.0
    limit = max_grid_cells()
    if cells > limit:
        raise InputError(
            f"grid of {' x '.join(f'{d:.0f}' for d in dims)} = {cells:.3g} cells exceeds the "
            f"bound of {limit} cells",
            source=source,
            field=setting,
            expected=f"a coarser '{setting}' or a smaller area (or raise the bound with the "
            "environment variable NAVKIT_MAX_GRID_CELLS)",
        )


#: Largest coordinate magnitude accepted in point data, metres (the same bound as the settings'
#: :data:`MAX_SETTING_MAGNITUDE`; ``cloud_to_grid`` also treats a return beyond it as a
#: no-return). Far beyond any sensor's range or any map, and small enough that every grid index
#: navkit computes from a coordinate (``|x| / cell`` with a cell of a micrometre or more) fits
#: an int64 and that float64 keeps sub-micrometre steps (a path's 1e-4 m precision): a finite
#: value beyond it is corrupt data, refused before any kernel runs.
MAX_COORDINATE_M = 1e9


def check_coordinates(
    values: NDArray[np.floating], *, field: str, source: str | None = None
) -> None:
    """Refuse finite coordinates beyond :data:`MAX_COORDINATE_M` in magnitude.

    NaN and +-inf pass (no-returns in sensor data; each function drops them as it documents).
    Two reductions when every value is within the bound (the usual case); the offending value
    is located only when one is not.

    Raises
    ------
    InputError
        Naming the field, the largest offending value and the bound.
    """
    a = np.asarray(values)
    if a.size == 0 or a.dtype.kind not in "fc":
        return
    if -MAX_COORDINATE_M <= a.min() and a.max() <= MAX_COORDINATE_M:  # NaN fails: slow path
        return
    with np.errstate(invalid="ignore"):
        bad = np.isfinite(a) & (np.abs(a) > MAX_COORDINATE_M)
    if bad.any():
        worst = float(np.abs(a[bad]).max())
        raise InputError(
            f"has a coordinate of magnitude {worst:.3g} m ({int(bad.sum())} such values)",
            source=source,
            field=field,
            expected=f"finite coordinates within +-{MAX_COORDINATE_M:.0e} m (NaN / inf = no "
            "return)",
        )


#: No setting of a robot is beyond this in SI units (1e9 m, 1e9 s, 1e9 points); larger values
#: are typos or fuzz and would overflow the arithmetic they feed (the same bound as every
#: :class:`navkit.domains.Domain`).
MAX_SETTING_MAGNITUDE = _MAX_MAGNITUDE

_NUMBER_TYPES = {"float": (int, float, np.integer, np.floating), "int": (int, np.integer)}


def check_settings(obj: object, *, allow_inf: tuple[str, ...] = ()) -> None:
    """Check the plain-number fields of a settings dataclass: right type, finite.

    Every field annotated ``float`` or ``int`` (also ``float | None``) must hold a number of that
    kind (a bool or a string from a settings file is refused), and a float must be finite (NaN
    always refused, infinity only for the fields in ``allow_inf``, e.g. "inf disables"); a field
    annotated ``bool`` must hold a bool; no number may exceed :data:`MAX_SETTING_MAGNITUDE` in
    magnitude. A field declared with a :class:`navkit.domains.Domain` (``field(metadata=
    {"domain": ...})``, :func:`navkit.domains.domain_field`) must lie in it - the same check as
    the CLI's options, and the domain decides finiteness (its ``allow_inf``); rules that are no
    range (odd sizes, one field bounded by another) are checked by each class's ``__post_init__``.
    A field annotated ``tuple[int, ...]`` (or ``float``) with a domain holds a list of such
    numbers, each in it (the error names the entry: ``levels[1]``).

    Raises
    ------
    ConfigError
        Naming the class, the field, the value and what was expected.
    """
    import dataclasses

    from navkit.domains import DOMAIN_KEY
    from navkit.errors import ConfigError

    cls = type(obj).__name__
    for f in dataclasses.fields(obj):  # type: ignore[arg-type]
        ann = (f.type.__name__ if isinstance(f.type, type) else str(f.type)).replace(" ", "")
        optional = ann.endswith("|None") or ann.startswith("None|")
        base = ann.replace("|None", "").replace("None|", "")
        value = getattr(obj, f.name)
        if value is None and optional:
            continue
        if base == "bool":
            if not isinstance(value, (bool, np.bool_)):
                raise ConfigError(
                    f"is {value!r} ({type(value).__name__})",
                    source=cls,
                    field=f.name,
                    expected="true or false",
                )
            continue
        domain = f.metadata.get(DOMAIN_KEY)
        element = base[len("tuple[") : -len(",...]")] if base.endswith(",...]") else None
        if domain is not None and element in _NUMBER_TYPES:
            # a tuple of numbers (pyramid levels): every entry in the declared domain
            if not isinstance(value, (tuple, list)):
                raise ConfigError(
                    f"is {value!r} ({type(value).__name__})",
                    source=cls,
                    field=f.name,
                    expected=f"a list of numbers, each {domain.describe()}",
                )
            for i, v in enumerate(value):
                if isinstance(v, (bool, np.bool_)) or not isinstance(v, _NUMBER_TYPES[element]):
                    raise ConfigError(
                        f"is {v!r} ({type(v).__name__})",
                        source=cls,
                        field=f"{f.name}[{i}]",
                        expected=domain.describe(),
                    )
                domain.check(v, f"{f.name}[{i}]", source=cls, error=ConfigError)
            continue
        kinds = _NUMBER_TYPES.get(base)
        if kinds is None:
            continue
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, kinds):
            raise ConfigError(
                f"is {value!r} ({type(value).__name__})",
                source=cls,
                field=f.name,
                expected="an integer" if base == "int" else "a number",
            )
        if domain is not None and f.name not in allow_inf:
            # the declared domain decides finiteness too (``allow_inf``: "inf disables")
            domain.check(value, f.name, source=cls, error=ConfigError)
            continue
        if base == "float" and not np.isfinite(value):
            if np.isinf(value) and f.name in allow_inf:
                continue
            raise ConfigError(
                f"is {value!r}",
                source=cls,
                field=f.name,
                expected="a finite number" + (" or inf" if f.name in allow_inf else ""),
            )
        if domain is not None:
            domain.check(value, f.name, source=cls, error=ConfigError)
            continue
        if abs(float(value)) > MAX_SETTING_MAGNITUDE:
            raise ConfigError(
                f"is {value!r}",
                source=cls,
                field=f.name,
                expected=f"a magnitude of at most {MAX_SETTING_MAGNITUDE:.0e} (SI units)",
            )


def as_vectors(
    x: ArrayLike, size: int, name: str = "x", *, finite: bool = False
) -> NDArray[np.float64]:
    """``x`` as float64 ``(..., size)`` (at least 1-D), or :class:`InputError`.

    With ``finite`` every entry must be finite (rotations, quaternions: maths, not sensor data).
    """
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"cannot be read as numbers: {exc}", field=name, expected=f"(..., {size}) floats"
        ) from None
    if arr.ndim < 1 or arr.shape[-1] != size:
        raise InputError(f"has shape {arr.shape}", field=name, expected=f"(..., {size}) array")
    if finite and not np.isfinite(arr).all():
        raise InputError("has NaN or inf entries", field=name, expected="finite numbers")
    return arr


def as_quaternions(q: ArrayLike, name: str = "quat_xyzw") -> NDArray[np.float64]:
    """Finite ``(..., 4)`` quaternions with a non-zero norm (not normalised), or InputError."""
    arr = as_vectors(q, 4, name, finite=True)
    with np.errstate(over="ignore"):
        norm = np.linalg.norm(arr, axis=-1)
    if not np.all((norm > 1e-12) & np.isfinite(norm)):
        raise InputError("has a zero or huge quaternion", field=name, expected="norm > 0")
    return arr


def as_rotations(R: ArrayLike, name: str = "R") -> NDArray[np.float64]:
    """Finite ``(..., 3, 3)`` matrices (not checked for orthonormality), or InputError."""
    try:
        arr = as_matrices(R, 3, name)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(
            f"cannot be read as numbers: {exc}", field=name, expected="(..., 3, 3) floats"
        ) from None
    if not np.isfinite(arr).all():
        raise InputError("has NaN or inf entries", field=name, expected="a finite rotation")
    return arr
