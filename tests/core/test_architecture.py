"""The dependency rule of docs/architecture.md, checked on the source: a capability never imports
io, viz, cli or sim; the core (geometry, sensors) imports no capability."""

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2] / "src" / "navkit"
CAPABILITIES = ("obstacles", "planes", "stereo", "localization", "path")
EDGE = ("io", "viz", "cli", "sim", "mission", "experiments")
CORE = ("geometry", "sensors")


def navkit_imports(path: Path) -> set[str]:
    """Top-level navkit sub-packages a module imports (``navkit.io.atomic`` -> ``io``)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        else:
            continue
        for name in names:
            parts = name.split(".")
            if parts[0] == "navkit" and len(parts) > 1:
                found.add(parts[1])
    return found


def modules(package: str) -> list[Path]:
    return sorted((SRC / package).rglob("*.py"))


@pytest.mark.parametrize("package", CAPABILITIES)
def test_capabilities_do_not_import_the_edge(package):
    offenders = {
        str(p.relative_to(SRC)): sorted(navkit_imports(p) & set(EDGE)) for p in modules(package)
    }
    assert {k: v for k, v in offenders.items() if v} == {}


@pytest.mark.parametrize("package", CORE)
def test_core_imports_no_capability(package):
    forbidden = set(CAPABILITIES) | set(EDGE)
    offenders = {
        str(p.relative_to(SRC)): sorted(navkit_imports(p) & forbidden) for p in modules(package)
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_the_checker_sees_imports(tmp_path):
    f = tmp_path / "m.py"
    f.write_text(
        "import navkit.io.atomic\nfrom navkit.sim import Scene\nfrom navkit import errors\n"
    )
    assert navkit_imports(f) == {"io", "sim"}
