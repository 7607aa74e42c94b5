"""Docs and project hygiene: no link out of the repository, relative links resolve, a changelog
that knows the current version, project URLs."""

from __future__ import annotations

import re
from pathlib import Path

import navkit

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[2]
DOCS = [ROOT / "README.md", ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").rglob("*.md"))]
LINK = re.compile(r"\]\(([^)\s]+)\)")


def test_no_doc_points_outside_the_repository():
    offenders = []
    for doc in DOCS:
        for k, line in enumerate(doc.read_text(encoding="utf-8").splitlines(), 1):
            if "../shared" in line or "shared/data" in line or "shared/specs" in line:
                offenders.append(f"{doc.relative_to(ROOT)}:{k}: {line.strip()}")
    assert offenders == []


def test_relative_links_resolve_inside_the_repository():
    broken = []
    for doc in DOCS:
        for target in LINK.findall(doc.read_text(encoding="utf-8")):
            if re.match(r"[a-z]+://|#|mailto:", target):
                continue
            path = (doc.parent / target.split("#")[0]).resolve()
            if not path.exists() or ROOT not in path.parents:
                broken.append(f"{doc.relative_to(ROOT)}: {target}")
    assert broken == []


def test_changelog_and_project_metadata():
    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    assert "## [Unreleased]" in text and "Semantic Versioning" in text
    assert f"## [{navkit.__version__}]" in text  # the released version is listed
    assert re.fullmatch(r"\d+\.\d+\.\d+", navkit.__version__)  # SemVer, tagged vX.Y.Z
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert {"Homepage", "Repository", "Changelog"} <= set(meta["urls"])
    assert all(u.startswith("https://") for u in meta["urls"].values())
