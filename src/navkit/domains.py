"""Domains of numbers: what values a CLI option, a settings field or a file field may take.

A :class:`Domain` is declared where the number is defined - a ``navkit`` option
(:func:`navkit.cli.common.option`), a field of a settings dataclass (``field(metadata=
{"domain": ...})``, see :func:`domain_field`, enforced by
:func:`navkit.geometry._validate.check_settings`), a field of a file a reader parses - and one
check, :meth:`Domain.check`, enforces it. A refused value is an :class:`~navkit.errors.InputError`
naming the option, field or file, the value and the domain ("--rings: is 0 (expected an integer
>= 1)").

Every domain is finite (NaN is never a value; infinity only with ``allow_inf``, for settings where
"inf disables") and bounded in magnitude by :data:`MAX_MAGNITUDE` unless it says otherwise
(``unbounded``: seeds). A quantity that may be negative says so in its domain's ``note``.

This module imports nothing heavy: the CLI declares its options with it at import time.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from typing import Any

from navkit.errors import InputError

__all__ = [
    "COUNT",
    "DEPTH_SCALE",
    "DOMAIN_KEY",
    "FOCAL_LENGTH",
    "IMAGE_SIDE",
    "MAX_MAGNITUDE",
    "NON_NEGATIVE",
    "NON_NEGATIVE_INT",
    "POSITIVE",
    "POSITIVE_INT",
    "SEED",
    "Domain",
    "check_intrinsics",
    "domain_field",
    "inside_image",
]

#: No number a robot measures or counts is beyond this in SI units (1e9 m, 1e9 s, 1e9 points);
#: larger values are typos or fuzz and would overflow the arithmetic they feed.
MAX_MAGNITUDE = 1e9

#: The key of a dataclass field's metadata that holds its :class:`Domain`.
DOMAIN_KEY = "domain"


def _num(v: float) -> str:
    return str(int(v)) if float(v).is_integer() and abs(v) < 1e15 else f"{v:g}"


@dataclasses.dataclass(frozen=True)
class Domain:
    """The values a number may take.

    Attributes
    ----------
    integer : bool
        Whole numbers only (a float such as ``3.0`` from a file counts as whole).
    lo, hi : float or None
        Bounds (None: only :data:`MAX_MAGNITUDE`).
    lo_open, hi_open : bool
        The bound itself is excluded (``> 0`` rather than ``>= 0``).
    multiple_of : int or None
        The value must be a multiple of this (0 always is).
    allow_inf : bool
        ``inf`` is accepted too (a setting where infinity disables a test).
    unbounded : bool
        No :data:`MAX_MAGNITUDE` bound (seeds).
    note : str
        What a special value means, or why a negative value is legal; shown in ``--help``.
    """

    integer: bool = False
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    multiple_of: int | None = None
    allow_inf: bool = False
    unbounded: bool = False
    note: str = ""

    def describe(self) -> str:
        """``"an integer >= 1"``, ``"a number in (0, 90)"``, ``"a finite number"``, ..."""
        kind = "an integer" if self.integer else "a number"
        lo, hi = self.lo, self.hi
        if lo is not None and hi is not None:
            text = (
                f"{kind} in {'(' if self.lo_open else '['}{_num(lo)}, {_num(hi)}"
                f"{')' if self.hi_open else ']'}"
            )
        elif lo is not None:
            text = f"{kind} {'>' if self.lo_open else '>='} {_num(lo)}"
        elif hi is not None:
            text = f"{kind} {'<' if self.hi_open else '<='} {_num(hi)}"
        else:
            text = "a finite " + ("integer" if self.integer else "number")
        if self.multiple_of:
            text += f", a multiple of {self.multiple_of}"
        if self.allow_inf:
            text += " (or inf)"
        if self.note:
            text += f" ({self.note})"
        return text

    def why_not(self, value: Any) -> str | None:
        """None when ``value`` is in the domain, else what is wrong with it ("is 0")."""
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            return f"is {value!r} ({type(value).__name__})"
        v = float(value)
        if math.isnan(v):
            return "is nan"
        if math.isinf(v):
            return None if (self.allow_inf and v > 0) else f"is {v}"
        if self.integer and not v.is_integer():
            return f"is {value!r}, not a whole number"
        if not self.unbounded and abs(v) > MAX_MAGNITUDE:
            return f"is {value!r}, beyond the bound {MAX_MAGNITUDE:.0e} on any navkit number"
        if self.lo is not None and (v < self.lo or (self.lo_open and v == self.lo)):
            return f"is {value!r}"
        if self.hi is not None and (v > self.hi or (self.hi_open and v == self.hi)):
            return f"is {value!r}"
        if self.multiple_of and int(v) % self.multiple_of:
            return f"is {value!r}"
        return None

    def contains(self, value: Any) -> bool:
        """Whether ``value`` is in the domain."""
        return self.why_not(value) is None

    def check(
        self,
        value: Any,
        name: str,
        *,
        source: Any = None,
        error: type[InputError] = InputError,
    ) -> None:
        """Refuse ``value`` outside the domain.

        Parameters
        ----------
        value : number
        name : str
            The option (``"--rings"``) or field (``"depth_scale"``) it came from.
        source : str or path, optional
            The file (or settings class) of a field; None for an option.
        error : InputError subclass
            What to raise (``FormatError`` for a file, ``ConfigError`` for a setting).

        Raises
        ------
        InputError
            Naming ``source``, ``name``, the value and the domain.
        """
        why = self.why_not(value)
        if why is None:
            return
        if source is None:
            raise error(why, source=name, expected=self.describe())
        raise error(why, source=source, field=name, expected=self.describe())

    def check_array(
        self,
        values: Any,
        name: str,
        *,
        source: Any = None,
        error: type[InputError] = InputError,
    ) -> None:
        """:meth:`check` for every entry of an array; the error names the first bad entry's
        index (``"v[3]: is 1e+308 ..."``)."""
        import numpy as np

        full = np.asarray(values, dtype=np.float64)
        a = full.ravel()
        with np.errstate(invalid="ignore"):
            suspect = ~np.isfinite(a)
            if not self.unbounded:
                suspect |= np.abs(a) > MAX_MAGNITUDE
            if self.lo is not None:
                suspect |= a <= self.lo
            if self.hi is not None:
                suspect |= a >= self.hi
            if self.integer or self.multiple_of:
                suspect |= a != np.round(a)
        for i in np.flatnonzero(suspect):
            why = self.why_not(float(a[i]))
            if why is not None:
                index = ", ".join(str(int(k)) for k in np.unravel_index(i, full.shape))
                where = f"{name}[{index}]"
                if source is None:
                    raise error(why, source=where, expected=self.describe())
                raise error(why, source=source, field=where, expected=self.describe())

    def edges(self) -> tuple[list[float], list[float]]:
        """Values just inside and just outside the domain (for tests): the bounds and their
        nearest neighbours, NaN, and the magnitude bound."""
        step = 1.0 if self.integer else None
        inside: list[float] = []
        outside: list[float] = [math.nan]

        def near(b: float, up: bool) -> float:
            if step is not None:
                return b + (step if up else -step)
            return math.nextafter(b, math.inf if up else -math.inf)

        lo = self.lo if self.lo is not None else (None if self.unbounded else -MAX_MAGNITUDE)
        hi = self.hi if self.hi is not None else (None if self.unbounded else MAX_MAGNITUDE)
        if lo is not None:
            first = near(lo, True) if self.lo_open else lo
            if self.integer:
                first = float(math.ceil(first))
            inside.append(first)
            outside.append(lo if self.lo_open else near(lo, False))
        if hi is not None:
            last = near(hi, False) if self.hi_open else hi
            if self.integer:
                last = float(math.floor(last))
            inside.append(last)
            outside.append(hi if self.hi_open else near(hi, True))
        if self.multiple_of:
            inside = [self.multiple_of * math.ceil(v / self.multiple_of) for v in inside]
            inside = [v for v in inside if self.contains(v)]
            outside.append(float(self.multiple_of + 1))
        return [v for v in inside if self.contains(v)], [v for v in outside if not self.contains(v)]


def domain_field(default: Any, domain: Domain, **kwargs: Any) -> Any:
    """A dataclass field with a default and a :class:`Domain` (checked by ``check_settings``)."""
    return dataclasses.field(default=default, metadata={DOMAIN_KEY: domain}, **kwargs)


POSITIVE = Domain(lo=0.0, lo_open=True)
NON_NEGATIVE = Domain(lo=0.0)
POSITIVE_INT = Domain(integer=True, lo=1)
NON_NEGATIVE_INT = Domain(integer=True, lo=0)
COUNT = POSITIVE_INT
SEED = Domain(integer=True, lo=0, unbounded=True)

# ------------------------------------------------------------------ camera intrinsics (files)
#: An image side in pixels.
IMAGE_SIDE = Domain(integer=True, lo=1, hi=100_000)
#: A focal length in pixels.
FOCAL_LENGTH = POSITIVE
#: Raw depth units per metre (``metres = raw / depth_scale``).
DEPTH_SCALE = POSITIVE


def inside_image(side: int) -> Domain:
    """The domain of a principal point coordinate on an image side of ``side`` pixels."""
    return Domain(lo=0.0, hi=float(side), note="inside the image")


def check_intrinsics(
    values: dict[str, Any],
    *,
    source: Any,
    error: type[InputError] = InputError,
) -> tuple[int, int]:
    """Check the intrinsics fields of a camera file; return ``(width, height)``.

    ``values`` holds ``fx``, ``fy`` (focal lengths, > 0), ``cx``, ``cy`` (principal point,
    inside the image: ``cx`` in [0, width], ``cy`` in [0, height]), ``width``, ``height``
    (positive integers) and optionally ``depth_scale`` (> 0).

    Raises
    ------
    InputError
        (``error``) naming ``source``, the field and its domain.
    """
    for name in ("width", "height"):
        IMAGE_SIDE.check(values[name], name, source=source, error=error)
    width, height = int(values["width"]), int(values["height"])
    for name in ("fx", "fy"):
        FOCAL_LENGTH.check(values[name], name, source=source, error=error)
    inside_image(width).check(values["cx"], "cx", source=source, error=error)
    inside_image(height).check(values["cy"], "cy", source=source, error=error)
    if "depth_scale" in values:
        DEPTH_SCALE.check(values["depth_scale"], "depth_scale", source=source, error=error)
    return width, height
