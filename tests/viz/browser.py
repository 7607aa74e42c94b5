"""Open a page in headless Chromium: screenshot and console errors (skips where Chromium is absent)."""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import pytest

CHROMIUM_FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
    "--enable-logging=stderr",
    "--v=0",
]


@dataclass
class BrowserResult:
    screenshot: Path
    console_errors: list[str]


def chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    pytest.skip(
        "headless Chromium is not installed (Debian package 'chromium'; .ci/run installs it)"
    )


def open_page(page: Path, screenshot: Path, size: tuple[int, int] = (1280, 2400)) -> BrowserResult:
    """Render ``page`` (a local file) in headless Chromium, save a screenshot, collect console errors."""
    with tempfile.TemporaryDirectory() as profile:
        proc = subprocess.run(
            [
                chromium(),
                *CHROMIUM_FLAGS,
                f"--user-data-dir={profile}",
                f"--window-size={size[0]},{size[1]}",
                f"--screenshot={screenshot}",
                page.resolve().as_uri(),
            ],
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
    # Chromium logs page console messages as 'CONSOLE(line)] "message", source: url'; page
    # errors (uncaught exceptions, failed loads of the page's own resources) come the same way.
    errors = [
        line
        for line in proc.stderr.splitlines()
        if (re.search(r"CONSOLE|Uncaught|Failed to load resource", line) and page.name in line)
        or "Uncaught" in line
    ]
    return BrowserResult(screenshot=screenshot, console_errors=errors)
