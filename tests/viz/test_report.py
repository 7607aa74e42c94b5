"""The HTML report: self-contained, escaped, and rendered by a real browser with the figures visible."""

import re

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from navkit.viz.report import Report

from .browser import open_page


def _report() -> Report:
    fig, ax = plt.subplots(figsize=(6, 4))
    t = np.linspace(0, 2 * np.pi, 200)
    ax.fill(np.cos(t), np.sin(t), color="tab:red")
    ax.set_aspect("equal")
    r = Report("Test <report>", subtitle="made by the tests")
    r.section("A figure").add_figure(fig, caption="a red disc")
    r.section("Figures").add_table(
        "numbers", [("error", 0.123456), ("count", 3)], header=("what", "value")
    )
    return r


def test_report_is_self_contained_and_escaped(tmp_path):
    page = _report().write(tmp_path / "report.html")
    text = page.read_text()
    assert "Test &lt;report&gt;" in text and "<report>" not in text
    assert re.search(r'src="data:image/png;base64,[A-Za-z0-9+/=]{1000,}"', text)
    assert "http://" not in text and "https://" not in text and "<script" not in text
    assert '<td class="num">0.1235</td>' in text


def test_report_renders_in_headless_chromium(tmp_path):
    import cv2

    page = _report().write(tmp_path / "report.html")
    result = open_page(page, tmp_path / "shot.png", size=(1000, 900))
    assert result.console_errors == []
    shot = cv2.imread(str(result.screenshot))
    assert shot is not None and shot.shape[0] > 100
    # the embedded figure is visible: a large patch of tab:red (BGR ~ (40, 39, 214)) on the page
    red = (shot[..., 2] > 180) & (shot[..., 1] < 80) & (shot[..., 0] < 80)
    assert red.sum() > 5000
