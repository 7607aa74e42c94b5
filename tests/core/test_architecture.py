"""The dependency rule of the shared ARCHITECTURE.md and docs/architecture.md, checked on the
source: every import anywhere in a module (top level or inside a function, absolute or relative)
counts. Layers, bottom up: core (errors, geometry, sensors, ...) <- capabilities <- io, sim <- viz
<- mission, experiments <- runtime, batch <- cli; the mission never imports viz (the CLI joins
them), the runtime and batch layers may (their sinks write figures and views). No cycles between packages."""

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2] / "src" / "navkit"
CORE = {
    "errors",
    "geometry",
    "sensors",
    "timing",
    "datasets",
    "jit",
    "domains",  # the declared domains of options, settings and file fields
    "results",  # the online objects' Result / Failure bases
    "_intrinsics",  # Numba intrinsics shared by the capabilities' kernels
    "_version",
    "__init__",
}
CAPABILITIES = {"obstacles", "planes", "stereo", "localization", "path"}
ALLOWED = {
    "geometry": {"errors", "jit", "domains"},
    "sensors": {"errors", "geometry"},
    **{c: CORE for c in CAPABILITIES},  # and no other capability
    "io": CORE | CAPABILITIES,
    "sim": CORE | CAPABILITIES,
    "viz": CORE | CAPABILITIES | {"io", "sim"},
    "mission": CORE | CAPABILITIES | {"io", "sim"},
    "experiments": CORE | CAPABILITIES | {"io", "sim"},
    # the runtime and the batch layer write their outputs and views through io and viz (sinks)
    "runtime": CORE | CAPABILITIES | {"io", "sim", "viz", "mission"},
    "batch": CORE | CAPABILITIES | {"io", "sim", "viz", "mission", "runtime"},
}


def package_of(path: Path) -> str:
    rel = path.relative_to(SRC)
    return rel.parts[0] if len(rel.parts) > 1 else rel.stem


def is_module(name: str) -> bool:
    """A navkit sub-package or module (not a name such as ``__version__``)."""
    return (SRC / name).is_dir() or (SRC / f"{name}.py").is_file()


def navkit_imports(path: Path) -> set[str]:
    """Top-level navkit sub-packages a module imports anywhere (``navkit.io.atomic`` -> ``io``,
    ``from navkit import io`` -> ``io``, ``from ..io import x`` -> ``io``)."""
    rel = path.relative_to(SRC) if path.is_relative_to(SRC) else Path(path.name)
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = ["navkit", *rel.parts[: len(rel.parts) - node.level]]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            names = [f"{mod}.{a.name}" for a in node.names] if mod == "navkit" else [mod]
        else:
            continue
        for name in names:
            parts = name.split(".")
            if parts[0] == "navkit" and len(parts) > 1 and is_module(parts[1]):
                found.add(parts[1])
    return found


def graph() -> dict[str, set[str]]:
    g: dict[str, set[str]] = {}
    for p in SRC.rglob("*.py"):
        pkg = package_of(p)
        g.setdefault(pkg, set()).update(navkit_imports(p) - {pkg})
    return g


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_each_package_imports_only_the_layers_below(package):
    if not (SRC / package).is_dir():
        pytest.skip(f"no navkit.{package} package yet")
    offenders = {
        str(p.relative_to(SRC)): sorted(navkit_imports(p) - ALLOWED[package] - {package})
        for p in sorted((SRC / package).rglob("*.py"))
    }
    assert {k: v for k, v in offenders.items() if v} == {}


def test_no_cycles_between_packages():
    g = graph()
    state: dict[str, int] = {}
    cycles = []

    def visit(n: str, stack: list[str]) -> None:
        state[n] = 1
        for m in sorted(g.get(n, ())):
            if state.get(m) == 1:
                cycles.append([*stack[stack.index(m) :], m] if m in stack else [n, m])
            elif m not in state:
                visit(m, [*stack, m])
        state[n] = 2

    for n in sorted(g):
        if n not in state:
            visit(n, [n])
    assert cycles == []


def test_the_checker_sees_imports(tmp_path):
    f = tmp_path / "m.py"
    f.write_text(
        "import navkit.io.atomic\nfrom navkit.sim import Scene\nfrom navkit import errors, viz\n"
        "def f():\n    from navkit.cli.common import progress\n"
    )
    assert navkit_imports(f) == {"io", "sim", "errors", "viz", "cli"}
