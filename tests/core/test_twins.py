"""Every compiled kernel has a NumPy twin, a caller and a test that compares the two.

Each kernel module (``navkit.jit.KERNEL_MODULES``) declares ``TWINS``: every public ``@njit``
function (no leading underscore) -> the dotted path of its NumPy twin. Helpers called only from
other kernels have a leading underscore, or are listed in the module's ``HELPERS``. A test
comparing a kernel with its twin says so with ``@pytest.mark.twin("kernel_name", ...)``. Every
kernel of a table has a caller in the package, unless the module lists it in ``TEST_ONLY`` (an
array entry point that lets the tests compare a scalar helper the other kernels inline).
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path
from types import ModuleType

import pytest

from navkit import jit

pytest.importorskip("numba")

ROOT = Path(__file__).resolve().parents[2]
SRC = ROOT / "src" / "navkit"


def _module_names() -> list[str]:
    return ["navkit." + rel.removesuffix(".py").replace("/", ".") for rel in jit.KERNEL_MODULES]


def _kernels(mod: ModuleType) -> set[str]:
    """The public ``@njit`` functions defined in ``mod``."""
    from numba.core.registry import CPUDispatcher

    return {
        name
        for name, obj in vars(mod).items()
        if isinstance(obj, CPUDispatcher)
        and obj.__module__ == mod.__name__
        and not name.startswith("_")
    }


def _resolve(path: str) -> object:
    """The object at a dotted path: the longest importable module, then attributes."""
    parts = path.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj: object = importlib.import_module(".".join(parts[:k]))
        except ModuleNotFoundError:
            continue
        for attr in parts[k:]:
            obj = getattr(obj, attr)
        return obj
    raise ModuleNotFoundError(path)


def _marked_kernels() -> set[str]:
    """Kernel names given to ``pytest.mark.twin`` anywhere under tests/."""
    out: set[str] = set()
    for path in (ROOT / "tests").rglob("test_*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if (
                isinstance(node, ast.Call)
                and isinstance(node.func, ast.Attribute)
                and node.func.attr == "twin"
                and isinstance(node.func.value, ast.Attribute)
                and node.func.value.attr == "mark"
            ):
                out |= {a.value for a in node.args if isinstance(a, ast.Constant)}
    return out


def _used_names() -> dict[str, set[Path]]:
    """Every name read, imported or called in src/navkit -> the files that use it."""
    out: dict[str, set[Path]] = {}
    for path in SRC.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Name):
                name = node.id
            elif isinstance(node, ast.Attribute):
                name = node.attr
            elif isinstance(node, ast.alias):
                name = node.name
            else:
                continue
            out.setdefault(name, set()).add(path)
    return out


TABLES = _module_names()


def test_every_kernel_module_declares_its_twins():
    for name in _module_names():
        assert hasattr(importlib.import_module(name), "TWINS"), name


@pytest.mark.parametrize("name", TABLES)
def test_the_table_lists_every_public_kernel_and_only_kernels(name):
    mod = importlib.import_module(name)
    helpers = set(getattr(mod, "HELPERS", ()))
    kernels = _kernels(mod)
    assert kernels - helpers == set(mod.TWINS), f"{name}: kernels and TWINS differ"
    assert helpers <= kernels, f"{name}: HELPERS names no kernel"


@pytest.mark.parametrize("name", TABLES)
def test_every_twin_resolves_to_a_python_function(name):
    from numba.core.registry import CPUDispatcher

    for kernel, twin in importlib.import_module(name).TWINS.items():
        obj = _resolve(twin)
        assert callable(obj) and not isinstance(obj, CPUDispatcher), f"{kernel} -> {twin}"


def test_every_kernel_has_a_test_against_its_twin():
    marked = _marked_kernels()
    missing = sorted(f"{name}.{k}" for name in TABLES for k in importlib.import_module(name).TWINS)
    missing = [m for m in missing if m.rsplit(".", 1)[1] not in marked]
    assert not missing, f"kernels without a @pytest.mark.twin test: {missing}"


def test_kernel_names_are_unique_across_the_tables():
    """The marker names kernels without their module: a name must say which kernel it is."""
    seen: dict[str, str] = {}
    for name in TABLES:
        for k in importlib.import_module(name).TWINS:
            assert k not in seen, f"{k} in {name} and {seen[k]}"
            seen[k] = name


def test_every_kernel_has_a_caller():
    """A kernel nothing in the package calls is dead: delete it (and its twin if it is dead
    too)."""
    used = _used_names()
    dead = []
    for name in TABLES:
        mod = importlib.import_module(name)
        own = Path(mod.__file__ or "")
        test_only = set(getattr(mod, "TEST_ONLY", ()))
        assert test_only <= set(mod.TWINS), f"{name}: TEST_ONLY names no kernel of the table"
        for k in set(mod.TWINS) - test_only:
            callers = used.get(k, set()) - {own}
            in_module = own.read_text(encoding="utf-8").count(f"{k}(") > 1  # beyond its def
            if not callers and not in_module:
                dead.append(f"{name}.{k}")
    assert not dead, f"kernels without a caller: {dead}"
