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


# Reference, not a diary: no session numbers, no story of the development machine or of the
# agents that worked on the code, no commit hashes (git history and CHANGELOG.md hold those).
DIARY = re.compile(
    r"""(?ix)
      \bsessions?\s+\d | \bsession's
    | \b(first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth|this|last|previous
         |next|earlier|same)\s+session\b
    | \bround\s+\d | \bthis\s+round\b | \bround's\b
    | \b(first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth)\s+round\b
    | \bdevelopment\s+(machine|vm|container)\b | \b\d-core\s+(development\s+)?vm\b
    | \b(this|the|shared)\s+vm\b
    | \bagents?\b | \bhelper\s+agents?\b | \bthe\s+helpers'
    | tried\s+and\s+(reverted|dropped) | \bgit\s+bisect | \bbisected\b | \bre-pinned\b
    """
)
# A commit hash: 7-40 lowercase hex digits with at least one letter and one digit.
COMMIT = re.compile(r"(?<![\w./#-])(?=[0-9a-f]*[a-f])(?=[0-9a-f]*\d)[0-9a-f]{7,40}(?![\w])")
# Files not yet rewritten (other branches are changing them); shrink this list, never grow it.
DIARY_PENDING: set[str] = set()
DIARY_PENDING_DIRS: tuple[str, ...] = ()


def _reference_files() -> list[Path]:
    files = [ROOT / "README.md"]
    for top, pattern in (
        ("docs", "*.md"),
        ("src", "*.py"),
        ("tests", "*.py"),
        ("benchmarks", "*.py"),
    ):
        files += sorted((ROOT / top).rglob(pattern))
    return [
        f
        for f in files
        if (rel := f.relative_to(ROOT).as_posix()) not in DIARY_PENDING
        and not rel.startswith(DIARY_PENDING_DIRS)
    ]


def test_no_diary_in_code_or_docs():
    hits = []
    for f in _reference_files():
        if f == Path(__file__):
            continue
        for k, line in enumerate(f.read_text(encoding="utf-8").splitlines(), 1):
            m = DIARY.search(line) or COMMIT.search(line)
            if m:
                hits.append(f"{f.relative_to(ROOT)}:{k}: {m.group(0)!r}: {line.strip()[:100]}")
    assert hits == []


def test_the_diary_patterns_catch_what_they_are_for():
    for text in (
        "measured in session 7",
        "the third session's figures",
        "Tenth round: stages 1-7",
        "on the 2-core VM",
        "the shared 2-core development machine",
        "three other agents",
        "tried and reverted",
        "before = `d9a87c1`",
    ):
        assert DIARY.search(text) or COMMIT.search(text), text
    for text in (
        "a first pass and a second pass",
        "Stage 2-5 pass 2a",
        "bisect_right(s0, s)",
        "from tests.localization.helpers import LSHAPE",
        "on a loaded machine wall times scatter",
        "0x7fffffff, 1e-9, 2026-11-28, 640x480, deadbeef",
        "sha256 e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855",
    ):
        assert not DIARY.search(text) and not COMMIT.search(text), text
