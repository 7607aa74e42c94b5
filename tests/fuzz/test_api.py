"""Public functions fed empty, all-NaN, wrong-shape and degenerate arrays.

The functions are found by introspection: every public function of the capability and geometry
packages whose first parameter takes an array and whose other parameters have defaults. Each is
called with every array below; a case passes on a navkit error or a returned value, with no other
exception (NumPy warnings count as failures: pytest turns them into errors) and bounded memory.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from .conftest import check

MODULES = [
    "navkit.geometry",
    "navkit.obstacles",
    "navkit.localization",
    "navkit.path",
    "navkit.path.track",
    "navkit.stereo",
    "navkit.planes",
]

_line = np.c_[np.linspace(0, 1, 8), 2 * np.linspace(0, 1, 8), np.zeros(8)]
ARRAYS: dict[str, Any] = {
    "empty-3": np.zeros((0, 3)),
    "empty-2": np.zeros((0, 2)),
    "nan-3": np.full((8, 3), np.nan),
    "nan-2": np.full((8, 2), np.nan),
    "wrong-4": np.ones((5, 4)),
    "one-d": np.ones(3),
    "scalar": np.float64(0.0),
    "identical-3": np.ones((8, 3)),
    "collinear-3": _line,
    "collinear-2": _line[:, :2],
    "huge-3": np.full((8, 3), 1e300),
    "grid-3": np.full((4, 5, 3), np.nan),
}


def _functions() -> list[tuple[str, Callable[..., Any]]]:
    found = []
    for name in MODULES:
        mod = importlib.import_module(name)
        for attr in getattr(mod, "__all__", []):
            fn = getattr(mod, attr)
            if not inspect.isfunction(fn):
                continue
            try:
                params = list(inspect.signature(fn).parameters.values())
            except (TypeError, ValueError):
                continue
            if not params or "Array" not in str(params[0].annotation):
                continue
            required = [
                p
                for p in params[1:]
                if p.default is inspect.Parameter.empty
                and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
            ]
            if not required:
                found.append((f"{fn.__module__}.{fn.__name__}", fn))
    return sorted(dict(found).items())


FUNCTIONS = _functions()


@pytest.mark.parametrize(("name", "fn"), FUNCTIONS, ids=[n for n, _ in FUNCTIONS])
def test_degenerate_arrays(name: str, fn: Callable[..., Any]) -> None:
    failures = []
    for label, arr in ARRAYS.items():
        try:
            check("api", fn, arr)
        except AssertionError as exc:
            failures.append(f"{name}({label}): {exc}")
    assert not failures, "\n".join(failures)


def test_functions_found() -> None:
    assert len(FUNCTIONS) >= 15, [n for n, _ in FUNCTIONS]
