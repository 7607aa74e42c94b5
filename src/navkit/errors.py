"""The navkit exception hierarchy.

Library code raises these; only the command line turns them into exit codes (2 for bad input).
Every input error names *where* (a file or an argument), *what* (the field) and what was
*expected*, so a user can fix the input without reading a traceback.

>>> raise InputError("ranges must be 2-D", source="scan.npz", field="ranges",
...                  expected="array of shape (n_azimuth, n_elevation)")
Traceback (most recent call last):
...
navkit.errors.InputError: scan.npz: field 'ranges': ranges must be 2-D (expected array of shape (n_azimuth, n_elevation))
"""

from __future__ import annotations

from os import PathLike


class NavkitError(Exception):
    """Base class of every error navkit raises on purpose."""


class InputError(NavkitError, ValueError):
    """Input that cannot be used: a bad file, a bad array, a bad setting.

    Parameters
    ----------
    message : str
        What is wrong.
    source : str or path, optional
        The file (or argument name) the input came from.
    field : str, optional
        The field, column, key or array inside ``source``.
    expected : str, optional
        What would have been accepted.
    """

    def __init__(
        self,
        message: str,
        *,
        source: str | PathLike[str] | None = None,
        field: str | None = None,
        expected: str | None = None,
    ) -> None:
        self.message = message
        self.source = None if source is None else str(source)
        self.field = field
        self.expected = expected
        super().__init__(self._render())

    def _render(self) -> str:
        parts = []
        if self.source:
            parts.append(f"{self.source}:")
        if self.field:
            parts.append(f"field '{self.field}':")
        parts.append(self.message)
        text = " ".join(parts)
        if self.expected:
            text += f" (expected {self.expected})"
        return text


class FormatError(InputError):
    """A file whose contents do not follow its format (truncated, missing fields, bad values)."""


class ConfigError(InputError):
    """A setting or a scene description that is out of range or inconsistent."""


class DataNotFoundError(NavkitError, FileNotFoundError):
    """A file or a recorded data set that is not where it was looked for."""


class DegenerateGeometryError(NavkitError):
    """Geometry that does not determine the answer (collinear points, parallel planes, ...)."""


class OptionalDependencyError(NavkitError, ImportError):
    """An optional package is needed for this feature; the message says how to install it."""


def require_module(module: str, extra: str, feature: str):  # type: ignore[no-untyped-def]
    """Import an optional dependency or raise :class:`OptionalDependencyError` with a hint."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError as exc:
        raise OptionalDependencyError(
            f"{feature} needs the package '{module}': pip install 'navkit[{extra}]'"
        ) from exc
